//! Particle runs as an ensemble ([`run_ensemble`] with a particle
//! [`Rattle`] as the template): every member's outcome is, bit for bit,
//! the run of that member alone on one thread, in the order of the
//! initial states, in a pool of 1, 2 or 3 threads; a member that fails
//! comes back with its typed error and the trajectory up to the failure,
//! and the others complete. On the cluster path (boxes of rigid water, with
//! and without forces the user brings) and on the coupled path (chains on
//! the sparse solver, whose symbolic factorisation the copies share).

use geoshake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, SolverChoice,
};
use geoshake::runtime::rayon::ThreadPoolBuilder;
use geoshake::runtime::{run_ensemble, RunOutcome, SolveError, StepError, Stop};
use geoshake_testkit::same_bits::assert_same_bits;

/// Waters per box.
const WATERS: usize = 100;
const STEPS: u64 = 40;
const STRIDE: u64 = 7;

fn in_pool<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// A weak harmonic tether of every atom to the origin, as a user's field.
fn with_tether(system: ParticleSystem) -> ParticleSystem {
    system.with_forces(|q: &[f64], f: &mut [f64]| {
        f.iter_mut().zip(q).for_each(|(f, q)| *f -= 1e-4 * q);
        0.5e-4 * q.iter().map(|q| q * q).sum::<f64>()
    })
}

/// The solver of a box of water (with the tether when `forces`).
fn water_solver(forces: bool) -> (Rattle, ParticleState) {
    let (system, state) = generate::water(WATERS, 11).unwrap();
    let system = if forces { with_tether(system) } else { system };
    (Rattle::new(system, 2.0, Options::default()).unwrap(), state)
}

/// The solver of a chain on the sparse solver.
fn chain_solver() -> (Rattle, ParticleState) {
    let (system, state) = generate::chain(60, 4).unwrap();
    let options = Options {
        solver: SolverChoice::Sparse,
        ..Options::default()
    };
    let rattle = Rattle::new(system, 2.0, options).unwrap();
    assert_eq!(rattle.solver_name(), "sparse");
    (rattle, state)
}

/// 8 members: the projected start at 50, 100, …, 400 K.
fn members(rattle: &mut Rattle, mut state: ParticleState) -> Vec<ParticleState> {
    rattle.project(&mut state).unwrap();
    (1..=8)
        .map(|k| {
            let mut s = state.clone();
            generate::set_temperature(rattle.system(), &mut s, 50.0 * k as f64);
            s
        })
        .collect()
}

/// Each member run alone on one thread, by a solver of its own.
fn alone(solver: fn() -> (Rattle, ParticleState), starts: &[ParticleState]) -> Vec<RunOutcome> {
    in_pool(1, || {
        starts
            .iter()
            .map(|s| {
                let (mut rattle, _) = solver();
                rattle.run(s, Stop::Steps(STEPS)).stride(STRIDE).execute()
            })
            .collect()
    })
}

fn assert_same_outcomes(got: &[RunOutcome], want: &[RunOutcome], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert_eq!(g.error, w.error, "{what}: member {k}");
        assert_eq!(g.trajectory.len(), w.trajectory.len(), "{what}: member {k}");
        assert_same_bits(&g.trajectory, &w.trajectory);
        assert_eq!(g.summary.steps, w.summary.steps, "{what}: member {k}");
    }
}

/// The ensemble in pools of 1, 2 and 3 threads against the members alone.
fn same_as_alone(solver: fn() -> (Rattle, ParticleState), mut starts: Vec<ParticleState>) {
    // The template has taken steps of its own, and the last member is the
    // state they made: members must not depend on what the template (or
    // a copy of it) did before, so that one runs as new, as it does alone.
    let (mut template, _) = solver();
    let mut warm = starts[0].clone();
    template.run_in_place(&mut warm, 3);
    *starts.last_mut().unwrap() = warm;
    let want = alone(solver, &starts);
    for threads in [1, 2, 3] {
        let got = in_pool(threads, || {
            run_ensemble(&template, &starts, Stop::Steps(STEPS), STRIDE)
        });
        assert_same_outcomes(&got, &want, &format!("{threads} threads"));
    }
    // Members that differ: every member's own run, in input order.
    let last = |o: &RunOutcome| o.trajectory.p(o.trajectory.len() - 1).to_vec();
    assert!(want.windows(2).all(|w| last(&w[0]) != last(&w[1])));
}

#[test]
fn water_boxes_at_eight_temperatures_as_when_run_alone() {
    let water = || water_solver(false);
    let (mut rattle, state) = water();
    assert_eq!(rattle.solver_name(), "clusters");
    let starts = members(&mut rattle, state);
    same_as_alone(water, starts);
}

#[test]
fn water_boxes_with_brought_forces_as_when_run_alone() {
    let water = || water_solver(true);
    let (mut rattle, state) = water();
    let starts = members(&mut rattle, state);
    same_as_alone(water, starts);
}

#[test]
fn chains_on_the_sparse_solver_as_when_run_alone() {
    let (mut rattle, state) = chain_solver();
    let starts = members(&mut rattle, state);
    same_as_alone(chain_solver, starts);
}

/// Nothing lost: a member with a NaN momentum and one with a collapsed
/// molecule (its hydrogens on its oxygen) fail with their own typed
/// errors and keep what they ran; the six others complete, as alone.
#[test]
fn broken_members_fail_alone_and_the_others_complete() {
    let water = || water_solver(false);
    let (mut rattle, state) = water();
    let mut starts = members(&mut rattle, state);
    starts[2].p_mut()[7] = f64::NAN;
    let q = starts[5].q_mut();
    let oxygen = [q[0], q[1], q[2]];
    q[3..6].copy_from_slice(&oxygen);
    q[6..9].copy_from_slice(&oxygen);
    let want = alone(water, &starts);
    for threads in [1, 3] {
        let got = in_pool(threads, || {
            run_ensemble(&rattle, &starts, Stop::Steps(STEPS), STRIDE)
        });
        assert_same_outcomes(&got, &want, &format!("{threads} threads"));
        for (k, out) in got.iter().enumerate() {
            match (k, &out.error) {
                (2, Some(StepError::NonFinite { entry, .. })) => {
                    assert_eq!(*entry, 3 * 3 * WATERS + 7);
                }
                (
                    5,
                    Some(StepError::AtMember {
                        step,
                        family,
                        member,
                        source,
                        ..
                    }),
                ) => {
                    assert_eq!((*step, family.as_str(), *member / 3), (1, "bond", 0));
                    assert!(matches!(
                        source,
                        SolveError::Singular { .. } | SolveError::NotConverged { .. }
                    ));
                    // The start state is kept, as given.
                    assert_eq!(out.trajectory.len(), 1);
                    assert_eq!(out.trajectory.q(0), starts[5].q());
                }
                (2 | 5, e) => panic!("member {k}: {e:?}"),
                (_, None) => {
                    let traj = &out.trajectory;
                    assert_eq!(traj.step(traj.len() - 1), STEPS);
                }
                (_, Some(e)) => panic!("member {k}: {e}"),
            }
        }
    }
}
