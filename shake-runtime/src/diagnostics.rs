//! Opt-in diagnostics of a run: what the theory says should hold, measured.
//!
//! With [`Integrator::with_diagnostics`](crate::Integrator::with_diagnostics)
//! every stored or observed state comes with a [`DiagnosticRecord`]: the
//! energy H, the residuals |g| and |{g,H}| of that state, and summaries of
//! the steps since the previous record (Newton iterations, ‖λ‖, and the
//! condition of N), and the multipliers of every recorded state, λ of the
//! SHAKE step leaving it and σ of the projection that gave it (kept beside
//! the records in the trajectory, m of each per record:
//! [`Trajectory::lambda`](crate::Trajectory::lambda),
//! [`Trajectory::sigma`](crate::Trajectory::sigma), and the constraint
//! force from them, [`Trajectory::constraint_force`](crate::Trajectory::constraint_force)).
//! Sign convention of the paper: q' = H_p + g_pᵀλ, p' = −H_q − g_qᵀλ; the
//! library's λ, σ are fibre parameters (impulses), for holonomic g and
//! Störmer–Verlet (h/2) times the classical multipliers of Section 5.1.3.
//! The per-step summaries are a few comparisons per step;
//! the residuals cost one evaluation of g, {g,H} and H per record. With
//! diagnostics off none of this is computed.

/// Measurements at one recorded state and over the steps leading to it.
///
/// ```
/// use geoshake_runtime::{Integrator, ImplicitMidpoint, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.05).with_diagnostics();
/// let z0 = integ.project_to_hidden(&geoshake_runtime::State::from_slices(&[0.6, -0.8], &[0.8, 0.6])).unwrap();
/// let out = integ.run(z0, Stop::Steps(20)).stride(10).execute();
/// let rec = &out.trajectory.diagnostics[2];
/// assert_eq!(rec.step, 20);
/// assert!(rec.constraint < 1e-14 && rec.hidden_constraint < 1e-13);
/// assert!(rec.max_shake_iterations >= 2);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct DiagnosticRecord {
    /// Step index of the recorded state.
    pub step: u64,
    /// Its time.
    pub t: f64,
    /// H at the recorded state.
    pub energy: f64,
    /// ‖g‖∞ at the recorded state.
    pub constraint: f64,
    /// ‖{g,H}‖∞ at the recorded state (O(h) for SHAKE, round-off for
    /// RATTLE).
    pub hidden_constraint: f64,
    /// Most Newton iterations on λ in one step since the previous record.
    pub max_shake_iterations: usize,
    /// Most base-map stage iterations in one step since the previous record.
    pub max_base_iterations: usize,
    /// Newton iterations of the projection onto M^H for this record (RATTLE).
    pub rattle_iterations: usize,
    /// Largest ‖λ‖∞ since the previous record.
    pub max_lambda: f64,
    /// Largest condition number of N since the previous record (relative to
    /// its size at the start; see [`Options::max_condition`](crate::Options::max_condition)).
    pub max_condition: f64,
}

/// Running maxima over the steps between two records.
#[derive(Copy, Clone, Debug, Default)]
pub(crate) struct Accumulator {
    pub(crate) shake: usize,
    pub(crate) base: usize,
    pub(crate) lambda: f64,
    pub(crate) condition: f64,
}

impl Accumulator {
    #[inline]
    pub(crate) fn add(&mut self, info: &crate::report::StepInfo) {
        self.shake = self.shake.max(info.shake_iterations);
        self.base = self.base.max(info.base_iterations);
        self.lambda = self.lambda.max(info.lambda);
        self.condition = self.condition.max(info.condition);
    }
}
