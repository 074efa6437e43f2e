//! The fibre flow of a single quadratic constraint whose generator squares
//! to −ω²I (the Hopf sphere) is taken in closed form, exp(λL) =
//! cos(ωλ) I + sin(ωλ)/ω L, instead of a matrix exponential: checked here
//! against the exact rotation z_k ↦ e^{−2iλ} z_k of Section 5.4 and against
//! the matrix-exponential path of a quadratic constraint that is not a
//! rotation (one with a linear part), both to round-off.

use geoshake::models::{HopfFree, HopfGravity};
use geoshake::{constrained_system, FibreFlow};

constrained_system! {
    /// The Hopf sphere shifted by a linear term: still quadratic, but with
    /// ∇g(0) ≠ 0, so the runtime uses the matrix exponential.
    struct ShiftedSphere {
        parameters { c }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints { sphere: (q[0] - c)^2 + q[1]^2 + p[0]^2 + p[1]^2 - 1 }
    }
}

/// e^{−2iλ} applied to z_k = q_k + i p_k.
fn rotation(lambda: f64, q: [f64; 2], p: [f64; 2]) -> ([f64; 2], [f64; 2]) {
    let (c, s) = ((2.0 * lambda).cos(), (2.0 * lambda).sin());
    let f = |k: usize| (c * q[k] + s * p[k], c * p[k] - s * q[k]);
    let (a, b) = (f(0), f(1));
    ([a.0, b.0], [a.1, b.1])
}

#[test]
fn hopf_fibre_flow_is_the_exact_rotation() {
    let (q0, p0) = ([0.6, -0.3], [0.2, 0.7]);
    for sys_flow in [
        FibreFlow::new(&HopfFree::new(1.0)),
        FibreFlow::new(&HopfGravity::new(0.0, -1.0, 0.98)),
    ] {
        let mut flow = sys_flow;
        for lambda in [1e-9, 0.05, 0.7, -2.3, 10.0] {
            let (mut q, mut p) = (q0, p0);
            flow.apply(&HopfFree::new(1.0), &[lambda], &mut q, &mut p)
                .unwrap();
            let (qe, pe) = rotation(lambda, q0, p0);
            for k in 0..2 {
                // Round-off of cos/sin of 2λ (|2λ| ≤ 20) and two products.
                let tol = 8.0 * f64::EPSILON * (1.0 + 2.0 * lambda.abs());
                assert!((q[k] - qe[k]).abs() <= tol && (p[k] - pe[k]).abs() <= tol);
            }
            // The increment is a small quantity: compared with the exact
            // increment written without cancellation (cos 2λ − 1 = −2 sin²λ),
            // it must carry its own relative precision, not that of |z|.
            let (mut dq, mut dp) = ([0.0; 2], [0.0; 2]);
            flow.increment(&HopfFree::new(1.0), &[lambda], &q0, &p0, &mut dq, &mut dp)
                .unwrap();
            let (a, b) = (-2.0 * lambda.sin().powi(2), (2.0 * lambda).sin());
            let tol = 8.0 * f64::EPSILON * (a.abs() + b.abs());
            for k in 0..2 {
                let (eq, ep) = (a * q0[k] + b * p0[k], a * p0[k] - b * q0[k]);
                assert!((dq[k] - eq).abs() <= tol, "{lambda}: dq {} vs {eq}", dq[k]);
                assert!((dp[k] - ep).abs() <= tol, "{lambda}: dp {} vs {ep}", dp[k]);
            }
        }
    }
}

#[test]
fn an_affine_quadratic_flow_still_uses_the_exponential_and_agrees() {
    // (q0 − c, q1, p0, p1) rotates: the flow is the rotation about (c, 0, 0, 0).
    let c = 0.3;
    let sys = ShiftedSphere::new(c);
    let mut flow = FibreFlow::new(&sys);
    let (q0, p0) = ([0.6, -0.3], [0.2, 0.7]);
    for lambda in [0.05, 0.7, -2.3] {
        let (mut q, mut p) = (q0, p0);
        flow.apply(&sys, &[lambda], &mut q, &mut p).unwrap();
        let (qe, pe) = rotation(lambda, [q0[0] - c, q0[1]], p0);
        let qe = [qe[0] + c, qe[1]];
        for k in 0..2 {
            // Scaling and squaring to round-off: a few dozen ε.
            assert!((q[k] - qe[k]).abs() < 1e-14 && (p[k] - pe[k]).abs() < 1e-14);
        }
    }
}
