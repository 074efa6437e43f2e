use geoshake::constrained_system;

// `**` (Python, Fortran) for a power: the error says `^` is the operator.
constrained_system! {
    pub struct Oscillator {
        dof q[1], p[1];
        hamiltonian = (p[0]**2 + q[0]**2) / 2;
    }
}

fn main() {}
