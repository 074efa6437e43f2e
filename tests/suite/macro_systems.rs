//! The paper's systems, declared with `constrained_system!`: they must
//! compile, and their structural facts must be what the paper says.

use geoshake::{constrained_system, ConstrainedSystem, ConstraintKind, Hamiltonian};

constrained_system! {
    /// Planar pendulum (the paper's Example 1.3).
    pub struct Pendulum {
        parameters { length, gravity }
        dof q[2], p[2];
        let r2 = q[0]^2 + q[1]^2;
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints {
            rod: r2 - length^2,
        }
    }
}

#[test]
fn pendulum_facts() {
    assert_eq!(Pendulum::DOF, 2);
    assert_eq!(Pendulum::CONSTRAINTS, 1);
    let s = Pendulum::new(1.0, 9.81);
    assert_eq!((s.dof(), s.constraint_count()), (2, 1));
    assert_eq!(s.kind(), ConstraintKind::Holonomic);
    assert_eq!((s.separable(),), (true,));
    assert_eq!((s.quadratic_kinetic(),), (true,));
    assert_eq!(s.jacobian_pattern(), &[(0, 0), (0, 1)]);
    assert_eq!(s.constraint_name(0), "rod");
    let (q, p) = ([0.6, -0.8], [0.8, 0.6]);
    let mut g = [0.0];
    s.constraints(&q, &p, &mut g);
    assert!(g[0].abs() < 1e-15);
    assert!((s.hamiltonian(&q, &p) - (0.5 - 9.81 * 0.8)).abs() < 1e-14);
}
