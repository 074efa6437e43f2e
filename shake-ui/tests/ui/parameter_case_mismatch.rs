use geoshake::constrained_system;

// Parameters may be capitalised, and case counts: `L` declared, `l` used is
// an unknown symbol, with the declared spelling suggested. The constant `L`
// in scope shows that this is the only error (`new` binds its arguments).
const L: f64 = 1.0;

constrained_system! {
    pub struct Pendulum {
        parameters { L, G }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + G * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - l^2 }
    }
}

fn main() {
    let _ = L;
}
