//! What a run may ask for, on both engines: the start time, the number of
//! steps, the stop time, h and the stored states are checked together
//! before the first step, and a request that cannot be met is a typed
//! error carrying the offending value, never an abort of the process, a
//! loop without end, or NaN and ∞ among the stored times. With them, the
//! particle path's tolerance and iteration budget, and the fallible
//! constructors of a dense `State`.

use geoshake_runtime::nalgebra::DVector;
use geoshake_runtime::particles::{
    stencils::Distance, Options, ParticleState, ParticleSystem, Rattle, Table,
};
use geoshake_runtime::validate::{MAX_ITERATIONS, MAX_STEPS, MIN_RELATIVE_TOLERANCE};
use geoshake_runtime::{
    examples::Pendulum, Integrator, RunOutcome, State, StateError, StepError, Stop, StormerVerlet,
};

// ---------------------------------------------------------------------------
// The dense path

/// A pendulum without gravity: at rest it stays at rest for any h.
fn weightless() -> Pendulum {
    Pendulum {
        gravity: 0.0,
        length: 1.0,
    }
}

fn at_bottom() -> State {
    State::from_slices(&[0.0, -1.0], &[0.0, 0.0])
}

fn invalid(e: Option<StepError>, what: &str) -> f64 {
    match e {
        Some(StepError::InvalidInput { what: w, value }) if w.contains(what) => value,
        other => panic!("expected InvalidInput ({what}), got {other:?}"),
    }
}

#[test]
fn dense_run_whose_last_time_overflows_is_refused() {
    // A 3-step SHAKE run with h = f64::MAX returned Ok, with the stored
    // times 0, 1.8e308, ∞, ∞.
    for h in [f64::MAX, -f64::MAX] {
        let mut integ = Integrator::new(weightless(), StormerVerlet, h).shake();
        let out = integ.run(at_bottom(), Stop::Steps(3)).execute();
        assert!(out.trajectory.is_empty());
        let value = invalid(out.error, "t0 + k·h of the last step must be finite");
        assert_eq!(value, h.signum() * f64::INFINITY);
    }
    // From a start time near the end of f64's range, one step of 1 is
    // fine but h = f64::MAX is not.
    let mut integ = Integrator::new(weightless(), StormerVerlet, f64::MAX).shake();
    let out = integ
        .run(at_bottom(), Stop::Steps(1))
        .start_time(f64::MAX)
        .execute();
    assert_eq!(invalid(out.error, "last step"), f64::INFINITY);
    let out = integ.run(at_bottom(), Stop::Steps(1)).execute();
    assert_eq!(out.into_result().unwrap().times(), vec![0.0, f64::MAX]);
}

#[test]
fn dense_run_of_more_than_2_pow_53_steps_is_refused() {
    // What Python's `run(..., steps=2**63, stride=1)` asks for (it killed
    // the interpreter) and `stride=2**62` (it never returned).
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.01);
    for stride in [1, 1 << 62] {
        let out = integ
            .run(at_bottom(), Stop::Steps(1 << 63))
            .stride(stride)
            .execute();
        assert!(out.trajectory.is_empty());
        assert_eq!(invalid(out.error, "2^53 steps"), 2f64.powi(63));
    }
    let out = integ
        .run(at_bottom(), Stop::Steps(MAX_STEPS + 1))
        .store(false)
        .execute();
    assert_eq!(invalid(out.error, "2^53 steps"), (MAX_STEPS + 1) as f64);
}

#[test]
fn dense_storage_that_does_not_fit_is_a_typed_error() {
    // 2^53 + 1 states of 4 numbers: refused by the reservation, before
    // the first step.
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.01);
    let out = integ.run(at_bottom(), Stop::Steps(MAX_STEPS)).execute();
    assert!(out.trajectory.is_empty());
    assert_eq!(
        out.error,
        Some(StepError::Storage {
            step: 0,
            states: MAX_STEPS + 1,
            dof: 2
        })
    );
    let e = out.error.unwrap();
    assert_eq!((e.step(), e.time()), (0, None));
    // With a stride: first, every stride-th and last, 2^53 / 3 + 2 of them.
    let out = integ
        .run(at_bottom(), Stop::Steps(MAX_STEPS))
        .stride(3)
        .execute();
    assert!(matches!(
        out.error,
        Some(StepError::Storage { states, .. }) if states == MAX_STEPS / 3 + 2
    ));
}

#[test]
fn dense_run_reserves_exactly_the_states_it_stores() {
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    let z0 = Pendulum::default().state(0.3, 0.0);
    let traj = integ
        .run(z0, Stop::Steps(7))
        .stride(3)
        .execute()
        .into_result()
        .unwrap();
    assert_eq!(traj.steps(), vec![0, 3, 6, 7]);
    assert_eq!(traj.state_bytes(), 4 * 4 * 8);
}

// ---------------------------------------------------------------------------
// The particle path

/// A dimer of unit masses and bond length 1 (d = 6), with step size h.
fn dimer(h: f64, options: Options) -> Result<Rattle, StepError> {
    let mut bonds = Table::new(2, 1);
    bonds.push(&[0, 1], &[1.0]).unwrap();
    let system = ParticleSystem::new(3, vec![1.0, 1.0])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bonds)
        .unwrap();
    Rattle::new(system, h, options)
}

/// A dimer state on M and M^H; at rest when `moving` is false.
fn dimer_state(moving: bool) -> ParticleState {
    let v = if moving { 0.1 } else { 0.0 };
    ParticleState::new(
        vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        vec![0.0, v, 0.0, 0.0, -v, 0.0],
    )
}

/// The run was refused before any step: `InvalidInput` with this message
/// fragment, nothing stored, no step taken.
fn refused(out: RunOutcome, what: &str) -> f64 {
    assert!(
        out.trajectory.is_empty(),
        "stored {} states",
        out.trajectory.len()
    );
    assert_eq!(out.summary.steps, 0);
    match out.error {
        Some(StepError::InvalidInput { what: w, value }) if w.contains(what) => value,
        other => panic!("expected InvalidInput ({what}), got {other:?}"),
    }
}

#[test]
fn particle_run_of_u64_max_steps_is_refused_not_aborted() {
    // The stored-state count 0 ..= u64::MAX is u64::MAX + 1: it wrapped to
    // 0, nothing was reserved, and the run grew its buffer until the
    // allocator aborted the process.
    let mut rattle = dimer(0.01, Options::default()).unwrap();
    let state = dimer_state(true);
    let out = rattle.run(&state, Stop::Steps(u64::MAX)).execute();
    assert_eq!(refused(out, "2^53 steps"), u64::MAX as f64);
    // Without storage too: it would never have returned.
    let out = rattle
        .run(&state, Stop::Steps(u64::MAX))
        .store(false)
        .execute();
    assert_eq!(refused(out, "2^53 steps"), u64::MAX as f64);
}

#[test]
fn particle_storage_that_does_not_fit_is_a_typed_error() {
    // 2^53 states of 12 numbers each: counted exactly, refused by the
    // reservation.
    let mut rattle = dimer(0.01, Options::default()).unwrap();
    let state = dimer_state(true);
    let out = rattle.run(&state, Stop::Steps(MAX_STEPS - 1)).execute();
    assert!(out.trajectory.is_empty() && out.summary.steps == 0);
    assert_eq!(
        out.error,
        Some(StepError::Storage {
            step: 0,
            states: MAX_STEPS,
            dof: 6
        })
    );
}

#[test]
fn particle_run_to_far_or_non_finite_stop_time_is_refused() {
    let mut rattle = dimer(0.01, Options::default()).unwrap();
    let state = dimer_state(true);
    // 1e302 steps: aborted (stored) or never returned (not stored).
    for store in [true, false] {
        let out = rattle.run(&state, Stop::Time(1e300)).store(store).execute();
        assert_eq!(refused(out, "more than 2^53 steps"), 1e302);
    }
    // NaN and ±∞ returned Ok with 0 steps; a time before the start too.
    for t_end in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1.0] {
        let out = rattle.run(&state, Stop::Time(t_end)).execute();
        let value = refused(out, "stop time must lie in the direction of h");
        assert_eq!(value.to_bits(), t_end.to_bits());
    }
    // A reachable stop time still runs.
    let out = rattle.run(&state, Stop::Time(0.05)).execute();
    assert_eq!((out.summary.steps, out.trajectory.len()), (5, 6));
    assert!(out.error.is_none());
}

#[test]
fn particle_non_finite_start_time_is_refused() {
    // Every stored time was NaN (or ∞).
    for t0 in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut rattle = dimer(0.01, Options::default()).unwrap();
        let mut state = dimer_state(true).with_time(t0);
        let out = rattle.run(&state, Stop::Steps(3)).execute();
        let value = refused(out, "start time must be finite");
        assert!(value.to_bits() == t0.to_bits(), "{value} for {t0}");
        // A single step refuses it too, and leaves the state alone.
        match rattle.step(&mut state) {
            Err(StepError::InvalidInput { value, .. }) => assert!(!value.is_finite()),
            other => panic!("expected InvalidInput, got {other:?}"),
        }
        assert_eq!(state.step(), 0);
    }
}

#[test]
fn particle_run_whose_last_time_overflows_is_refused() {
    // h = f64::MAX, at rest: every step succeeds, and the times were
    // 0, 1.8e308, ∞, ∞.
    let mut rattle = dimer(f64::MAX, Options::default()).unwrap();
    let state = dimer_state(false);
    let out = rattle.run(&state, Stop::Steps(3)).execute();
    assert_eq!(
        refused(out, "t0 + k·h of the last step must be finite"),
        f64::INFINITY
    );
    // One step ends at f64::MAX: finite, allowed.
    let traj = rattle
        .run(&state, Stop::Steps(1))
        .execute()
        .into_result()
        .unwrap();
    assert_eq!(traj.time(1), f64::MAX);
}

#[test]
fn particle_tolerance_below_round_off_is_refused() {
    // tol = 1e-20 was accepted, and a step iterated to max_iter.
    for tol in [1e-20, 3.0 * f64::EPSILON, 0.0, f64::NAN] {
        match dimer(
            0.01,
            Options {
                tol,
                ..Options::default()
            },
        ) {
            Err(StepError::InvalidInput { what, value }) if what.starts_with("tol") => {
                assert_eq!(value.to_bits(), tol.to_bits())
            }
            Err(e) => panic!("tol = {tol}: expected InvalidOption, got {e:?}"),
            Ok(_) => panic!("tol = {tol} was accepted"),
        }
    }
    let tol = MIN_RELATIVE_TOLERANCE;
    let mut rattle = dimer(
        0.01,
        Options {
            tol,
            ..Options::default()
        },
    )
    .unwrap();
    let state = dimer_state(true);
    let out = rattle.run(&state, Stop::Steps(10)).execute();
    assert!(out.error.is_none());
    assert!(
        out.summary.max_residual.unwrap() <= tol,
        "{:?}",
        out.summary
    );
}

#[test]
fn particle_iteration_budget_is_bounded() {
    // usize::MAX was accepted: a step that cannot converge never returned.
    for max_iter in [usize::MAX, MAX_ITERATIONS + 1, 0] {
        match dimer(
            0.01,
            Options {
                max_iter,
                ..Options::default()
            },
        ) {
            Err(StepError::InvalidInput { what, value }) if what.starts_with("max_iter") => {
                assert_eq!(value, max_iter as f64)
            }
            Err(e) => panic!("max_iter = {max_iter}: expected InvalidOption, got {e:?}"),
            Ok(_) => panic!("max_iter = {max_iter} was accepted"),
        }
    }
    let max_iter = MAX_ITERATIONS;
    assert!(dimer(
        0.01,
        Options {
            max_iter,
            ..Options::default()
        }
    )
    .is_ok());
}

// ---------------------------------------------------------------------------
// State

#[test]
fn state_constructors_have_fallible_forms() {
    // State::from_slices(&[1.0], &[1.0, 2.0]), State::new and
    // State::from_vector with an odd length panic; these do not.
    assert_eq!(
        State::try_from_slices(&[1.0], &[1.0, 2.0]),
        Err(StateError::LengthMismatch { q: 1, p: 2 })
    );
    assert_eq!(
        State::try_new(DVector::zeros(3), DVector::zeros(1)),
        Err(StateError::LengthMismatch { q: 3, p: 1 })
    );
    assert_eq!(
        State::try_from_vector(&DVector::from_vec(vec![1.0, 2.0, 3.0])),
        Err(StateError::OddLength { len: 3 })
    );
    let z = State::try_from_vector(&DVector::from_vec(vec![1.0, 2.0, 3.0, 4.0])).unwrap();
    assert_eq!(z, State::from_slices(&[1.0, 2.0], &[3.0, 4.0]));
    assert_eq!(State::try_from_slices(&[], &[]), Ok(State::zeros(0)));
}
