use geoshake::constrained_system;

constrained_system! {
    pub struct Oscillator {
        parameters { omega }
        dof q[1], p[1];
        hamiltonian = p[0]^2 / 2 + omega * q[0]^2 / (omega - omega);
    }
}

fn main() {}
