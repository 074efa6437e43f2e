//! The constraint force from the recorded multipliers against the rod
//! tension of the pendulum's physics (the paper's Example 1.3, unit mass):
//! for g = |q|² − L², H = |p|²/2 + γ q₂, the exact multiplier on M^H is
//! the tension T = v²/L + γ cos θ (θ from the downward vertical) divided by
//! 2L, and the force on the bob is f = −g_qᵀ λ = −T q/L.
//!
//! The recorded λ and σ are impulses of the two half kicks at a stored q
//! (Störmer–Verlet: λ = (h/2) λ_c, σ = (h/2) μ_c). Each half alone is
//! off the exact multiplier by O(h) (with opposite signs: expanding
//! g(q + h p − h²/2 (H_q + g_qᵀ λ_c)) = 0 gives λ_c = λ(z) − h p·H_q/L² +
//! O(h²), and μ_c the same with +h by the method's symmetry), their sum by
//! O(h²). So the force error at the stored states must fall by 4 when h is
//! halved; a force built from one half only falls by 2. Both are tested:
//! the second shows the test can tell the orders apart.

use geoshake::examples::Pendulum;
use geoshake::{Integrator, Method, Options, Stop, StormerVerlet, Trajectory};

const GAMMA: f64 = 9.81;
const L: f64 = 1.0;
const T_END: f64 = 2.0;

fn run(h: f64, method: Method, every_step: bool) -> Trajectory {
    let p = Pendulum {
        gravity: GAMMA,
        length: L,
    };
    let mut integ = Integrator::new(p, StormerVerlet, h)
        .with_method(method)
        .with_options(Options {
            project_every_step: every_step,
            ..Options::default()
        })
        .with_diagnostics();
    // Released from θ = 1.2 rad with ω = 0.5: v and p·H_q are far from 0,
    // so each half kick's O(h) error is visible.
    let z0 = integ.project_to_hidden(&p.state(1.2, 0.5)).unwrap();
    // States at the same times for every h: t = 0, 0.05, 0.1, …
    let stride = (0.05 / h).round() as u64;
    integ
        .run(z0, Stop::Time(T_END))
        .stride(stride)
        .execute()
        .into_result()
        .unwrap()
}

/// The exact force −T q/L at (q, p): the tension from the state.
fn exact_force(q: &[f64], p: &[f64]) -> [f64; 2] {
    let v2 = p[0] * p[0] + p[1] * p[1];
    let cos_theta = -q[1] / L;
    let t = v2 / L + GAMMA * cos_theta;
    [-t * q[0] / L, -t * q[1] / L]
}

/// Largest |f − f_exact|∞ over the stored states (the first has no step
/// arriving, the last none leaving),
/// with f from λ + σ (`halves = false`) or from 2σ (`halves = true`).
fn force_error(traj: &Trajectory, halves: bool) -> f64 {
    let sys = Pendulum {
        gravity: GAMMA,
        length: L,
    };
    let mut worst: f64 = 0.0;
    let mut f = [0.0; 2];
    for i in 1..traj.len() - 1 {
        assert!(traj.constraint_force(&sys, i, &mut f));
        let (q, p) = (traj.q(i), traj.p(i));
        if halves {
            // −g_qᵀ (2σ/h): the last half kick alone, doubled.
            let c = 2.0 * traj.sigma(i)[0] / traj_h(traj);
            f = [-2.0 * q[0] * c, -2.0 * q[1] * c];
        }
        let e = exact_force(q, p);
        worst = worst.max((f[0] - e[0]).abs()).max((f[1] - e[1]).abs());
    }
    worst
}

fn traj_h(traj: &Trajectory) -> f64 {
    (traj.time(1) - traj.time(0)) / traj.step(1) as f64
}

#[test]
fn rattle_force_is_the_rod_tension_to_second_order() {
    let hs = [0.01, 0.005, 0.0025];
    let errs: Vec<f64> = hs
        .iter()
        .map(|&h| force_error(&run(h, Method::Rattle, false), false))
        .collect();
    println!("RATTLE force error {errs:?}");
    // The tension reaches ~20 here; C h² with C of the order of the
    // derivatives of the motion (γ, v², ~10²) stays below 1e-2 at h = 0.01.
    assert!(errs[0] < 1e-2, "{errs:?}");
    for w in errs.windows(2) {
        let ratio = w[0] / w[1];
        assert!((3.6..4.4).contains(&ratio), "ratio {ratio}, {errs:?}");
    }
}

#[test]
fn one_half_kick_alone_is_first_order() {
    let errs: Vec<f64> = [0.01, 0.005]
        .iter()
        .map(|&h| force_error(&run(h, Method::Rattle, false), true))
        .collect();
    let ratio = errs[0] / errs[1];
    assert!((1.8..2.2).contains(&ratio), "ratio {ratio}, {errs:?}");
}

#[test]
fn shake_force_is_second_order_too() {
    // SHAKE does not project (σ = 0): λ is the whole impulse at q. Its
    // stored p is not tangent (O(h) off M^H), so the tension is evaluated
    // from the RATTLE state at the same q, the projection of p.
    let hs = [0.01, 0.005, 0.0025];
    let errs: Vec<f64> = hs
        .iter()
        .map(|&h| {
            let traj = run(h, Method::Shake, false);
            assert!((0..traj.len()).all(|i| traj.sigma(i)[0] == 0.0));
            let sys = Pendulum {
                gravity: GAMMA,
                length: L,
            };
            let mut worst: f64 = 0.0;
            let mut f = [0.0; 2];
            for i in 1..traj.len() - 1 {
                assert!(traj.constraint_force(&sys, i, &mut f));
                let (q, p) = (traj.q(i), traj.p(i));
                // Tangential part of p (Π for this g moves p along q).
                let s = (q[0] * p[0] + q[1] * p[1]) / (L * L);
                let pt = [p[0] - s * q[0], p[1] - s * q[1]];
                let e = exact_force(q, &pt);
                worst = worst.max((f[0] - e[0]).abs()).max((f[1] - e[1]).abs());
            }
            worst
        })
        .collect();
    println!("SHAKE force error {errs:?}");
    for w in errs.windows(2) {
        let ratio = w[0] / w[1];
        assert!((3.6..4.4).contains(&ratio), "ratio {ratio}, {errs:?}");
    }
}

#[test]
fn multipliers_do_not_depend_on_where_rattle_projects() {
    // Π ∘ S_hᵏ = Π ∘ R_hᵏ: projecting every step or only the stored states
    // gives the same states, so the same λ and σ, to round-off (λ of the
    // run that projects only the stored states has σ taken off).
    let a = run(0.01, Method::Rattle, false);
    let b = run(0.01, Method::Rattle, true);
    assert_eq!(a.len(), b.len());
    for i in 0..a.len() - 1 {
        for (x, y) in [
            (a.lambda(i)[0], b.lambda(i)[0]),
            (a.sigma(i)[0], b.sigma(i)[0]),
        ] {
            // λ ~ h·10 = 0.1; a few hundred steps of round-off.
            assert!((x - y).abs() < 1e-12, "record {i}: {x} vs {y}");
        }
    }
    assert!(a.lambda(a.len() - 1)[0].is_nan());
}
