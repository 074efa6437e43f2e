use geoshake::constrained_system;

constrained_system! {
    pub struct Twice {
        dof q[3], p[3];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2) / 2;
        constraints {
            plane: q[2],
            plane: q[0] + q[1],
        }
    }
}

fn main() {}
