use geoshake::constrained_system;

// 2000 constraints on 8 coordinates can never have an invertible N: refused
// at once, before anything is differentiated (this used to take minutes).
constrained_system! {
    pub struct Crowded {
        const N = 2000;
        dof q[8], p[8];
        hamiltonian = sum i in 0..8 { p[i]^2 / 2 };
        constraints {
            link[k in 0..N]: q[k % 7]^2 + q[k % 7 + 1]^2 - 1 - k,
        }
    }
}

fn main() {}
