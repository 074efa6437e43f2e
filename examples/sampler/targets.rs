//! The sampler's targets, declared once: `examples/sampler/main.rs` runs
//! them and `tests/suite/sampler.rs` checks them against their known answers
//! (it includes this file).

use geoshake::constrained_system;

constrained_system! {
    /// The unit sphere S² ⊂ R³ with U = 0: the uniform distribution.
    pub struct Sphere {
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2;
        constraints { sphere: q[0]^2 + q[1]^2 + q[2]^2 - 1 }
    }
}

constrained_system! {
    /// Von Mises–Fisher on S² with mean direction e_z: π ∝ exp(κ z).
    pub struct VonMisesFisher {
        parameters { kappa }
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 - kappa * q[2];
        constraints { sphere: q[0]^2 + q[1]^2 + q[2]^2 - 1 }
    }
}

constrained_system! {
    /// The flat torus S¹ × S¹ ⊂ R⁴, q = (cos θ₁, sin θ₁, cos θ₂, sin θ₂),
    /// with π ∝ exp(k₁ cos θ₁ + k₂ cos θ₂ + ν cos(θ₁ − θ₂)).
    pub struct Torus {
        parameters { k1, k2, nu }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2
            - k1 * q[0] - k2 * q[2] - nu * (q[0] * q[2] + q[1] * q[3]);
        constraints {
            first: q[0]^2 + q[1]^2 - 1,
            second: q[2]^2 + q[3]^2 - 1,
        }
    }
}

constrained_system! {
    /// SO(3) ⊂ R⁹ (R row-major in q, columns orthonormal: RᵀR = I, six
    /// constraints) with the matrix Fisher density π ∝ exp(κ tr R).
    pub struct Rotation {
        parameters { kappa }
        dof q[9], p[9];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2 + p[4]^2 + p[5]^2
            + p[6]^2 + p[7]^2 + p[8]^2) / 2 - kappa * (q[0] + q[4] + q[8]);
        constraints {
            c00: q[0]^2 + q[3]^2 + q[6]^2 - 1,
            c11: q[1]^2 + q[4]^2 + q[7]^2 - 1,
            c22: q[2]^2 + q[5]^2 + q[8]^2 - 1,
            c01: q[0] * q[1] + q[3] * q[4] + q[6] * q[7],
            c02: q[0] * q[2] + q[3] * q[5] + q[6] * q[8],
            c12: q[1] * q[2] + q[4] * q[5] + q[7] * q[8],
        }
    }
}

constrained_system! {
    /// The graph y = a sin(ωx) in R², with U = x²/2: π ∝ e^{−x²/2} with
    /// respect to arc length, ds = √(1 + (aω cos ωx)²) dx. Its folds (for
    /// aω > 1 a step can land on another crossing of the fibre with M)
    /// are where the reversibility check matters.
    pub struct Wavy {
        parameters { a, w }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + q[0]^2 / 2;
        constraints { graph: q[1] - a * sin(w * q[0]) }
    }
}

/// Composite Simpson's rule on [a, b] with n (even) panels: the exact
/// expectations the samples are compared with, for the example and the
/// tests alike.
pub fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for k in 1..n {
        s += f(a + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}
