//! Accurate emission: the macro emits values in the form
//! the user wrote, so a chain translated far from the origin meets its
//! constraints as well as the untranslated one.
//!
//! A free chain's link constraint g_k = |x_k − x_{k−1}|² − l² is
//! translation invariant. Evaluated as written, the difference Δ = x_k −
//! x_{k−1} of two stored coordinates is exact or off by one rounding of
//! size ε|Δ|, and the stored coordinates themselves carry a rounding of
//! size ε|x| (every step writes them back): so |g_k| ≲ c·ε·|x|·|Δ| at
//! round-off, with a small c (2 from d|Δ|² = 2Δ·dΔ, times the few roundings
//! of a step). Expanded into |x_k|² − 2x_k·x_{k−1} + |x_{k−1}|² − l², the
//! evaluation itself errs by ε|x|², which for |x| = 10³ and |Δ| = 1 is 10³
//! times that bound: that was the behaviour before. Measured on this test
//! (2000 RATTLE steps, h = 0.01): expanded emission max |g| = 2.8e-14
//! untranslated and 1.2e-9 translated (3700 round-off units); factored
//! emission 3.2e-15 and 5.4e-13 (2.7 and 1.7 units).

use geoshake::{constrained_system, ConstrainedSystem, Integrator, State, StormerVerlet};

constrained_system! {
    /// A free chain of 8 unit masses in the plane, 7 rigid links.
    struct FreeChain {
        parameters { length }
        const N = 8;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 };
        constraints {
            link[k in 1..N]: (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2,
        }
    }
}

const N: usize = 8;

/// max over steps and links of |g_k| / (ε Σ_j |∂g_k/∂q_j| |q_j|): the
/// constraint residual in units of its round-off scale (≈ 2√2·2 ε|x||Δ|
/// at most: the bound of the module doc with c ≤ 5.7).
fn worst_residual(shift: f64, fast_paths: bool) -> (f64, f64) {
    let sys = FreeChain::new(1.0);
    let mut q = vec![0.0; 2 * N];
    let (mut x, mut y) = (0.0, 0.0);
    for k in 1..N {
        let a: f64 = if k % 2 == 0 { 0.4 } else { -0.3 };
        x += a.sin();
        y -= a.cos();
        q[2 * k] = x;
        q[2 * k + 1] = y;
    }
    let p: Vec<f64> = (0..2 * N).map(|i| 0.5 * ((i as f64) * 0.7).sin()).collect();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.01)
        .rattle()
        .fast_paths(fast_paths);
    let z = integ
        .project_to_hidden(&State::from_slices(&q, &p))
        .expect("projection");
    // The same state translated by `shift` in every coordinate.
    let q: Vec<f64> = z.q.iter().map(|v| v + shift).collect();
    let mut z = State::from_slices(&q, z.p.as_slice());
    let mut g = vec![0.0; N - 1];
    let (mut worst, mut worst_abs) = (0.0f64, 0.0f64);
    for _ in 0..2000 {
        integ.step_in_place(&mut z).expect("step");
        sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
        for k in 1..N {
            // ε Σ_j |∂g_k/∂q_j| |q_j|: what rounding each stored coordinate
            // to its last bit changes g_k by, the floor at which the
            // classical SHAKE Newton stops (shake-runtime/src/classical.rs).
            let (dx, dy) = (z.q[2 * k] - z.q[2 * k - 2], z.q[2 * k + 1] - z.q[2 * k - 1]);
            let scale = f64::EPSILON
                * 2.0
                * (dx.abs() * (z.q[2 * k].abs() + z.q[2 * k - 2].abs())
                    + dy.abs() * (z.q[2 * k + 1].abs() + z.q[2 * k - 1].abs()))
                .max(1.0);
            worst = worst.max(g[k - 1].abs() / scale);
            worst_abs = worst_abs.max(g[k - 1].abs());
        }
    }
    (worst, worst_abs)
}

/// The emission claim, on the general SHAKE Newton (which iterates to the
/// round-off floor of g).
#[test]
fn a_translated_chain_meets_its_constraints_to_round_off() {
    let (near, near_abs) = worst_residual(0.0, false);
    let (far, far_abs) = worst_residual(1e3, false);
    println!("max |g|: untranslated {near_abs:.2e} ({near:.1} round-off units), translated by 1e3 {far_abs:.2e} ({far:.1} units)");
    // c = 8 round-off units: the bound of the module doc with room for the
    // roundings of one step; the expanded form would give ~10³ units.
    assert!(near <= 8.0, "untranslated: {near} units ({near_abs:e})");
    assert!(far <= 8.0, "translated: {far} units ({far_abs:e})");
}

/// The same on the classical fast path (holonomic g, separable H,
/// Störmer–Verlet: the default here). Known defect: its contraction-based
/// stopping rule ends the untranslated run at ≈ 11 round-off units
/// (|g| = 1.5e-14), where the general Newton reaches its floor.
#[test]
#[ignore = "known: the classical fast path stops at ~11x the round-off floor of g on this chain (issue 12)"]
fn a_translated_chain_meets_its_constraints_to_round_off_on_the_classical_path() {
    let (near, near_abs) = worst_residual(0.0, true);
    let (far, far_abs) = worst_residual(1e3, true);
    assert!(near <= 8.0, "untranslated: {near} units ({near_abs:e})");
    assert!(far <= 8.0, "translated: {far} units ({far_abs:e})");
}
