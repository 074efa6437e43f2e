//! The runtime factorises N = {{H,g_i},g_j} within its structural band when
//! that pays (a chain's N is tridiagonal). Checked against a dense
//! computation with nalgebra: det N to round-off, and the 1-norm condition
//! estimate within the factor such estimators guarantee.

use geoshake::{constrained_system, ConstrainedSystem, Integrator, State, Stop, StormerVerlet};
use nalgebra::DMatrix;
use std::cell::RefCell;
use std::ops::ControlFlow;

constrained_system! {
    /// A hanging chain of 16 unit masses (m = 16: banded N).
    struct Chain16 {
        parameters { length, gravity }
        const N = 16;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }
}

/// The positions of a chain of n unit links hanging from the origin, link k
/// at angle `angle(k)` from the downward vertical.
fn chain_positions(n: usize, angle: impl Fn(usize) -> f64) -> Vec<f64> {
    let mut q = vec![0.0; 2 * n];
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..n {
        let a = angle(k);
        x += a.sin();
        y -= a.cos();
        q[2 * k] = x;
        q[2 * k + 1] = y;
    }
    q
}

/// ‖A‖₁, the largest column sum.
fn norm1(a: &DMatrix<f64>) -> f64 {
    (0..a.ncols())
        .map(|j| a.column(j).iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

#[test]
fn banded_det_and_condition_match_a_dense_computation() {
    let sys = Chain16::new(1.0, 9.81);
    let n = 16;
    // A zig-zag chain at rest, on M: link k at angle ±0.4 from the vertical.
    let q = chain_positions(n, |k| if k % 2 == 0 { 0.4 } else { -0.3 });
    let p: Vec<f64> = (0..2 * n).map(|i| 0.1 * ((i as f64) * 0.7).sin()).collect();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.01).rattle();
    let z = integ
        .project_to_hidden(&State::from_slices(&q, &p))
        .unwrap();
    let mut z1 = z.clone();
    let info = integ.step_in_place(&mut z1).unwrap();

    let mut buf = vec![0.0; n * n];
    sys.nondegeneracy_matrix(z1.q.as_slice(), z1.p.as_slice(), &mut buf);
    let dense = DMatrix::from_column_slice(n, n, &buf);
    let det = dense.clone().lu().determinant();
    // Round-off of a 16×16 elimination: a few hundred ε relative.
    assert!(
        (info.det_n - det).abs() <= 1e-12 * det.abs(),
        "banded det {} vs dense {det}",
        info.det_n
    );
    // m ≥ 2: the reported condition is ‖N‖₁‖N⁻¹‖₁ with ‖N⁻¹‖₁ estimated
    // (Hager–Higham: never above the true value, within a small factor of
    // it in practice) or bounded from the last state's estimate through
    // ‖N₁ − N₀‖₁, a bound kept within twice that estimate (`Guard`).
    let inv = dense.clone().try_inverse().unwrap();
    let kappa = norm1(&dense) * norm1(&inv);
    assert!(
        info.condition <= 2.0 * kappa * (1.0 + 1e-12) && info.condition >= kappa / 3.0,
        "condition {} vs {kappa}",
        info.condition
    );
}

/// Along a run the check estimates ‖N⁻¹‖₁ only now and then and bounds it
/// in between from the last estimate and ‖N₁ − N₀‖₁ (`Guard`): at every
/// step the reported condition must stay between a third of the true κ₁(N)
/// (what the estimate guarantees) and twice it (what the bound is held to).
#[test]
fn the_condition_between_estimates_stays_within_twice_the_true_one() {
    let sys = Chain16::new(1.0, 9.81);
    let n = 16;
    let q = chain_positions(n, |k| 0.9 * (0.8 * k as f64).sin());
    let p = vec![0.0; 2 * n];
    let mut integ = Integrator::new(sys, StormerVerlet, 0.01).rattle();
    let mut z = integ
        .project_to_hidden(&State::from_slices(&q, &p))
        .unwrap();
    let mut buf = vec![0.0; n * n];
    sys.nondegeneracy_matrix(z.q.as_slice(), z.p.as_slice(), &mut buf);
    let mut before = norm1(&DMatrix::from_column_slice(n, n, &buf));
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for _ in 0..400 {
        let info = integ.step_in_place(&mut z).unwrap();
        sys.nondegeneracy_matrix(z.q.as_slice(), z.p.as_slice(), &mut buf);
        let dense = DMatrix::from_column_slice(n, n, &buf);
        let inv = dense.clone().try_inverse().unwrap();
        // The reported condition is relative to max(‖N‖₁, ‖N₀‖₁), N₀ at
        // the state `step_in_place` started from.
        let kappa = norm1(&dense).max(before) * norm1(&inv);
        before = norm1(&dense);
        let r = info.condition / kappa;
        lo = lo.min(r);
        hi = hi.max(r);
    }
    println!("reported / true condition over 400 steps: {lo:.3} ..= {hi:.3}");
    assert!(
        lo >= 1.0 / 3.0 && hi <= 2.0 * (1.0 + 1e-12),
        "{lo} ..= {hi}"
    );
}

/// The same inside a run, where the guard carries its estimate from step
/// to step and bounds ‖N⁻¹‖₁ from it while N changes slowly. A SHAKE run,
/// so that the state the observer sees is the one checked; a whipping
/// chain, so that N changes fast and both the bound and the estimate run.
/// The reported condition never falls below a third of the true one. (It
/// can exceed twice the true one here: the bound is held within twice the
/// last estimate, and the true ‖N⁻¹‖₁ may have fallen since. Reporting
/// more than the truth only makes the check stricter.)
#[test]
fn the_condition_in_a_run_never_falls_below_a_third_of_the_true_one() {
    let sys = Chain16::new(1.0, 9.81);
    let n = 16;
    let q = chain_positions(n, |k| 1.2 * (0.8 * k as f64).sin());
    let p: Vec<f64> = (0..2 * n)
        .map(|i| {
            if i % 2 == 0 {
                0.5 * (i / 2) as f64
            } else {
                0.0
            }
        })
        .collect();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.005);
    let z0 = integ
        .project_to_hidden(&State::from_slices(&q, &p))
        .unwrap();
    let mut buf = vec![0.0; n * n];
    sys.nondegeneracy_matrix(z0.q.as_slice(), z0.p.as_slice(), &mut buf);
    // The reference ‖N₀‖₁ of the run, at its start.
    let reference = norm1(&DMatrix::from_column_slice(n, n, &buf));
    let reported = RefCell::new(Vec::new());
    let kappas = RefCell::new(Vec::new());
    let steps = 2000;
    let mut record = |e: &geoshake::StepEvent| {
        reported.borrow_mut().push(e.info.condition);
        ControlFlow::Continue(())
    };
    let out = integ
        .run(z0, Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k == 0 {
                return;
            }
            let mut buf = vec![0.0; n * n];
            sys.nondegeneracy_matrix(z.q.as_slice(), z.p.as_slice(), &mut buf);
            let dense = DMatrix::from_column_slice(n, n, &buf);
            let inv = dense.clone().try_inverse().unwrap();
            kappas
                .borrow_mut()
                .push(norm1(&dense).max(reference) * norm1(&inv));
        })
        .on_step(&mut record)
        .execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    let (reported, kappas) = (reported.into_inner(), kappas.into_inner());
    assert_eq!(reported.len(), steps as usize);
    assert_eq!(kappas.len(), steps as usize);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for (r, k) in reported.iter().zip(&kappas) {
        lo = lo.min(r / k);
        hi = hi.max(r / k);
    }
    let (kmin, kmax) = kappas
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(a, b), k| (a.min(*k), b.max(*k)));
    println!("true condition {kmin:.1} ..= {kmax:.1}; reported / true: {lo:.3} ..= {hi:.3}");
    // The run must have moved N (else it tests nothing).
    assert!(kmax > 1.5 * kmin, "{kmin} ..= {kmax}");
    assert!(lo >= 1.0 / 3.0, "{lo} ..= {hi}");
}
