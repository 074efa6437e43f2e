use geoshake::constrained_system;

// {a, b} = 1 and {c, d} = -1 - 4 q[1] p[1]: neither vanishes on M; both are reported.
// (Four constraints need d >= 4: with m > d the macro refuses before any pair check.)
constrained_system! {
    pub struct NotCoisotropic {
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2 + q[0]^2 + q[1]^2 + q[2]^2 + q[3]^2) / 2;
        constraints {
            a: q[0],
            b: p[0],
            c: q[1]^2 + p[1] - 1,
            d: q[1] - p[1]^2,
        }
    }
}

fn main() {}
