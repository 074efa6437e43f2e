//! A base map written outside the runtime, against its public API only
//! (in the test kit, `shake_testkit::yoshida`, so that this example and
//! `tests/custom_base_map.rs` run the same code):
//! Yoshida's fourth-order composition of a symmetric base map ψ_h,
//!
//!   φ_h = ψ_{γ₁h} ∘ ψ_{γ₂h} ∘ ψ_{γ₁h},  γ₁ = 1/(2 − 2^{1/3}), γ₂ = 1 − 2γ₁
//!
//! (Yoshida 1990; Hairer, Lubich & Wanner, *Geometric Numerical
//! Integration*, II.4). A composition of symplectic maps is symplectic, the
//! symmetric composition of a symmetric map is symmetric, and the order
//! rises from 2 to 4. Its tangent map is the product of the three stages'
//! tangent maps, each taken at the point where that stage was applied: the
//! workspace keeps one workspace of ψ per stage, so each stage remembers its
//! own input.
//!
//! SHAKE and RATTLE take any [`BaseMap`] (the paper's Definitions 1.1 and
//! 1.2). The example prints, at T = 1:
//!
//! 1. φ_h alone (RATTLE with no constraint, `Unconstrained`) on the harmonic
//!    oscillator against its exact solution: order 4;
//! 2. RATTLE over φ_h for the planar pendulum against the angle ODE solved
//!    by RK4 at a tiny step, next to RATTLE over Störmer–Verlet: both order
//!    2, with the same error constant to three digits. The constraint step
//!    (λ, σ), not the base map, limits geometric RATTLE to order 2; a
//!    fourth-order method on M^H is RATTLE *composed* (Section 4,
//!    [`Composition`]), shown in the last column over φ_h.
//!
//! `tests/custom_base_map.rs` checks these orders and the symplecticity of
//! RATTLE over φ_h on M^H.
//!
//! Run with `cargo run --release --example custom_base_map`.

use shake::models::Pendulum;
use shake::runtime::examples::HarmonicOscillator;
use shake::{BaseMap, Composition, Integrator, State, Stop, StormerVerlet, Unconstrained};
use shake_testkit::reference::{pendulum_reference, pendulum_state};
use shake_testkit::yoshida::Yoshida4;

/// The global error at T = 1 of RATTLE over `base` with step `h`, composed
/// by `c`.
fn rattle_error<B: BaseMap>(base: B, c: Composition, h: f64) -> f64 {
    let (length, gravity, theta, omega, t) = (1.0, 9.81, 1.0, 0.0, 1.0);
    let sys = Pendulum::new(length, gravity);
    let z0 = pendulum_state(length, theta, omega);
    let mut integ = Integrator::new(sys, base, h).rattle().composed(c);
    let traj = integ
        .run(z0, Stop::Time(t))
        .stride(u64::MAX)
        .execute()
        .into_result()
        .expect("the pendulum swing runs");
    let last = traj.last().expect("the last state is stored");
    let (th, om) = pendulum_reference(gravity, length, theta, omega, t);
    last.distance(&pendulum_state(length, th, om))
}

/// The global error at T = 1 of `base` alone on q'' = −q from (1, 0)
/// (exact solution (cos t, −sin t)).
fn free_error<B: BaseMap>(base: B, h: f64) -> f64 {
    let mut integ = Integrator::new(Unconstrained(HarmonicOscillator), base, h);
    let traj = integ
        .run(State::from_slices(&[1.0], &[0.0]), Stop::Time(1.0))
        .stride(u64::MAX)
        .execute()
        .into_result()
        .expect("the oscillator runs");
    let last = traj.last().expect("the last state is stored");
    last.distance(&State::from_slices(&[1f64.cos()], &[-1f64.sin()]))
}

fn order(prev: Option<f64>, e: f64) -> String {
    prev.map(|a| format!("{:.2}", (a / e).log2()))
        .unwrap_or_default()
}

fn main() {
    println!("Global errors at T = 1 (orders from halving h):");
    println!(
        "{:>7}  {:>20}  {:>20}  {:>20}  {:>20}",
        "h", "φ_h alone (osc.)", "RATTLE/SV (pend.)", "RATTLE/φ_h (pend.)", "RATTLE/φ_h ∘ TJ"
    );
    let mut prev = [None; 4];
    for h in [0.1, 0.05, 0.025, 0.0125] {
        let e = [
            free_error(Yoshida4(StormerVerlet), h),
            rattle_error(StormerVerlet, Composition::SINGLE, h),
            rattle_error(Yoshida4(StormerVerlet), Composition::SINGLE, h),
            rattle_error(Yoshida4(StormerVerlet), Composition::TRIPLE_JUMP, h),
        ];
        let cells: Vec<String> = (0..4)
            .map(|i| format!("{:.3e} ({:>4})", e[i], order(prev[i], e[i])))
            .collect();
        println!(
            "{h:>7}  {:>20}  {:>20}  {:>20}  {:>20}",
            cells[0], cells[1], cells[2], cells[3]
        );
        prev = e.map(Some);
    }
}
