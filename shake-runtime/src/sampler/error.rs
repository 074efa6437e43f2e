//! The sampler's typed errors: input it refuses before the first
//! transition. A proposal that fails during sampling is not an error but a
//! counted rejection ([`Rejection`](super::Rejection)).

use crate::error::{human, sci, StepError};

/// Why [`sample`](super::sample) refused to start.
///
/// ```
/// use geoshake_runtime::sampler::{sample, SamplerError, SamplerOptions};
/// use geoshake_runtime::examples::Pendulum;
/// let opts = SamplerOptions { draws: 0, ..SamplerOptions::default() };
/// let err = sample(&Pendulum::default(), &[[1.0, 0.0]], &opts).unwrap_err();
/// assert!(matches!(err, SamplerError::InvalidOption { what: "draws", .. }));
/// ```
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SamplerError {
    /// An option is outside its domain: no chains, no draws, no
    /// integration steps, a step size that is not in (0, 10⁶], a
    /// target acceptance outside (0, 1), a reverse tolerance that is not
    /// positive.
    #[error("invalid sampler option `{what}` = {}: {why}", human(*.value))]
    InvalidOption {
        /// The field of [`SamplerOptions`](super::SamplerOptions).
        what: &'static str,
        /// Its value.
        value: f64,
        /// What it must be.
        why: &'static str,
    },
    /// The number of starting points is neither 1 (shared by every chain)
    /// nor the number of chains.
    #[error("{given} starting points for {chains} chains: give one for all, or one per chain")]
    StartCount {
        /// Starting points given.
        given: usize,
        /// Chains asked for.
        chains: usize,
    },
    /// A starting point has the wrong length.
    #[error("the start of chain {chain} has {given} coordinates, the system has d = {dof}")]
    StartDimension {
        /// The chain.
        chain: usize,
        /// Its length.
        given: usize,
        /// d.
        dof: usize,
    },
    /// A starting point is not on M = {q : g(q) = 0} (to
    /// [`Options::constraint_tolerance`](crate::Options::constraint_tolerance)),
    /// or not finite; `source` is the engine's verdict (the constraint
    /// furthest off, its residual and tolerance). Bring it onto M first
    /// ([`Integrator::project_to_hidden`](crate::Integrator::project_to_hidden)).
    #[error("the start of chain {chain} is not on M: {source}")]
    StartOffManifold {
        /// The chain.
        chain: usize,
        /// The engine's error.
        #[source]
        source: StepError,
    },
    /// The target density is zero, infinite or NaN at a starting point:
    /// U(q) = −log π(q) is not finite there.
    #[error("the potential U = −log π is {} at the start of chain {chain}: the target density must be positive and finite there", sci(*.potential))]
    StartDensity {
        /// The chain.
        chain: usize,
        /// U(q) at its start.
        potential: f64,
    },
    /// The draws do not fit in memory: chains × draws × (d positions and
    /// the per-draw statistics) could not be allocated (or overflows the
    /// address space), checked before any chain runs.
    #[error("{chains} chains of {draws} draws of {dim} coordinates do not fit in memory ({} bytes)", sci(*.bytes))]
    Storage {
        /// Chains asked for.
        chains: usize,
        /// Draws per chain.
        draws: usize,
        /// d.
        dim: usize,
        /// The bytes they need (∞ when that overflows).
        bytes: f64,
    },
    /// [`sample_until`](super::sample_until)'s `stop` was set before the
    /// draws were complete.
    #[error("the sampler was interrupted before its draws were complete")]
    Interrupted,
    /// The system is not of the form the sampler needs: holonomic
    /// constraints g(q) and H(q, p) = ½|p|² + U(q) (an identity mass: the
    /// momenta are drawn from N(0, I)).
    #[error("the sampler needs holonomic constraints g(q) and H = |p|²/2 + U(q): {why}")]
    UnsupportedSystem {
        /// What the system does otherwise.
        why: &'static str,
    },
}
