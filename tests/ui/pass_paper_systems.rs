//! The paper's systems, each in a few lines.
use geoshake::{constrained_system, ConstrainedSystem, ConstraintKind};

constrained_system! {
    /// Planar pendulum (Example 1.3).
    pub struct Pendulum {
        parameters { length, gravity }
        dof q[2], p[2];
        let r2 = q[0]^2 + q[1]^2;
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: r2 - length^2 }
    }
}

constrained_system! {
    /// The Hopf constraint without potential (Section 5.4.1).
    pub struct HopfFree {
        parameters { radius2 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints { hopf: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
    }
}

constrained_system! {
    /// The Hopf constraint with a linear potential H = |p|²/2 − g·q (Section 5.4.2).
    pub struct HopfGravity {
        parameters { g0, g1, radius2 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
        constraints { hopf: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
    }
}

constrained_system! {
    /// Index-1 constraints (Section 5.3): α = 0, H(q, p, β).
    pub struct IndexOne {
        coordinates q, alpha;
        momenta p, beta;
        hamiltonian = p^2 / 2 + q^2 / 2 + beta^2 / 2 + beta * q;
        constraints { alpha_zero: alpha }
    }
}

fn main() {
    let _ = (
        Pendulum::new(1.0, 9.81),
        HopfFree::new(1.0),
        HopfGravity::new(0.0, -1.0, 0.98),
        IndexOne::new(),
    );
    assert_eq!(HopfGravity::new(0.0, -1.0, 0.98).kind(), ConstraintKind::Quadratic);
    assert_eq!(IndexOne::new().kind(), ConstraintKind::Holonomic);
}
