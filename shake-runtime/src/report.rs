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
    /// Newton iterations on λ (SHAKE): on a particle system the largest
    /// count of one cluster (clusters solver), or the count of the whole
    /// graph (band and sparse solvers).
    pub shake_iterations: usize,
    /// SHAKE's Newton iterations summed over the step's independent solves:
    /// a particle system's clusters; on every other path the one solve's
    /// count, `shake_iterations`.
    pub shake_iterations_total: u64,
    /// Newton iterations of the base map's stage equations (all of them).
    pub base_iterations: usize,
    /// Newton iterations of the projection onto M^H (0 unless projected).
    pub rattle_iterations: usize,
    /// ‖λ‖∞, the fibre displacement of SHAKE (NaN on a particle system,
    /// whose kernels do not gather it).
    pub lambda: f64,
    /// The condition number of N at the new state (relative to the start,
    /// see [`Options::max_condition`](crate::Options::max_condition); NaN
    /// on a particle system, whose Cholesky factor of N = G M⁻¹ Gᵀ checks
    /// only that N is positive definite).
    pub condition: f64,
    /// det N at the new state (NaN on a particle system).
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
    /// earlier, e.g. in [`Run::on_step`](crate::Run::on_step). NaN on a
    /// particle system (holonomic constraints: N = G M⁻¹ Gᵀ has no fold
    /// while G keeps full rank).
    pub fold: f64,
    /// The largest relative constraint residual at the new state,
    /// |g_k(q1)| / (|∇g_k(q1)| · the extent of member k's particles), on a
    /// particle system (see
    /// [`particles::Options::tol`](crate::particles::Options::tol)).
    /// `None` where a step does not measure it: the dense path refuses a
    /// state off M instead (its guard, [`Options`](crate::Options)); a
    /// diagnosed run records |g| per stored state.
    pub residual: Option<f64>,
    /// The largest relative hidden-constraint residual at the new state,
    /// |(G M⁻¹ p)_k| / (|∇g_k| · |M⁻¹ p| over member k's particles), on a
    /// particle system after RATTLE's velocity stage. `None` where it is
    /// not measured (SHAKE, and the dense path).
    pub hidden: Option<f64>,
}

/// What a run's steps measured, summed or maximised over the steps taken
/// (the driver adds each step's [`StepInfo`]; a run that failed at step k
/// counts steps 1 to k − 1).
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(10)).execute();
/// let s = out.summary;
/// assert_eq!(s.steps, 10);
/// assert!(s.max_newton_iterations >= 1 && s.newton_iterations >= 10);
/// assert_eq!(s.max_residual, None); // the dense path refuses a state off M instead
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct RunSummary {
    /// Steps taken.
    pub steps: u64,
    /// The largest [`StepInfo::shake_iterations`] of any step.
    pub max_newton_iterations: usize,
    /// [`StepInfo::shake_iterations_total`] summed over the steps.
    pub newton_iterations: u64,
    /// The largest [`StepInfo::residual`] of any step (`None` when no
    /// step measured one).
    pub max_residual: Option<f64>,
    /// The largest [`StepInfo::hidden`] of any step (`None` when no step
    /// measured one).
    pub max_hidden: Option<f64>,
}

impl RunSummary {
    /// Counts one step.
    #[inline]
    pub(crate) fn add(&mut self, info: &StepInfo) {
        self.steps += 1;
        self.max_newton_iterations = self.max_newton_iterations.max(info.shake_iterations);
        self.newton_iterations += info.shake_iterations_total;
        if info.residual.is_some() || info.hidden.is_some() {
            self.max_residual = larger(self.max_residual, info.residual);
            self.max_hidden = larger(self.max_hidden, info.hidden);
        }
    }
}

/// The larger of two measurements, either possibly missing; a NaN
/// measurement wins (a step that measured NaN is not hidden by a max).
fn larger(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(if x.is_nan() || y.is_nan() {
            f64::NAN
        } else {
            x.max(y)
        }),
        (x, None) | (None, x) => x,
    }
}
