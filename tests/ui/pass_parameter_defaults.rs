//! Defaults for every parameter give `impl Default` (through `new`, so in
//! declaration order); integers, signs and exponents are read as f64.
use geoshake::constrained_system;

constrained_system! {
    /// A pendulum in a field that may point up.
    pub struct Pendulum {
        parameters { length = 1.5, gravity = -9.81, mass = 2, tilt = 1e-3 }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / (2 * mass) + mass * gravity * (q[1] + tilt * q[0]);
        constraints { rod: q[0]^2 + q[1]^2 - length^2 }
    }
}

constrained_system! {
    /// Without defaults there is no `Default`; named fields still work.
    pub struct Plain {
        parameters { length, gravity }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - length^2 }
    }
}

constrained_system! {
    /// The run-time (particles) form takes defaults too.
    pub struct Springs {
        parameters { stiffness = 100.0 }
        particles x[3];
        potential {
            spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
        }
    }
}

fn main() {
    assert_eq!(Springs::default(), Springs::new(100.0));
    let p = Pendulum::default();
    assert_eq!(p, Pendulum::new(1.5, -9.81, 2.0, 1e-3));
    assert_eq!((p.length, p.gravity, p.mass, p.tilt), (1.5, -9.81, 2.0, 0.001));
    // Struct update syntax: change one parameter by name, keep the rest.
    let long = Pendulum { length: 3.0, ..Pendulum::default() };
    assert_eq!(long.gravity, -9.81);
    let plain = Plain { length: 1.0, gravity: 9.81 };
    assert_eq!(plain, Plain::new(1.0, 9.81));
}
