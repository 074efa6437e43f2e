//! The driver: many steps, a stride, one contiguous trajectory, and the
//! partial trajectory on failure.

use super::{ParticleError, ParticleState, Rattle, Trajectory};

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
    pub error: Option<ParticleError>,
}

impl RunOutcome {
    /// The trajectory and summary, or the partial trajectory with the error.
    #[allow(clippy::result_large_err)]
    pub fn into_result(self) -> Result<(Trajectory, RunSummary), (Trajectory, ParticleError)> {
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
    /// ```
    /// use shake_runtime::particles::{generate, Options, Rattle};
    /// let (system, mut state) = generate::chain(20, 7).unwrap();
    /// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// let out = rattle.run(&mut state, 100, 10);
    /// let (traj, summary) = out.into_result().unwrap();
    /// assert_eq!((traj.len(), traj.step(10)), (11, 100));
    /// assert!(summary.max_rel_g <= 1e-10);
    /// ```
    pub fn run(&mut self, state: &mut ParticleState, steps: u64, stride: u64) -> RunOutcome {
        let mut trajectory = Trajectory::new(state.q.len());
        let mut summary = RunSummary::default();
        if let Some(s) = std::num::NonZeroU64::new(stride) {
            let first = state.step;
            let at_start = first.is_multiple_of(s.get());
            // Reserved up front (no allocation per step); a request that
            // cannot be stored is a typed error before the first step, not
            // an abort of the process after hours.
            let stored = first
                .checked_add(steps)
                .map(|last| last / s - first / s + u64::from(at_start));
            let room = match stored {
                Some(n) => trajectory.try_reserve(n).is_ok(),
                None => false,
            };
            if !room {
                return RunOutcome {
                    trajectory,
                    summary,
                    error: Some(ParticleError::Storage {
                        step: first,
                        states: stored.unwrap_or(u64::MAX),
                        dof: state.q.len(),
                    }),
                };
            }
            if at_start {
                trajectory.push(state);
            }
        }
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

    /// Runs from `state` to time `t_end` (the number of steps is
    /// round((t_end − t)/h); `t_end` before `t` takes none).
    pub fn run_to(&mut self, state: &mut ParticleState, t_end: f64, stride: u64) -> RunOutcome {
        let n = ((t_end - state.time) / self.step_size()).round();
        let steps = if n.is_finite() && n > 0.0 {
            n as u64
        } else {
            0
        };
        self.run(state, steps, stride)
    }
}
