//! The driver: an integrator built from a system, a base map and h.
//!
//! ```
//! use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
//! let mut rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).rattle();
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[0.6, -0.8], &[0.8, 0.6])).unwrap();
//! let out = rattle.run(z0, Stop::Time(1.0)).stride(10).execute();
//! assert!(out.error.is_none());
//! assert_eq!(out.trajectory.len(), 11);
//! ```

use crate::base_map::BaseMap;
use crate::composition::Composition;
use crate::diagnostics::{Accumulator, DiagnosticRecord};
use crate::error::{SolveError, Stage, StepError};
use crate::linalg::norm_inf;
use crate::newton::NewtonOptions;
use crate::rattle::{check_nondegeneracy, project_constraint, project_hidden};
use crate::shake::{shake_step, Workspace};
use crate::state::State;
use crate::system::ConstrainedSystem;
pub use crate::trajectory::Trajectory;

/// Which map a step is: SHAKE S_h (onto M) or RATTLE R_h = Π ∘ S_h (onto M^H).
///
/// ```
/// use shake_runtime::{Integrator, ImplicitMidpoint, Method, examples::Pendulum};
/// let integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).shake();
/// assert_eq!(integ.method(), Method::Shake);
/// ```
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Default)]
pub enum Method {
    /// Geometric SHAKE (Definition 1.1): states stay on M, the hidden
    /// constraint residual is O(h).
    Shake,
    /// Geometric RATTLE (Definition 1.2): states on M^H.
    #[default]
    Rattle,
}

/// Tolerances, limits and checks of an [`Integrator`].
///
/// ```
/// use shake_runtime::Options;
/// let opts = Options { max_condition: 1e6, ..Options::default() };
/// assert_eq!(opts.jump_ratio, 1.0);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Options {
    /// Every Newton iteration of a step.
    pub newton: NewtonOptions,
    /// A state handed to [`Integrator::step`] or [`Integrator::run`] must
    /// satisfy ‖g‖∞ ≤ this (default 1e-8), else
    /// [`StepError::NotOnConstraint`]. Every (sub)step's result must too,
    /// else [`StepError::NewtonNotConverged`] in [`Stage::Shake`] (SHAKE's
    /// Newton stopped far from a root, which only happens for absurd h).
    pub constraint_tolerance: f64,
    /// After every step N is evaluated at the new state; the step fails with
    /// [`StepError::NondegeneracyLost`] when max(‖N‖₁, ‖N₀‖₁) · ‖N⁻¹‖₁ exceeds
    /// this (default 1e10), N₀ being N at the start of the run. For m ≥ 2
    /// this bounds the condition number κ₁(N); for m = 1 it says N shrank by
    /// that factor since the start.
    pub max_condition: f64,
    /// SHAKE's Newton iteration starts from λ = 0, and its first iterate λ₁
    /// is the linear prediction of the fibre displacement, of order h. The
    /// converged λ differs from it by O(h)·‖λ₁‖ when the solution is the
    /// nearby one; the step fails with [`StepError::FibreJump`] when
    /// ‖λ − λ₁‖∞ > `jump_ratio` · ‖λ₁‖∞ + 1e-8·|h| (default 1: the
    /// correction is as large as the prediction itself). The projection Π
    /// onto M^H is held to the same test with its σ, wherever a run
    /// projects (every step, or only the stored states): near a fold of
    /// M^H (Section 5.4.2, case iii) it is Π that would otherwise land on
    /// another crossing of the fibre. `f64::INFINITY` turns the check off.
    pub jump_ratio: f64,
    /// Check after every step that det N kept its sign
    /// ([`StepError::ComponentJump`]) (default true).
    pub check_component: bool,
    /// In a RATTLE [`Run`], project onto M^H after every step instead of only
    /// at the states that are stored or observed (default false; both give
    /// the same states to round-off, by Π ∘ S_hᵏ = Π ∘ R_hᵏ).
    pub project_every_step: bool,
}

impl Options {
    /// The fibre-jump test shared by SHAKE's λ and the projection's σ: the
    /// Newton correction beyond the first (linear) iterate must stay below
    /// `jump_ratio` times that prediction (plus 1e-8·|h| so that a step
    /// starting exactly on M^H, where the prediction is 0, passes).
    fn check_jump(
        &self,
        stage: Stage,
        correction: f64,
        predicted: f64,
        found: f64,
        h: f64,
    ) -> Result<(), StepError> {
        if correction > self.jump_ratio * predicted + 1e-8 * h.abs() {
            return Err(StepError::FibreJump {
                stage,
                step: 0,
                t: 0.0,
                lambda: found,
                predicted,
            });
        }
        Ok(())
    }
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
        }
    }
}

/// What one step did.
///
/// ```
/// use shake_runtime::{Integrator, ImplicitMidpoint, State, examples::Pendulum};
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
    /// see [`Options::max_condition`]).
    pub condition: f64,
    /// det N at the new state.
    pub det_n: f64,
}

/// When a run stops.
///
/// ```
/// use shake_runtime::Stop;
/// let a = Stop::Steps(100);
/// let b = Stop::Time(1.0);
/// assert_ne!(a, b);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum Stop {
    /// After this many steps.
    Steps(u64),
    /// At this time (from the run's start time): the run takes
    /// n = (T − t0)/h steps, rounded to the nearest integer when within
    /// 1e-9 of it and up otherwise (the step size never changes).
    Time(f64),
}

/// The result of a run: the trajectory computed so far and, if the run
/// stopped early, why. On an error the last good state is always stored.
///
/// ```
/// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute();
/// let traj = out.into_result().unwrap();
/// assert_eq!(traj.len(), 4);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct RunOutcome {
    /// Everything stored before the run ended.
    pub trajectory: Trajectory,
    /// Why the run ended early, if it did.
    pub error: Option<StepError>,
}

impl RunOutcome {
    /// `Ok(trajectory)` or `Err((partial trajectory, error))`.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.0);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.0, 0.0]), Stop::Steps(3)).execute();
    /// assert!(out.into_result().is_err());
    /// ```
    #[allow(clippy::result_large_err)] // the partial trajectory is the point
    pub fn into_result(self) -> Result<Trajectory, (Trajectory, StepError)> {
        match self.error {
            None => Ok(self.trajectory),
            Some(e) => Err((self.trajectory, e)),
        }
    }
}

/// Geometric SHAKE or RATTLE for a system `S` over a base map `B` with step
/// size h. All buffers are allocated here; a step allocates nothing.
///
/// ```
/// use shake_runtime::{Integrator, ImplicitMidpoint, State, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).rattle();
/// let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
/// let z1 = integ.step(&z0).unwrap();
/// let back = integ.with_step_size(-0.1).step(&z1).unwrap();
/// assert!(back.distance(&z0) < 1e-14); // RATTLE over a symmetric map is symmetric
/// ```
#[derive(Clone, Debug)]
pub struct Integrator<S: ConstrainedSystem, B: BaseMap> {
    system: S,
    base: B,
    h: f64,
    method: Method,
    composition: Composition,
    /// Kahan summation of the state in runs (see `compensated`).
    compensated: bool,
    /// True inside a run (single steps have no carry to keep).
    carrying: bool,
    /// Kahan's carry of the state (2d): minus the bits lost so far.
    carry: Vec<f64>,
    options: Options,
    diagnostics: bool,
    ws: Workspace,
    /// ‖N‖₁ at the start of the run (or step).
    reference_norm: f64,
    /// det N at the previous state.
    det_prev: f64,
    out_q: Vec<f64>,
    out_p: Vec<f64>,
    /// The kick fractions of the base map when the classical path applies
    /// (see `classical`), and whether it is used.
    classical: Option<(f64, f64)>,
    fast_paths: bool,
    /// `ws.jac`/`ws.piv` hold the factors of N at the current state's q
    /// (set by the classical step's check and by `begin`).
    n_fresh: bool,
    /// The last result of `step_in_place`, already checked (with ‖N‖₁
    /// and det N there), so that the next call need not check it again.
    checked: Vec<f64>,
    checked_valid: bool,
    checked_norm: f64,
    checked_det: f64,
    /// ‖N‖₁ at the result of the last substep.
    last_norm: f64,
    /// λ of the first substep of the last composed step (kept only with
    /// diagnostics): the multiplier of the step leaving the state.
    lead_lambda: Vec<f64>,
}

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// An integrator for `system` over the base map `base` with step size
    /// `h` (negative h integrates backwards; h = 0 or non-finite is reported
    /// by the first step as [`StepError::InvalidInput`]). Defaults to RATTLE.
    ///
    /// ```
    /// use shake_runtime::{Integrator, SymplecticEuler, examples::Pendulum};
    /// let integ = Integrator::new(Pendulum::default(), SymplecticEuler, 0.01);
    /// assert_eq!(integ.step_size(), 0.01);
    /// ```
    pub fn new(system: S, base: B, h: f64) -> Self {
        let ws = Workspace::new(&system);
        let classical = crate::classical::classical(&system, &base);
        let (d, m) = (system.dof(), system.constraint_count());
        Integrator {
            system,
            base,
            h,
            method: Method::Rattle,
            composition: Composition::SINGLE,
            compensated: true,
            carrying: false,
            carry: vec![0.0; 2 * d],
            options: Options::default(),
            diagnostics: false,
            ws,
            reference_norm: f64::NAN,
            det_prev: f64::NAN,
            out_q: vec![0.0; d],
            out_p: vec![0.0; d],
            classical,
            fast_paths: true,
            n_fresh: false,
            checked: vec![0.0; 2 * d],
            checked_valid: false,
            checked_norm: f64::NAN,
            checked_det: f64::NAN,
            last_norm: f64::NAN,
            lead_lambda: vec![0.0; m],
        }
    }

    /// Use geometric SHAKE.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake().method(), Method::Shake);
    /// ```
    pub fn shake(mut self) -> Self {
        self.method = Method::Shake;
        self
    }

    /// Use geometric RATTLE (the default).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).rattle().method(), Method::Rattle);
    /// ```
    pub fn rattle(mut self) -> Self {
        self.method = Method::Rattle;
        self
    }

    /// Use the given method.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_method(Method::Shake);
    /// assert_eq!(i.method(), Method::Shake);
    /// ```
    pub fn with_method(mut self, method: Method) -> Self {
        self.method = method;
        self
    }

    /// Take each step as the symmetric composition `c` of RATTLE (or SHAKE)
    /// substeps γ_k h, raising the order to `c.order()` over a symmetric
    /// base map (see [`composition`](crate::composition)).
    ///
    /// ```
    /// use shake_runtime::{Composition, Integrator, ImplicitMidpoint, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).composed(Composition::YOSHIDA_6);
    /// assert_eq!(i.order(), 6);
    /// assert_eq!(i.composition(), Composition::YOSHIDA_6);
    /// ```
    pub fn composed(mut self, c: Composition) -> Self {
        self.composition = c;
        self
    }

    /// Add each step's increment to the state with Kahan's compensated
    /// summation, the increment computed in increment form (see
    /// [`compensated`](crate::compensated)); the carry is reset at the start
    /// of every run. On by default: with it the round-off part of the
    /// energy error grows like √n (Brouwer's law), without it like n — the
    /// stress example measures both (the README has the numbers). A single
    /// [`step`](Self::step) has no carry and takes the plain SHAKE step
    /// either way.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).compensated(false);
    /// assert!(!i.is_compensated());
    /// ```
    pub fn compensated(mut self, on: bool) -> Self {
        self.compensated = on;
        self
    }

    /// Use the fast paths where they apply (default true): the classical
    /// SHAKE/RATTLE step for holonomic constraints, separable H with
    /// quadratic kinetic energy and a kick–drift–kick base map (see
    /// [`BaseMap::kick_drift_kick`]): one equation in the positions with an
    /// analytic Jacobian, a projection by one linear solve, and one
    /// factorisation of N per step for the checks and the projection.
    /// `false` takes the general path everywhere; both give the same steps
    /// to round-off (`tests/fast_paths.rs`).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// let fast = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).step(&z0).unwrap();
    /// let general = Integrator::new(Pendulum::default(), StormerVerlet, 0.01)
    ///     .fast_paths(false)
    ///     .step(&z0)
    ///     .unwrap();
    /// assert!(fast.distance(&general) < 1e-15);
    /// ```
    pub fn fast_paths(mut self, on: bool) -> Self {
        self.fast_paths = on;
        self
    }

    /// Whether runs use compensated summation.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert!(Integrator::new(Pendulum::default(), StormerVerlet, 0.01).is_compensated());
    /// ```
    pub fn is_compensated(&self) -> bool {
        self.compensated
    }

    /// The composition scheme of a step ([`Composition::SINGLE`] unless
    /// [`composed`](Self::composed)).
    ///
    /// ```
    /// use shake_runtime::{Composition, Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).composition(), Composition::SINGLE);
    /// ```
    pub fn composition(&self) -> Composition {
        self.composition
    }

    /// The order of a step as an approximation of the exact flow on M^H:
    /// the base map's order without composition, the composition's order
    /// over a symmetric base map, and the base map's order otherwise (a
    /// composition of a non-symmetric method does not raise its order).
    ///
    /// ```
    /// use shake_runtime::{Composition, Integrator, SymplecticEuler, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).order(), 2);
    /// let euler = Integrator::new(Pendulum::default(), SymplecticEuler, 0.1).composed(Composition::TRIPLE_JUMP);
    /// assert_eq!(euler.order(), 1);
    /// ```
    pub fn order(&self) -> u32 {
        if self.composition.stages() == 1 || !B::SYMMETRIC {
            B::ORDER
        } else {
            self.composition.order()
        }
    }

    /// Replace the options.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Options, examples::Pendulum};
    /// let opts = Options { project_every_step: true, ..Options::default() };
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_options(opts);
    /// assert!(i.options().project_every_step);
    /// ```
    pub fn with_options(mut self, options: Options) -> Self {
        self.options = options;
        self
    }

    /// Record a [`DiagnosticRecord`] with every stored or observed state.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    /// let out = i.run(State::from_slices(&[0.0, -1.0], &[0.3, 0.0]), Stop::Steps(2)).execute();
    /// assert_eq!(out.trajectory.diagnostics.len(), 3);
    /// ```
    pub fn with_diagnostics(mut self) -> Self {
        self.diagnostics = true;
        self
    }

    /// The same integrator with another step size (buffers are kept).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// assert_eq!(i.with_step_size(-0.1).step_size(), -0.1);
    /// ```
    pub fn with_step_size(&mut self, h: f64) -> &mut Self {
        self.h = h;
        self
    }

    /// The step size h.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.25).step_size(), 0.25);
    /// ```
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// SHAKE or RATTLE.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).method(), Method::Rattle);
    /// ```
    pub fn method(&self) -> Method {
        self.method
    }

    /// The options in force.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, Options, examples::Pendulum};
    /// assert_eq!(*Integrator::new(Pendulum::default(), StormerVerlet, 0.1).options(), Options::default());
    /// ```
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// The system.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).system().length, 1.0);
    /// ```
    pub fn system(&self) -> &S {
        &self.system
    }

    /// The base map.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// assert_eq!(*i.base_map(), StormerVerlet);
    /// ```
    pub fn base_map(&self) -> &B {
        &self.base
    }

    /// The multipliers λ of the last SHAKE step: y = exp(Σ λ_i X_{g_i})(z0).
    /// For holonomic g and Störmer–Verlet, λ = (h/2) λ_classical of the
    /// paper's Section 5.1.3.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake();
    /// i.step(&State::from_slices(&[0.0, -1.0], &[0.0, 0.0])).unwrap();
    /// // At rest at the bottom the rod pulls up: p⁺ = p − 2λq with q = (0, −1), so λ > 0.
    /// assert!(i.last_multipliers()[0] > 0.0);
    /// ```
    pub fn last_multipliers(&self) -> &[f64] {
        &self.ws.lambda
    }

    fn check_h(&self) -> Result<(), StepError> {
        if self.h == 0.0 || !self.h.is_finite() {
            return Err(StepError::InvalidInput {
                what: "step size h must be finite and nonzero",
                value: self.h,
            });
        }
        Ok(())
    }

    fn check_dims(&self, z: &State) -> Result<(), StepError> {
        if z.q.len() != self.system.dof() || z.p.len() != self.system.dof() {
            return Err(StepError::InvalidInput {
                what: "state dimension differs from the system's DOF",
                value: z.q.len().max(z.p.len()) as f64,
            });
        }
        Ok(())
    }

    /// Validates a starting state on M and resets the nondegeneracy
    /// tracking (reference ‖N‖ and det N) to it.
    fn begin(&mut self, q: &[f64], p: &[f64], step: u64, t: f64) -> Result<(), StepError> {
        self.check_h()?;
        self.carry.fill(0.0);
        if !q.iter().chain(p).all(|x| x.is_finite()) {
            return Err(StepError::NonFinite {
                what: "initial state",
                step,
                t,
            });
        }
        self.reference_norm = f64::NAN;
        self.det_prev = f64::NAN;
        if self.system.constraint_count() == 0 {
            return Ok(());
        }
        self.system.constraints(q, p, &mut self.ws.g);
        let r = norm_inf(&self.ws.g);
        if !(r <= self.options.constraint_tolerance) {
            return Err(StepError::NotOnConstraint {
                step,
                t,
                residual: r,
                tolerance: self.options.constraint_tolerance,
            });
        }
        let nd = check_nondegeneracy(&self.system, q, p, &mut self.ws);
        let cond = nd.condition(0.0);
        if !(cond <= self.options.max_condition) {
            return Err(StepError::NondegeneracyLost {
                stage: Stage::Shake,
                step,
                t,
                condition: cond,
                limit: self.options.max_condition,
            });
        }
        self.reference_norm = nd.norm;
        self.det_prev = nd.det;
        self.n_fresh = self.classical.is_some();
        Ok(())
    }

    /// One step from (q, p), in place: the substeps γ_k h of the
    /// composition (one substep of size h without one), each a SHAKE step,
    /// projected onto M^H unless it is the last one and `project` is false,
    /// and each checked. `step` is the index of the new state, `t` the time
    /// at the start of the step. Iteration counts are summed over the
    /// substeps, ‖λ‖ and the condition of N are the largest.
    fn advance(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        project: bool,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        let gammas = self.composition.coefficients();
        if gammas.len() == 1 {
            return self.substep(q, p, self.h, project, step, t);
        }
        let last = gammas.len() - 1;
        let mut total = StepInfo::default();
        for (k, &gamma) in gammas.iter().enumerate() {
            let info = self.substep(q, p, gamma * self.h, project || k < last, step, t)?;
            if k == 0 && self.diagnostics {
                self.lead_lambda.copy_from_slice(&self.ws.lambda);
            }
            total.shake_iterations += info.shake_iterations;
            total.base_iterations += info.base_iterations;
            total.rattle_iterations += info.rattle_iterations;
            total.lambda = total.lambda.max(info.lambda);
            total.condition = total.condition.max(info.condition);
            total.det_n = info.det_n;
        }
        Ok(total)
    }

    /// One SHAKE step of size `h` from (q, p), in place, then (if
    /// `project`) Π, then the checks.
    fn substep(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        self.n_fresh = false;
        if let (Some(kdk), true) = (self.classical, self.fast_paths) {
            return self.classical_substep(q, p, h, project, step, t, kdk);
        }
        let opts = self.options;
        // Inside a run the increment is added with Kahan's compensation
        // (its carry is kept across the run's steps).
        let carry = if self.compensated && self.carrying {
            Some(self.carry.as_mut_slice())
        } else {
            None
        };
        let report = shake_step(
            &self.system,
            &self.base,
            h,
            q,
            p,
            &mut self.ws,
            &opts.newton,
            carry,
        )
        .map_err(|e| e.at(step, t))?;
        let mut info = StepInfo {
            shake_iterations: report.iterations,
            base_iterations: report.base_iterations,
            lambda: report.lambda,
            ..StepInfo::default()
        };
        if project {
            let pr = project_hidden(&self.system, q, p, &mut self.ws, &opts.newton)
                .map_err(|e| e.at(step, t))?;
            info.rattle_iterations = pr.iterations;
            opts.check_jump(
                Stage::Rattle,
                pr.correction,
                pr.predicted,
                pr.displacement,
                h,
            )
            .map_err(|e| e.at(step, t))?;
        }
        if !q.iter().chain(p.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFinite {
                what: "state",
                step,
                t,
            });
        }
        if self.system.constraint_count() == 0 {
            return Ok(info);
        }
        // Newton's stopping rule looks at the size of its updates, not at
        // the residual; far outside its basin (absurd h) it can stop on a
        // huge λ with g ≠ 0. Such a state is refused here: a step never
        // returns a point off M. (NaN-propagating maximum.)
        self.system.constraints(q, p, &mut self.ws.g);
        self.guard_shake_result(q, p, &report, &mut info, project, step, t, h)?;
        Ok(info)
    }

    /// The guard after SHAKE, the same on both paths: g(z1) within the
    /// constraint tolerance (Newton stops on its updates, so far outside
    /// its basin it can stop off M), N's condition and the sign of det N
    /// (a component jump), and the size of λ against its linear prediction
    /// (a fibre jump). `self.ws.g` holds g at the new state.
    #[allow(clippy::too_many_arguments)]
    fn guard_shake_result(
        &mut self,
        q: &[f64],
        p: &[f64],
        report: &crate::shake::ShakeReport,
        info: &mut StepInfo,
        project: bool,
        step: u64,
        t: f64,
        h: f64,
    ) -> Result<(), StepError> {
        let opts = &self.options;
        let residual = self.ws.g.iter().fold(0.0f64, |a, x| {
            if x.is_nan() || x.abs() > a {
                x.abs()
            } else {
                a
            }
        });
        if !(residual <= opts.constraint_tolerance) {
            return Err(StepError::NewtonNotConverged {
                stage: Stage::Shake,
                step,
                t,
                source: SolveError::NotConverged {
                    iterations: report.iterations,
                    residual,
                },
            });
        }
        let nd = check_nondegeneracy(&self.system, q, p, &mut self.ws);
        info.condition = nd.condition(self.reference_norm);
        info.det_n = nd.det;
        if !(info.condition <= opts.max_condition) {
            return Err(StepError::NondegeneracyLost {
                stage: if project { Stage::Rattle } else { Stage::Shake },
                step,
                t,
                condition: info.condition,
                limit: opts.max_condition,
            });
        }
        if opts.check_component
            && self.det_prev.is_finite()
            && nd.det.signum() != self.det_prev.signum()
        {
            return Err(StepError::ComponentJump {
                step,
                t,
                det_before: self.det_prev,
                det_after: nd.det,
            });
        }
        self.det_prev = nd.det;
        self.last_norm = nd.norm;
        opts.check_jump(
            Stage::Shake,
            report.lambda_correction,
            report.lambda_predicted,
            report.lambda,
            h,
        )
        .map_err(|e| e.at(step, t))?;
        Ok(())
    }

    /// [`substep`](Self::substep) on the classical path (see `classical`):
    /// SHAKE with its own Newton iteration, then one evaluation and
    /// factorisation of N at the new q for the checks and (if `project`)
    /// for Π, which is one linear solve.
    #[allow(clippy::too_many_arguments)]
    fn classical_substep(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        step: u64,
        t: f64,
        kdk: (f64, f64),
    ) -> Result<StepInfo, StepError> {
        let opts = self.options;
        let carry = if self.compensated && self.carrying {
            Some(self.carry.as_mut_slice())
        } else {
            None
        };
        let report = crate::classical::shake_step(
            &self.system,
            kdk,
            h,
            q,
            p,
            &mut self.ws,
            &opts.newton,
            carry,
        )
        .map_err(|e| e.at(step, t))?;
        let mut info = StepInfo {
            shake_iterations: report.iterations,
            lambda: report.lambda,
            ..StepInfo::default()
        };
        if !q.iter().chain(p.iter()).all(|x| x.is_finite()) {
            return Err(StepError::NonFinite {
                what: "state",
                step,
                t,
            });
        }
        // g at the new state was the last residual of SHAKE's iteration
        // (the state is z0 + Δ, rounded once more by the addition).
        self.guard_shake_result(q, p, &report, &mut info, project, step, t, h)?;
        self.n_fresh = true;
        if project {
            // Linear in σ: one solve, no second root to jump to.
            crate::classical::project(&self.system, q, p, &mut self.ws);
            info.rattle_iterations = 1;
        }
        Ok(info)
    }

    /// One step in place, allocation-free: z ← S_h(z) or R_h(z).
    ///
    /// Like [`step`](Self::step), the checks of nondegeneracy compare the new
    /// state with `z`. On error `z` is left unchanged.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake();
    /// let mut z = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// integ.step_in_place(&mut z).unwrap();
    /// let mut g = [0.0];
    /// integ.system().constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    /// assert!(g[0].abs() < 1e-15);
    /// ```
    pub fn step_in_place(&mut self, z: &mut State) -> Result<StepInfo, StepError> {
        self.check_dims(z)?;
        let d = self.system.dof();
        if self.fast_paths
            && self.checked_valid
            && self.system.constraint_count() > 0
            && z.q.as_slice() == &self.checked[..d]
            && z.p.as_slice() == &self.checked[d..]
        {
            // The result of the last step, checked there (finite, on M,
            // N's condition relative to the step before, which bounds the
            // condition begin() would compute): take its N as this step's
            // reference instead of evaluating and factorising it again.
            self.check_h()?;
            self.reference_norm = self.checked_norm;
            self.det_prev = self.checked_det;
        } else {
            self.checked_valid = false;
            self.begin(z.q.as_slice(), z.p.as_slice(), 0, 0.0)?;
        }
        self.carrying = false;
        self.out_q.copy_from_slice(z.q.as_slice());
        self.out_p.copy_from_slice(z.p.as_slice());
        let mut q = std::mem::take(&mut self.out_q);
        let mut p = std::mem::take(&mut self.out_p);
        let res = self.advance(&mut q, &mut p, self.method == Method::Rattle, 1, 0.0);
        if res.is_ok() {
            z.q.as_mut_slice().copy_from_slice(&q);
            z.p.as_mut_slice().copy_from_slice(&p);
            self.checked[..d].copy_from_slice(&q);
            self.checked[d..].copy_from_slice(&p);
            self.checked_valid = true;
            self.checked_norm = self.last_norm;
            self.checked_det = self.det_prev;
        }
        self.out_q = q;
        self.out_p = p;
        res
    }

    /// One step: S_h(z) for SHAKE (z ∈ M), R_h(z) for RATTLE (z ∈ M^H).
    ///
    /// The input must satisfy ‖g(z)‖ ≤ [`Options::constraint_tolerance`];
    /// errors report step 1 and t = 0.
    ///
    /// ```
    /// use shake_runtime::{Integrator, ImplicitMidpoint, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1);
    /// let z1 = integ.step(&State::from_slices(&[0.6, -0.8], &[0.8, 0.6])).unwrap();
    /// let mut hidden = [0.0];
    /// integ.system().hidden_constraints(z1.q.as_slice(), z1.p.as_slice(), &mut hidden);
    /// assert!(hidden[0].abs() < 1e-14);
    /// ```
    pub fn step(&mut self, z: &State) -> Result<State, StepError> {
        let mut z1 = z.clone();
        self.step_in_place(&mut z1)?;
        Ok(z1)
    }

    /// Π: moves z ∈ M along its fibre onto M^H (RATTLE's projection).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z = integ.project(&State::from_slices(&[0.0, -1.0], &[0.3, 0.4])).unwrap();
    /// assert!((z.p[1]).abs() < 1e-15 && (z.p[0] - 0.3).abs() < 1e-15);
    /// ```
    pub fn project(&mut self, z: &State) -> Result<State, StepError> {
        self.check_dims(z)?;
        if !z.is_finite() {
            return Err(StepError::NonFinite {
                what: "state",
                step: 0,
                t: 0.0,
            });
        }
        let mut out = z.clone();
        project_hidden(
            &self.system,
            out.q.as_mut_slice(),
            out.p.as_mut_slice(),
            &mut self.ws,
            &self.options.newton,
        )?;
        Ok(out)
    }

    /// Initial data: brings a nearby point onto M (Gauss–Newton, orthogonal
    /// to M) and then onto M^H along the fibre (Π). Fails with a typed error
    /// when either Newton iteration fails, when the result is not on M to
    /// [`Options::constraint_tolerance`], or when N is singular there.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z = integ.project_to_hidden(&State::from_slices(&[0.7, -0.75], &[1.0, 0.2])).unwrap();
    /// let (mut g, mut gh) = ([0.0], [0.0]);
    /// integ.system().constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    /// integ.system().hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    /// assert!(g[0].abs() < 1e-15 && gh[0].abs() < 1e-15);
    /// ```
    pub fn project_to_hidden(&mut self, z: &State) -> Result<State, StepError> {
        self.check_dims(z)?;
        if !z.is_finite() {
            return Err(StepError::NonFinite {
                what: "initial state",
                step: 0,
                t: 0.0,
            });
        }
        let mut out = z.clone();
        let (q, p) = (out.q.as_mut_slice(), out.p.as_mut_slice());
        let opts = self.options.newton;
        if let Err(e) = project_constraint(&self.system, q, p, &mut self.ws, &opts) {
            // Whatever stopped Gauss–Newton (a singular g_z g_zᵀ, no
            // convergence), the point could not be brought onto M.
            let _ = e;
            self.system.constraints(q, p, &mut self.ws.g);
            return Err(StepError::NotOnConstraint {
                step: 0,
                t: 0.0,
                residual: norm_inf(&self.ws.g),
                tolerance: self.options.constraint_tolerance,
            });
        }
        project_hidden(&self.system, q, p, &mut self.ws, &opts)?;
        if self.system.constraint_count() > 0 {
            self.system.constraints(q, p, &mut self.ws.g);
            let r = norm_inf(&self.ws.g);
            if !(r <= self.options.constraint_tolerance) {
                return Err(StepError::NotOnConstraint {
                    step: 0,
                    t: 0.0,
                    residual: r,
                    tolerance: self.options.constraint_tolerance,
                });
            }
            let nd = check_nondegeneracy(&self.system, q, p, &mut self.ws);
            if nd.inverse_norm.is_infinite() {
                return Err(StepError::NondegeneracyLost {
                    stage: Stage::Rattle,
                    step: 0,
                    t: 0.0,
                    condition: f64::INFINITY,
                    limit: self.options.max_condition,
                });
            }
        }
        Ok(out)
    }

    /// A run from `z0` until `stop`; configure it with
    /// [`Run::stride`], [`Run::observe`], … and start it with
    /// [`Run::execute`].
    ///
    /// A RATTLE run steps with SHAKE and applies Π only to the states it
    /// stores or observes: since Π ∘ S_hᵏ = Π ∘ R_hᵏ (the paper's equation
    /// after Proposition 4.2; see [`rattle`](crate::rattle)) these are the
    /// RATTLE states, at a fraction of the cost.
    ///
    /// ```
    /// use shake_runtime::{Integrator, ImplicitMidpoint, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.01);
    /// let mut energies = Vec::new();
    /// let out = integ
    ///     .run(State::from_slices(&[0.0, -1.0], &[1.0, 0.0]), Stop::Time(2.0))
    ///     .stride(50)
    ///     .observe(|_step, _t, z| energies.push(0.5 * z.p.norm_squared() + z.q[1]))
    ///     .execute();
    /// assert!(out.error.is_none());
    /// assert_eq!(energies.len(), 5);
    /// assert!(energies.iter().all(|e| (e - energies[0]).abs() < 1e-4));
    /// ```
    pub fn run(&mut self, z0: State, stop: Stop) -> Run<'_, S, B, fn(u64, f64, &State)> {
        Run {
            integ: self,
            z0,
            stop,
            stride: 1,
            store: true,
            t0: 0.0,
            observer: |_, _, _| {},
        }
    }

    /// With diagnostics, after the step leaving the last recorded state:
    /// writes that step's λ (of its first substep) into the record. A
    /// RATTLE run that projects only the states it records stepped from
    /// the SHAKE state z⁻, so its λ also carries the projection's σ (same
    /// fibre, same point: the parameters add); σ is taken off so that the
    /// record's λ is RATTLE's, from the state on M^H.
    fn fill_leaving_lambda(&mut self, traj: &mut Trajectory, per_step: bool) {
        let m = self.system.constraint_count();
        let lead = if self.composition.stages() == 1 {
            &self.ws.lambda
        } else {
            &self.lead_lambda
        };
        let subtract = self.method == Method::Rattle && !per_step;
        if let Some((lambda, sigma)) = traj.last_multipliers_mut() {
            for j in 0..m {
                lambda[j] = lead[j] - if subtract { sigma[j] } else { 0.0 };
            }
        }
    }

    /// Stores (and shows to the observer) the state (q, p) at step k.
    #[allow(clippy::too_many_arguments)]
    fn record<F: FnMut(u64, f64, &State)>(
        &mut self,
        q: &[f64],
        p: &[f64],
        projected: bool,
        k: u64,
        t: f64,
        acc: &mut Accumulator,
        traj: &mut Trajectory,
        store: bool,
        observer: &mut F,
        scratch: &mut State,
    ) -> Result<(), StepError> {
        scratch.q.as_mut_slice().copy_from_slice(q);
        scratch.p.as_mut_slice().copy_from_slice(p);
        let mut rattle_iterations = 0;
        if self.method == Method::Rattle && !projected && self.n_fresh && self.fast_paths {
            // The classical path: N at this q is factorised and checked.
            crate::classical::project(
                &self.system,
                scratch.q.as_slice(),
                scratch.p.as_mut_slice(),
                &mut self.ws,
            );
            rattle_iterations = 1;
        } else if self.method == Method::Rattle && !projected {
            let pr = project_hidden(
                &self.system,
                scratch.q.as_mut_slice(),
                scratch.p.as_mut_slice(),
                &mut self.ws,
                &self.options.newton,
            )
            .map_err(|e| e.at(k, t))?;
            rattle_iterations = pr.iterations;
            // The stored state is the projection of the SHAKE state z⁻ of
            // this step: it must be the nearby crossing of the fibre with
            // M^H, on the component the run is on.
            self.options
                .check_jump(
                    Stage::Rattle,
                    pr.correction,
                    pr.predicted,
                    pr.displacement,
                    self.h,
                )
                .map_err(|e| e.at(k, t))?;
            if self.options.check_component && self.system.constraint_count() > 0 {
                let nd = check_nondegeneracy(
                    &self.system,
                    scratch.q.as_slice(),
                    scratch.p.as_slice(),
                    &mut self.ws,
                );
                if self.det_prev.is_finite() && nd.det.signum() != self.det_prev.signum() {
                    return Err(StepError::ComponentJump {
                        step: k,
                        t,
                        det_before: self.det_prev,
                        det_after: nd.det,
                    });
                }
            }
        }
        if self.diagnostics {
            let (sq, sp) = (scratch.q.as_slice(), scratch.p.as_slice());
            let (mut constraint, mut hidden) = (0.0, 0.0);
            if self.system.constraint_count() > 0 {
                self.system.constraints(sq, sp, &mut self.ws.g);
                self.system.hidden_constraints(sq, sp, &mut self.ws.hidden);
                constraint = norm_inf(&self.ws.g);
                hidden = norm_inf(&self.ws.hidden);
            }
            traj.diagnostics.push(DiagnosticRecord {
                step: k,
                t,
                energy: self.system.hamiltonian(sq, sp),
                constraint,
                hidden_constraint: hidden,
                max_shake_iterations: acc.shake,
                max_base_iterations: acc.base,
                rattle_iterations,
                max_lambda: acc.lambda,
                max_condition: acc.condition,
            });
            // σ: the projection that gave this state, done just now or
            // (projected) by the last substep; λ is known only once the
            // step leaving the state is taken (`execute` fills it in).
            traj.push_multipliers(
                (self.method == Method::Rattle).then_some(self.ws.sigma.as_slice()),
            );
            *acc = Accumulator::default();
        }
        observer(k, t, scratch);
        if store {
            traj.push(k, scratch.q.as_slice(), scratch.p.as_slice());
        }
        Ok(())
    }
}

/// A configured run; see [`Integrator::run`].
///
/// ```
/// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let out = integ
///     .run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(10))
///     .stride(5)
///     .start_time(1.0)
///     .execute();
/// assert_eq!(out.trajectory.times(), vec![1.0, 1.5, 2.0]);
/// ```
#[must_use = "a run does nothing until `execute` is called"]
pub struct Run<'a, S: ConstrainedSystem, B: BaseMap, F> {
    integ: &'a mut Integrator<S, B>,
    z0: State,
    stop: Stop,
    stride: u64,
    store: bool,
    t0: f64,
    observer: F,
}

impl<'a, S: ConstrainedSystem, B: BaseMap, F: FnMut(u64, f64, &State)> Run<'a, S, B, F> {
    /// Store (and observe) every `k`-th state, plus the first and the last
    /// (default 1; 0 is an [`StepError::InvalidInput`]).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(7)).stride(3).execute();
    /// assert_eq!(out.trajectory.steps(), vec![0, 3, 6, 7]);
    /// ```
    pub fn stride(mut self, k: u64) -> Self {
        self.stride = k;
        self
    }

    /// The time of the initial state (default 0).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.5);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Time(3.0)).start_time(2.0).execute();
    /// assert_eq!(out.trajectory.times(), vec![2.0, 2.5, 3.0]);
    /// ```
    pub fn start_time(mut self, t0: f64) -> Self {
        self.t0 = t0;
        self
    }

    /// Whether to keep the states in the returned [`Trajectory`] (default
    /// true); with `false` only the observer sees them.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut n = 0;
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(5))
    ///     .store(false).observe(|_, _, _| n += 1).execute();
    /// assert!(out.trajectory.is_empty());
    /// assert_eq!(n, 6);
    /// ```
    pub fn store(mut self, store: bool) -> Self {
        self.store = store;
        self
    }

    /// Call `observer(step, t, state)` at every stored state (same points as
    /// the stride; the state is projected onto M^H for RATTLE).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut times = Vec::new();
    /// let _ = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(2))
    ///     .observe(|_, t, _| times.push(t)).execute();
    /// assert_eq!(times, vec![0.0, 0.1, 0.2]);
    /// ```
    pub fn observe<G: FnMut(u64, f64, &State)>(self, observer: G) -> Run<'a, S, B, G> {
        Run {
            integ: self.integ,
            z0: self.z0,
            stop: self.stop,
            stride: self.stride,
            store: self.store,
            t0: self.t0,
            observer,
        }
    }

    /// Runs, and returns everything computed, with the error that stopped
    /// the run early if any. On an error the last good state is stored (and
    /// observed) even when it is not on the stride.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let out = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute();
    /// assert!(out.error.is_none());
    /// ```
    pub fn execute(self) -> RunOutcome {
        let Run {
            integ,
            z0,
            stop,
            stride,
            store,
            t0,
            mut observer,
        } = self;
        let mut traj = Trajectory::default();
        let fail = |traj: Trajectory, e: StepError| RunOutcome {
            trajectory: traj,
            error: Some(e),
        };
        if let Err(e) = integ.check_h().and_then(|_| integ.check_dims(&z0)) {
            return fail(traj, e);
        }
        if stride == 0 {
            return fail(
                traj,
                StepError::InvalidInput {
                    what: "stride must be at least 1",
                    value: 0.0,
                },
            );
        }
        let h = integ.h;
        let n = match stop {
            Stop::Steps(n) => n,
            Stop::Time(t_end) => {
                let x = (t_end - t0) / h;
                if !(x >= 0.0) || !x.is_finite() {
                    return fail(
                        traj,
                        StepError::InvalidInput {
                            what: "stop time must lie in the direction of h from the start time",
                            value: t_end,
                        },
                    );
                }
                // Beyond 2^53 steps neither the step count nor the times
                // t0 + k h are exact any more (and the run would not end).
                if x > 9007199254740992.0 {
                    return fail(
                        traj,
                        StepError::InvalidInput {
                            what: "stop time needs more than 2^53 steps of size h",
                            value: x,
                        },
                    );
                }
                if (x - x.round()).abs() <= 1e-9 * x.max(1.0) {
                    x.round() as u64
                } else {
                    x.ceil() as u64
                }
            }
        };
        // Exactly the states the run will store: 0, s, 2s, …, and the last
        // (a failing run may add its last good state: the buffer grows).
        let capacity = if store {
            // (reserved up to 256 MB; a longer run grows the buffer)
            let budget = (1usize << 28) / (16 * integ.system.dof().max(1));
            usize::try_from(n / stride + 1 + u64::from(n % stride != 0))
                .unwrap_or(usize::MAX)
                .min(budget)
        } else {
            0
        };
        traj = Trajectory::new(integ.system.dof(), t0, h, stride, capacity);
        if integ.diagnostics {
            traj.set_constraints(integ.system.constraint_count());
            traj.reserve_multipliers(capacity);
        }
        let mut q: Vec<f64> = z0.q.as_slice().to_vec();
        let mut p: Vec<f64> = z0.p.as_slice().to_vec();
        let mut prev_q = q.clone();
        let mut prev_p = p.clone();
        let mut scratch = z0;
        // SHAKE's difference quotients take their scale from the first state
        // they meet: this run's, not whatever an earlier run on this
        // integrator started from (an ensemble reuses one integrator per
        // thread; a member's result must not depend on its neighbours).
        integ.ws.lambda_scale = 0.0;
        if let Err(e) = integ.begin(&q, &p, 0, t0) {
            return fail(traj, e);
        }
        integ.carrying = true;
        let per_step = integ.method == Method::Rattle && integ.options.project_every_step;
        let mut acc = Accumulator::default();
        // The initial state: projected for RATTLE, as given for SHAKE.
        if per_step {
            if let Err(e) = project_hidden(
                &integ.system,
                &mut q,
                &mut p,
                &mut integ.ws,
                &integ.options.newton,
            ) {
                return fail(traj, e.at(0, t0));
            }
        }
        if let Err(e) = integ.record(
            &q,
            &p,
            per_step,
            0,
            t0,
            &mut acc,
            &mut traj,
            store,
            &mut observer,
            &mut scratch,
        ) {
            return fail(traj, e);
        }
        let mut last_recorded = 0;
        for k in 1..=n {
            let t_prev = t0 + (k - 1) as f64 * h;
            prev_q.copy_from_slice(&q);
            prev_p.copy_from_slice(&p);
            match integ.advance(&mut q, &mut p, per_step, k, t_prev) {
                Ok(info) => {
                    acc.add(&info);
                    if integ.diagnostics && last_recorded == k - 1 {
                        integ.fill_leaving_lambda(&mut traj, per_step);
                    }
                }
                Err(e) => {
                    if last_recorded != k - 1 {
                        // The last good state; if even its projection fails, the
                        // step error is the one to report.
                        let _ = integ.record(
                            &prev_q,
                            &prev_p,
                            per_step,
                            k - 1,
                            t_prev,
                            &mut acc,
                            &mut traj,
                            store,
                            &mut observer,
                            &mut scratch,
                        );
                    }
                    return fail(traj, e);
                }
            }
            if k % stride == 0 || k == n {
                let t = t0 + k as f64 * h;
                if let Err(e) = integ.record(
                    &q,
                    &p,
                    per_step,
                    k,
                    t,
                    &mut acc,
                    &mut traj,
                    store,
                    &mut observer,
                    &mut scratch,
                ) {
                    return fail(traj, e);
                }
                last_recorded = k;
            }
        }
        RunOutcome {
            trajectory: traj,
            error: None,
        }
    }
}
