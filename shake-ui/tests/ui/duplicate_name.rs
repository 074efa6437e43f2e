use geoshake::constrained_system;

constrained_system! {
    pub struct Oscillator {
        parameters { x, omega }
        coordinates x;
        momenta px;
        hamiltonian = px^2 / 2 + omega^2 * x^2 / 2;
    }
}

fn main() {}
