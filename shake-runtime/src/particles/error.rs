//! How a large-system step, projection or run fails.

/// Why a topology was refused. Every variant names the family and, where one
/// member is at fault, the member (its row in the table).
///
/// ```
/// use geoshake_runtime::particles::{Table, TopologyError};
/// let mut bonds = Table::new(2, 1);
/// let e = bonds.push(&[0, 0], &[1.0]).unwrap_err();
/// assert!(matches!(e, TopologyError::RepeatedParticle { member: 0, particle: 0, .. }));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TopologyError {
    /// A row has the wrong number of particle indices or numbers.
    #[error(
        "family `{family}`, member {member}: {what} has {got} entries, the family takes {expected}"
    )]
    RowShape {
        /// The family (empty while the table is not yet named).
        family: String,
        /// The row.
        member: usize,
        /// "particle list" or "data".
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Entries the family takes.
        expected: usize,
    },
    /// A member names the same particle twice.
    #[error("family `{family}`, member {member}: particle {particle} appears twice")]
    RepeatedParticle {
        /// The family.
        family: String,
        /// The row.
        member: usize,
        /// The repeated particle.
        particle: usize,
    },
    /// A member names a particle the system does not have.
    #[error("family `{family}`, member {member}: particle {particle} does not exist (the system has {particles})")]
    DanglingParticle {
        /// The family.
        family: String,
        /// The row.
        member: usize,
        /// The index given.
        particle: usize,
        /// The number of particles.
        particles: usize,
    },
    /// Two members of a family touch the same particles with the same
    /// numbers: the same constraint twice, so N is singular.
    #[error("family `{family}`: members {first} and {second} are the same constraint")]
    DuplicateMember {
        /// The family.
        family: String,
        /// The earlier row.
        first: usize,
        /// The later row.
        second: usize,
    },
    /// A number in a row (or a mass) is NaN or infinite, or a mass is not
    /// positive.
    #[error("family `{family}`, member {member}: value {value} is not allowed ({why})")]
    BadValue {
        /// The family ("masses" for the masses).
        family: String,
        /// The row (the particle for masses).
        member: usize,
        /// The value.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// A connected cluster of constraints has more constraints than the
    /// coordinates it moves: G cannot have full rank, N = G M⁻¹ Gᵀ is
    /// singular (the nondegeneracy condition fails on every state).
    #[error("{constraints} constraints (from member {member} of `{family}` on) act on {coordinates} coordinates: more constraints than coordinates, N = G M⁻¹ Gᵀ is singular")]
    TooManyConstraints {
        /// A family of the cluster.
        family: String,
        /// A member of the cluster.
        member: usize,
        /// Constraints in the cluster.
        constraints: usize,
        /// Coordinates the cluster moves.
        coordinates: usize,
    },
    /// The stencil's dimension differs from the system's.
    #[error(
        "family `{family}` is written for particles in R^{stencil}, the system's are in R^{system}"
    )]
    Dimension {
        /// The family.
        family: String,
        /// The stencil's DIM.
        stencil: usize,
        /// The system's dimension.
        system: usize,
    },
}

/// Why a step of [`Rattle`](super::Rattle) (or the projection of initial
/// data) failed, or why a solver could not be built.
///
/// Steps are counted from 1: step k maps the state at t0 + (k−1)·h to the
/// state at t_k = t0 + k·h. A failing step k reports `step = k` and
/// `time = t0 + k·h` (the time it was to reach, computed as t0 + k·h, not
/// accumulated); a run that fails there returns the states stored up to step
/// k − 1. The projection of initial data reports step 0 and time t0.
///
/// ```
/// use geoshake_runtime::particles::ParticleError;
/// let e = ParticleError::StepSize { h: -1.0 };
/// assert!(e.to_string().contains("step size"));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ParticleError {
    /// The topology was refused (while building the solver).
    #[error(transparent)]
    Topology(#[from] TopologyError),
    /// h is not a finite positive number.
    #[error("the step size h = {h} must be finite and positive")]
    StepSize {
        /// The step size given.
        h: f64,
    },
    /// A run's request is unusable: a start time or stop time that is NaN
    /// or infinite, more than [`MAX_STEPS`](crate::validate::MAX_STEPS)
    /// steps, or a last time t0 + k·h that is not finite (every stored
    /// time would be NaN or ∞). Found before any step.
    #[error("invalid input: {what} (value {value:e})")]
    InvalidInput {
        /// What is wrong.
        what: &'static str,
        /// The offending value.
        value: f64,
    },
    /// A state's arrays do not have n·D entries.
    #[error("{what} has {got} entries, the system has {expected} coordinates")]
    Shape {
        /// "q" or "p".
        what: &'static str,
        /// Entries given.
        got: usize,
        /// n·D.
        expected: usize,
    },
    /// An option is out of its range (a tolerance not in
    /// [4ε, 1), an iteration budget not in 1 ..= 10 000; see
    /// [`Options`](super::Options)).
    #[error("option {what} = {value} is not allowed: {why}")]
    InvalidOption {
        /// The option.
        what: &'static str,
        /// The value given.
        value: f64,
        /// Its range.
        why: &'static str,
    },
    /// The trajectory a run was asked to store does not fit in memory (or
    /// its size does not fit in a machine word): refused before any step.
    #[error(
        "step {step}: storing {states} states of {dof} coordinates each does not fit in memory"
    )]
    Storage {
        /// The step the run starts from.
        step: u64,
        /// States the run would store.
        states: u64,
        /// n·D.
        dof: usize,
    },
    /// A forced solver cannot take this constraint graph.
    #[error("the {solver} solver cannot take this constraint graph: {why}")]
    Solver {
        /// The solver asked for.
        solver: &'static str,
        /// Why not.
        why: String,
    },
    /// A NaN or infinity in the state or in a computed value.
    #[error("step {step} (t = {time:.6e}): non-finite value in {what} at index {index}")]
    NotFinite {
        /// The failing step.
        step: u64,
        /// t0 + step·h.
        time: f64,
        /// Where: "q", "p", "constraint", "force", "multiplier".
        what: &'static str,
        /// The coordinate (or constraint) index.
        index: usize,
    },
    /// Newton's method for g(q1) = 0 did not bring every constraint's
    /// relative residual below the tolerance within the iteration budget.
    #[error("step {step} (t = {time:.6e}): no convergence of g(q1) = 0 after {iterations} iterations, relative residual {residual:.2e} at member {member} of `{family}`")]
    NotConverged {
        /// The failing step.
        step: u64,
        /// t0 + step·h.
        time: f64,
        /// The largest relative residual |g_k| / (|∇g_k| · extent_k).
        residual: f64,
        /// Newton iterations done.
        iterations: usize,
        /// The family of the worst member.
        family: String,
        /// Its row.
        member: usize,
    },
    /// A Newton or projection matrix was singular (or, for N = G M⁻¹ Gᵀ,
    /// not numerically positive definite): the nondegeneracy condition fails
    /// at this state.
    #[error("step {step} (t = {time:.6e}): singular {matrix} at member {member} of `{family}` (iteration {iterations})")]
    Singular {
        /// The failing step.
        step: u64,
        /// t0 + step·h.
        time: f64,
        /// "Newton matrix G(q1) M⁻¹ G(q0)ᵀ" or "N = G M⁻¹ Gᵀ".
        matrix: &'static str,
        /// Newton iterations done.
        iterations: usize,
        /// A family at fault.
        family: String,
        /// A member at fault.
        member: usize,
    },
}
