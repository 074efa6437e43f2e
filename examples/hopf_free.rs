//! The harmonic (Hopf) constraint with H = |p|²/2, the paper's Section 5.4.1.
//!
//!     cargo run --release --example hopf_free
//!
//! On the unit sphere |q|² + |p|² = 1 of R⁴ the hidden constraint is q·p = 0,
//! and the exact solution turns q and p in their planes at the constant
//! angular speed ω = (q0∧p0)/(|q0|² − |p0|²) (eq hopf_dea_exact_solution,
//! with α = −sign(q0∧p0)|p0|/|q0|). RATTLE over the midpoint rule stays on
//! that circle to round-off; only the timing differs: it turns a little
//! faster, ω_h = ω(1 + O(h²)).

use geoshake::models::HopfFree;
use geoshake::{ImplicitMidpoint, Integrator, State, Stop};

fn main() {
    let h = 0.1;
    // |q| = 0.8 > |p| = 0.6, q ⊥ p: a point of M^H (component |q| > |p|).
    let z0 = State::from_slices(&[0.8, 0.0], &[0.0, 0.6]);
    let (qq, pp) = (0.64, 0.36);
    let omega = (z0.q[0] * z0.p[1] - z0.q[1] * z0.p[0]) / (qq - pp);
    let lambda = pp / (2.0 * (qq - pp));
    println!("H = |p|²/2 on |q|² + |p|² = 1, midpoint RATTLE, h = {h}");
    println!("exact: ω = {omega:.6}, λ = |p|²/(2(|q|²−|p|²)) = {lambda:.6} (the paper's λ is twice this)");

    let mut shake = Integrator::new(HopfFree::new(1.0), ImplicitMidpoint, h).shake();
    shake.step(&z0).expect("one SHAKE step");
    println!(
        "SHAKE's fibre displacement in the first step: μ/h = {:.6} (half of λ: the projection adds the rest)",
        shake.last_multipliers()[0] / h
    );

    let mut rattle = Integrator::new(HopfFree::new(1.0), ImplicitMidpoint, h).rattle();
    let out = rattle.run(z0, Stop::Time(100.0)).execute();
    let traj = out
        .into_result()
        .expect("H = |p|²/2 is well posed off the exceptional fibres");
    println!(
        "\n{:>6} {:>11} {:>11} {:>11} {:>12} {:>12}",
        "t", "|q| − 0.8", "|p| − 0.6", "q·p", "angle θ", "θ − ω t"
    );
    // On the exact circle q = 0.8 (cos θ, sin θ), p = 0.6 (−sin θ, cos θ);
    // one step turns by about ω h, so the angle is unwrapped step by step.
    let mut angle = 0.0;
    for (k, (s, t)) in traj.states().zip(traj.times()).enumerate() {
        let a = s.q[1].atan2(s.q[0]);
        angle += (a - angle + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        if k % 100 == 0 {
            println!(
                "{t:>6.1} {:>11.1e} {:>11.1e} {:>11.1e} {angle:>12.6} {:>12.6}",
                s.q.norm() - 0.8,
                s.p.norm() - 0.6,
                s.q.dot(&s.p),
                angle - omega * t
            );
        }
    }
    let t = *traj.times().last().unwrap();
    println!(
        "\nnumerical angular speed ω_h = {:.8}: ω_h/ω − 1 = {:.3e} (O(h²)); the points stay on the circle",
        angle / t,
        angle / t / omega - 1.0
    );
}
