//! Every `Ok` of a projection lies on M and M^H to round-off.
//!
//! Three ways a projection used to return a state off M or M^H:
//! - Π's Newton iteration for σ stops on its update relative to σ. On the
//!   periodic fibres of the Hopf constraint it may settle at σ of 10²–10³
//!   (it went round the fibre), where the last update is lost in the
//!   rounding of σ + Δσ: {g,H} was left 10³ times above its round-off
//!   (41 of 20 000 random starts of the system below). A polish now
//!   restarts σ from 0 at the iterate (`newton::Polish`).
//! - `project` took a state within the constraint tolerance of M and moved
//!   it along its fibre only, so the result was off M by as much as the
//!   input (|g| = 2e-9 for a pendulum state scaled by 1 + 1e-9); such a
//!   state is now brought onto M first.
//! - The relative membership test compared |g| = ∞ with a bound of ∞ and
//!   let a state of size 10²⁰⁰ through; an overflowed g is refused.
//!
//! The check of M^H is independent of the library's own: the distance of
//! the result to M^H, |{g,H}| / ‖∇{g,H}‖₂ with the gradient in closed
//! form, against the rounding of the state itself, ε‖z‖∞. A state on
//! M^H rounded to f64 is that far from it; Π computes its result by a
//! flow along the fibre, which rounds every component at the scale of z,
//! so a few ε‖z‖∞ is what round-off leaves (the unpolished iteration left
//! up to 4 270 ε‖z‖∞).

use geoshake::models::HopfGravity;
use geoshake::prelude::*;
use geoshake::runtime::examples::Pendulum;
use geoshake::{SolveError, SymplecticEuler};

/// Distances to M^H in units of ε‖z‖∞ that round-off leaves.
const ROUNDINGS: f64 = 16.0;

/// HopfGravity(c, r²): H = |p|²/2 − c·q, g = |q|² + |p|² − r², so
/// {g,H} = 2 q·p + 2 c·p and ∇{g,H} = (2p, 2(q + c)).
fn distance_to_mh(c: [f64; 2], q: &[f64], p: &[f64]) -> f64 {
    let gh = 2.0 * (q[0] * p[0] + q[1] * p[1]) + 2.0 * (c[0] * p[0] + c[1] * p[1]);
    let grad =
        2.0 * (p[0].powi(2) + p[1].powi(2) + (q[0] + c[0]).powi(2) + (q[1] + c[1]).powi(2)).sqrt();
    gh.abs() / grad
}

#[test]
fn projection_far_along_a_periodic_fibre_reaches_round_off() {
    // A strong field (|c| = 10⁶) on the Hopf sphere: Newton for σ goes
    // round the fibre many times from a random start.
    let c = [-0.2316, -1.039e6];
    let sys = HopfGravity::new(c[0], c[1], 1.0419);
    let mut seed: u64 = 12345;
    let mut uniform = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut worst = 0.0f64;
    for _ in 0..20_000 {
        let z0 = State::from_slices(&[uniform(), uniform()], &[uniform(), uniform()]);
        let h = 0.1 * uniform().abs();
        let z = Integrator::new(sys, SymplecticEuler, h)
            .project_to_hidden(&z0)
            .expect("a start of size 1 projects");
        let zmax = z.q.amax().max(z.p.amax());
        let rel = distance_to_mh(c, z.q.as_slice(), z.p.as_slice()) / (f64::EPSILON * zmax);
        worst = worst.max(rel);
        let mut g = [0.0];
        sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
        // g = |z|² − r² with terms of size ~1: its round-off.
        assert!(
            g[0].abs() <= 8.0 * f64::EPSILON,
            "|g| = {:e} at {z:?}",
            g[0]
        );
    }
    assert!(worst <= ROUNDINGS, "a result {worst:.0} ε‖z‖ from M^H");
}

#[test]
fn project_brings_a_state_near_m_onto_m() {
    let sys = Pendulum::default();
    let th: f64 = 0.7;
    for scale in [1.0 + 1e-9, 1.0 + 1e-12, 1.0 - 3e-10] {
        // A state on M^H of the unit pendulum, scaled off M within the
        // default constraint tolerance (1e-8 relative).
        let z0 = State::from_slices(
            &[scale * th.sin(), -scale * th.cos()],
            &[scale * 0.3 * th.cos(), scale * 0.3 * th.sin()],
        );
        let z = Integrator::new(sys, StormerVerlet, 0.1)
            .project(&z0)
            .expect("within the tolerance");
        let (mut g, mut gh) = ([0.0], [0.0]);
        sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
        sys.hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
        // g = |q|² − 1 and {g,H} = 2 q·p/m: terms of size 1 and 0.6.
        assert!(
            g[0].abs() <= 4.0 * f64::EPSILON,
            "×{scale}: |g| = {:e}",
            g[0]
        );
        assert!(
            gh[0].abs() <= 4.0 * f64::EPSILON,
            "×{scale}: |{{g,H}}| = {:e}",
            gh[0]
        );
        // Onto M orthogonally, then along the fibre: q is the nearest
        // point of the circle, as far from z0 as z0 was from M.
        let moved = (z.q[0] - z0.q[0]).hypot(z.q[1] - z0.q[1]);
        assert!(
            (moved - (scale - 1.0).abs()).abs() <= 4.0 * f64::EPSILON,
            "{moved:e}"
        );
    }
}

#[test]
fn a_state_whose_g_overflows_is_not_on_m() {
    let th: f64 = 0.7;
    let s = 1e200;
    let z0 = State::from_slices(&[s * th.sin(), -s * th.cos()], &[s * 0.3, s * 0.4]);
    for r in [
        Integrator::new(Pendulum::default(), StormerVerlet, 0.1).project(&z0),
        Integrator::new(Pendulum::default(), StormerVerlet, 0.1).project_to_hidden(&z0),
    ] {
        match r {
            Err(StepError::NotOnConstraint {
                cause: Some(SolveError::NonFinite { .. }),
                ..
            }) => {}
            other => panic!("|g| = ∞ was taken for on M: {other:?}"),
        }
    }
}

/// Momentum-dependent constraints coisotropic on M only, with the
/// parameter that shifts M to the ends of f64 (once a hang of every base
/// map): M lies where p_y² overflows, so no state of M can be computed,
/// and every base map must say so with a typed error within the deadline.
#[test]
fn an_extreme_parameter_ends_in_a_typed_error() {
    use crate::oracle::MomentumDependent;
    use geoshake::ImplicitMidpoint;
    for c in [f64::MAX, -f64::MAX, 1e300, 1e160] {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let sys = MomentumDependent::new(c);
            let z0 = State::from_slices(&[0.1, 0.2, 0.3], &[0.4, 0.5, 0.6]);
            let oks = [
                Integrator::new(sys, StormerVerlet, 0.1)
                    .project_to_hidden(&z0)
                    .is_ok(),
                Integrator::new(sys, SymplecticEuler, 0.1)
                    .project_to_hidden(&z0)
                    .is_ok(),
                Integrator::new(sys, ImplicitMidpoint, 0.1)
                    .project_to_hidden(&z0)
                    .is_ok(),
            ];
            tx.send(oks).unwrap();
        });
        // Each answer takes microseconds; the deadline is for a hang.
        match rx.recv_timeout(std::time::Duration::from_secs(20)) {
            Ok(oks) => assert_eq!(oks, [false; 3], "c = {c:e}: a state of M found"),
            Err(_) => panic!("c = {c:e}: no answer within 20 s"),
        }
    }
}
