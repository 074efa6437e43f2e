//! Self-tests of the independent oracles in `shake-testkit/src/reference.rs`:
//! against each other, against closed forms and against known facts, so that
//! the oracles themselves can be trusted. Every tolerance says where it comes
//! from: round-off where the quantity is exact, O(h^k) where a method of
//! order k is involved.

use crate::common;

use common::reference::*;
use nalgebra::DVector;
use std::f64::consts::PI;

const EPS: f64 = f64::EPSILON;

fn v(x: &[f64]) -> DVector<f64> {
    DVector::from_column_slice(x)
}

/// A point of the Hopf M^H for H = |p|²/2 on the sphere |z|² = a² + b²:
/// q = a(cos φ, sin φ), p = ε b(−sin φ, cos φ).
fn hopf_mh_point(a: f64, b: f64, phi: f64, eps: f64) -> ([f64; 2], [f64; 2]) {
    (
        [a * phi.cos(), a * phi.sin()],
        [-eps * b * phi.sin(), eps * b * phi.cos()],
    )
}

fn z4(q: [f64; 2], p: [f64; 2]) -> DVector<f64> {
    v(&[q[0], q[1], p[0], p[1]])
}

/// Observed order log2(e(h)/e(h/2)).
fn order(e_h: f64, e_h2: f64) -> f64 {
    (e_h / e_h2).log2()
}

// ---------------------------------------------------------------------------
// 0. derivatives and brackets
// ---------------------------------------------------------------------------

#[test]
fn num_dual_derivatives_are_exact_on_the_pendulum() {
    let s = PlanarPendulum {
        length: 1.3,
        gravity: 2.0,
    };
    let z = [0.3, -0.7, 0.5, 1.1];
    let (gh, hh) = hessian(&s, Fun::H, &z);
    let (gg, hg) = hessian(&s, Fun::G(0), &z);
    // Closed forms: ∇H = (0, G, p), ∇²H = diag(0,0,1,1); ∇g = (2q, 0), ∇²g = diag(2,2,0,0).
    let gh_exact = v(&[0.0, 2.0, 0.5, 1.1]);
    let gg_exact = v(&[0.6, -1.4, 0.0, 0.0]);
    assert!((gh - &gh_exact).amax() <= 2.0 * EPS);
    assert!((gg - &gg_exact).amax() <= 2.0 * EPS);
    assert!((gradient(&s, Fun::H, &z) - gh_exact).amax() <= 2.0 * EPS);
    for i in 0..4 {
        for j in 0..4 {
            let eh = if i == j && i >= 2 { 1.0 } else { 0.0 };
            let eg = if i == j && i < 2 { 2.0 } else { 0.0 };
            assert_eq!(hh[(i, j)], eh);
            assert_eq!(hg[(i, j)], eg);
        }
    }
    // {g, H} = g_q·H_p − g_p·H_q = 2 q·p.
    let hidden = hidden_constraints(&s, &v(&z))[0];
    assert!((hidden - 2.0 * (0.3 * 0.5 - 0.7 * 1.1)).abs() <= 4.0 * EPS);
}

#[test]
fn multipliers_match_the_pendulum_tension() {
    // By hand (radial force balance, mass 1): on M^H, p' = −(0,G) − 2λq must
    // have radial component −|p|²/ℓ, so λ = (|p|² − G q_2)/(2ℓ²).
    let s = PlanarPendulum {
        length: 1.3,
        gravity: 2.0,
    };
    for &(th, om) in &[(0.0, 0.0), (0.4, 1.0), (2.0, -0.3), (-2.9, 2.5)] {
        let z = s.state(th, om);
        let lam = multipliers(&s, &z)[0];
        let pp = z[2] * z[2] + z[3] * z[3];
        let exact = (pp - s.gravity * z[1]) / (2.0 * s.length * s.length);
        // Round-off of a handful of products and one 1×1 solve.
        assert!(
            (lam - exact).abs() <= 1e-14 * (1.0 + exact.abs()),
            "λ = {lam}, closed form {exact}"
        );
    }
}

#[test]
fn multipliers_match_the_hopf_formula_and_its_scaling() {
    // The N-formula of the reference integrator against eq hopf_lambda,
    // with λ_paper = 2 λ_MISSION.
    for &r2 in &[1.0f64, 0.98] {
        for &(a, eps) in &[(0.9f64, 1.0), (0.9, -1.0), (0.4, 1.0), (0.4, -1.0)] {
            let b = (r2 - a * a).sqrt();
            let (q, p) = hopf_mh_point(a, b, 0.7, eps);
            let lam = multipliers(&HopfFree { radius2: r2 }, &z4(q, p))[0];
            let exact = hopf_lambda(q, p);
            assert!((lam - exact).abs() <= 1e-14 * (1.0 + exact.abs()));
            let paper = b * b / (a * a - b * b);
            assert!((hopf_lambda_paper(q, p) - paper).abs() <= 1e-14 * (1.0 + paper.abs()));
            assert!((paper - 2.0 * lam).abs() <= 1e-14 * (1.0 + paper.abs()));
        }
    }
}

// ---------------------------------------------------------------------------
// 2. the exact Hopf solution
// ---------------------------------------------------------------------------

/// Points of M^H on both components (|q| > |p|, |q| < |p|), both orientations
/// (q ∧ p ≷ 0), and two radii.
fn hopf_cases() -> Vec<([f64; 2], [f64; 2], f64)> {
    let mut out = Vec::new();
    for &r2 in &[1.0f64, 0.98] {
        for &a in &[0.9f64, 0.4] {
            for &eps in &[1.0, -1.0] {
                let b = (r2 - a * a).sqrt();
                let (q, p) = hopf_mh_point(a, b, 1.1, eps);
                out.push((q, p, r2));
            }
        }
    }
    out
}

#[test]
fn hopf_exact_solves_the_dae() {
    // Central differences of the solution against q' = (1+2λ)p, p' = −2λq
    // (MISSION's λ). Error O(δ²·ω³|z|) with δ = 1e-4: ≤ 1e-8·ω³ here.
    let delta = 1e-4;
    for (q0, p0, _) in hopf_cases() {
        let lam = hopf_lambda(q0, p0);
        let omega = (1.0f64.max((lam * (1.0 + 2.0 * lam)).abs())).sqrt();
        for &t in &[0.0, 0.7, 5.3] {
            let (q, p) = hopf_exact(q0, p0, t);
            let (qa, pa) = hopf_exact(q0, p0, t + delta);
            let (qb, pb) = hopf_exact(q0, p0, t - delta);
            for k in 0..2 {
                let dq = (qa[k] - qb[k]) / (2.0 * delta);
                let dp = (pa[k] - pb[k]) / (2.0 * delta);
                let tol = 1e-7 * omega.powi(3);
                assert!((dq - (1.0 + 2.0 * lam) * p[k]).abs() <= tol, "q' residual");
                assert!((dp + 2.0 * lam * q[k]).abs() <= tol, "p' residual");
            }
        }
    }
}

#[test]
fn hopf_exact_stays_on_m_and_mh_and_conserves_h() {
    // Rotations are exact up to round-off in cos/sin: a few ulps.
    for (q0, p0, r2) in hopf_cases() {
        let h0 = 0.5 * (p0[0] * p0[0] + p0[1] * p0[1]);
        for &t in &[0.3, 3.0, 50.0] {
            let (q, p) = hopf_exact(q0, p0, t);
            let g = q[0] * q[0] + q[1] * q[1] + p[0] * p[0] + p[1] * p[1] - r2;
            let qp = q[0] * p[0] + q[1] * p[1];
            let h = 0.5 * (p[0] * p[0] + p[1] * p[1]);
            assert!(g.abs() <= 8.0 * EPS && qp.abs() <= 8.0 * EPS && (h - h0).abs() <= 8.0 * EPS);
        }
        // Group property z(t+s) = z(s)∘z(t): the flow is a one-parameter group.
        let (q1, p1) = hopf_exact(q0, p0, 1.3);
        let (q2, p2) = hopf_exact(q1, p1, 2.1);
        let (q3, p3) = hopf_exact(q0, p0, 3.4);
        for k in 0..2 {
            assert!((q2[k] - q3[k]).abs() <= 1e-14 && (p2[k] - p3[k]).abs() <= 1e-14);
        }
    }
}

#[test]
fn hopf_alpha_sign_follows_the_orientation_not_the_component() {
    // The paper's formula R(t/(α − 1/α)) with α = −sign(q∧p)|p|/|q| is right,
    // with the other sign wrong, on *both* components.
    let t = 1.0;
    for (q0, p0, _) in hopf_cases() {
        let alpha = hopf_alpha_paper(q0, p0);
        let mag = (p0[0].hypot(p0[1])) / q0[0].hypot(q0[1]);
        assert!((alpha.abs() - mag).abs() <= 1e-14 * mag);
        assert_eq!(alpha.signum(), -wedge(q0, p0).signum());
        let (qe, _) = hopf_exact(q0, p0, t);
        let good = rot(t / (alpha - 1.0 / alpha), q0);
        let bad = rot(t / (-alpha + 1.0 / alpha), q0);
        let dist = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]);
        assert!(dist(good, qe) <= 1e-14);
        assert!(
            dist(bad, qe) >= 1e-2,
            "the wrong sign must be visibly wrong"
        );
    }
}

// ---------------------------------------------------------------------------
// 3. the reference integrator
// ---------------------------------------------------------------------------

#[test]
fn reference_agrees_with_the_exact_hopf_solution() {
    // Order-12 GBS with h = 0.05 over t = 10: truncation ≪ 1e-13; the bound
    // 1e-10 leaves room for round-off growth over 200 steps.
    let mut worst: f64 = 0.0;
    for (q0, p0, r2) in hopf_cases() {
        let z = reference_solution(&HopfFree { radius2: r2 }, &z4(q0, p0), 10.0, 200);
        let (q, p) = hopf_exact(q0, p0, 10.0);
        worst = worst.max((z - z4(q, p)).amax());
    }
    println!("reference vs exact Hopf, t = 10: max error {worst:.2e}");
    assert!(worst <= 1e-10);
}

/// The planar pendulum as the angle ODE θ'' = −(G/ℓ) sin θ, by RK4.
fn pendulum_by_angle(s: &PlanarPendulum, th0: f64, om0: f64, t: f64, n: usize) -> DVector<f64> {
    let k = s.gravity / s.length;
    let mut f = |y: &DVector<f64>| v(&[y[1], -k * y[0].sin()]);
    let mut y = v(&[th0, om0]);
    for _ in 0..n {
        y = rk4_step(&mut f, &y, t / n as f64);
    }
    s.state(y[0], y[1])
}

#[test]
fn reference_agrees_with_the_pendulum_angle_ode() {
    let s = PlanarPendulum {
        length: 1.3,
        gravity: 2.0,
    };
    let (th0, om0, t) = (2.0, 0.3, 10.0);
    // RK4 at h = 1e-3: O(h⁴) error; its size is measured by halving h (the
    // difference bounds the error of the finer run up to a factor 16/15).
    let coarse = pendulum_by_angle(&s, th0, om0, t, 10_000);
    let fine = pendulum_by_angle(&s, th0, om0, t, 20_000);
    let rk4_err = (&coarse - &fine).amax();
    let z = reference_solution(&s, &s.state(th0, om0), t, 200);
    let err = (&z - &fine).amax();
    println!("pendulum: RK4 self-difference {rk4_err:.2e}, reference vs RK4 {err:.2e}");
    assert!(rk4_err <= 1e-11);
    assert!(err <= 1e-10);
}

fn check_invariants<S: System>(name: &str, s: &S, z0: &DVector<f64>, t_end: f64) -> f64 {
    let times: Vec<f64> = (1..=t_end as usize).map(|k| k as f64).collect();
    let traj = reference_trajectory(s, z0, &times);
    let h0 = energy(s, z0);
    let mut worst: f64 = 0.0;
    for z in &traj {
        worst = worst
            .max((energy(s, z) - h0).abs())
            .max(constraints(s, z).amax())
            .max(hidden_constraints(s, z).amax());
    }
    println!("{name}: max |ΔH|, |g|, |{{g,H}}| over t ≤ {t_end}: {worst:.2e}");
    worst
}

#[test]
fn reference_keeps_energy_and_constraints() {
    // The invariants are exact for the ODE; what remains is truncation
    // (≪ 1e-13 per unit time) plus round-off of a few hundred steps.
    let tol = 1e-11;
    let sp = SphericalPendulum::default();
    assert!(check_invariants("spherical", &sp, &sp.state(1.0, 0.2, 0.3, 0.9), 20.0) <= tol);
    let dp = DoublePendulum::default();
    assert!(check_invariants("double", &dp, &dp.state(1.2, -0.5, 0.4, 0.8), 10.0) <= tol);
    let hg = HopfGravity::through(&PAPER_Z_A);
    assert!(check_invariants("hopf z_a", &hg, &v(&PAPER_Z_A), 20.0) <= tol);
    let ie = Index1Extended(Index1Example::default());
    let (q0, p0) = (v(&[0.8]), v(&[-0.3]));
    let b0 = index1_beta(&ie.0, &q0, &p0, &v(&[0.0]));
    let z0 = v(&[q0[0], 0.0, p0[0], b0[0]]);
    assert!(check_invariants("index-1 extended", &ie, &z0, 10.0) <= tol);
}

#[test]
fn reference_converges_at_its_order() {
    // GBS with `levels` columns has order 2·levels: halving h divides the
    // error by 2^(2·levels). Truth: order 12 with h = 0.02.
    let s = PlanarPendulum::default();
    let (z0, t) = (s.state(2.0, 0.3), 2.0);
    let truth = reference_solution(&s, &z0, t, 100);
    for &(levels, steps) in &[(2usize, 16usize), (3, 8)] {
        let e = |n: usize| (reference_solution_levels(&s, &z0, t, n, levels) - &truth).amax();
        let (e1, e2, e3) = (e(steps), e(2 * steps), e(4 * steps));
        let (o1, o2) = (order(e1, e2), order(e2, e3));
        println!("levels {levels}: errors {e1:.2e} {e2:.2e} {e3:.2e}, orders {o1:.2} {o2:.2}");
        let p = 2.0 * levels as f64;
        assert!((o2 - p).abs() <= 0.3, "observed order {o2}, expected {p}");
    }
    // The default (order 12) is converged at h = 0.05: halving h changes the
    // result only at the round-off floor (measured 3e-13 to 5e-13 over t = 10
    // for h from 0.1 to 0.0125, not decreasing: accumulated round-off).
    let a = reference_solution(&s, &z0, 10.0, 200);
    let b = reference_solution(&s, &z0, 10.0, 400);
    println!(
        "order 12, h = 0.05 vs 0.025 over t = 10: {:.2e}",
        (&a - &b).amax()
    );
    assert!((a - b).amax() <= 2e-12);
}

// ---------------------------------------------------------------------------
// 1. classical SHAKE and RATTLE
// ---------------------------------------------------------------------------

fn classical_systems_check<S: System>(name: &str, s: &S, z0: &DVector<f64>) {
    let bases = [ClassicalBase::StormerVerlet, ClassicalBase::SymplecticEuler];
    for base in bases {
        // (a) constraints: g(q1) = 0 is solved by Newton to round-off; RATTLE
        // also puts the hidden constraint at round-off, SHAKE does not.
        let (mut zs, mut zr) = (z0.clone(), z0.clone());
        let mut shake_hidden: f64 = 0.0;
        for _ in 0..20 {
            zs = classical_shake_z(s, base, &zs, 0.05);
            zr = classical_rattle_z(s, base, &zr, 0.05);
            assert!(constraints(s, &zs).amax() <= 1e-14, "{name} SHAKE |g|");
            assert!(constraints(s, &zr).amax() <= 1e-14, "{name} RATTLE |g|");
            assert!(
                hidden_constraints(s, &zr).amax() <= 1e-13,
                "{name} RATTLE hidden"
            );
            shake_hidden = shake_hidden.max(hidden_constraints(s, &zs).amax());
            // SHAKE and RATTLE differ only along the fibre: same positions.
            let d = s.dof();
            assert!(
                (zs.rows(0, d) - zr.rows(0, d)).amax() <= 1e-13,
                "{name} positions"
            );
        }
        assert!(shake_hidden >= 1e-6, "{name}: SHAKE should be O(h) off M^H");
        // (b) order against the reference: RATTLE on M^H, t = 1.
        let t = 1.0;
        let truth = reference_solution(s, z0, t, 40);
        let err = |n: usize| {
            let mut z = z0.clone();
            for _ in 0..n {
                z = classical_rattle_z(s, base, &z, t / n as f64);
            }
            (z - &truth).amax()
        };
        let (e1, e2, e3) = (err(10), err(20), err(40));
        let (o1, o2) = (order(e1, e2), order(e2, e3));
        println!("{name} {base:?}: errors {e1:.2e} {e2:.2e} {e3:.2e}, orders {o1:.2} {o2:.2}");
        let expected = match base {
            ClassicalBase::StormerVerlet => 2.0,
            ClassicalBase::SymplecticEuler => 1.0,
        };
        assert!((o2 - expected).abs() <= 0.2, "{name} {base:?}: order {o2}");
    }
}

#[test]
fn classical_methods_on_planar_pendulum() {
    let s = PlanarPendulum::default();
    classical_systems_check("planar", &s, &s.state(1.5, 0.4));
}

#[test]
fn classical_methods_on_spherical_pendulum() {
    let s = SphericalPendulum::default();
    classical_systems_check("spherical", &s, &s.state(1.0, 0.2, 0.3, 0.9));
}

#[test]
fn classical_methods_on_double_pendulum() {
    let s = DoublePendulum::default();
    classical_systems_check("double", &s, &s.state(1.2, -0.5, 0.4, 0.8));
}

#[test]
fn classical_methods_on_non_separable_pendulum() {
    let s = NonSeparablePendulum {
        eps: 0.7,
        gravity: 1.0,
    };
    // On M^H: q = (sin θ, −cos θ), velocity H_p = (1 + ε q_1²) p tangent.
    let th: f64 = 1.1;
    let z0 = v(&[th.sin(), -th.cos(), 0.6 * th.cos(), 0.6 * th.sin()]);
    assert!(hidden_constraints(&s, &z0).amax() <= 1e-15);
    classical_systems_check("non-separable", &s, &z0);
}

#[test]
fn shake_does_not_depend_on_the_point_of_the_fibre() {
    // Claim 4: starting from (q0, p0 + g_q(q0)ᵀc) gives the same z1⁻ (λ absorbs c).
    let s = DoublePendulum::default();
    let z0 = s.state(1.2, -0.5, 0.4, 0.8);
    let (q0, p0) = split(&z0);
    let c = v(&[0.37, -0.81]);
    let mut p0_shifted = p0.clone();
    for i in 0..2 {
        let gr = gradient(&s, Fun::G(i), z0.as_slice());
        for k in 0..4 {
            p0_shifted[k] += gr[k] * c[i];
        }
    }
    for base in [ClassicalBase::StormerVerlet, ClassicalBase::SymplecticEuler] {
        let a = classical_shake(&s, base, &q0, &p0, 0.1);
        let b = classical_shake(&s, base, &q0, &p0_shifted, 0.1);
        // Round-off of one Newton solve with O(1) data.
        assert!((&a.q1 - &b.q1).amax() <= 1e-14);
        assert!((&a.p1_minus - &b.p1_minus).amax() <= 1e-14);
        // and the multipliers differ by exactly the shift: λ_geo = (h/2)λ (SV), hλ (SE).
        let scale = match base {
            ClassicalBase::StormerVerlet => 0.05,
            ClassicalBase::SymplecticEuler => 0.1,
        };
        assert!(((&b.lambda - &a.lambda) * scale - &c).amax() <= 1e-13);
    }
}

#[test]
fn stormer_verlet_rattle_is_symmetric_and_euler_is_not() {
    let s = NonSeparablePendulum {
        eps: 0.7,
        gravity: 1.0,
    };
    let th: f64 = 1.1;
    let z0 = v(&[th.sin(), -th.cos(), 0.6 * th.cos(), 0.6 * th.sin()]);
    let h = 0.1;
    let sv = ClassicalBase::StormerVerlet;
    let back = classical_rattle_z(&s, sv, &classical_rattle_z(&s, sv, &z0, h), -h);
    assert!((&back - &z0).amax() <= 1e-14, "R_-h ∘ R_h = id (round-off)");
    let se = ClassicalBase::SymplecticEuler;
    let back = classical_rattle_z(&s, se, &classical_rattle_z(&s, se, &z0, h), -h);
    // Not symmetric: the defect is O(h²) with an O(1) constant.
    assert!((&back - &z0).amax() >= 1e-4);
}

#[test]
fn stormer_verlet_rattle_energy_does_not_drift() {
    // Symplectic: the energy error oscillates, O(h²), without drift. Compare
    // the largest error in the first and in the last quarter of a long run.
    let s = PlanarPendulum::default();
    let mut z = s.state(2.0, 0.0);
    let h0 = energy(&s, &z);
    let n = 8000;
    let mut errs = Vec::with_capacity(n);
    for _ in 0..n {
        z = classical_rattle_z(&s, ClassicalBase::StormerVerlet, &z, 0.1);
        errs.push((energy(&s, &z) - h0).abs());
    }
    let first = errs[..n / 4].iter().cloned().fold(0.0, f64::max);
    let last = errs[3 * n / 4..].iter().cloned().fold(0.0, f64::max);
    println!("SV-RATTLE pendulum h = 0.1: max |ΔH| first quarter {first:.3e}, last {last:.3e}");
    assert!(first <= 0.1 * 0.1 && last <= 1.1 * first);
}

// ---------------------------------------------------------------------------
// 4. paper formulas for the figures
// ---------------------------------------------------------------------------

#[test]
fn hopf_map_and_stereographic_projection() {
    let z = [0.31, -0.52, 0.77, 0.14];
    let r2: f64 = z.iter().map(|x| x * x).sum();
    let (zeta, rho) = hopf_map(&z);
    // |ζ|² + ρ² = (|z0|² + |z1|²)²: the Hopf map sends S³(r) to S²(r²).
    assert!((zeta[0] * zeta[0] + zeta[1] * zeta[1] + rho * rho - r2 * r2).abs() <= 8.0 * EPS);
    // Invariant along the fibre.
    for &th in &[0.4, 2.0, 5.5] {
        let (zt, rt) = hopf_map(&fibre_point(&z, th));
        assert!((zt[0] - zeta[0]).abs() + (zt[1] - zeta[1]).abs() + (rt - rho).abs() <= 1e-15);
    }
    // Stereographic projection against its inverse (2w, |w|² − 1)/(|w|² + 1)
    // on the unit sphere, and degree-0 homogeneity.
    let n = (r2 * r2).sqrt();
    let (zu, ru) = ([zeta[0] / n, zeta[1] / n], rho / n);
    let w = stereographic(zu, ru);
    let ww = w[0] * w[0] + w[1] * w[1];
    let back = [
        2.0 * w[0] / (ww + 1.0),
        2.0 * w[1] / (ww + 1.0),
        (ww - 1.0) / (ww + 1.0),
    ];
    assert!((back[0] - zu[0]).abs() + (back[1] - zu[1]).abs() + (back[2] - ru).abs() <= 1e-14);
    let w2 = stereographic([3.0 * zeta[0], 3.0 * zeta[1]], 3.0 * rho);
    assert!((w2[0] - w[0]).abs() + (w2[1] - w[1]).abs() <= 1e-14);
}

#[test]
fn fibre_point_is_the_flow_of_half_x_g() {
    // fibre_point(z, θ) = exp((θ/2) X_g)(z) with MISSION's X_g = (g_p, −g_q);
    // X_g from num-dual, integrated by RK4 (h = 1e-3, error ~1e-13).
    let s = HopfFree::default();
    let z = [0.31, -0.52, 0.77, 0.14];
    let th = 1.7;
    let mut f = |y: &DVector<f64>| j_grad(&gradient(&s, Fun::G(0), y.as_slice()));
    let mut y = v(&z);
    let n = 850;
    for _ in 0..n {
        y = rk4_step(&mut f, &y, 0.5 * th / n as f64);
    }
    let fp = fibre_point(&z, th);
    assert!((y - v(&fp)).amax() <= 1e-12);
}

#[test]
fn hr_prime_is_the_derivative_of_h_along_the_fibre() {
    let z = [0.31, -0.52, 0.77, 0.14];
    let gv = [0.3, -0.7];
    let hg = HopfGravity {
        radius2: 1.0,
        gvec: gv,
    };
    let delta = 1e-5;
    for k in 0..12 {
        let th = 0.1 + k as f64 * 0.5;
        // Central differences: error O(δ²) ≈ 1e-10 times O(1) derivatives, plus
        // round-off eps/δ ≈ 1e-11.
        let fd1 = (hr(&z, gv, th + delta) - hr(&z, gv, th - delta)) / (2.0 * delta);
        let fd2 = (hr_prime(&z, gv, th + delta) - hr_prime(&z, gv, th - delta)) / (2.0 * delta);
        assert!((fd1 - hr_prime(&z, gv, th)).abs() <= 1e-8);
        assert!((fd2 - hr_second(&z, gv, th)).abs() <= 1e-8);
        // hr agrees with the system's H at the fibre point.
        assert!((hr(&z, gv, th) - value(&hg, Fun::H, &fibre_point(&z, th))).abs() <= 4.0 * EPS);
    }
    // Hr'(0) = dH·(½X_g) = −{g,H}/2 (bracket by num-dual); eq_Hprime2 gives +{g,H}/2.
    let hidden = hidden_constraints(&hg, &v(&z))[0];
    assert!((hr_prime(&z, gv, 0.0) + 0.5 * hidden).abs() <= 4.0 * EPS);
    assert!((hr_prime_paper(&z, gv, 0.0) - 0.5 * hidden).abs() <= 4.0 * EPS);
}

#[test]
fn paper_eq_hprime_orientation_and_eq_hprime2_sign_typo() {
    // eq_Hprime (gv = 0) is the derivative along the opposite orientation:
    // paper(θ) = −Hr'(−θ). eq_Hprime2 (gv ≠ 0) equals neither orientation's
    // derivative; flipping the sign of its gv·q sin θ term gives the e^{iθ} one.
    let z = [0.31, -0.52, 0.77, 0.14];
    for k in 0..12 {
        let th = 0.1 + k as f64 * 0.5;
        let a = hr_prime_paper(&z, [0.0, 0.0], th);
        let b = -hr_prime(&z, [0.0, 0.0], -th);
        assert!((a - b).abs() <= 4.0 * EPS);
    }
    let gv = [0.3, -0.7];
    let th = 0.9;
    let other = |t: f64| hr(&z, gv, -t); // H along z_k ↦ e^{+iθ} z_k
    let delta = 1e-5;
    let d_other = (other(th + delta) - other(th - delta)) / (2.0 * delta);
    let d_printed = hr_prime(&z, gv, th);
    let paper = hr_prime_paper(&z, gv, th);
    let gq = gv[0] * z[0] + gv[1] * z[1];
    assert!((paper - d_other).abs() >= 1e-3 && (paper - d_printed).abs() >= 1e-3);
    assert!((paper + 2.0 * gq * th.sin() - d_other).abs() <= 1e-8);
}

#[test]
fn fibre_critical_points_in_the_three_cases() {
    let z = [0.31, -0.52, 0.77, 0.14];
    let dir = [0.6, -0.8];
    // Independent count of sign changes of Hr' on a fine grid.
    let sign_changes = |gv: [f64; 2]| {
        let n = 100_000;
        (0..n)
            .filter(|&k| {
                let t0 = 2.0 * PI * k as f64 / n as f64;
                let t1 = 2.0 * PI * (k + 1) as f64 / n as f64;
                hr_prime(&z, gv, t0) * hr_prime(&z, gv, t1) < 0.0
            })
            .count()
    };
    // (i): gravity small against the sin 2θ, cos 2θ coefficients.
    let gv = [0.05 * dir[0], 0.05 * dir[1]];
    let cp = fibre_critical_points(&z, gv);
    assert_eq!(fibre_case(&cp), FibreCase::FourNondegenerate);
    assert_eq!(sign_changes(gv), 4);
    for c in &cp {
        assert!(hr_prime(&z, gv, c.theta).abs() <= 1e-15);
    }
    // (ii): gravity large.
    let gv = [5.0 * dir[0], 5.0 * dir[1]];
    let cp = fibre_critical_points(&z, gv);
    assert_eq!(fibre_case(&cp), FibreCase::TwoNondegenerate);
    assert_eq!(sign_changes(gv), 2);
    for c in &cp {
        assert!(hr_prime(&z, gv, c.theta).abs() <= 1e-14);
    }
    // (iii): choose gv so that θ0 is a double root: Hr'(θ0) = Hr''(θ0) = 0 is
    // linear in gv (Hr' = A sin 2θ − B cos 2θ + gv·(q sin θ − p cos θ)).
    let th0: f64 = 2.3;
    let (q, p) = ([z[0], z[1]], [z[2], z[3]]);
    let a = 0.5 * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0] - p[1] * p[1]);
    let b = q[0] * p[0] + q[1] * p[1];
    let (s, c) = th0.sin_cos();
    let (s2, c2) = (2.0 * th0).sin_cos();
    let r1 = [q[0] * s - p[0] * c, q[1] * s - p[1] * c];
    let r2 = [q[0] * c + p[0] * s, q[1] * c + p[1] * s];
    let (b1, b2) = (-(a * s2 - b * c2), -(2.0 * a * c2 + 2.0 * b * s2));
    let det = r1[0] * r2[1] - r1[1] * r2[0];
    let gv = [
        (b1 * r2[1] - r1[1] * b2) / det,
        (r1[0] * b2 - b1 * r2[0]) / det,
    ];
    assert!(hr_prime(&z, gv, th0).abs() <= 1e-14 && hr_second(&z, gv, th0).abs() <= 1e-14);
    let cp = fibre_critical_points(&z, gv);
    println!("case (iii) at gv = {gv:?}: {cp:?}");
    assert_eq!(fibre_case(&cp), FibreCase::TwoPlusDegenerate);
    let deg = cp.iter().find(|c| c.degenerate).unwrap();
    assert!((deg.theta - th0).abs() <= 1e-6);
    // gv = 0 on M^H: Hr' = A sin 2θ, roots kπ/2.
    let (qf, pf) = hopf_mh_point(0.9, 0.19f64.sqrt(), 0.4, 1.0);
    let zf = [qf[0], qf[1], pf[0], pf[1]];
    let cp = fibre_critical_points(&zf, [0.0, 0.0]);
    assert_eq!(fibre_case(&cp), FibreCase::FourNondegenerate);
    for (k, c) in cp.iter().enumerate() {
        assert!((c.theta - k as f64 * PI / 2.0).abs() <= 1e-12);
    }
}

#[test]
fn paper_table_facts() {
    // MISSION.md: hidden constraint ≈ 3e-16, |q|² + |p|² = 0.98 (not 1).
    // Measured here: |z|² = 0.98000000636, i.e. 0.98 only to 6.4e-9.
    for (name, z) in [("z_a", PAPER_Z_A), ("z_b", PAPER_Z_B), ("z_c", PAPER_Z_C)] {
        let r2: f64 = z.iter().map(|x| x * x).sum();
        let on_own = HopfGravity::through(&z);
        let hidden = hidden_constraints(&on_own, &v(&z))[0];
        let g098 = constraints(&HopfGravity::with_radius2(PAPER_RADIUS2), &v(&z))[0];
        let cp = fibre_critical_points(&z, [0.0, -1.0]);
        println!(
            "{name}: |z|² − 0.98 = {:.3e}, {{g,H}} = {hidden:.2e}, fibre {:?}",
            r2 - 0.98,
            fibre_case(&cp)
        );
        assert!((r2 - PAPER_RADIUS2).abs() <= 1e-8);
        assert!((r2 - 1.0).abs() >= 0.01);
        assert!(hidden.abs() <= 1e-15);
        assert!(g098.abs() > 1e-9, "not round-off: use HopfGravity::through");
        // θ = 0 is among the fibre's critical points.
        assert!(cp.iter().any(|c| c.theta.min(2.0 * PI - c.theta) <= 1e-12));
    }
}

#[test]
fn onto_unit_mh_keeps_the_plotted_point() {
    let gv = [0.0, -1.0];
    let hg = HopfGravity::default();
    for z in [PAPER_Z_A, PAPER_Z_B, PAPER_Z_C, [0.31, -0.52, 0.77, 0.14]] {
        let y = hopf_onto_mh(&z, gv, 1.0);
        let yv = v(&y);
        assert!(constraints(&hg, &yv)[0].abs() <= 4.0 * EPS);
        assert!(hidden_constraints(&hg, &yv)[0].abs() <= 1e-15);
        let (w0, w1) = (hopf_plane_point(&z), hopf_plane_point(&y));
        assert!(
            (w0[0] - w1[0]).abs() + (w0[1] - w1[1]).abs() <= 1e-13 * (1.0 + w0[0].hypot(w0[1]))
        );
        // Idempotent: a point on M^H stays (θ = 0 is a root).
        let y2 = hopf_onto_mh(&y, gv, 1.0);
        assert!((v(&y2) - yv).amax() <= 4.0 * EPS);
    }
}

// ---------------------------------------------------------------------------
// 5. index-1
// ---------------------------------------------------------------------------

#[test]
fn index1_midpoint_step_solves_its_equations_and_is_symmetric() {
    let s = Index1Example::default();
    let (q0, p0) = (v(&[0.8]), v(&[-0.3]));
    let b0 = index1_beta(&s, &q0, &p0, &v(&[0.0]));
    let h = 0.1;
    let (q1, p1, b) = index1_midpoint_step(&s, &q0, &p0, &b0, h);
    // 0 = H_β at the midpoint, to round-off.
    assert!(index1_midpoint_residual(&s, &q0, &p0, &q1, &p1, &b).amax() <= 1e-15);
    // The midpoint rule is symmetric: stepping back with −h returns, same β̄.
    let (q2, p2, b2) = index1_midpoint_step(&s, &q1, &p1, &b, -h);
    assert!((q2 - &q0).amax() <= 1e-15 && (p2 - &p0).amax() <= 1e-15);
    assert!((b2 - &b).amax() <= 1e-15);
}

#[test]
fn index1_midpoint_has_order_two_against_the_reference() {
    // The reference integrates the extended system (q, α, p, β), g = α.
    let s = Index1Example::default();
    let ext = Index1Extended(s);
    let (q0, p0) = (v(&[0.8]), v(&[-0.3]));
    let b0 = index1_beta(&s, &q0, &p0, &v(&[0.0]));
    let t = 2.0;
    let truth = reference_solution(&ext, &v(&[q0[0], 0.0, p0[0], b0[0]]), t, 80);
    let err = |n: usize| {
        let (mut q, mut p, mut b) = (q0.clone(), p0.clone(), b0.clone());
        for _ in 0..n {
            (q, p, b) = index1_midpoint_step(&s, &q, &p, &b, t / n as f64);
        }
        (q[0] - truth[0]).abs().max((p[0] - truth[2]).abs())
    };
    let (e1, e2, e3) = (err(20), err(40), err(80));
    let (o1, o2) = (order(e1, e2), order(e2, e3));
    println!("index-1 midpoint: errors {e1:.2e} {e2:.2e} {e3:.2e}, orders {o1:.2} {o2:.2}");
    assert!((o2 - 2.0).abs() <= 0.1);
}
