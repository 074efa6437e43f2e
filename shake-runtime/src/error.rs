//! Typed failures. Every variant carries the numbers that explain it: the
//! step and time where it happened, and the residual, condition number or
//! displacement that crossed its limit.

use std::fmt;

/// Which implicit equation of a step failed.
///
/// ```
/// use shake_runtime::Stage;
/// assert_eq!(Stage::Shake.to_string(), "SHAKE (λ such that g(z1⁻) = 0)");
/// ```
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The stage equations of an implicit base map φ_h.
    BaseMap,
    /// SHAKE's equation for λ: g(φ_h(exp(Σ λ_i X_{g_i})(z0))) = 0.
    Shake,
    /// RATTLE's (and the projection Π's) equation for σ:
    /// {g_i, H}(exp(Σ σ_i X_{g_i})(z)) = 0.
    Rattle,
    /// The numerical integration of a fibre flow with no closed form.
    Fibre,
    /// Bringing initial data onto M = {g = 0}.
    ProjectionOntoM,
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stage::BaseMap => "the base map's stage equations",
            Stage::Shake => "SHAKE (λ such that g(z1⁻) = 0)",
            Stage::Rattle => "RATTLE (σ such that {g,H}(z1) = 0)",
            Stage::Fibre => "the fibre flow integration",
            Stage::ProjectionOntoM => "the projection onto M",
        })
    }
}

/// Why one Newton iteration (or the fibre integration) failed, without the
/// step context; [`StepError`] adds where and when.
///
/// ```
/// use shake_runtime::SolveError;
/// let e = SolveError::NotConverged { iterations: 50, residual: 1e-3 };
/// assert!(e.to_string().contains("50 iterations"));
/// ```
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The stopping rule (see [`newton`](crate::newton)) was not met within
    /// the iteration budget.
    #[error("no convergence in {iterations} iterations (residual {residual:.3e})")]
    NotConverged {
        /// Iterations done.
        iterations: usize,
        /// The last residual norm (∞-norm).
        residual: f64,
    },
    /// The Newton matrix was exactly singular.
    #[error("singular Newton matrix at iteration {iterations}")]
    Singular {
        /// Iterations done.
        iterations: usize,
    },
    /// A NaN or infinity appeared in the iterate or the residual.
    #[error("non-finite value at iteration {iterations}")]
    NonFinite {
        /// Iterations done.
        iterations: usize,
    },
}

/// A step (or a run, or the projection of initial data) failed.
///
/// `step` counts the steps from the start of the run (the failing step is
/// the one from `step - 1` to `step`; 0 for initial data), `t` is the time
/// at the start of the failing step.
///
/// ```
/// use shake_runtime::{Integrator, StormerVerlet, StepError, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, f64::NAN);
/// let z0 = shake_runtime::State::from_slices(&[1.0, 0.0], &[0.0, 0.0]);
/// assert!(matches!(integ.step(&z0), Err(StepError::InvalidInput { .. })));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    /// A parameter of the call is unusable: h = 0 or not finite, a stop time
    /// of the wrong sign, a stride of 0, a state of the wrong dimension.
    #[error("invalid input: {what} (value {value})")]
    InvalidInput {
        /// What is wrong.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A state (the input or one computed) has a NaN or infinite entry.
    #[error("non-finite {what} at step {step}, t = {t}")]
    NonFinite {
        /// Which state: "initial state" or "state".
        what: &'static str,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
    },
    /// A Newton iteration did not converge.
    #[error("Newton did not converge in {stage} at step {step}, t = {t}: {source}")]
    NewtonNotConverged {
        /// Which equation.
        stage: Stage,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// Iterations and residual.
        #[source]
        source: SolveError,
    },
    /// N_ij = {{H,g_i},g_j} is singular or ill-conditioned: the
    /// nondegeneracy assumption (the paper's Assumption 1.1) fails here, and
    /// SHAKE/RATTLE are not well defined. `condition` is the condition
    /// number of N relative to its size at the start of the run (see
    /// [`Options::max_condition`](crate::Options::max_condition)); ∞ when N
    /// (or SHAKE's Newton matrix) is exactly singular.
    #[error("nondegeneracy lost in {stage} at step {step}, t = {t}: condition of N = {condition:.3e} (limit {limit:.1e})")]
    NondegeneracyLost {
        /// Where it was detected.
        stage: Stage,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// The (relative) condition number of N.
        condition: f64,
        /// The limit it crossed.
        limit: f64,
    },
    /// det N changed sign between two steps: the trajectory crossed (or
    /// jumped over) a point where N is singular, onto another component of
    /// M^H (the paper's Section 5.4.2, case iii).
    #[error("jumped to another component of M^H at step {step}, t = {t}: det N changed sign from {det_before:.3e} to {det_after:.3e}")]
    ComponentJump {
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// det N at the previous step.
        det_before: f64,
        /// det N now.
        det_after: f64,
    },
    /// A Newton iteration along the fibre converged to a displacement far
    /// from its own first (linear) prediction: SHAKE's λ (the solution found
    /// is not the nearby one of order h but another intersection of the
    /// fibre with the modified hidden constraint set), or the projection's σ
    /// (Π landed on another crossing of the fibre with M^H).
    #[error("fibre jump in {stage} at step {step}, t = {t}: the fibre displacement is {lambda:.3e} but its linear prediction was {predicted:.3e}: Newton left the nearby point of M and M^H, which signals a fold or another component of M^H (Section 5.4.2)")]
    FibreJump {
        /// Where: SHAKE's λ or the projection's σ.
        stage: Stage,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// ‖λ‖∞ (or ‖σ‖∞) found.
        lambda: f64,
        /// ‖λ₁‖∞ (or ‖σ₁‖∞) of the first Newton iterate.
        predicted: f64,
    },
    /// The state handed to SHAKE/RATTLE is not on M = {g = 0} (or, for
    /// initial data, could not be brought onto it).
    #[error(
        "initial data not on M: |g| = {residual:.3e} > {tolerance:.1e} (step {step}, t = {t})"
    )]
    NotOnConstraint {
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// ‖g(z)‖∞.
        residual: f64,
        /// The tolerance it exceeds.
        tolerance: f64,
    },
}

impl StepError {
    /// The step index where the error happened (0 for input errors).
    ///
    /// ```
    /// use shake_runtime::StepError;
    /// let e = StepError::ComponentJump { step: 7, t: 0.7, det_before: 1.0, det_after: -1.0 };
    /// assert_eq!(e.step(), 7);
    /// ```
    pub fn step(&self) -> u64 {
        match *self {
            StepError::InvalidInput { .. } => 0,
            StepError::NonFinite { step, .. }
            | StepError::NewtonNotConverged { step, .. }
            | StepError::NondegeneracyLost { step, .. }
            | StepError::ComponentJump { step, .. }
            | StepError::FibreJump { step, .. }
            | StepError::NotOnConstraint { step, .. } => step,
        }
    }

    /// Sets the step index and time (the low-level functions report 0; the
    /// driver knows better).
    pub(crate) fn at(mut self, step_index: u64, time: f64) -> Self {
        match &mut self {
            StepError::InvalidInput { .. } => {}
            StepError::NonFinite { step, t, .. }
            | StepError::NewtonNotConverged { step, t, .. }
            | StepError::NondegeneracyLost { step, t, .. }
            | StepError::ComponentJump { step, t, .. }
            | StepError::FibreJump { step, t, .. }
            | StepError::NotOnConstraint { step, t, .. } => {
                *step = step_index;
                *t = time;
            }
        }
        self
    }

    /// Turns a Newton failure in `stage` into a step error (step/time filled
    /// in later by [`StepError::at`]).
    pub(crate) fn from_solve(stage: Stage, e: SolveError) -> Self {
        match e {
            SolveError::Singular { .. } if matches!(stage, Stage::Shake | Stage::Rattle) => {
                StepError::NondegeneracyLost {
                    stage,
                    step: 0,
                    t: 0.0,
                    condition: f64::INFINITY,
                    limit: f64::INFINITY,
                }
            }
            e => StepError::NewtonNotConverged {
                stage,
                step: 0,
                t: 0.0,
                source: e,
            },
        }
    }
}
