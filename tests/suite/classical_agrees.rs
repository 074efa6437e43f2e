//! Claim 2 of the paper (Section 5.1.3) on every path the library can take
//! for one system: geometric SHAKE and RATTLE over Störmer–Verlet and
//! symplectic Euler are the classical methods, so one step of the library
//! and one step of the independent classical formulas
//! (`geoshake_testkit::reference`, Newton on the full system in nalgebra)
//! agree to round-off from every state of a trajectory.
//!
//! The scene is the `paper` example's (the double pendulum of unit rods
//! and masses, h = 0.05, 250 states of a RATTLE trajectory) and so is the
//! bound: 50 ε on |z1 − z1,classical|∞ for states of size O(1). Each path
//! the integrator may take is forced in turn: the fixed-size classical
//! step (the macro's stack arrays), the classical slice path
//! (`fixed_size(false)`), the run lane (a one-step run with nothing
//! watching each step: `run::lane`), and the general path
//! (`fast_paths(false)`: base map and fibre flow through Newton).

use crate::common;

use common::reference as r;
use geoshake::models::DoublePendulum;
use geoshake::{BaseMap, Integrator, State, Stop, StormerVerlet, SymplecticEuler};
use nalgebra::DVector;

const EPS: f64 = f64::EPSILON;
const H: f64 = 0.05;
const STATES: usize = 250;

/// The paths a SHAKE or RATTLE step can take for a classical system.
#[derive(Clone, Copy, Debug)]
enum Path {
    FixedSize,
    Slices,
    Lane,
    General,
}

/// One step of the library from z on `path`.
fn step<B: BaseMap>(base: B, rattle: bool, path: Path, z: &State) -> State {
    let sys = DoublePendulum::new(1.0, 1.0, 1.0);
    let integ = Integrator::new(sys, base, H);
    let integ = match path {
        Path::FixedSize | Path::Lane => integ,
        Path::Slices => integ.fixed_size(false),
        Path::General => integ.fast_paths(false),
    };
    let mut integ = if rattle {
        integ.rattle()
    } else {
        integ.shake()
    };
    match path {
        Path::Lane => {
            let traj = integ
                .run(z.clone(), Stop::Steps(1))
                .execute()
                .into_result()
                .unwrap_or_else(|(_, e)| panic!("{path:?}: {e}"));
            traj.last().expect("two states")
        }
        _ => integ.step(z).unwrap_or_else(|e| panic!("{path:?}: {e}")),
    }
}

/// The 250 states of the paper scene's trajectory (classical RATTLE steps
/// from the same start, so the states do not depend on the library).
fn states(cb: r::ClassicalBase) -> Vec<DVector<f64>> {
    let dbl = r::DoublePendulum::default();
    let mut z = dbl.state(1.0, -0.5, 0.3, 0.8);
    let mut out = Vec::with_capacity(STATES);
    for _ in 0..STATES {
        out.push(z.clone());
        z = r::classical_rattle_z(&dbl, cb, &z, H);
    }
    out
}

/// max over the states of |one library step − one classical step|∞.
fn worst<B: BaseMap + Copy>(base: B, cb: r::ClassicalBase, rattle: bool, path: Path) -> f64 {
    let dbl = r::DoublePendulum::default();
    states(cb)
        .iter()
        .map(|z| {
            let ours = step(base, rattle, path, &State::from_vector(z)).to_vector();
            let classical = if rattle {
                r::classical_rattle_z(&dbl, cb, z, H)
            } else {
                r::classical_shake_z(&dbl, cb, z, H)
            };
            (ours - classical).amax()
        })
        .fold(0.0, f64::max)
}

fn check<B: BaseMap + Copy>(base: B, cb: r::ClassicalBase) {
    let mut failed = Vec::new();
    for path in [Path::FixedSize, Path::Slices, Path::Lane, Path::General] {
        for rattle in [false, true] {
            let d = worst(base, cb, rattle, path);
            let method = if rattle { "RATTLE" } else { "SHAKE" };
            eprintln!("{} {method} {path:?}: {d:.3e} = {:.1} ε", B::NAME, d / EPS);
            if d > 50.0 * EPS {
                failed.push(format!("{method} {path:?} {d:.3e}"));
            }
        }
    }
    assert!(failed.is_empty(), "{}: above 50 ε: {failed:?}", B::NAME);
}

#[test]
fn double_pendulum_over_stormer_verlet_is_classical_on_every_path() {
    check(StormerVerlet, r::ClassicalBase::StormerVerlet);
}

#[test]
fn double_pendulum_over_symplectic_euler_is_classical_on_every_path() {
    check(SymplecticEuler, r::ClassicalBase::SymplecticEuler);
}
