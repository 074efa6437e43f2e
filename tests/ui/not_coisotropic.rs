use shake::constrained_system;

// {a, b} = 1 and {c, d} = -1 - 4 q[1] p[1]: neither vanishes on M; both are reported.
constrained_system! {
    pub struct NotCoisotropic {
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2 + q[0]^2 + q[1]^2) / 2;
        constraints {
            a: q[0],
            b: p[0],
            c: q[1]^2 + p[1] - 1,
            d: q[1] - p[1]^2,
        }
    }
}

fn main() {}
