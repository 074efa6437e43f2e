//! What the reverse check of composed steps costs (`Options::reverse_tolerance`,
//! BENCHMARKS.md section 7.1):
//!
//!     cargo run --release --example reverse_check_cost
//!
//! µs per step of a lazily projected RATTLE run, best of 5, with the check
//! on (the default) and off, for the triple jump and Yoshida 6A over the
//! pendulum (Störmer–Verlet, the classical path) and the Hopf scene with
//! gravity (implicit midpoint, the general path), one line per run:
//! `reverse_check run=… on_us=… off_us=… ratio=…`.

use geoshake::BaseMap;
use geoshake::{
    Composition, ConstrainedSystem, ImplicitMidpoint, Integrator, Options, State, Stop,
    StormerVerlet,
};
use geoshake_testkit::models::{Hopf, Pendulum};

/// Best of 5 runs of `n` steps from `z0`, µs per step.
fn per_step<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: &S,
    base: B,
    c: Composition,
    reverse_tolerance: f64,
    z0: &State,
    n: u64,
) -> f64 {
    let opts = Options {
        reverse_tolerance,
        ..Options::default()
    };
    let mut best = f64::INFINITY;
    for _ in 0..5 {
        let t = std::time::Instant::now();
        let out = Integrator::new(sys.clone(), base, 0.01)
            .composed(c)
            .with_options(opts)
            .run(z0.clone(), Stop::Steps(n))
            .execute();
        let us = t.elapsed().as_secs_f64() * 1e6 / n as f64;
        assert!(out.error.is_none(), "{:?}", out.error);
        best = best.min(us);
    }
    best
}

fn line(run: &str, on: f64, off: f64) {
    println!(
        "reverse_check run={run} on_us={on:.3} off_us={off:.3} ratio={:.2}",
        on / off
    );
}

fn main() {
    let pendulum = Pendulum::default();
    let zp = pendulum.state(1.0, 0.5);
    let hopf = Hopf::gravity();
    let zh = Integrator::new(hopf, ImplicitMidpoint, 0.01)
        .project_to_hidden(&State::from_slices(
            &[-0.78652612, -0.4043988],
            &[-0.3880746864163783, 0.2173391755798215],
        ))
        .expect("the Hopf start projects onto M^H");
    for (c, tag) in [
        (Composition::TRIPLE_JUMP, "triple_jump"),
        (Composition::YOSHIDA_6, "yoshida_6"),
    ] {
        let p = |tol| per_step(&pendulum, StormerVerlet, c, tol, &zp, 20_000);
        line(&format!("pendulum_sv_{tag}"), p(1e-6), p(f64::INFINITY));
        let h = |tol| per_step(&hopf, ImplicitMidpoint, c, tol, &zh, 5_000);
        line(&format!("hopf_midpoint_{tag}"), h(1e-6), h(f64::INFINITY));
    }
}
