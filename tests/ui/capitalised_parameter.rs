use shake::constrained_system;

// A parameter named like a constant would become a non-snake-case field and
// argument of `new` (a pattern, E0005, if a constant `L` is in scope): refused
// at the name, with the snake_case spelling.
const L: f64 = 1.0;

constrained_system! {
    pub struct Pendulum {
        parameters { L, gravity }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - L^2 }
    }
}

fn main() {
    let _ = L;
}
