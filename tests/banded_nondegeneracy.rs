//! The runtime factorises N = {{H,g_i},g_j} within its structural band when
//! that pays (a chain's N is tridiagonal). Checked against a dense
//! computation with nalgebra: det N to round-off, and the 1-norm condition
//! estimate within the factor such estimators guarantee.

use nalgebra::DMatrix;
use shake::{constrained_system, ConstrainedSystem, Integrator, State, StormerVerlet};

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

#[test]
fn banded_det_and_condition_match_a_dense_computation() {
    let sys = Chain16::new(1.0, 9.81);
    let n = 16;
    // A zig-zag chain at rest, on M: link k at angle ±0.4 from the vertical.
    let mut q = vec![0.0; 2 * n];
    let (mut x, mut y) = (0.0, 0.0);
    for k in 0..n {
        let a: f64 = if k % 2 == 0 { 0.4 } else { -0.3 };
        x += a.sin();
        y -= a.cos();
        q[2 * k] = x;
        q[2 * k + 1] = y;
    }
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
    // m ≥ 2: the reported condition is ‖N‖₁‖N⁻¹‖₁ with an estimated
    // ‖N⁻¹‖₁ (Hager–Higham), which never exceeds the true value and is
    // within a small factor of it in practice.
    let inv = dense.clone().try_inverse().unwrap();
    let norm1 = |a: &DMatrix<f64>| {
        (0..n)
            .map(|j| a.column(j).iter().map(|v| v.abs()).sum::<f64>())
            .fold(0.0, f64::max)
    };
    let kappa = norm1(&dense) * norm1(&inv);
    assert!(
        info.condition <= kappa * (1.0 + 1e-12) && info.condition >= kappa / 3.0,
        "condition {} vs {kappa}",
        info.condition
    );
}
