use geoshake::constrained_system;

// Each exponent is allowed, their merge x^1000 * x^1000 = x^2000 is not.
constrained_system! {
    pub struct Hostile {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + q[1]^1000 * q[1]^1000;
        constraints { rod: q[0]^2 + q[1]^2 - 1 }
    }
}

fn main() {}
