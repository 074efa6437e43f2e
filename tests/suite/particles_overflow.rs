//! Results that overflow f64 from finite inputs are typed errors, not
//! `Ok` with NaN or ∞: the constraint forces at a step size near the bottom
//! of f64's range, and the potential energy of a field of 10³⁰⁰. Both were
//! found by `tests/fuzz_particles.rs`.

use geoshake::runtime::particles::{
    stencils::Distance, ConstraintForces, Options, ParticleState, ParticleSystem, Rattle,
    SolverChoice, Table,
};
use geoshake::runtime::StepError;

fn dimer() -> ParticleSystem {
    let mut bonds = Table::new(2, 1);
    bonds.push(&[0, 1], &[1.0]).unwrap();
    ParticleSystem::new(3, vec![1.0, 2.0])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bonds)
        .unwrap()
}

/// Λ = 2ν/h²: with h = 1e-227 a step's multipliers ν of ≈ 1e-228 give
/// Λ ≈ 1e226 · … and h² underflows to 0, so Λ was NaN or ∞ in an `Ok`.
#[test]
fn constraint_forces_that_overflow_are_a_typed_error() {
    let mut rattle = Rattle::new(dimer(), 1e-227, Options::default()).unwrap();
    let mut z = ParticleState::new(
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        vec![0.1, 0.3, 0.0, 0.2, -0.1, 0.4],
    );
    rattle.step(&mut z).unwrap();
    let mut out = ConstraintForces::new(rattle.system());
    match rattle.constraint_forces(&z, &mut out) {
        Ok(()) => assert!(
            out.multipliers
                .iter()
                .chain(&out.forces)
                .chain(&out.virial)
                .all(|x| x.is_finite()),
            "Ok with multipliers {:?}",
            out.multipliers
        ),
        Err(e) => assert!(matches!(e, StepError::NonFinite { .. }), "{e}"),
    }
}

/// A uniform field of 1e300 on a particle at height 1e10: the force is
/// finite, V = −∞ (it was returned as `Ok(-inf)`).
#[test]
fn a_potential_energy_that_overflows_is_a_typed_error() {
    let g = 1e300;
    let system = dimer().with_forces(move |q: &[f64], f: &mut [f64]| {
        f[2] -= g;
        f[5] -= g;
        g * (q[2] + q[5])
    });
    let mut rattle = Rattle::new(system, 0.01, Options::default()).unwrap();
    let z = ParticleState::new(vec![0.0, 0.0, -1e10, 1.0, 0.0, -1e10], vec![0.0; 6]);
    match rattle.potential_energy(&z) {
        Ok(v) => assert!(v.is_finite(), "Ok({v})"),
        Err(e) => assert!(matches!(e, StepError::NonFinite { .. }), "{e}"),
    }
}

/// A chain whose first bond is stretched to 1e200, so that its |r|²
/// overflows and its residual reads NaN: the running maximum of the
/// residuals (`if !(r <= worst)`) let the next, finite, member replace the
/// NaN, and the clusters solver "converged" at iteration 0, returning the
/// bond 1e200 long as `Ok` (a ring of 5 with momenta of 1e216, SHAKE, in
/// the fuzz suite). A residual of NaN fails the whole cluster. Stretched
/// to 1e154, |r|² = 1e308 is finite but |∇g|² = 4|r|² is not: the scale
/// 1/∞ = 0 made the residual read 0 (the Python suite's `Bonds` with
/// positions of 2e154). A scale that overflowed fails too.
#[test]
fn a_bond_whose_square_overflows_is_not_hidden_by_the_next_member() {
    let chain = || {
        let mut bonds = Table::new(2, 1);
        bonds.push(&[0, 1], &[1.0]).unwrap();
        bonds.push(&[1, 2], &[1.0]).unwrap();
        ParticleSystem::new(3, vec![1.0, 2.0, 1.0])
            .unwrap()
            .with_constraints("bond", Distance::<3>, bonds)
            .unwrap()
    };
    for solver in [
        SolverChoice::Clusters,
        SolverChoice::Band,
        SolverChoice::Sparse,
    ] {
        let options = Options {
            solver,
            ..Options::default()
        };
        let mut rattle = Rattle::new(chain(), 0.1, options).unwrap();
        for far in [1e154, 1e200] {
            let q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0];
            let mut x = [-far, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0];
            let given = x;
            match rattle.shake_positions(&q0, &mut x) {
                Ok(_) => panic!("{far:e} {solver:?}: Ok with x = {x:?}"),
                Err(e) => {
                    assert!(matches!(e, StepError::AtMember { .. }), "{solver:?}: {e}");
                    assert_eq!(x, given);
                }
            }
        }
    }
}
