use geoshake::constrained_system;

constrained_system! {
    pub struct Oscillator {
        dof q[1], p[1];
        hamiltonian = p[0]^2 / 2 + * q[0]^2;
    }
}

fn main() {}
