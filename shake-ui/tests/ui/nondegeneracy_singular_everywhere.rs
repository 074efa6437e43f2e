use geoshake::constrained_system;

// N = g_q H_pp g_qᵀ = [[1, 1], [1, 1]] has no zero row but is singular on
// all of M^H.
constrained_system! {
    pub struct Degenerate {
        dof q[2], p[2];
        hamiltonian = (p[0] + p[1])^2 / 2 + q[0]^2 + q[1]^2;
        constraints {
            a: q[0],
            b: q[1],
        }
    }
}

fn main() {}
