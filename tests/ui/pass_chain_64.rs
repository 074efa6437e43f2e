//! A chain of 64 links anchored at the origin: d = 128, m = 64.
use geoshake::{constrained_system, ConstrainedSystem, Hamiltonian};

constrained_system! {
    pub struct Chain64 {
        parameters { mass, length, gravity }
        const N = 64;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / (2*mass) + mass * gravity * q[2*i+1] };
        constraints {
            link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
        }
    }
}

fn main() {
    assert_eq!((Chain64::DOF, Chain64::CONSTRAINTS), (128, 64));
    let c = Chain64::new(1.0, 0.1, 9.81);
    assert_eq!((c.dof(), c.constraint_count()), (128, 64));
    assert_eq!(c.jacobian_pattern().len(), 2 + 4 * 63);
}
