use geoshake::constrained_system;

constrained_system! {
    pub struct Chain {
        parameters { length }
        const N = 3;
        dof q[2*N], p[2*N];
        hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 };
        constraints {
            link[k in 0..N]: (q[2*k+2] - q[2*k])^2 + (q[2*k+3] - q[2*k+1])^2 - length^2,
        }
    }
}

fn main() {}
