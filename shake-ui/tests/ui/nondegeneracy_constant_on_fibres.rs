use geoshake::constrained_system;

// The paper's Section 5.2 with H = p²/2: H is constant on the fibres,
// M^H = M and the solutions are not unique.
constrained_system! {
    pub struct Free {
        coordinates q, qbar;
        momenta p, pbar;
        hamiltonian = p^2 / 2;
        constraints { bar: qbar }
    }
}

fn main() {}
