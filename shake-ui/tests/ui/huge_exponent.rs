use geoshake::constrained_system;

// Exponents beyond the documented limit are refused, never an integer overflow.
constrained_system! {
    pub struct Hostile {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + q[1]^2000000000 * q[1]^2000000000;
        constraints { rod: q[0]^2 + q[1]^2 - 1 }
    }
}

fn main() {}
