use geoshake::constrained_system;

// A misspelt named coordinate: the error names the nearest declared one.
constrained_system! {
    pub struct Pendulum {
        parameters { length, gravity }
        coordinates theta, phi;
        momenta p_theta, p_phi;
        hamiltonian = (p_theta^2 + p_phi^2) / 2 - gravity * cos(thetta);
        constraints { cone: phi - length * theta }
    }
}

fn main() {}
