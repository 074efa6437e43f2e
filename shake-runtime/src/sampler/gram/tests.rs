//! Tests of the Gram-determinant correction: its gradient and Hessian are
//! the derivatives of ½ log det(g_q g_qᵀ) (against finite differences and
//! the circle's closed form), a singular G gives non-finite numbers, and
//! the fixed-size step sees the wrapper.

use super::Gram;
use crate::examples::Pendulum;
use crate::system::{ConstrainedSystem, ConstraintKind, Hamiltonian, SizeVisitor};

/// g₁ = q₀² + 2q₁² + 3q₂² − 1, g₂ = q₀q₁ + sin q₂ on R³ with
/// U = q₁²/2: G varies with q in every direction, and `grad_q` writes
/// only its entry 1 (the wrapper must not add ∇Ψ over last call's).
#[derive(Clone)]
struct Twisted;

impl Hamiltonian for Twisted {
    fn dof(&self) -> usize {
        3
    }
    fn separable(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * p.iter().map(|x| x * x).sum::<f64>() + 0.5 * q[1] * q[1]
    }
    fn grad_q(&self, q: &[f64], _: &[f64], h_q: &mut [f64]) {
        h_q[1] = q[1];
    }
    fn grad_p(&self, _: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p.copy_from_slice(p);
    }
    fn hessian(&self, _: &[f64], _: &[f64], h_zz: &mut [f64]) {
        h_zz[1 + 6] = 1.0;
        for k in 3..6 {
            h_zz[k + 6 * k] = 1.0;
        }
    }
}

impl ConstrainedSystem for Twisted {
    fn constraint_count(&self) -> usize {
        2
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        ["ellipsoid", "twist"][i]
    }
    fn constraints(&self, q: &[f64], _: &[f64], g: &mut [f64]) {
        g[0] = q[0] * q[0] + 2.0 * q[1] * q[1] + 3.0 * q[2] * q[2] - 1.0;
        g[1] = q[0] * q[1] + q[2].sin();
    }
    fn constraint_jacobian(&self, q: &[f64], _: &[f64], g_z: &mut [f64]) {
        let j = [2.0 * q[0], q[1], 4.0 * q[1], q[0], 6.0 * q[2], q[2].cos()];
        g_z[..6].copy_from_slice(&j);
    }
    fn constraint_hessian(&self, q: &[f64], _: &[f64], lambda: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * lambda[0];
        out[1 + 6] = 4.0 * lambda[0];
        out[2 + 2 * 6] = 6.0 * lambda[0] - q[2].sin() * lambda[1];
        out[1] = lambda[1];
        out[6] = lambda[1];
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let mut g_z = [0.0; 12];
        self.constraint_jacobian(q, p, &mut g_z);
        for i in 0..2 {
            out[i] = (0..3).map(|k| g_z[i + 2 * k] * p[k]).sum();
        }
    }
    fn hidden_constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {
        unreachable!("not read by these tests")
    }
    fn nondegeneracy_matrix(&self, _: &[f64], _: &[f64], _: &mut [f64]) {
        unreachable!("not read by these tests")
    }
}

/// Points where G is regular (on M or not: Ψ is defined on R^d).
const POINTS: [[f64; 3]; 4] = [
    [0.3, -0.4, 0.2],
    [-0.7, 0.1, 0.45],
    [0.55, 0.5, -0.3],
    [1.2, -0.9, 0.8],
];

/// Central differences of the corrected potential against the
/// gradient: Σ_i ∇²g_i w_i is ∇(½ log det G). The correction is of
/// order one here (checked), so a wrong formula (G⁻ᵀ for G⁻¹ would be
/// invisible, G being symmetric; a factor 2, a transposed Hessian
/// block, a w_i of the wrong constraint are not) is off by O(1), far
/// outside the 1e-7 the differences allow. Calling `grad_q` twice on
/// one buffer checks that the wrapped system's unwritten entries are
/// not accumulated.
#[test]
fn the_gradient_is_the_derivative_of_half_log_det() {
    let sys = Gram::new(Twisted);
    let p = [0.3, -0.2, 0.1];
    for q in POINTS {
        let mut grad = [0.0; 3];
        sys.grad_q(&q, &p, &mut grad);
        sys.grad_q(&q, &p, &mut grad);
        let mut plain = [0.0; 3];
        Twisted.grad_q(&q, &p, &mut plain);
        let correction = (0..3).fold(0.0f64, |a, k| a.max((grad[k] - plain[k]).abs()));
        assert!(correction > 0.1, "{q:?}: correction {correction}");
        for k in 0..3 {
            let e = 1e-5;
            let (mut up, mut down) = (q, q);
            up[k] += e;
            down[k] -= e;
            let diff = (sys.hamiltonian(&up, &p) - sys.hamiltonian(&down, &p)) / (up[k] - down[k]);
            assert!(
                (grad[k] - diff).abs() <= 1e-7 * (1.0 + diff.abs()),
                "{q:?}, k = {k}: {} vs {diff}",
                grad[k]
            );
        }
        let (mut both, mut h_p) = ([7.0; 3], [0.0; 3]);
        sys.gradient(&q, &p, &mut both, &mut h_p);
        assert_eq!(both, grad);
        assert_eq!(h_p, p);
    }
}

/// The circle |q|² = ℓ² in closed form: G = 4|q|², Ψ = ½ log(4|q|²),
/// ∇Ψ = q/|q|², ∇²Ψ = (|q|² I − 2 q qᵀ)/|q|⁴ (off M, where G varies).
#[test]
fn the_circle_in_closed_form() {
    let pendulum = Pendulum::default();
    let sys = Gram::new(pendulum);
    let (q, p): ([f64; 2], [f64; 2]) = ([0.78, -1.04], [0.5, 0.25]);
    let r2 = q[0] * q[0] + q[1] * q[1];
    let psi = 0.5 * (4.0 * r2).ln();
    let h = pendulum.hamiltonian(&q, &p) + psi;
    assert!((sys.hamiltonian(&q, &p) - h).abs() <= 1e-15 * h.abs());
    let mut grad = [0.0; 2];
    sys.grad_q(&q, &p, &mut grad);
    // Gravity γ = 1 along q₁.
    let exact = [q[0] / r2, q[1] / r2 + 1.0];
    for k in 0..2 {
        assert!((grad[k] - exact[k]).abs() <= 1e-15, "{grad:?} vs {exact:?}");
    }
    let mut hess = [0.0; 16];
    sys.hessian(&q, &p, &mut hess);
    sys.hessian(&q, &p, &mut hess);
    for k in 0..2 {
        for l in 0..2 {
            let delta = if k == l { r2 } else { 0.0 };
            let exact = (delta - 2.0 * q[k] * q[l]) / (r2 * r2);
            let got = hess[k + 4 * l];
            assert!((got - exact).abs() <= 1e-9, "({k}, {l}): {got} vs {exact}");
        }
    }
    // The p-block is the wrapped system's; H_qp stays zero.
    assert_eq!(
        (hess[2 + 4 * 2], hess[3 + 4 * 3], hess[2 + 4 * 3]),
        (1.0, 1.0, 0.0)
    );
    assert!((0..2).all(|k| (2..4).all(|l| hess[k + 4 * l] == 0.0 && hess[l + 4 * k] == 0.0)));
}

/// The Hessian's q-block against differences of the exact gradient
/// with another step: symmetric and consistent to 1e-6.
#[test]
fn the_hessian_is_the_derivative_of_the_gradient() {
    let sys = Gram::new(Twisted);
    let p = [0.3, -0.2, 0.1];
    for q in POINTS {
        let mut hess = [0.0; 36];
        sys.hessian(&q, &p, &mut hess);
        for l in 0..3 {
            let e = 1e-4;
            let (mut up, mut down) = (q, q);
            up[l] += e;
            down[l] -= e;
            let (mut gu, mut gd) = ([0.0; 3], [0.0; 3]);
            sys.grad_q(&up, &p, &mut gu);
            sys.grad_q(&down, &p, &mut gd);
            for k in 0..3 {
                let diff = (gu[k] - gd[k]) / (up[l] - down[l]);
                let got = hess[k + 6 * l];
                assert!(
                    (got - diff).abs() <= 1e-6 * (1.0 + diff.abs()),
                    "{q:?} ({k}, {l}): {got} vs {diff}"
                );
                assert_eq!(got, hess[l + 6 * k]);
            }
        }
    }
}

/// Where g_q has lost rank, Ψ = −∞ and ∇Ψ is NaN: no panic, and the
/// sampler reads them as a non-finite energy.
#[test]
fn a_singular_gram_matrix_is_not_finite() {
    let sys = Gram::new(Pendulum::default());
    let (q, p) = ([0.0, 0.0], [1.0, 0.0]);
    assert_eq!(sys.hamiltonian(&q, &p), f64::NEG_INFINITY);
    let mut grad = [0.0; 2];
    sys.grad_q(&q, &p, &mut grad);
    assert!(grad.iter().all(|g| g.is_nan()));
}

/// The wrapper offers the wrapped system's sizes with itself, so the
/// fixed-size step calls the corrected functions; it is Send and Sync
/// (chains share it by reference while they clone it).
#[test]
fn the_fixed_size_step_sees_the_wrapper() {
    struct Potential;
    impl<S: Hamiltonian> SizeVisitor<S> for Potential {
        type Output = Option<(usize, usize, f64)>;
        fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output {
            Some((D, M, sys.hamiltonian(&[0.6, -0.8], &[0.0, 0.0])))
        }
        fn dynamic(self, _: &S) -> Self::Output {
            None
        }
    }
    let sys = Gram::new(Pendulum::default());
    // U = −0.8 and Ψ = ½ log 4 on the unit circle.
    let expected = -0.8 + 0.5 * 4f64.ln();
    let (d, m, h) = sys.with_sizes(Potential).unwrap();
    assert_eq!((d, m), (2, 1));
    assert!((h - expected).abs() < 1e-15);
    fn shared<T: Send + Sync + Clone>() {}
    shared::<Gram<Pendulum>>();
}
