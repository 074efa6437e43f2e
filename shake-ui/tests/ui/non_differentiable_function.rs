use geoshake::constrained_system;

constrained_system! {
    pub struct Bouncing {
        dof q[1], p[1];
        hamiltonian = p[0]^2 / 2 + abs(q[0]);
    }
}

fn main() {}
