use geoshake::constrained_system;

// Defaults for some parameters only: `impl Default` needs all of them, so
// the first without one is named (rather than `Default` silently missing).
constrained_system! {
    pub struct Pendulum {
        parameters { length = 1.0, gravity }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - length^2 }
    }
}

fn main() {}
