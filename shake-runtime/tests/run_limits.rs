//! What a run may ask for: the start time, the number of steps, the stop
//! time, h and the stored states are checked together before the first
//! step, and a request that cannot be met is a typed error carrying the
//! offending value, never an abort of the process, a loop without end, or
//! NaN and ∞ among the stored times.

use shake_runtime::validate::MAX_STEPS;
use shake_runtime::{examples::Pendulum, Integrator, State, StepError, Stop, StormerVerlet};

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
