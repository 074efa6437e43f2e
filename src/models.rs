//! The paper's systems, declared with [`constrained_system!`](crate::constrained_system).
//!
//! Ready to integrate, and the systems behind the `paper` scene and the claim
//! tests. Each doc comment names the paper's section; the generated part of
//! each doc states H and g as the macro understood them.
//!
//! ```
//! use geoshake::models::Pendulum;
//! use geoshake::{ImplicitMidpoint, Integrator, State};
//!
//! let mut rattle = Integrator::new(Pendulum::new(1.0, 1.0), ImplicitMidpoint, 0.05).rattle();
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[1.0, 0.0], &[0.0, 0.0])).unwrap();
//! let z1 = rattle.step(&z0).unwrap();
//! assert!((z1.q.norm() - 1.0).abs() < 1e-14);
//! ```

use crate::constrained_system;

constrained_system! {
    /// The planar pendulum of Example 1.3: a unit mass in a constant gravity
    /// field, H = |p|²/2 + gravity·q₂, on the circle |q|² = length² (the
    /// paper prints ‖q‖¹ − 1; we read ‖q‖² − 1, the same M).
    pub struct Pendulum {
        parameters { length, gravity }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - length^2 }
    }
}

constrained_system! {
    /// The spherical pendulum: H = |p|²/2 + gravity·q₃ on |q|² = length²
    /// (holonomic, Section 5.1).
    pub struct SphericalPendulum {
        parameters { length, gravity }
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2 + gravity * q[2];
        constraints { rod: q[0]^2 + q[1]^2 + q[2]^2 - length^2 }
    }
}

constrained_system! {
    /// The planar double pendulum with unit masses: two rods of lengths l1,
    /// l2, the first anchored at the origin (holonomic, m = 2).
    pub struct DoublePendulum {
        parameters { l1, l2, gravity }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2 + gravity * (q[1] + q[3]);
        constraints {
            rod1: q[0]^2 + q[1]^2 - l1^2,
            rod2: (q[2] - q[0])^2 + (q[3] - q[1])^2 - l2^2,
        }
    }
}

constrained_system! {
    /// The harmonic (Hopf) constraint of Section 5.4.1 without potential:
    /// H = |p|²/2 on the 3-sphere |q|² + |p|² = radius2 in R⁴. The constraint
    /// depends on the momenta; its fibres are the great circles of the Hopf
    /// fibration.
    pub struct HopfFree {
        parameters { radius2 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
    }
}

constrained_system! {
    /// The harmonic constraint with a linear potential, Section 5.4.2:
    /// H = |p|²/2 − g·q with g = (g0, g1) (the paper takes g = (0, −1)), on
    /// |q|² + |p|² = radius2. The paper's initial data lie on radius2 = 0.98.
    pub struct HopfGravity {
        parameters { g0, g1, radius2 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
        constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
    }
}

constrained_system! {
    /// A hanging chain of 8 unit masses joined by rods of one length, the
    /// first anchored at the origin (holonomic, m = 8, banded g_q).
    pub struct Chain8 {
        parameters { length, gravity }
        const N = 8;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }
}

constrained_system! {
    /// Index-1 constraints (Section 5.3) on the extended space R⁴ with
    /// positions (q, α) and momenta (p, β): the holonomic constraint α = 0 and
    /// H(q, p, β) = (q² + p²)/2 + β²/2 + β⁴/12 − coupling·β p sin q, so that
    /// H_ββ = 1 + β² ≥ 1 (nondegenerate everywhere) and the hidden
    /// constraint is H_β = 0. For |coupling| < 1 every orbit is bounded.
    pub struct IndexOne {
        parameters { coupling }
        coordinates q, alpha;
        momenta p, beta;
        hamiltonian = (q^2 + p^2) / 2 + beta^2 / 2 + beta^4 / 12 - coupling * beta * p * sin(q);
        constraints { alpha_zero: alpha }
    }
}
