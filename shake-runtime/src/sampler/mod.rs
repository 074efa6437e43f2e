//! Constrained Hamiltonian Monte Carlo on M = {q : g(q) = 0}: RATTLE
//! steps of this crate's engine, a reversibility check and a Metropolis
//! test (Brubaker, Salzmann and Urtasun 2012; Zappa, Holmes-Cerfon and
//! Goodman 2018; Lelièvre, Rousset and Stoltz 2019; Graham and Storkey's
//! mici).
//!
//! # The target
//!
//! A density π(q) on the submanifold M ⊂ R^d of codimension m, with
//! respect to the Hausdorff (surface) measure σ_M, given through the
//! potential U = −log π: the system is H(q, p) = ½|p|² + U(q) (an identity
//! mass) with holonomic constraints g(q), declared with
//! `constrained_system!` like any other. The sampler checks that form
//! before it starts ([`SamplerError::UnsupportedSystem`]).
//!
//! Why the draws have density π with respect to σ_M, and no Gram
//! determinant enters: RATTLE over Störmer–Verlet is a symplectic map of
//! T*M (the paper's Section 4) and so preserves its Liouville measure,
//! which for the metric M inherits from R^d is σ_M(dq) times the Lebesgue
//! measure of the (d − m)-dimensional fibre T*_q M ≅ T_q M. The Gaussian
//! factor e^{−|p|²/2} integrates over every fibre to the same
//! (2π)^{(d−m)/2}, so the q-marginal of e^{−H} is e^{−U} σ_M = π σ_M.
//!
//! **The Gram-determinant correction is an option.** It is needed for
//! another target: when π is a density on R^d and the intended
//! distribution is that of q given g(q) = 0 (the co-area formula), its
//! density with respect to σ_M is π(q)/√det(g_q g_qᵀ).
//! [`Density::Ambient`] samples that one, with the potential
//! U + ½ log det(g_q g_qᵀ) (mici's `dens_wrt_hausdorff = False`); the
//! default [`Density::Hausdorff`] is mici's `dens_wrt_hausdorff = True`.
//! For a sphere |q|² − r², a product of circles, or SO(3) as RᵀR − I, the
//! Gram matrix is constant on M and the two targets coincide.
//!
//! # One transition
//!
//! From q ∈ M, with step size h and L steps:
//!
//! 1. p ~ N(0, I_d), then Π: p ← p − g_qᵀ(g_q g_qᵀ)⁻¹ g_q p, RATTLE's own
//!    projection onto M^H ([`Integrator::project`](crate::Integrator::project)),
//!    which for this H is the orthogonal projection onto T_q M: p is then
//!    standard normal on the fibre.
//! 2. L RATTLE steps z ← R_h(z) over Störmer–Verlet
//!    ([`Integrator::step_in_place`](crate::Integrator::step_in_place)), each
//!    followed by the **reversibility check**: the step back R_{−h} (for H
//!    even in p, the step from the end with negated momentum) must return
//!    to the step's start position within `reverse_tolerance` times the
//!    step's length (positions only; see
//!    [`SamplerOptions::reverse_tolerance`]), and every Newton solve of
//!    both must converge. A step
//!    whose solve found another solution than the nearby one is not undone
//!    by the step back; accepting it would bias the chain.
//! 3. The Metropolis test: accept the end point with probability
//!    min(1, e^{H(z₀) − H(z_L)}); otherwise q stays.
//!
//! The proposal ρ ∘ R_h^L (ρ negates p) is a volume-preserving involution
//! where the checks pass, and they pass for a trajectory when they pass
//! for its reversal (to round-off, and away from the limit of the
//! conditions: a miss within round-off of the tolerance, or a solve at the
//! edge of convergence, may be judged differently in the two directions),
//! so the chain satisfies detailed balance with respect to e^{−H} to that
//! precision; p is drawn afresh at every transition, so ρ itself
//! need not be applied. A failed check or solve is a counted rejection
//! ([`Rejection`]), never an error of the run.
//!
//! # Dynamic integration time
//!
//! With [`SamplerOptions::max_tree_depth`] the trajectory length is not
//! fixed: multinomial HMC with the no-U-turn criterion (Hoffman and Gelman
//! 2014; Betancourt 2017), mici's `DynamicMultinomialHMC`. The trajectory
//! is doubled, forward or backward in time at random, by subtrees of the
//! same checked RATTLE steps, until the momenta summed over it turn
//! against its first or last momentum, and the chain moves to a state of
//! the trajectory drawn with probability ∝ e^{−H}. A subtree that turns,
//! diverges (H − H₀ > 1000) or meets a failed solve or check is dropped
//! and the doubling stops: the trajectory is then one that building from
//! any of its states would also stop at, so the scheme stays reversible.
//! A draw that stayed at z₀ is counted as a `metropolis` rejection, or as
//! the kind of failure that stopped the very first step.
//!
//! # Warm-up, chains, output
//!
//! Warm-up searches a step size near the scale of M, then adapts it by
//! two dual averagings (Hoffman and Gelman 2014): towards
//! [`SamplerOptions::target_acceptance`] and towards at most
//! [`SamplerOptions::target_failure_rate`] of the trajectories cut short
//! by a failed solve or check; its draws are dropped. Chains
//! run in parallel on rayon's pool (install a pool to choose the number of
//! threads, as for [`ensemble`](crate::ensemble())); each draws from its
//! own stream (`chain`) of a ChaCha8 generator seeded with
//! [`SamplerOptions::seed`], so its draws are bit for bit the same
//! whatever the number of threads. [`Samples`] holds the draws as a
//! (chains, draws, dim) array with per-draw statistics;
//! [`Samples::summary`] gives the rank-normalised split-R̂ and bulk ESS of
//! Vehtari et al. (2021) ([`rhat`], [`ess_bulk`]).
//!
//! ```
//! use geoshake_runtime::examples::Pendulum;
//! use geoshake_runtime::sampler::{sample, Estimate, SamplerOptions};
//!
//! // Without gravity U = 0: the uniform distribution on the unit circle,
//! // where E[x²] = 1/2.
//! let circle = Pendulum { gravity: 0.0, length: 1.0 };
//! let opts = SamplerOptions { chains: 2, draws: 500, warmup: 200, seed: 7, ..Default::default() };
//! let samples = sample(&circle, &[[1.0, 0.0]], &opts)?;
//! let x2 = Estimate::of(&samples.series(|q| q[0] * q[0]));
//! assert!((x2.mean - 0.5).abs() < 5.0 * x2.mcse);
//! let summary = samples.summary();
//! assert!(summary.max_rhat() < 1.05, "{summary}");
//! # Ok::<(), geoshake_runtime::sampler::SamplerError>(())
//! ```

mod adapt;
mod chain;
mod convergence;
mod error;
mod gram;
mod output;
mod tree;

pub use convergence::{ess_bulk, ess_mean, ess_tail, rhat};
pub use error::SamplerError;
pub use output::{ChainSummary, Estimate, Rejection, RejectionCounts, Samples, Summary};

use std::sync::atomic::AtomicBool;

use rayon::prelude::*;

use crate::base_map::StormerVerlet;
use crate::integrator::Integrator;
use crate::newton::NewtonOptions;
use crate::state::State;
use crate::system::ConstrainedSystem;

use chain::Chain;
use gram::Gram;

/// The largest step size accepted: far beyond any usable step on a
/// manifold of any sensible scale, and small enough that the adaptation's
/// μ = log(10 h₀) and the engine's times stay finite.
const MAX_STEP_SIZE: f64 = 1e6;

/// The largest [`SamplerOptions::newton`] step tolerance: an error of λ
/// of 1e-9 ‖λ‖ moves the step back's end by about h ‖g_q‖ ‖λ‖ 1e-9, a
/// tenth of the default `reverse_tolerance` times a step of length
/// h ‖p‖ where ‖g_q‖ ‖λ‖ is of the order of ‖p‖.
const MAX_SOLVE_TOLERANCE: f64 = 1e-9;

/// The deepest tree of the dynamic integration time: 2²⁰ − 1 steps a
/// transition, far past any useful trajectory, and a bound on the work a
/// mistyped depth can ask for.
const MAX_TREE_DEPTH: u32 = 20;

/// Which measure the density e^{−U} of the system is taken with respect
/// to, and so which distribution on M is sampled.
///
/// - [`Density::Hausdorff`] (the default): π = e^{−U} is a density on M
///   with respect to its surface (Hausdorff) measure σ_M, the measure
///   RATTLE preserves ([module](self) docs). Use it when U was written for
///   M itself: a von Mises–Fisher density on a sphere, a Boltzmann density
///   of a molecule with rigid bonds whose reference measure is σ_M, a
///   uniform distribution on M.
/// - [`Density::Ambient`]: π = e^{−U} is a density on R^d, and the target
///   is the law of q given g(q) = 0. By the co-area formula (Federer 1969,
///   §3.2; Diaconis, Holmes and Shahshahani 2013) its density with respect
///   to σ_M is π/√det G, G = g_q g_qᵀ: the sampler runs on the potential
///   U + ½ log det G, whose gradient Σ_i ∇²g_i w_i (w_i the column i of
///   g_qᵀ G⁻¹) it computes from the constraints' second derivatives. Use
///   it to condition a model on R^d on an observation g(q) = 0 (mici's
///   `dens_wrt_hausdorff = False`). The target then depends on g, not
///   only on M: g and c(q)·g give other conditionals (Borel's paradox).
///
/// The two agree where det G is constant on M (a sphere |q|² − r², a
/// product of circles, SO(3) as RᵀR − I). On the ellipse
/// x²/a² + y²/b² = 1 with U = 0, Hausdorff is uniform in arc length and
/// Ambient uniform in the angle θ of x = a cos θ, y = b sin θ: with
/// g = x²/a² + y²/b² − 1, |∇g| = (2/(ab))·√(a² sin²θ + b² cos²θ) and
/// ds = √(a² sin²θ + b² cos²θ) dθ, so ds/|∇g| = (ab/2) dθ.
///
/// An enum rather than a flag: the call site names the measure
/// (`density: Density::Ambient`), as Python's `density="ambient"` does.
/// Ambient costs per gradient one LU of the m × m matrix G and m
/// evaluations of a constraint's Hessian; the draws' `energy` is then that
/// of the corrected potential.
///
/// ```
/// use geoshake_runtime::sampler::{Density, SamplerOptions};
/// let opts = SamplerOptions { density: Density::Ambient, ..SamplerOptions::default() };
/// assert_eq!(SamplerOptions::default().density, Density::Hausdorff);
/// # let _ = opts;
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq, Hash)]
pub enum Density {
    /// e^{−U} with respect to the surface measure of M.
    #[default]
    Hausdorff,
    /// e^{−U} a density on R^d, conditioned on g(q) = 0: e^{−U}/√det(g_q g_qᵀ)
    /// with respect to the surface measure of M.
    Ambient,
}

/// The settings of a sampler run.
///
/// ```
/// use geoshake_runtime::sampler::SamplerOptions;
/// let opts = SamplerOptions { steps: 20, ..SamplerOptions::default() };
/// assert_eq!((opts.chains, opts.draws, opts.target_acceptance), (4, 1000, Some(0.8)));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct SamplerOptions {
    /// Number of chains (default 4).
    pub chains: usize,
    /// Draws kept per chain, after warm-up (default 1000).
    pub draws: usize,
    /// Warm-up transitions per chain, dropped (default 1000).
    pub warmup: usize,
    /// L, the RATTLE steps of one transition (default 10); unused with
    /// `max_tree_depth`.
    pub steps: usize,
    /// `Some(k)`: a dynamic integration time instead of a fixed L:
    /// multinomial HMC with the no-U-turn criterion (module docs),
    /// its trajectory doubled until it turns back on itself, at most k
    /// times (2^k − 1 steps; k in 1..=20). `None` (the default): static
    /// HMC with `steps` steps.
    ///
    /// ```
    /// use geoshake_runtime::examples::Pendulum;
    /// use geoshake_runtime::sampler::{sample, Estimate, SamplerOptions};
    /// // e^{2 cos θ} on the unit circle (gravity 2 along −y):
    /// // E[−y] = I₁(2)/I₀(2) = 0.697775.
    /// let circle = Pendulum { gravity: 2.0, length: 1.0 };
    /// let opts = SamplerOptions { max_tree_depth: Some(8), draws: 2000, seed: 1, ..SamplerOptions::default() };
    /// let s = sample(&circle, &[[0.0, -1.0]], &opts).unwrap();
    /// let e = Estimate::of(&s.series(|q| -q[1]));
    /// assert!((e.mean - 0.697775).abs() < 4.5 * e.mcse, "{e:?}");
    /// // Trajectories of many lengths.
    /// assert!(s.steps.iter().any(|&n| n > 3) && s.steps.iter().any(|&n| n <= 3));
    /// ```
    pub max_tree_depth: Option<u32>,
    /// h: the step size, the starting value of the adaptation when there
    /// is one (default 0.1); positive and at most 10⁶ (so that the
    /// adaptation's log(10 h) and every step's t + h stay finite).
    pub step_size: f64,
    /// Each transition draws its step size uniformly from
    /// h·[1 − j, 1 + j] with j this (default 0.2, in [0, 1)): a trajectory
    /// length L·h that matches a period of the dynamics (an oscillation
    /// about a mode) takes the chain back near its start, and a random
    /// length breaks that resonance (Neal 2011, Section 5.4.4). Without
    /// it the von Mises density e^{20 cos θ} sampled with h = 0.31 and
    /// L = 10 (two periods of the oscillation about its mode) gives
    /// E[cos θ] = 0.989 instead of 0.975 while every chain agrees. A
    /// mixture of kernels that each keep the target keeps it too.
    pub step_size_jitter: f64,
    /// The mean acceptance probability that warm-up adapts h to (default
    /// `Some(0.8)`); `None` keeps h.
    pub target_acceptance: Option<f64>,
    /// The largest fraction of proposals that the adaptation lets a
    /// failed solve or check reject (default 0.01, in (0, 1)): h is the
    /// smaller of the step that meets `target_acceptance` and the step
    /// that keeps these failures to this rate. Such failures cluster where
    /// the momentum is largest, at the crossings between modes; a step
    /// tuned on acceptance alone can lose most crossings and leave every
    /// chain on one side, R̂ near 1 and the mean wrong. Used only when
    /// `target_acceptance` is set, and only for static HMC (with
    /// `max_tree_depth` a failure cuts the trajectory short but the chain
    /// still moves).
    pub target_failure_rate: f64,
    /// A step q₀ → q₁ is rejected when its step back misses q₀ by more
    /// than this times ‖q₁ − q₀‖∞ + 10⁻⁴·max(‖q₀‖∞, ‖q₁‖∞) (default 1e-8):
    /// positions only, as mici (RATTLE's momenta are functions of the two
    /// positions), against the step's own length, so that translating M
    /// changes nothing; the second term is a floor for round-off, which is
    /// relative to the coordinates. Steps that follow the nearby branch
    /// miss by round-off times the conditioning of the solves (about 1e-14
    /// of ‖q‖), a branch jump by a fraction of the step.
    /// `f64::INFINITY` turns the check off, and its step back with it:
    /// half the cost, and a biased chain wherever a solve can jump.
    pub reverse_tolerance: f64,
    /// The Newton iterations of every solve of a transition: each step's
    /// SHAKE and Π, and the step back's (default
    /// [`NewtonOptions::default`], to round-off). A larger
    /// `step_tolerance` stops SHAKE once its update of λ is below that
    /// fraction of ‖λ‖∞, as mici stops its projections at
    /// ‖Δq‖∞ < 1e-8 (`examples/sampler.py`): fewer updates per step, and a
    /// step that is no longer R_h to round-off, only to that tolerance.
    /// The step back then misses by about h ‖g_q‖ times that error of λ,
    /// which must stay well below `reverse_tolerance` times the step: a
    /// `step_tolerance` from 4ε (the default) to 1e-9, `stagnation_threshold`
    /// in (0, 1) and at least one iteration, else
    /// [`SamplerError::InvalidOption`].
    ///
    /// ```
    /// use geoshake_runtime::examples::Pendulum;
    /// use geoshake_runtime::sampler::{sample, SamplerOptions};
    /// use geoshake_runtime::NewtonOptions;
    /// let newton = NewtonOptions { step_tolerance: 1e-10, ..NewtonOptions::default() };
    /// let opts = SamplerOptions { newton, draws: 200, warmup: 100, ..SamplerOptions::default() };
    /// let circle = Pendulum { gravity: 2.0, length: 1.0 };
    /// let s = sample(&circle, &[[0.0, -1.0]], &opts).unwrap();
    /// assert!(s.summary().acceptance() > 0.5);
    /// ```
    pub newton: NewtonOptions,
    /// The seed of every chain's generator (default 0).
    pub seed: u64,
    /// The measure e^{−U} is a density with respect to (default
    /// [`Density::Hausdorff`]; see [`Density`]).
    pub density: Density,
}

impl Default for SamplerOptions {
    fn default() -> Self {
        SamplerOptions {
            chains: 4,
            draws: 1000,
            warmup: 1000,
            steps: 10,
            max_tree_depth: None,
            step_size: 0.1,
            step_size_jitter: 0.2,
            target_acceptance: Some(0.8),
            target_failure_rate: 0.01,
            reverse_tolerance: 1e-8,
            newton: NewtonOptions::default(),
            seed: 0,
            density: Density::Hausdorff,
        }
    }
}

impl SamplerOptions {
    /// Refuses options outside their domain.
    ///
    /// ```
    /// use geoshake_runtime::sampler::{SamplerError, SamplerOptions};
    /// let bad = SamplerOptions { step_size: -0.1, ..SamplerOptions::default() };
    /// assert!(matches!(bad.validate(), Err(SamplerError::InvalidOption { what: "step_size", .. })));
    /// assert!(SamplerOptions::default().validate().is_ok());
    /// ```
    pub fn validate(&self) -> Result<(), SamplerError> {
        let invalid = |what, value: f64, why| Err(SamplerError::InvalidOption { what, value, why });
        if self.chains == 0 {
            return invalid("chains", 0.0, "at least one chain");
        }
        if self.draws == 0 {
            return invalid("draws", 0.0, "at least one draw per chain");
        }
        if self.steps == 0 {
            return invalid("steps", 0.0, "at least one RATTLE step per transition");
        }
        if let Some(k) = self.max_tree_depth
            && !(1..=MAX_TREE_DEPTH).contains(&k)
        {
            return invalid("max_tree_depth", k as f64, "from 1 to 20");
        }
        if !(self.step_size > 0.0 && self.step_size <= MAX_STEP_SIZE) {
            return invalid("step_size", self.step_size, "positive and at most 1e6");
        }
        if !(0.0..1.0).contains(&self.step_size_jitter) {
            return invalid("step_size_jitter", self.step_size_jitter, "in [0, 1)");
        }
        if let Some(t) = self.target_acceptance
            && !(t > 0.0 && t < 1.0)
        {
            return invalid("target_acceptance", t, "strictly between 0 and 1");
        }
        if !(self.target_failure_rate > 0.0 && self.target_failure_rate < 1.0) {
            return invalid(
                "target_failure_rate",
                self.target_failure_rate,
                "strictly between 0 and 1",
            );
        }
        if !(self.reverse_tolerance > 0.0) {
            return invalid(
                "reverse_tolerance",
                self.reverse_tolerance,
                "positive (infinity turns the check off)",
            );
        }
        let newton = &self.newton;
        if !(newton.step_tolerance >= NewtonOptions::default().step_tolerance
            && newton.step_tolerance <= MAX_SOLVE_TOLERANCE)
        {
            return invalid(
                "newton.step_tolerance",
                newton.step_tolerance,
                "from 4ε (round-off, the default) to 1e-9",
            );
        }
        if !(newton.stagnation_threshold > 0.0 && newton.stagnation_threshold < 1.0) {
            return invalid(
                "newton.stagnation_threshold",
                newton.stagnation_threshold,
                "strictly between 0 and 1",
            );
        }
        if newton.max_iterations == 0 {
            return invalid("newton.max_iterations", 0.0, "at least one iteration");
        }
        Ok(())
    }
}

/// Samples the density e^{−U} (with respect to the Hausdorff measure on M,
/// or conditioned from R^d: [`SamplerOptions::density`]) of `system`, H = ½|p|² + U(q) with holonomic constraints g(q), by
/// constrained HMC (see the [module](self) docs). `starts` holds one point
/// of M for every chain, or one for all.
///
/// Errors, before any transition: options out of their domain, a start of
/// the wrong length, off M, or where U is not finite, and a system of
/// another form. Nothing after that is an error: failed proposals are
/// counted rejections, and a chain that rejected everything says so in
/// [`Samples::summary`].
///
/// ```
/// use geoshake_runtime::examples::Pendulum;
/// use geoshake_runtime::sampler::{sample, SamplerError, SamplerOptions};
/// let circle = Pendulum { gravity: 0.0, length: 1.0 };
/// let opts = SamplerOptions::default();
/// // (1, 0.1) is not on the unit circle.
/// let err = sample(&circle, &[[1.0, 0.1]], &opts).unwrap_err();
/// assert!(matches!(err, SamplerError::StartOffManifold { chain: 0, .. }));
/// ```
pub fn sample<S, Q>(
    system: &S,
    starts: &[Q],
    options: &SamplerOptions,
) -> Result<Samples, SamplerError>
where
    S: ConstrainedSystem + Clone + Send + Sync,
    Q: AsRef<[f64]> + Sync,
{
    sample_until(system, starts, options, &AtomicBool::new(false))
}

/// [`sample`] that can be stopped from another thread: every chain ends at
/// its next transition once `stop` is set, and the run returns
/// [`SamplerError::Interrupted`] (a Ctrl-C in Python, a deadline, a
/// user's cancel button). Chains do not share draws, so a partial run
/// would be chains of unequal length: it is not returned.
///
/// ```
/// use std::sync::atomic::AtomicBool;
/// use geoshake_runtime::examples::Pendulum;
/// use geoshake_runtime::sampler::{sample_until, SamplerError, SamplerOptions};
/// let circle = Pendulum { gravity: 0.0, length: 1.0 };
/// let stop = AtomicBool::new(true);
/// let err = sample_until(&circle, &[[1.0, 0.0]], &SamplerOptions::default(), &stop);
/// assert!(matches!(err, Err(SamplerError::Interrupted)));
/// ```
pub fn sample_until<S, Q>(
    system: &S,
    starts: &[Q],
    options: &SamplerOptions,
    stop: &AtomicBool,
) -> Result<Samples, SamplerError>
where
    S: ConstrainedSystem + Clone + Send + Sync,
    Q: AsRef<[f64]> + Sync,
{
    options.validate()?;
    let d = system.dof();
    if starts.len() != 1 && starts.len() != options.chains {
        return Err(SamplerError::StartCount {
            given: starts.len(),
            chains: options.chains,
        });
    }
    let start = |c: usize| starts[if starts.len() == 1 { 0 } else { c }].as_ref();
    for c in 0..starts.len() {
        if start(c).len() != d {
            return Err(SamplerError::StartDimension {
                chain: c,
                given: start(c).len(),
                dof: d,
            });
        }
    }
    check_structure(system)?;
    let outputs = match options.density {
        Density::Hausdorff => run_chains(system, starts, options, stop)?,
        Density::Ambient => run_chains(&Gram::new(system.clone()), starts, options, stop)?,
    };

    let (chains, draws) = (options.chains, options.draws);
    let mut samples = Samples {
        chains,
        draws,
        dim: d,
        positions: Vec::with_capacity(chains * draws * d),
        accepted: Vec::with_capacity(chains * draws),
        acceptance_probability: Vec::with_capacity(chains * draws),
        energy: Vec::with_capacity(chains * draws),
        steps: Vec::with_capacity(chains * draws),
        rejection: Vec::with_capacity(chains * draws),
        step_size: Vec::with_capacity(chains),
    };
    for out in outputs {
        samples.positions.extend_from_slice(&out.positions);
        for t in &out.transitions {
            samples.accepted.push(t.accepted);
            samples.acceptance_probability.push(t.alpha);
            samples.energy.push(t.energy);
            samples.steps.push(t.steps);
            samples.rejection.push(t.rejection);
        }
        samples.step_size.push(out.step_size);
    }
    Ok(samples)
}

/// The checks of the starts against `system` (the potential the chains
/// run on, corrected or not), then the chains; the starts' count and
/// lengths are checked by the caller.
fn run_chains<S, Q>(
    system: &S,
    starts: &[Q],
    options: &SamplerOptions,
    stop: &AtomicBool,
) -> Result<Vec<chain::ChainOutput>, SamplerError>
where
    S: ConstrainedSystem + Clone + Send + Sync,
    Q: AsRef<[f64]> + Sync,
{
    let start = |c: usize| starts[if starts.len() == 1 { 0 } else { c }].as_ref();
    let mut probe = Integrator::new(system.clone(), StormerVerlet, options.step_size);
    for c in 0..starts.len() {
        check_start(&mut probe, start(c), c)?;
    }
    check_identity_mass(system, start(0))?;
    check_storage(options.chains, options.draws, system.dof())?;
    let outputs: Option<Vec<chain::ChainOutput>> = (0..options.chains)
        .into_par_iter()
        .map(|c| Chain::new(system, start(c), options.seed, c, options).run(options, stop))
        .collect();
    outputs.ok_or(SamplerError::Interrupted)
}

/// The bytes of one draw besides its d positions: acceptance
/// probability, energy, step count, the accepted flag and the rejection.
const DRAW_STATS_BYTES: usize = 3 * 8 + 2 + 1;

/// The draws must fit: their size is computed without overflow and the
/// positions are reserved once (and given back) before any chain runs, so
/// a request past memory is a typed error, not an abort in a chain.
fn check_storage(chains: usize, draws: usize, dim: usize) -> Result<(), SamplerError> {
    let values = chains.checked_mul(draws).and_then(|n| n.checked_mul(dim));
    let bytes = chains
        .checked_mul(draws)
        .and_then(|n| n.checked_mul(dim.checked_mul(8)?.checked_add(DRAW_STATS_BYTES)?));
    let fits = match (values, bytes) {
        (Some(values), Some(bytes)) if bytes <= isize::MAX as usize => {
            Vec::<f64>::new().try_reserve_exact(values).is_ok()
        }
        _ => false,
    };
    if fits {
        return Ok(());
    }
    Err(SamplerError::Storage {
        chains,
        draws,
        dim,
        bytes: bytes.map_or(f64::INFINITY, |b| b as f64),
    })
}

/// A start must be on M (the engine's test, with its tolerance) and have
/// a finite potential.
fn check_start<S: ConstrainedSystem>(
    probe: &mut Integrator<S, StormerVerlet>,
    q: &[f64],
    chain: usize,
) -> Result<(), SamplerError> {
    let z = State::from_slices(q, &vec![0.0; q.len()]);
    if probe.system().constraint_count() > 0 {
        probe
            .project(&z)
            .map_err(|source| SamplerError::StartOffManifold { chain, source })?;
    }
    let potential = probe.system().hamiltonian(q, z.p.as_slice());
    if !potential.is_finite() {
        return Err(SamplerError::StartDensity { chain, potential });
    }
    Ok(())
}

/// The form the sampler needs, as the system declares it: holonomic g and
/// a separable H.
fn check_structure<S: ConstrainedSystem>(system: &S) -> Result<(), SamplerError> {
    if !system.kind().is_holonomic() {
        return Err(SamplerError::UnsupportedSystem {
            why: "a constraint depends on the momenta",
        });
    }
    if !system.separable() {
        return Err(SamplerError::UnsupportedSystem {
            why: "H is not separable, H ≠ T(p) + U(q)",
        });
    }
    Ok(())
}

/// ∂H/∂p = p and H(q, p) − H(q, 0) = |p|²/2, checked at a start (where U
/// is finite) on two momenta of distinct entries (so that no permutation
/// or scaling of p passes), to round-off.
fn check_identity_mass<S: ConstrainedSystem>(system: &S, q: &[f64]) -> Result<(), SamplerError> {
    let d = q.len();
    let mut grad = vec![0.0; d];
    for shift in [0.5, 0.25] {
        // Entries 1 + (k·φ mod 1) + shift: distinct, of order one.
        let p: Vec<f64> = (0..d)
            .map(|k| 1.0 + (k as f64 * 0.618_033_988_749_895).fract() + shift)
            .collect();
        system.grad_p(q, &p, &mut grad);
        let potential = system.hamiltonian(q, &vec![0.0; d]);
        let kinetic = system.hamiltonian(q, &p) - potential;
        let half_norm = 0.5 * p.iter().map(|x| x * x).sum::<f64>();
        let off = grad
            .iter()
            .zip(&p)
            .any(|(g, x)| !((g - x).abs() <= 1e-12 * x.abs()));
        // (H(q, p) − U(q) loses the digits of U: round-off relative to both.)
        let scale = half_norm.max(potential.abs()).max(1.0);
        if off || !((kinetic - half_norm).abs() <= 1e-10 * scale) {
            return Err(SamplerError::UnsupportedSystem {
                why: "the kinetic energy is not |p|²/2 (the sampler draws p from N(0, I))",
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
