use geoshake::constrained_system;

constrained_system! {
    pub struct Line {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints {
            a: q[0] - q[1],
            b: 2 * q[0] - 2 * q[1],
        }
    }
}

fn main() {}
