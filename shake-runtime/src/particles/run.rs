//! The driver: many steps, a stride, one contiguous trajectory, and the
//! partial trajectory on failure.

use std::num::NonZeroU64;

use super::{ParticleState, Rattle, Trajectory};
use crate::error::StepError;
use crate::tolerance::{check_run, stored_states, MAX_STEPS};

/// What a run measured over its steps.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct RunSummary {
    /// Steps done.
    pub steps: u64,
    /// Largest relative constraint residual of any step.
    pub max_rel_g: f64,
    /// Largest relative hidden-constraint residual of any step.
    pub max_hidden: f64,
    /// Largest Newton iteration count of any step.
    pub max_newton_iterations: usize,
    /// Newton iterations summed over steps (and over clusters on the
    /// cluster path).
    pub newton_iterations: u64,
}

/// A run's result: the stored states, what the steps measured, and the
/// error that stopped it early, if any.
#[derive(Clone, Debug)]
pub struct RunOutcome {
    /// States at every step that is a multiple of the stride (including the
    /// start when it is one), up to the last successful step.
    pub trajectory: Trajectory,
    /// Measured over the successful steps.
    pub summary: RunSummary,
    /// The failure (step k, time t0 + k·h) that ended the run.
    pub error: Option<StepError>,
}

impl RunOutcome {
    /// The trajectory and summary, or the partial trajectory with the error.
    #[allow(clippy::result_large_err)]
    pub fn into_result(self) -> Result<(Trajectory, RunSummary), (Trajectory, StepError)> {
        match self.error {
            None => Ok((self.trajectory, self.summary)),
            Some(e) => Err((self.trajectory, e)),
        }
    }
}

impl Rattle {
    /// Takes `steps` steps from `state` (in place), storing every state
    /// whose step index is a multiple of `stride` (`stride = 0`: none) in one
    /// buffer reserved up front. Stops at the first failing step k: the
    /// error carries k and t0 + k·h, `state` is left at step k − 1, and the
    /// trajectory holds the states stored up to k − 1.
    ///
    /// Before any step the request is checked as a whole, as the dense
    /// driver checks its own: the start time finite, the last step index at
    /// most [`MAX_STEPS`](crate::validate::MAX_STEPS) and its time
    /// t0 + k·h finite ([`StepError::InvalidInput`]), and the states to
    /// store counted without overflow and reserved
    /// ([`StepError::Storage`] when they do not fit).
    ///
    /// ```
    /// use geoshake_runtime::{particles::{generate, Options, Rattle}, StepError};
    /// let (system, mut state) = generate::chain(20, 7).unwrap();
    /// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// let out = rattle.run(&mut state, 100, 10);
    /// let (traj, summary) = out.into_result().unwrap();
    /// assert_eq!((traj.len(), traj.step(10)), (11, 100));
    /// assert!(summary.max_rel_g <= 1e-10);
    /// // More steps than f64 can count exactly: refused before the first.
    /// let out = rattle.run(&mut state, u64::MAX, 1);
    /// assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    /// assert_eq!(state.step(), 100);
    /// ```
    pub fn run(&mut self, state: &mut ParticleState, steps: u64, stride: u64) -> RunOutcome {
        let mut trajectory = Trajectory::new(state.q.len());
        let summary = RunSummary::default();
        let refuse = |trajectory, e| RunOutcome {
            trajectory,
            summary,
            error: Some(e),
        };
        let first = state.step;
        let last = match check_run(state.t0, self.step_size(), first, steps) {
            Ok(last) => last,
            Err(l) => {
                let e = StepError::InvalidInput {
                    what: l.what(),
                    value: l.value(),
                };
                return refuse(trajectory, e);
            }
        };
        if let Some(s) = NonZeroU64::new(stride) {
            // Reserved up front (no allocation per step); a request that
            // cannot be stored is a typed error before the first step, not
            // an abort of the process after hours.
            let stored = stored_states(first, last, s, false);
            if stored.is_none_or(|n| trajectory.try_reserve(n).is_err()) {
                let e = StepError::Storage {
                    step: first,
                    states: stored.unwrap_or(u64::MAX),
                    dof: state.q.len(),
                };
                return refuse(trajectory, e);
            }
            if first.is_multiple_of(s.get()) {
                trajectory.push(state);
            }
        }
        self.run_checked(state, steps, stride, trajectory)
    }

    /// The loop of [`run`](Self::run), once the request is checked and the
    /// trajectory reserved.
    fn run_checked(
        &mut self,
        state: &mut ParticleState,
        steps: u64,
        stride: u64,
        mut trajectory: Trajectory,
    ) -> RunOutcome {
        let mut summary = RunSummary::default();
        for _ in 0..steps {
            match self.step(state) {
                Ok(r) => {
                    summary.steps += 1;
                    summary.max_rel_g = summary.max_rel_g.max(r.max_rel_g);
                    summary.max_hidden = summary.max_hidden.max(r.max_hidden);
                    summary.max_newton_iterations =
                        summary.max_newton_iterations.max(r.newton_iterations);
                    summary.newton_iterations += r.newton_total;
                    if stride > 0 && state.step.is_multiple_of(stride) {
                        trajectory.push(state);
                    }
                }
                Err(e) => {
                    return RunOutcome {
                        trajectory,
                        summary,
                        error: Some(e),
                    }
                }
            }
        }
        RunOutcome {
            trajectory,
            summary,
            error: None,
        }
    }

    /// Runs from `state` to time `t_end`: round((t_end − t)/h) steps, none
    /// when `t_end` is before `t`. A `t_end` that is NaN or infinite, or
    /// more than [`MAX_STEPS`](crate::validate::MAX_STEPS) steps away, is
    /// refused with [`StepError::InvalidInput`] carrying `t_end`; the
    /// rest is checked as [`run`](Self::run) checks it.
    ///
    /// ```
    /// use geoshake_runtime::{particles::{generate, Options, Rattle}, StepError};
    /// let (system, mut state) = generate::chain(4, 7).unwrap();
    /// let mut rattle = Rattle::new(system, 0.5, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// let (traj, _) = rattle.run_to(&mut state, 2.0, 1).into_result().unwrap();
    /// assert_eq!(traj.time(4), 2.0);
    /// let out = rattle.run_to(&mut state, f64::NAN, 1);
    /// assert!(matches!(out.error, Some(StepError::InvalidInput { value, .. }) if value.is_nan()));
    /// ```
    pub fn run_to(&mut self, state: &mut ParticleState, t_end: f64, stride: u64) -> RunOutcome {
        let n = ((t_end - state.time) / self.step_size()).round();
        let refused = if !t_end.is_finite() {
            Some("stop time must be finite")
        } else if n > MAX_STEPS as f64 {
            Some("stop time needs more than 2^53 steps of size h")
        } else {
            None
        };
        if let Some(what) = refused {
            return RunOutcome {
                trajectory: Trajectory::new(state.q.len()),
                summary: RunSummary::default(),
                error: Some(StepError::InvalidInput { what, value: t_end }),
            };
        }
        // (n ≤ 2^53 here, or NaN from a NaN start time, which `run`
        // refuses: the cast is exact or 0.)
        let steps = if n > 0.0 { n as u64 } else { 0 };
        self.run(state, steps, stride)
    }
}
