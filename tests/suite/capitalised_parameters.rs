//! Parameters named as in the mathematics, `parameters { L, G }`, with
//! constants `L` and `G` of the same names in scope: the declarations
//! compile without a warning (this file denies them), `new` binds its
//! arguments instead of matching them against the constants, and the
//! systems keep |q| = L while they move under G. The same declaration read
//! at run time (`geoshake::declared`) accepts the names too and takes the
//! macro's steps.
#![deny(warnings)]

use geoshake::declared::DeclaredSystem;
use geoshake::prelude::*;
use geoshake::runtime::particles::{Options, ParticleState, Rattle};

/// The caller's own constants, named like the parameters: an argument
/// `L` of `new` would be a pattern matching this constant (E0005).
const L: f64 = 2.0;
const G: f64 = 9.81;

constrained_system! {
    /// The planar pendulum, a rod of length L under gravity G.
    pub struct Pendulum {
        parameters { L, G }
        dof q[2], p[2];
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + G * q[1];
        constraints { rod: q[0]^2 + q[1]^2 - L^2 }
    }
}

/// The same pendulum, declared at run time.
const PENDULUM: &str = "
pub struct Pendulum {
    parameters { L, G }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 + G * q[1];
    constraints { rod: q[0]^2 + q[1]^2 - L^2 }
}";

constrained_system! {
    /// A free rigid dimer in the plane: two particles at distance L,
    /// falling under gravity G (the particle form of the macro).
    pub struct Dimer {
        parameters { L, G }
        particles x[2];
        potential { fall[k in bobs(a)]: G * x[a][1] }
        constraints { rod[k in rods(a, b)]: norm2(x[a] - x[b]) - L^2 }
    }
}

/// The pendulum released at θ = 1 from rest, on M^H.
fn start<S: ConstrainedSystem, B: BaseMap>(rattle: &mut Integrator<S, B>) -> State {
    let (s, c) = 1f64.sin_cos();
    rattle
        .project_to_hidden(&State::from_slices(&[L * s, -L * c], &[0.0, 0.0]))
        .expect("the start projects onto M^H")
}

#[test]
fn the_macro_pendulum_stays_on_its_rod_of_length_l() {
    let pendulum = Pendulum::new(L, G);
    assert_eq!(pendulum, Pendulum { L: 2.0, G: 9.81 });
    assert_eq!((pendulum.L, pendulum.G), (L, G));
    let mut rattle = Integrator::new(pendulum, StormerVerlet, 0.01).rattle();
    let mut z = start(&mut rattle);
    let z0 = z.clone();
    for _ in 0..200 {
        z = rattle.step(&z).expect("a step");
        assert!((z.q.norm() - L).abs() < 1e-13, "|q| = {}", z.q.norm());
    }
    // It swung (through the bottom and up the other side), under G.
    assert!(z.q[0] * z0.q[0] < 0.0, "{:?} from {:?}", z.q, z0.q);
}

#[test]
fn the_declared_pendulum_accepts_them_and_takes_the_macro_steps() {
    let declared = DeclaredSystem::new(PENDULUM, &[("G", G), ("L", L)]).expect("accepted");
    assert_eq!(declared.parameter_names(), ["L", "G"]);
    let mut by_string = Integrator::new(declared, StormerVerlet, 0.01).rattle();
    let mut by_macro = Integrator::new(Pendulum::new(L, G), StormerVerlet, 0.01).rattle();
    let (mut a, mut b) = (start(&mut by_string), start(&mut by_macro));
    for _ in 0..200 {
        a = by_string.step(&a).expect("a step");
        b = by_macro.step(&b).expect("a step");
        assert!((a.q.norm() - L).abs() < 1e-13, "|q| = {}", a.q.norm());
        assert!(a.distance(&b) < 1e-13, "{a:?} against {b:?}");
    }
}

#[test]
fn the_particle_dimer_keeps_its_length_and_falls_freely() {
    let dimer = Dimer::new(L, G);
    assert_eq!((dimer.L, dimer.G), (L, G));
    assert_eq!(dimer.rod_stencil().L, L);
    let mut bobs = Dimer::bobs_table();
    bobs.push(&[0], &[]).expect("a row");
    bobs.push(&[1], &[]).expect("a row");
    let mut rods = Dimer::rods_table();
    rods.push(&[0, 1], &[]).expect("a row");
    let system = dimer.system(vec![1.0, 1.0], bobs, rods).expect("a system");
    let h = 0.01;
    // Each step solved to round-off, so that the length is kept to it.
    let options = Options {
        tol: 1e-15,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, h, options).expect("a solver");
    // Horizontal and spinning: the rod turns while the pair falls.
    let mut state = ParticleState::new(vec![0.0, 0.0, L, 0.0], vec![0.0, -1.0, 0.0, 1.0]);
    for step in 1..=100 {
        rattle.step(&mut state).expect("a step");
        let x = state.q();
        let length = (x[2] - x[0]).hypot(x[3] - x[1]);
        assert!((length - L).abs() < 1e-12, "|x1 - x0| = {length}");
        // The rod's forces cancel in the sum: the centre falls as -G t²/2,
        // which Störmer–Verlet follows exactly.
        let t = step as f64 * h;
        let centre = (x[1] + x[3]) / 2.0;
        assert!(
            (centre + G * t * t / 2.0).abs() < 1e-12,
            "centre {centre} at {t}"
        );
    }
}
