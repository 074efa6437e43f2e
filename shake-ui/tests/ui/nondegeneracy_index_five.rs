use geoshake::constrained_system;

// The paper's Section 5.2: g = q̄, H = p²/2 + p̄ q. N ≡ 0, index 5.
constrained_system! {
    pub struct IndexFive {
        coordinates q, qbar;
        momenta p, pbar;
        hamiltonian = p^2 / 2 + pbar * q;
        constraints { bar: qbar }
    }
}

fn main() {}
