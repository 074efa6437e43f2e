use geoshake::constrained_system;

constrained_system! {
    pub struct Mismatch {
        dof q[2], p[3];
        hamiltonian = p[0]^2 / 2;
    }
}

fn main() {}
