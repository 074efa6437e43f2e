//! Typed failures. Every variant carries the numbers that explain it: the
//! step and time where it happened, and the residual, condition number or
//! displacement that crossed its limit.

use std::fmt;

use crate::particles::TopologyError;

/// Which implicit equation of a step failed.
///
/// ```
/// use geoshake_runtime::Stage;
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
/// use geoshake_runtime::SolveError;
/// let e = SolveError::NotConverged { iterations: 50, residual: 1e-3 };
/// assert!(e.to_string().contains("50 iterations"));
/// ```
#[derive(Copy, Clone, Debug, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// The stopping rule (see [`newton`](crate::newton)) was not met within
    /// the iteration budget.
    #[error("no convergence in {iterations} iterations (residual {residual_})", residual_ = sci(*.residual))]
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

/// A number for a message: six significant digits at most, trailing zeros
/// dropped, so that t = 0.30000000000000004 reads `0.3`.
///
/// ```
/// use geoshake_runtime::error::human;
/// assert_eq!(human(0.30000000000000004), "0.3");
/// assert_eq!(human(12.5), "12.5");
/// assert_eq!(human(1e-9), "1.0e-9");
/// ```
pub fn human(x: f64) -> String {
    if x == 0.0 || (1e-4..1e6).contains(&x.abs()) {
        let digits = (5 - x.abs().log10().floor().max(-4.0) as i32).clamp(0, 9) as usize;
        let s = format!("{x:.digits$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{x:.1e}")
    }
}

/// A residual, condition or tolerance for a message: two significant
/// digits, in plain notation between 1e-3 and 1e4 (`4`, `0.25`, `1200`) and
/// in scientific notation outside (`1.2e-9`), never `4.0e0`.
///
/// ```
/// use geoshake_runtime::error::sci;
/// assert_eq!(sci(4.0), "4");
/// assert_eq!(sci(0.25), "0.25");
/// assert_eq!(sci(1234.0), "1200");
/// assert_eq!(sci(1.234e-9), "1.2e-9");
/// assert_eq!(sci(f64::INFINITY), "inf");
/// ```
pub fn sci(x: f64) -> String {
    if x == 0.0 || !x.is_finite() || !(1e-3..1e4).contains(&x.abs()) {
        return if x == 0.0 || !x.is_finite() {
            format!("{x}")
        } else {
            format!("{x:.1e}")
        };
    }
    // Round to two significant digits, then print without trailing zeros.
    let e = x.abs().log10().floor() as i32;
    let scale = 10f64.powi(1 - e);
    let r = (x * scale).round() / scale;
    let digits = (1 - e).max(0) as usize;
    let s = format!("{r:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// The second half of [`StepError::BranchJump`]'s message: how the step
/// back went.
fn reverse_outcome(miss: Option<f64>, tolerance: f64, cause: Option<&StepError>) -> String {
    match (miss, cause) {
        (Some(miss), _) => format!(
            "the composed step taken back with −h misses its start by {} > {}: a substep landed on another solution branch",
            sci(miss),
            sci(tolerance)
        ),
        (None, Some(cause)) => format!(
            "the composed step could not be taken back with −h to check it ({cause}): a substep may have landed on another solution branch"
        ),
        (None, None) => "the composed step taken back with −h does not return".to_string(),
    }
}

/// A step (or a run, or the projection of initial data) failed.
///
/// `step` is the index of the state the failing step was computing (step k
/// goes from state k − 1 to state k; 0 for the initial data) and `t` the
/// time of that state, t0 + k·h: a run that fails at step k stored its
/// states up to k − 1 (see [`RunOutcome`](crate::RunOutcome)). A single
/// [`Integrator::step`](crate::Integrator::step) is step 1 from t0 = 0.
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, StepError, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, f64::NAN);
/// let z0 = geoshake_runtime::State::from_slices(&[1.0, 0.0], &[0.0, 0.0]);
/// assert!(matches!(integ.step(&z0), Err(StepError::InvalidInput { .. })));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StepError {
    /// A parameter of the call is unusable: h = 0 or not finite, a stop time
    /// of the wrong sign, a stride of 0, a state of the wrong dimension.
    /// Found before any step: it has no step or time.
    #[error("invalid input: {what} (value {})", human(*.value))]
    InvalidInput {
        /// What is wrong.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// The states a run would store do not fit in memory (or their size
    /// does not fit in a machine word): refused before the first step, by
    /// a reservation of the whole trajectory, rather than an abort of the
    /// process when the buffer grows later.
    #[error("step {step}: storing {states} states of 2·{dof} numbers each does not fit in memory: store fewer (a larger stride)")]
    Storage {
        /// The step the run starts from.
        step: u64,
        /// States the run would store.
        states: u64,
        /// d (each state holds 2d numbers).
        dof: usize,
    },
    /// An input has the wrong number of entries: a state, or q or p of a
    /// particle state, whose length is not the system's. Found before any
    /// step: it has no step or time.
    #[error("invalid input: {what} has {got} entries, the system has {expected}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The system's.
        expected: usize,
    },
    /// A particle system's constraint graph cannot be run: a cluster with
    /// more constraints than coordinates (N = G M⁻¹ Gᵀ singular whatever
    /// the positions). Found by [`particles::Rattle::new`](crate::particles::Rattle::new),
    /// before any step; the other [`TopologyError`]s are refused where the
    /// system is built.
    #[error(transparent)]
    Topology(#[from] TopologyError),
    /// The solver the options force on a particle system cannot take its
    /// constraint graph (clusters too large, a band too wide). Found
    /// before any step.
    #[error("the {solver} solver cannot take this constraint graph: {why}")]
    Solver {
        /// The solver asked for.
        solver: &'static str,
        /// Why not.
        why: String,
    },
    /// A quantity was asked of a state that does not have it: the
    /// constraint forces of a state no RATTLE or SHAKE step of this solver
    /// made last. Found before any work: it has no step or time.
    #[error("{what} not available: {why}")]
    Unavailable {
        /// What was asked for.
        what: &'static str,
        /// Why the state does not have it.
        why: &'static str,
    },
    /// A state (the input or one computed) has a NaN or infinite entry.
    #[error("non-finite value in the {what} at step {step}, t = {}: entry {entry} of z = (q, p)", human(*.t))]
    NonFinite {
        /// Which state: the initial state, or the state after SHAKE or Π.
        what: &'static str,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// The first non-finite entry of z = (q, p) (entries d.. are p).
        entry: usize,
    },
    /// A Newton iteration did not converge (its iteration count and last
    /// residual are in `source`).
    #[error("Newton did not converge in {stage} at step {step}, t = {}: {source}", human(*.t))]
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
    /// An equation of a particle system's step failed at one member of a
    /// constraint family (the particle path solves each cluster, or the
    /// whole graph, on its own, and names the member whose residual is
    /// worst or whose pivot vanished). `source` says why: the budget ran
    /// out (with the relative residual |g_k| / (|∇g_k| · extent) of that
    /// member), or the Newton matrix G(q1) M⁻¹ G(q0)ᵀ (stage SHAKE) or N =
    /// G M⁻¹ Gᵀ (stage RATTLE, or the projection onto M) is singular there.
    #[error("{stage} failed at member {member} of `{family}` at step {step}, t = {}: {source}", human(*.t))]
    AtMember {
        /// Which equation.
        stage: Stage,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// The constraint family's declared name.
        family: String,
        /// The member (row of the family's table).
        member: usize,
        /// Why.
        #[source]
        source: SolveError,
    },
    /// SHAKE's Newton matrix ∂/∂λ g(φ_h(exp(Σ λ_i X_{g_i}) z0)) is exactly
    /// singular: the step cannot be solved from here (h too large for the
    /// fibre to cross M again nearby). Not the nondegeneracy of N, which is
    /// a property of the state: see [`StepError::NondegeneracyLost`].
    #[error("SHAKE's Jacobian is singular at step {step}, t = {} (Newton iteration {iterations})", human(*.t))]
    SingularShakeJacobian {
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// Newton iterations done.
        iterations: usize,
    },
    /// N_ij = {{H,g_i},g_j} is exactly singular at the state: the
    /// nondegeneracy assumption (the paper's Assumption 1.1) fails there and
    /// Π onto M^H is not defined.
    #[error("N = {{{{H,g_i}},g_j}} is singular in {stage} at step {step}, t = {}: the nondegeneracy assumption fails", human(*.t))]
    SingularNondegeneracyMatrix {
        /// Where it was detected.
        stage: Stage,
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
    },
    /// N_ij = {{H,g_i},g_j} is ill-conditioned: the nondegeneracy
    /// assumption (the paper's Assumption 1.1) is about to fail, and
    /// SHAKE/RATTLE are not reliable. `condition` is the condition number of
    /// N relative to its size at the start of the run (see
    /// [`Options::max_condition`](crate::Options::max_condition)).
    #[error("nondegeneracy lost in {stage} at step {step}, t = {}: condition of N = {condition_} > limit {limit_}", human(*.t), condition_ = sci(*.condition), limit_ = sci(*.limit))]
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
    #[error("jumped to another component of M^H at step {step}, t = {}: det N changed sign from {det_before_} to {det_after_}", human(*.t), det_before_ = sci(*.det_before), det_after_ = sci(*.det_after))]
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
    #[error("fibre jump in {stage} at step {step}, t = {}: the fibre displacement is {lambda_} but its linear prediction was {predicted_}: Newton left the nearby point of M and M^H, which signals a fold or another component of M^H (Section 5.4.2)", human(*.t), lambda_ = sci(*.lambda), predicted_ = sci(*.predicted))]
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
    /// A composed step (Section 4) is not undone by the same composition
    /// with −h. RATTLE over a symmetric base map is symmetric (R_{−h} ∘ R_h
    /// = id on M^H), so a step that followed the nearby solution branch
    /// comes back to its start to round-off; one whose substep landed on
    /// another crossing of a fibre with M or M^H does not, even when every
    /// other check passes (N keeps its sign and λ its first prediction when
    /// N is small or flat along the fibre). `miss` is ‖back − start‖∞
    /// (start projected onto M^H when it was not on it), `None` when the
    /// step back, or the projection of the start, failed (`cause`). See
    /// [`Options::reverse_tolerance`](crate::Options::reverse_tolerance).
    #[error("branch jump at step {step}, t = {}: {}", human(*.t), reverse_outcome(*.miss, *.tolerance, .cause.as_deref()))]
    BranchJump {
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// How far the step back lands from the step's start (∞-norm).
        miss: Option<f64>,
        /// The largest miss accepted (relative tolerance times the state's
        /// size).
        tolerance: f64,
        /// Why the step back failed, if it did.
        #[source]
        cause: Option<Box<StepError>>,
    },
    /// The state handed to SHAKE/RATTLE is not on M = {g = 0} (or, for
    /// initial data, could not be brought onto it: then `cause` says why
    /// the projection onto M stopped).
    #[error("not on M at step {step}, t = {}: |g| = {residual_} > {tolerance_}, largest for the constraint `{constraint}`", human(*.t), residual_ = sci(*.residual), tolerance_ = sci(*.tolerance))]
    NotOnConstraint {
        /// Step index.
        step: u64,
        /// Time.
        t: f64,
        /// ‖g(z)‖∞.
        residual: f64,
        /// The tolerance it exceeds.
        tolerance: f64,
        /// The declared name of the constraint with the largest |g_i|.
        constraint: String,
        /// Why the projection of initial data onto M failed, if it did.
        #[source]
        cause: Option<SolveError>,
    },
}

impl StepError {
    /// The step index where the error happened (0 for input errors).
    ///
    /// ```
    /// use geoshake_runtime::StepError;
    /// let e = StepError::ComponentJump { step: 7, t: 0.7, det_before: 1.0, det_after: -1.0 };
    /// assert_eq!(e.step(), 7);
    /// ```
    pub fn step(&self) -> u64 {
        match *self {
            StepError::InvalidInput { .. }
            | StepError::Shape { .. }
            | StepError::Topology(_)
            | StepError::Solver { .. }
            | StepError::Unavailable { .. } => 0,
            StepError::Storage { step, .. }
            | StepError::NonFinite { step, .. }
            | StepError::NewtonNotConverged { step, .. }
            | StepError::AtMember { step, .. }
            | StepError::SingularShakeJacobian { step, .. }
            | StepError::SingularNondegeneracyMatrix { step, .. }
            | StepError::NondegeneracyLost { step, .. }
            | StepError::ComponentJump { step, .. }
            | StepError::FibreJump { step, .. }
            | StepError::BranchJump { step, .. }
            | StepError::NotOnConstraint { step, .. } => step,
        }
    }

    /// The time t0 + k·h of the state the failing step k was computing
    /// (`None` for input and storage errors, found before any step).
    ///
    /// ```
    /// use geoshake_runtime::StepError;
    /// let e = StepError::ComponentJump { step: 7, t: 0.7, det_before: 1.0, det_after: -1.0 };
    /// assert_eq!(e.time(), Some(0.7));
    /// ```
    pub fn time(&self) -> Option<f64> {
        match *self {
            StepError::InvalidInput { .. }
            | StepError::Shape { .. }
            | StepError::Topology(_)
            | StepError::Solver { .. }
            | StepError::Unavailable { .. }
            | StepError::Storage { .. } => None,
            StepError::NonFinite { t, .. }
            | StepError::NewtonNotConverged { t, .. }
            | StepError::AtMember { t, .. }
            | StepError::SingularShakeJacobian { t, .. }
            | StepError::SingularNondegeneracyMatrix { t, .. }
            | StepError::NondegeneracyLost { t, .. }
            | StepError::ComponentJump { t, .. }
            | StepError::FibreJump { t, .. }
            | StepError::BranchJump { t, .. }
            | StepError::NotOnConstraint { t, .. } => Some(t),
        }
    }

    /// `Ok` when `value` is finite, else [`StepError::InvalidInput`]
    /// naming what it is (an input such as a start time, checked before
    /// any work).
    pub(crate) fn finite_input(what: &'static str, value: f64) -> Result<(), StepError> {
        if value.is_finite() {
            return Ok(());
        }
        Err(StepError::InvalidInput { what, value })
    }

    /// Sets the step index and time: the kernels that solve one equation
    /// (`shake`, `rattle`, the base maps) do not know where in a run they
    /// are, and every caller of them passes the step's own k and t0 + k·h.
    pub(crate) fn at(mut self, step_index: u64, time: f64) -> Self {
        match &mut self {
            StepError::InvalidInput { .. }
            | StepError::Shape { .. }
            | StepError::Topology(_)
            | StepError::Solver { .. }
            | StepError::Unavailable { .. }
            | StepError::Storage { .. } => {}
            StepError::NonFinite { step, t, .. }
            | StepError::NewtonNotConverged { step, t, .. }
            | StepError::AtMember { step, t, .. }
            | StepError::SingularShakeJacobian { step, t, .. }
            | StepError::SingularNondegeneracyMatrix { step, t, .. }
            | StepError::NondegeneracyLost { step, t, .. }
            | StepError::ComponentJump { step, t, .. }
            | StepError::FibreJump { step, t, .. }
            | StepError::BranchJump { step, t, .. }
            | StepError::NotOnConstraint { step, t, .. } => {
                *step = step_index;
                *t = time;
            }
        }
        self
    }

    /// Turns a Newton failure in `stage` into a step error, one variant per
    /// cause: a singular matrix in SHAKE is [`StepError::SingularShakeJacobian`],
    /// in the projection (whose matrix is −N) it is
    /// [`StepError::SingularNondegeneracyMatrix`]; anything else keeps the
    /// solver's own error as its source. Step and time are set by the caller
    /// with [`StepError::at`].
    pub(crate) fn from_solve(stage: Stage, e: SolveError) -> Self {
        match (stage, e) {
            (Stage::Shake, SolveError::Singular { iterations }) => {
                StepError::SingularShakeJacobian {
                    step: 0,
                    t: 0.0,
                    iterations,
                }
            }
            (Stage::Rattle, SolveError::Singular { .. }) => {
                StepError::SingularNondegeneracyMatrix {
                    stage,
                    step: 0,
                    t: 0.0,
                }
            }
            (stage, e) => StepError::NewtonNotConverged {
                stage,
                step: 0,
                t: 0.0,
                source: e,
            },
        }
    }
}
