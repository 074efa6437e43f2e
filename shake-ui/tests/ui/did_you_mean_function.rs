use geoshake::constrained_system;

// A misspelt function: the error names the nearest supported one.
constrained_system! {
    pub struct Pendulum {
        parameters { gravity }
        dof q[1], p[1];
        hamiltonian = p[0]^2 / 2 - gravity * cso(q[0]);
    }
}

fn main() {}
