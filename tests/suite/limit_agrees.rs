//! The hand-written limit of `examples/overhead.rs` (shake-testkit/src/bench/limit.rs)
//! computes the same RATTLE steps as the library, to round-off: from each
//! state of a library run, one step of each, compared. Not a timing test.

use geoshake_testkit::bench::limit;

use geoshake::{Integrator, State, StormerVerlet};
use limit::{limit_chain_state, pairs, LimitChain, LimitPendulum};

const H: f64 = 0.01;

/// Both solve the same equations to round-off: their steps differ by a few
/// ulps of the state, amplified by the conditioning of the Newton solves.
fn tolerance(z: &State) -> f64 {
    64.0 * f64::EPSILON * z.q.amax().max(z.p.amax()).max(1.0)
}

#[test]
fn the_limit_pendulum_takes_the_library_steps() {
    let sys = geoshake::models::Pendulum::new(1.3, 9.81);
    let lim = LimitPendulum {
        length: 1.3,
        gravity: 9.81,
    };
    let mut integ = Integrator::new(sys, StormerVerlet, H).rattle();
    let mut z = integ
        .project_to_hidden(&State::from_slices(&[1.0, -0.8], &[2.0, 1.0]))
        .unwrap();
    for _ in 0..300 {
        let (mut q, mut p) = ([z.q[0], z.q[1]], [z.p[0], z.p[1]]);
        lim.step(H, &mut q, &mut p);
        integ.step_in_place(&mut z).unwrap();
        let diff = State::from_slices(&q, &p).distance(&z);
        assert!(diff <= tolerance(&z), "{diff:e}");
    }
}

#[test]
fn the_limit_chain_takes_the_library_steps() {
    let sys = geoshake::models::Chain8::new(1.0, 1.0);
    let mut lim = LimitChain::<8>::new(1.0, 1.0);
    let mut integ = Integrator::new(sys, StormerVerlet, H).rattle();
    let (q0, p0) = limit_chain_state(8, 1.0);
    let mut z = State::from_slices(&q0, &p0);
    let mut worst = 0.0f64;
    for _ in 0..300 {
        let (mut q, mut p) = (pairs::<8>(z.q.as_slice()), pairs::<8>(z.p.as_slice()));
        lim.step(H, &mut q, &mut p);
        integ.step_in_place(&mut z).unwrap();
        let diff = State::from_slices(q.as_flattened(), p.as_flattened()).distance(&z);
        worst = worst.max(diff / tolerance(&z));
        assert!(diff <= tolerance(&z), "{diff:e}");
    }
    println!("worst difference / tolerance: {worst:.3}");
}
