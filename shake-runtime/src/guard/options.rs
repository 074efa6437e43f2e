//! The options of every check and solve of a step, in one place.

use crate::newton::NewtonOptions;

/// Tolerances, limits and checks of an [`Integrator`](crate::Integrator).
///
/// ```
/// use geoshake_runtime::Options;
/// let opts = Options { max_condition: 1e6, ..Options::default() };
/// assert_eq!(opts.jump_ratio, 1.0);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Options {
    /// Every Newton iteration of a step.
    pub newton: NewtonOptions,
    /// A state z = (q, p) is on M when every constraint satisfies
    /// |g_i(z)| ≤ this · (s_i/2)² + 64ε · s_i · ‖z‖, with s_i =
    /// ‖∂g_i/∂z‖₁ and ‖z‖ the largest variable of the kind g_i reads (‖q‖∞
    /// for a holonomic g_i, ‖p‖∞ for one of p alone, ‖z‖∞ otherwise)
    /// (default 1e-8). The first term is relative to g_i's own size and
    /// moves neither with units nor with the origin: a system and its copy
    /// with lengths scaled by L pass or fail alike, and for a distance
    /// constraint |q_a − q_b|² − ℓ² (where (s/2)² lies between ℓ² and 2ℓ²)
    /// 1e-8 allows the length to be off by about 5e-9 ℓ. The second is g's
    /// round-off at z. It must lie in (0, 1]. A state handed to
    /// [`Integrator::step`](crate::Integrator::step) or
    /// [`Integrator::run`](crate::Integrator::run) must be, else
    /// [`StepError::NotOnConstraint`](crate::StepError::NotOnConstraint) (its `tolerance` is the bound of the
    /// constraint at fault). This tolerance is for the data a run starts
    /// from: every (sub)step's result must be on M to round-off,
    /// |g_i| ≤ max(64ε, `newton.step_tolerance`) · s_i · ‖z‖ with s_i
    /// measured in that step, else [`StepError::NewtonNotConverged`](crate::StepError::NewtonNotConverged) in
    /// [`Stage::Shake`](crate::Stage::Shake) (SHAKE's Newton stopped short of its root: an
    /// ill-conditioned λ or an absurd h), or in [`Stage::Rattle`](crate::Stage::Rattle) for a
    /// state projected onto M^H only when a lazy run stores it (Π's fibre
    /// flow moves q when g reads p).
    pub constraint_tolerance: f64,
    /// After every step N is evaluated at the new state; the step fails with
    /// [`StepError::NondegeneracyLost`](crate::StepError::NondegeneracyLost) when max(‖N‖₁, ‖N₀‖₁) · ‖N⁻¹‖₁ exceeds
    /// this (default 1e10), N₀ being N at the start of the run. For m ≥ 2
    /// this bounds the condition number κ₁(N); for m = 1 it says N shrank by
    /// that factor since the start.
    pub max_condition: f64,
    /// SHAKE's Newton iteration starts from λ = 0, and its first iterate λ₁
    /// is the linear prediction of the fibre displacement, of order h. The
    /// converged λ differs from it by O(h)·‖λ₁‖ when the solution is the
    /// nearby one; the step fails with [`StepError::FibreJump`](crate::StepError::FibreJump) when
    /// ‖λ − λ₁‖∞ > `jump_ratio` · ‖λ₁‖∞ + 1e-8·|h| (default 1: the
    /// correction is as large as the prediction itself). The projection Π
    /// onto M^H is held to the same test with its σ, wherever a run
    /// projects (every step, or only the stored states): near a fold of
    /// M^H (Section 5.4.2, case iii) it is Π that would otherwise land on
    /// another crossing of the fibre. `f64::INFINITY` turns the check off.
    pub jump_ratio: f64,
    /// Check after every step that det N kept its sign
    /// ([`StepError::ComponentJump`](crate::StepError::ComponentJump)) (default true).
    pub check_component: bool,
    /// In a RATTLE [`Run`](crate::Run), project onto M^H after every step instead of only
    /// at the states that are stored or observed (default false; both give
    /// the same states to round-off, by Π ∘ S_hᵏ = Π ∘ R_hᵏ).
    pub project_every_step: bool,
    /// A composed step ([`Composition`](crate::Composition) with more than
    /// one stage, over a symmetric base map) is taken back with −h from its
    /// result, and the step fails with [`StepError::BranchJump`](crate::StepError::BranchJump) when that
    /// misses the step's start by more than this times the state's size
    /// (max of ‖z₀‖∞ and ‖z₁‖∞; default 1e-6). The substeps are symmetric,
    /// so a step on the nearby branch returns to round-off amplified by
    /// the conditioning of its Newton solves (≈ 1e-13 on the paper's
    /// examples), while a substep that landed on another crossing of a
    /// fibre misses by the distance between the crossings. This is the one
    /// check that sees such a jump when N keeps its sign and λ stays near
    /// its first prediction (Section 5.4.2; `tests/suite/hard_degenerate.rs`).
    /// It makes a composed step 1.8–3.4 times as costly (the step back,
    /// and in a lazily projected run Π of the start; BENCHMARKS.md,
    /// section 7.1); `f64::INFINITY` turns it off. Single steps are not
    /// checked this way.
    pub reverse_tolerance: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            newton: NewtonOptions::default(),
            constraint_tolerance: 1e-8,
            max_condition: 1e10,
            jump_ratio: 1.0,
            check_component: true,
            project_every_step: false,
            reverse_tolerance: 1e-6,
        }
    }
}
