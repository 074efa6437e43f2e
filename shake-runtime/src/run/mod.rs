//! The driver: a run of many steps from an initial state until a stop
//! rule, with a stride, storage of the states in a [`Trajectory`],
//! diagnostics, observers, and on error the partial trajectory up to the
//! last good state.
//!
//! - this file: [`Stop`], [`RunOutcome`], the [`Run`] builder and its loop;
//! - `stepper`: what the loop asks of the integrator it runs (start, step,
//!   store), which [`Integrator`](crate::Integrator) implements;
//! - `lane`: the loop inside the fixed-size classical step;
//! - `event`: what an `on_step` observer sees.
//!
//! The step itself is the [`step`](crate::step) maps'; the checks are the
//! [`guard`](crate::guard)'s. A run of a system with a fixed-size
//! classical step (one substep a step, fast paths and fixed sizes on) and
//! no diagnostics loops inside that step (`lane`), calling the `on_step`
//! observer there, and comes back here only to end:
//! the same steps and stored states, without the layers between this
//! loop and the substep (`tests/suite/run_lane.rs`).

mod event;
pub(crate) mod lane;
pub(crate) mod stepper;

pub use event::{StepEvent, StepObserver};

use std::ops::ControlFlow;

use crate::diagnostics::Accumulator;
use crate::error::StepError;
use crate::report::RunSummary;
use crate::state::State;
use crate::tolerance::MAX_STEPS;
use crate::trajectory::Trajectory;
use lane::{Lane, LaneEnd};
use stepper::{Projection, Stepper};

/// When a run stops.
///
/// ```
/// use geoshake_runtime::Stop;
/// let a = Stop::Steps(100);
/// let b = Stop::Time(1.0);
/// assert_ne!(a, b);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Stop {
    /// After this many steps.
    Steps(u64),
    /// At this time (from the run's start time): the run takes
    /// n = (T − t0)/h steps, rounded to the nearest integer when within
    /// 1e-9 of it and up otherwise (the step size never changes).
    Time(f64),
}

/// The result of a run: the trajectory computed so far, what its steps
/// measured and, if the run stopped early, why. On an error the last good
/// state is always stored.
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute();
/// let traj = out.into_result().unwrap();
/// assert_eq!(traj.len(), 4);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutcome {
    /// Everything stored before the run ended.
    pub trajectory: Trajectory,
    /// What the steps taken measured (iterations, residuals).
    pub summary: RunSummary,
    /// Why the run ended early, if it did.
    pub error: Option<StepError>,
}

impl RunOutcome {
    /// `Ok(trajectory)` or `Err((partial trajectory, error))`.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.0);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.0, 0.0]), Stop::Steps(3)).execute();
    /// assert!(out.into_result().is_err());
    /// ```
    #[allow(clippy::result_large_err)] // the partial trajectory is the point
    pub fn into_result(self) -> Result<Trajectory, (Trajectory, StepError)> {
        match self.error {
            None => Ok(self.trajectory),
            Some(e) => Err((self.trajectory, e)),
        }
    }
}

/// A configured run; see [`Integrator::run`](crate::Integrator::run).
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let out = integ
///     .run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(10))
///     .stride(5)
///     .start_time(1.0)
///     .execute();
/// assert_eq!(out.trajectory.times(), vec![1.0, 1.5, 2.0]);
/// ```
#[must_use = "a run does nothing until `execute` is called"]
pub struct Run<'a, T, F> {
    integ: &'a mut T,
    z0: State,
    stop: Stop,
    stride: u64,
    store: bool,
    t0: f64,
    observer: F,
    on_step: Option<&'a mut StepObserver<'a>>,
    /// Never loop inside the fixed-size step (`lane`): the tests that
    /// compare the two loops set it.
    driver_only: bool,
    /// Set when the run was refused while it was being set up (a start
    /// state that is not even a state): `execute` returns it.
    refused: Option<StepError>,
}

impl<'a, T> Run<'a, T, fn(u64, f64, &State)> {
    /// A run of `integ` from `z0` until `stop`, with the defaults: stride
    /// 1, states stored, start time 0, no observers.
    pub(crate) fn new(integ: &'a mut T, z0: State, stop: Stop) -> Self {
        Run {
            integ,
            z0,
            stop,
            stride: 1,
            store: true,
            t0: 0.0,
            observer: |_, _, _| {},
            on_step: None,
            driver_only: false,
            refused: None,
        }
    }

    /// A run that `execute` refuses with `e` before anything else (the
    /// start state could not be made a [`State`]).
    pub(crate) fn refused(integ: &'a mut T, stop: Stop, e: StepError) -> Self {
        Run {
            refused: Some(e),
            ..Run::new(integ, State::from_slices(&[], &[]), stop)
        }
    }
}

// The driver runs the crate's steppers only (`Stepper` is the crate's
// own); users reach it through `Integrator::run`.
#[allow(private_bounds)]
impl<'a, T: Stepper, F: FnMut(u64, f64, &State)> Run<'a, T, F> {
    /// Store (and observe) every `k`-th state, plus the first and the last
    /// (default 1; 0 is an [`StepError::InvalidInput`]).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(7)).stride(3).execute();
    /// assert_eq!(out.trajectory.steps(), vec![0, 3, 6, 7]);
    /// ```
    pub fn stride(mut self, k: u64) -> Self {
        self.stride = k;
        self
    }

    /// The time of the initial state (default 0).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.5);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Time(3.0)).start_time(2.0).execute();
    /// assert_eq!(out.trajectory.times(), vec![2.0, 2.5, 3.0]);
    /// ```
    pub fn start_time(mut self, t0: f64) -> Self {
        self.t0 = t0;
        self
    }

    /// Whether to keep the states in the returned [`Trajectory`] (default
    /// true); with `false` only the observer sees them.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut n = 0;
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(5))
    ///     .store(false).observe(|_, _, _| n += 1).execute();
    /// assert!(out.trajectory.is_empty());
    /// assert_eq!(n, 6);
    /// ```
    pub fn store(mut self, store: bool) -> Self {
        self.store = store;
        self
    }

    /// Call `observer(step, t, state)` at every stored state (same points as
    /// the stride; the state is projected onto M^H for RATTLE).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut times = Vec::new();
    /// let _ = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(2))
    ///     .observe(|_, t, _| times.push(t)).execute();
    /// assert_eq!(times, vec![0.0, 0.1, 0.2]);
    /// ```
    pub fn observe<G: FnMut(u64, f64, &State)>(self, observer: G) -> Run<'a, T, G> {
        Run {
            integ: self.integ,
            z0: self.z0,
            stop: self.stop,
            stride: self.stride,
            store: self.store,
            t0: self.t0,
            refused: self.refused,
            observer,
            on_step: self.on_step,
            driver_only: self.driver_only,
        }
    }

    /// Call `f` after every step with its [`StepEvent`] (step index, number
    /// of steps, time, [`StepInfo`](crate::StepInfo)); `ControlFlow::Break(())` ends the run
    /// there, with that state stored as the last one and no error. This is
    /// the hook for progress reporting (every step, not only the stored
    /// ones; keep `f` cheap).
    ///
    /// ```
    /// use std::ops::ControlFlow;
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut seen = 0;
    /// let mut until_4 = |e: &geoshake_runtime::StepEvent| {
    ///     seen += 1;
    ///     if e.step == 4 { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    /// };
    /// let out = integ
    ///     .run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(10))
    ///     .stride(3)
    ///     .on_step(&mut until_4)
    ///     .execute();
    /// assert!(out.error.is_none());
    /// assert_eq!(out.trajectory.steps(), vec![0, 3, 4]);
    /// assert_eq!(seen, 4);
    /// ```
    pub fn on_step(mut self, f: &'a mut StepObserver<'a>) -> Self {
        self.on_step = Some(f);
        self
    }

    /// Takes every step through the driver's own loop, never the loop
    /// inside a fixed-size classical step (`run::lane`), which takes the
    /// same steps faster. For tests that compare the two loops.
    #[doc(hidden)]
    pub fn through_driver(mut self) -> Self {
        self.driver_only = true;
        self
    }

    /// Runs, and returns everything computed, with the error that stopped
    /// the run early if any. On an error the last good state is stored (and
    /// observed) even when it is not on the stride.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute();
    /// assert!(out.error.is_none());
    /// ```
    pub fn execute(self) -> RunOutcome {
        let Run {
            integ,
            z0,
            stop,
            stride,
            store,
            t0,
            mut observer,
            mut on_step,
            driver_only,
            refused,
        } = self;
        let mut traj = Trajectory::default();
        let mut summary = RunSummary::default();
        let fail = |traj: Trajectory, summary: RunSummary, e: StepError| RunOutcome {
            trajectory: traj,
            summary,
            error: Some(e),
        };
        if let Some(e) = refused {
            return fail(traj, summary, e);
        }
        if let Err(e) = integ
            .check_start(&z0)
            .and_then(|_| StepError::finite_input("start time must be finite", t0))
        {
            return fail(traj, summary, e);
        }
        if stride == 0 {
            return fail(
                traj,
                summary,
                StepError::InvalidInput {
                    what: "stride must be at least 1",
                    value: 0.0,
                },
            );
        }
        let h = integ.step_size();
        let (dof, names) = integ.layout();
        let n = match stop {
            Stop::Steps(n) => n,
            Stop::Time(t_end) => {
                let x = (t_end - t0) / h;
                if !(x >= 0.0) || !x.is_finite() {
                    return fail(
                        traj,
                        summary,
                        StepError::InvalidInput {
                            what: "stop time must lie in the direction of h from the start time",
                            value: t_end,
                        },
                    );
                }
                // Beyond 2^53 steps neither the step count nor the times
                // t0 + k h are exact any more (and the run would not end).
                if x > MAX_STEPS as f64 {
                    return fail(
                        traj,
                        summary,
                        StepError::InvalidInput {
                            what: "stop time needs more than 2^53 steps of size h",
                            value: x,
                        },
                    );
                }
                if (x - x.round()).abs() <= 1e-9 * x.max(1.0) {
                    x.round() as u64
                } else {
                    x.ceil() as u64
                }
            }
        };
        // The extent of the run (t0, n, t0 + n·h) and its storage, checked
        // together as the particle path checks them.
        let diagnostics = integ.diagnostics().then(|| integ.constraint_count());
        traj = match Trajectory::for_run((dof, names), diagnostics, t0, h, n, stride, store) {
            Ok(traj) => traj,
            Err(e) => return fail(traj, summary, e),
        };
        let mut q: Vec<f64> = z0.q.as_slice().to_vec();
        let mut p: Vec<f64> = z0.p.as_slice().to_vec();
        let mut scratch = z0;
        let Projection { per_step, lazy } = match integ.begin_run(&mut q, &mut p, t0) {
            Ok(projection) => projection,
            Err(e) => return fail(traj, summary, e),
        };
        // A stepper whose failed step leaves (q, p) as they were needs no
        // copy of the state before each step (a lazy run replays into it).
        let atomic = integ.atomic_steps() && !lazy;
        let (mut prev_q, mut prev_p) = if atomic {
            (Vec::new(), Vec::new())
        } else {
            (q.clone(), p.clone())
        };
        let mut acc = Accumulator::default();
        // Stores (and shows) the state in (q, p) as step k at time t.
        macro_rules! record {
            ($k:expr, $t:expr) => {
                integ.record(
                    &q,
                    &p,
                    per_step,
                    $k,
                    $t,
                    &mut acc,
                    &mut traj,
                    store,
                    &mut observer,
                    &mut scratch,
                )
            };
        }
        if let Err(e) = record!(0, t0) {
            return fail(traj, summary, e);
        }
        let mut last_recorded = 0;
        // A lazily projecting RATTLE run keeps the SHAKE state of its last
        // stored step, to replay from it on failure (`Stepper::replay`).
        let (mut rec_q, mut rec_p) = if lazy {
            (q.clone(), p.clone())
        } else {
            (Vec::new(), Vec::new())
        };
        // The common case, one fixed-size classical substep a step and
        // nothing to see between stored states, loops inside that step
        // (`lane`); on an error it hands it over here, at the
        // step that failed, with what this loop would hold there.
        let mut first = 1;
        let mut handed = None;
        if n > 0 && !driver_only {
            let mut end = LaneEnd::default();
            // (A relay: the lane's borrow of the observer ends with it.)
            let watched = on_step.is_some();
            let mut relay = |e: &StepEvent| match on_step.as_mut() {
                Some(f) => f(e),
                None => ControlFlow::Continue(()),
            };
            let lane = Lane {
                first: 1,
                last: n,
                on_step: watched.then_some(&mut relay as &mut StepObserver<'_>),
                stride,
                t0,
                lazy,
                store,
                traj: &mut traj,
                observer: &mut observer,
                shown: &mut scratch,
                prev: (&mut prev_q, &mut prev_p),
                rec: (&mut rec_q, &mut rec_p),
                summary: &mut summary,
                end: &mut end,
            };
            // (What the lane did is read from its own record.)
            integ.lane(&mut q, &mut p, per_step, lane);
            match end {
                // A hook that answered without the runtime's fixed-size
                // step did nothing: this loop runs.
                LaneEnd::NotEntered => {}
                LaneEnd::Done => {
                    return RunOutcome {
                        trajectory: traj,
                        summary,
                        error: None,
                    }
                }
                LaneEnd::Failed {
                    k,
                    last_recorded: last,
                    error,
                } => {
                    (first, last_recorded) = (k, last);
                    handed = Some(error);
                }
                // Stopped by the `on_step` observer after step k, whose
                // state is in (q, p): it ends the trajectory, as below.
                LaneEnd::Stopped {
                    k,
                    last_recorded: last,
                } => {
                    if last != k
                        && let Err(e) = record!(k, t0 + k as f64 * h)
                    {
                        return fail(traj, summary, e);
                    }
                    return RunOutcome {
                        trajectory: traj,
                        summary,
                        error: None,
                    };
                }
            }
        }
        for k in first..=n {
            // Errors of step k carry k and the time it was computing.
            let t = t0 + k as f64 * h;
            // An error at step k ends the run with the state of step k − 1
            // stored last; for a lazy RATTLE run that state is the last one
            // whose projection exists, and a projection that failed before
            // step k is the error reported.
            macro_rules! end_before {
                ($e:expr) => {{
                    let mut e = $e;
                    if last_recorded != k - 1 {
                        let mut last = k - 1;
                        if lazy {
                            let (good, first) =
                                integ.replay(&mut rec_q, &mut rec_p, last_recorded, k, t0);
                            prev_q.copy_from_slice(&rec_q);
                            prev_p.copy_from_slice(&rec_p);
                            last = good;
                            e = first.unwrap_or(e);
                        }
                        if last > last_recorded {
                            let (before_q, before_p) =
                                if atomic { (&q, &p) } else { (&prev_q, &prev_p) };
                            let _ = integ.record(
                                before_q,
                                before_p,
                                per_step,
                                last,
                                t0 + last as f64 * h,
                                &mut acc,
                                &mut traj,
                                store,
                                &mut observer,
                                &mut scratch,
                            );
                        }
                    }
                    return fail(traj, summary, e);
                }};
            }
            if let Some(e) = handed.take() {
                // (The lane kept `prev` and `rec` as below.)
                end_before!(e);
            }
            // The state before the step is read only when step k fails
            // with step k − 1 not stored (the end must be stored then);
            // the stored state of a lazy run only when a later step fails
            // past it. Neither is copied when not needed (stride 1 copies
            // nothing: every state is stored as it is made).
            if last_recorded != k - 1 && !atomic {
                prev_q.copy_from_slice(&q);
                prev_p.copy_from_slice(&p);
            } else if lazy && stride > 1 {
                rec_q.copy_from_slice(&q);
                rec_p.copy_from_slice(&p);
            }
            let on_stride = k % stride == 0 || k == n;
            // A state the run shows: its Π made by the step where it can
            // (`StepMap::show`).
            let info = match integ.advance(&mut q, &mut p, per_step, k, t, lazy && on_stride) {
                Ok(info) => {
                    acc.add(&info);
                    summary.add(&info);
                    if integ.diagnostics() && last_recorded == k - 1 {
                        integ.fill_leaving_lambda(&mut traj, per_step);
                    }
                    info
                }
                // The step attempted was step k, at t0 + k·h: its error says so.
                Err(e) => end_before!(e.at(k, t0 + k as f64 * h)),
            };
            if on_stride {
                if let Err(e) = record!(k, t) {
                    // Step k's state could not be stored (its projection
                    // failed): the trajectory ends before step k.
                    end_before!(e.at(k, t));
                }
                last_recorded = k;
            }
            if let Some(f) = on_step.as_mut() {
                let event = StepEvent {
                    step: k,
                    steps: n,
                    t,
                    info,
                };
                if f(&event).is_break() {
                    // Stopped by the observer: the trajectory ends at the
                    // state it saw.
                    if !on_stride && let Err(e) = record!(k, t) {
                        return fail(traj, summary, e);
                    }
                    break;
                }
            }
        }
        RunOutcome {
            trajectory: traj,
            summary,
            error: None,
        }
    }
}
