use geoshake::constrained_system;

constrained_system! {
    pub struct Pendulum {
        parameters { length }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2;
        constraints {
            rod: q[0]^2 + q[1]^2 - length^2,
            oops: (q[0] + length) - q[0] - 1,
        }
    }
}

fn main() {}
