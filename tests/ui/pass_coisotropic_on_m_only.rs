//! {a, b} = q[0] = a: not identically zero, but zero on M. Accepted.
use geoshake::constrained_system;

constrained_system! {
    pub struct OnM {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2 + q[0]^2 + q[1]^2) / 2;
        constraints {
            a: q[0],
            b: p[1] + q[0] * p[0],
        }
    }
}

fn main() {
    let _ = OnM::new();
}
