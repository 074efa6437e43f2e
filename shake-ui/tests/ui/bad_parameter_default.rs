use geoshake::constrained_system;

// A parameter's default is a number literal: a name (or an expression) is
// refused at it, not evaluated.
constrained_system! {
    pub struct Pendulum {
        parameters { length = one, gravity = 9.81 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - length^2 }
    }
}

fn main() {}
