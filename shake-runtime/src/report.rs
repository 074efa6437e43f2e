//! What a step reports about itself: iteration counts, the size of its
//! multipliers, and how near it came to a point where the nondegeneracy
//! matrix N = {{H,g_i},g_j} is singular (Section 5.4.2). Plain data at the
//! bottom of the crate: the step maps write it, the guard, the driver and
//! the diagnostics read it.

/// What one step did.
///
/// ```
/// use geoshake_runtime::{Integrator, ImplicitMidpoint, State, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1);
/// let mut z = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
/// let info = integ.step_in_place(&mut z).unwrap();
/// assert!(info.shake_iterations >= 2 && info.lambda < 0.1);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct StepInfo {
    /// Newton iterations on λ (SHAKE).
    pub shake_iterations: usize,
    /// Newton iterations of the base map's stage equations (all of them).
    pub base_iterations: usize,
    /// Newton iterations of the projection onto M^H (0 unless projected).
    pub rattle_iterations: usize,
    /// ‖λ‖∞, the fibre displacement of SHAKE.
    pub lambda: f64,
    /// The condition number of N at the new state (relative to the start,
    /// see [`Options::max_condition`](crate::Options::max_condition)).
    pub condition: f64,
    /// det N at the new state.
    pub det_n: f64,
    /// How near the step came to a point where N = {{H,g_i},g_j} is
    /// singular: ‖N₁ − N₀‖₁ · ‖N₁⁻¹‖₁, N₀ and N₁ at the states before and
    /// after the (sub)step (‖N₁⁻¹‖₁ estimated for m ≥ 2; the largest over
    /// a composition's substeps; 0 at the first step of a run or when N
    /// did not change). Since 1/‖N₁⁻¹‖₁ is N₁'s distance to the singular
    /// matrices, this is h over the time left before N could become
    /// singular at its present rate of change: O(h) on a regular
    /// trajectory, growing like h/(t_s − t) towards a fold of M^H at t_s
    /// (Section 5.4.2, case iii), where the equations for λ and σ get a
    /// double root and the step is about to lose the nearby solution. At
    /// 1 the next step may reach it. A diagnostic only: the run is stopped
    /// by the guards ([`Options`](crate::Options)); watch this to stop it
    /// earlier, e.g. in [`Run::on_step`](crate::Run::on_step).
    pub fold: f64,
}

/// What one step (or a projection) of a particle system measured
/// ([`particles::Rattle`](crate::particles::Rattle)).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Largest relative constraint residual at the end (see
    /// [`particles::Options::tol`](crate::particles::Options::tol)).
    pub max_rel_g: f64,
    /// Largest relative hidden-constraint residual |(G M⁻¹ p)_k| /
    /// (|∇g_k| · |M⁻¹ p| over member k's particles) after the velocity
    /// stage (0 for SHAKE, which does not project).
    pub max_hidden: f64,
    /// Newton iterations: the largest of one cluster on the cluster path,
    /// the global count otherwise.
    pub newton_iterations: usize,
    /// Newton iterations summed over clusters (the global count on the
    /// coupled path).
    pub newton_total: u64,
}
