//! The facade: [`Integrator`], built from a system, a base map and h, with
//! the public API of single steps, projections and runs.
//!
//! The work is done in three layers, each a module that reads alone:
//! [`step`](crate::step) (the maps SHAKE, RATTLE and their compositions),
//! [`guard`](crate::guard) (every check of a step, configured by
//! [`Options`]) and [`run`](crate::run) (the driver: stop rules, stride,
//! storage, diagnostics, observers). The projections of initial data are
//! in `initial_data` (onto M, and Π onto M^H) and `keep_positions`.
//!
//! ```
//! use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
//! let mut rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).rattle();
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[0.6, -0.8], &[0.8, 0.6])).unwrap();
//! let out = rattle.run(z0, Stop::Time(1.0)).stride(10).execute();
//! assert!(out.error.is_none());
//! assert_eq!(out.trajectory.len(), 11);
//! ```

mod record;
mod stepper;

use crate::base_map::BaseMap;
use crate::composition::Composition;
use crate::error::StepError;
use crate::guard::Guard;
use crate::state::State;
use crate::step::{Composed, StepMap, Within};
use crate::system::ConstrainedSystem;
use crate::validate;

pub use crate::guard::Options;
pub use crate::report::{RunSummary, StepInfo};
pub use crate::run::{Run, RunOutcome, StepEvent, StepObserver, Stop};
pub use crate::step::Method;
pub use crate::trajectory::Trajectory;

/// Geometric SHAKE or RATTLE for a system `S` over a base map `B` with step
/// size h. All buffers are allocated here, except the second workspace of
/// a composed step's reverse check ([`Options::reverse_tolerance`]), made
/// when the first composed run or step begins (it doubles the workspace's
/// memory); a step allocates nothing.
///
/// ```
/// use geoshake_runtime::{Integrator, ImplicitMidpoint, State, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).rattle();
/// let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
/// let z1 = integ.step(&z0).unwrap();
/// let back = integ.with_step_size(-0.1).step(&z1).unwrap();
/// assert!(back.distance(&z0) < 1e-14); // RATTLE over a symmetric map is symmetric
/// ```
#[derive(Clone, Debug)]
pub struct Integrator<S: ConstrainedSystem, B: BaseMap> {
    pub(crate) system: S,
    pub(crate) h: f64,
    pub(crate) method: Method,
    /// Kahan summation of the state in runs (see `compensated`).
    pub(crate) compensated: bool,
    /// True inside a run (single steps have no carry to keep).
    pub(crate) carrying: bool,
    /// Kahan's carry of the state (2d): minus the bits lost so far.
    pub(crate) carry: Vec<f64>,
    /// Every check of a step, with its limits ([`Options`]).
    pub(crate) guard: Guard,
    pub(crate) diagnostics: bool,
    /// The step map: the composition of substeps (SHAKE, then Π if asked)
    /// over the base map, with its workspaces and its reverse check.
    pub(crate) steps: Composed<B>,
    pub(crate) out_q: Vec<f64>,
    pub(crate) out_p: Vec<f64>,
    /// The last result of `step_in_place`, already checked (with ‖N‖₁
    /// and det N there), so that the next call need not check it again.
    pub(crate) checked: Vec<f64>,
    pub(crate) checked_valid: bool,
    pub(crate) checked_norm: f64,
    pub(crate) checked_det: f64,
    /// The step size `check_h` accepted with the current options (NaN:
    /// none), so that a step from a checked state validates them only when
    /// they changed.
    pub(crate) valid_h: f64,
}

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// An integrator for `system` over the base map `base` with step size
    /// `h` (negative h integrates backwards; h = 0 or non-finite is reported
    /// by the first step as [`StepError::InvalidInput`]). Defaults to RATTLE.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, SymplecticEuler, examples::Pendulum};
    /// let integ = Integrator::new(Pendulum::default(), SymplecticEuler, 0.01);
    /// assert_eq!(integ.step_size(), 0.01);
    /// ```
    pub fn new(system: S, base: B, h: f64) -> Self {
        let (d, m) = (system.dof(), system.constraint_count());
        let steps = Composed::new(StepMap::new(&system, base), m);
        Integrator {
            system,
            h,
            method: Method::Rattle,
            compensated: true,
            carrying: false,
            carry: vec![0.0; 2 * d],
            guard: Guard::new(Options::default()),
            diagnostics: false,
            steps,
            out_q: vec![0.0; d],
            out_p: vec![0.0; d],
            checked: vec![0.0; 2 * d],
            checked_valid: false,
            checked_norm: f64::NAN,
            checked_det: f64::NAN,
            valid_h: f64::NAN,
        }
    }

    /// Use geometric SHAKE.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake().method(), Method::Shake);
    /// ```
    pub fn shake(mut self) -> Self {
        self.method = Method::Shake;
        self
    }

    /// Use geometric RATTLE (the default).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).rattle().method(), Method::Rattle);
    /// ```
    pub fn rattle(mut self) -> Self {
        self.method = Method::Rattle;
        self
    }

    /// Use the given method.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
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
    /// use geoshake_runtime::{Composition, Integrator, ImplicitMidpoint, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).composed(Composition::YOSHIDA_6);
    /// assert_eq!(i.order(), 6);
    /// assert_eq!(i.composition(), Composition::YOSHIDA_6);
    /// ```
    pub fn composed(mut self, c: Composition) -> Self {
        self.steps.composition = c;
        self
    }

    /// Add each step's increment to the state with Kahan's compensated
    /// summation, the increment computed in increment form (see
    /// [`compensated`](crate::compensated)); the carry is reset at the start
    /// of every run. On by default: with it the round-off part of the
    /// energy error grows like √n (Brouwer's law), without it like n — the
    /// stress example measures both (docs/guide/beyond.md has the numbers). A single
    /// [`step`](Self::step) has no carry and takes the plain SHAKE step
    /// either way.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
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
    /// to round-off (`tests/suite/fast_paths.rs`).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// let fast = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).step(&z0).unwrap();
    /// let general = Integrator::new(Pendulum::default(), StormerVerlet, 0.01)
    ///     .fast_paths(false)
    ///     .step(&z0)
    ///     .unwrap();
    /// assert!(fast.distance(&general) < 1e-15);
    /// ```
    pub fn fast_paths(mut self, on: bool) -> Self {
        self.steps.map.fast_paths = on;
        self
    }

    /// On the classical fast path, use the system's fixed-size step when it
    /// has one (default true): `constrained_system!` gives one to systems
    /// of one to eight constraints, which then step on stack arrays of
    /// their own size (with N a number for one constraint). `false` keeps
    /// the classical path on the workspace's vectors; both give the same
    /// steps to round-off, and to the bit for two to eight constraints
    /// (`tests/suite/fast_paths.rs`).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// let fixed = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).step(&z0).unwrap();
    /// let slices = Integrator::new(Pendulum::default(), StormerVerlet, 0.01)
    ///     .fixed_size(false)
    ///     .step(&z0)
    ///     .unwrap();
    /// assert!(fixed.distance(&slices) < 1e-15);
    /// ```
    pub fn fixed_size(mut self, on: bool) -> Self {
        self.steps.map.fixed_size = on;
        self
    }

    /// Whether runs use compensated summation.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert!(Integrator::new(Pendulum::default(), StormerVerlet, 0.01).is_compensated());
    /// ```
    pub fn is_compensated(&self) -> bool {
        self.compensated
    }

    /// The composition scheme of a step ([`Composition::SINGLE`] unless
    /// [`composed`](Self::composed)).
    ///
    /// ```
    /// use geoshake_runtime::{Composition, Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).composition(), Composition::SINGLE);
    /// ```
    pub fn composition(&self) -> Composition {
        self.steps.composition
    }

    /// The order of a step as an approximation of the exact flow on M^H:
    /// the base map's order without composition (at most 2 with
    /// constraints), the composition's order
    /// over a symmetric base map, and the base map's order otherwise (a
    /// composition of a non-symmetric method does not raise its order).
    ///
    /// ```
    /// use geoshake_runtime::{Composition, Integrator, SymplecticEuler, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).order(), 2);
    /// let euler = Integrator::new(Pendulum::default(), SymplecticEuler, 0.1).composed(Composition::TRIPLE_JUMP);
    /// assert_eq!(euler.order(), 1);
    /// ```
    pub fn order(&self) -> u32 {
        // With constraints, the step along the fibre (λ, σ) is of order 2
        // whatever φ_h: RATTLE over a base map of order 4 has order 2, with
        // the error constant of RATTLE over Störmer–Verlet
        // (examples/custom_base_map.rs measures it). Composition is the way
        // to a higher order on M^H.
        let single = if self.system.constraint_count() == 0 {
            B::ORDER
        } else {
            B::ORDER.min(2)
        };
        if self.steps.composition.stages() == 1 || !B::SYMMETRIC {
            single
        } else {
            self.steps.composition.order()
        }
    }

    /// Replace the options.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Options, examples::Pendulum};
    /// let opts = Options { project_every_step: true, ..Options::default() };
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_options(opts);
    /// assert!(i.options().project_every_step);
    /// ```
    pub fn with_options(mut self, options: Options) -> Self {
        self.guard.options = options;
        self.valid_h = f64::NAN;
        self
    }

    /// Record a [`DiagnosticRecord`](crate::DiagnosticRecord) with every stored or observed state.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
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
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
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
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.25).step_size(), 0.25);
    /// ```
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// SHAKE or RATTLE.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Method, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).method(), Method::Rattle);
    /// ```
    pub fn method(&self) -> Method {
        self.method
    }

    /// The options in force.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Options, examples::Pendulum};
    /// assert_eq!(*Integrator::new(Pendulum::default(), StormerVerlet, 0.1).options(), Options::default());
    /// ```
    pub fn options(&self) -> &Options {
        &self.guard.options
    }

    /// The system.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// assert_eq!(Integrator::new(Pendulum::default(), StormerVerlet, 0.1).system().length, 1.0);
    /// ```
    pub fn system(&self) -> &S {
        &self.system
    }

    /// The base map.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, examples::Pendulum};
    /// let i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// assert_eq!(*i.base_map(), StormerVerlet);
    /// ```
    pub fn base_map(&self) -> &B {
        &self.steps.map.base
    }

    /// The multipliers λ of the last SHAKE step: y = exp(Σ λ_i X_{g_i})(z0).
    /// For holonomic g and Störmer–Verlet, λ = (h/2) λ_classical of the
    /// paper's Section 5.1.3.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake();
    /// i.step(&State::from_slices(&[0.0, -1.0], &[0.0, 0.0])).unwrap();
    /// // At rest at the bottom the rod pulls up: p⁺ = p − 2λq with q = (0, −1), so λ > 0.
    /// assert!(i.last_multipliers()[0] > 0.0);
    /// ```
    pub fn last_multipliers(&self) -> &[f64] {
        &self.steps.map.ws.lambda
    }
    /// The bands (lower, upper) that SHAKE's Jacobian and N are factorised
    /// in, for tests (a chain's are (1, 1); a full band is (m − 1, m − 1)).
    #[doc(hidden)]
    pub fn newton_bands(&self) -> [(usize, usize); 2] {
        let ws = &self.steps.map.ws;
        [
            (ws.jac_band.lower, ws.jac_band.upper),
            (ws.n.band.lower, ws.n.band.upper),
        ]
    }

    pub(crate) fn check_h(&self) -> Result<(), StepError> {
        validate::step_size(self.h)?;
        validate::options(&self.guard.options)
    }

    pub(crate) fn check_dims(&self, z: &State) -> Result<(), StepError> {
        if z.q.len() != self.system.dof() || z.p.len() != self.system.dof() {
            return Err(StepError::InvalidInput {
                what: "state dimension differs from the system's DOF",
                value: z.q.len().max(z.p.len()) as f64,
            });
        }
        Ok(())
    }

    /// Validates a starting state (finite, on M, N well conditioned) and
    /// resets the guard's reference ‖N‖ and det N and the Kahan carry to it.
    pub(crate) fn begin(
        &mut self,
        q: &[f64],
        p: &[f64],
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        self.check_h()?;
        self.carry.fill(0.0);
        // The guard and N's buffers now describe this state: a later
        // single step from the state `step_in_place` returned before must
        // start afresh, not resume from them.
        self.checked_valid = false;
        // No Π of an earlier state may be shown for this one.
        (self.steps.map.show, self.steps.map.shown_fresh) = (false, false);
        self.guard
            .start(&self.system, q, p, &mut self.steps.map.ws, step, t)?;
        if self.system.constraint_count() > 0 {
            // `start` factorised N at this q (the classical path reuses it).
            self.steps.map.n_fresh = self.steps.map.classical.is_some();
        }
        if self.steps.reverse_checked(&self.system, &self.guard) {
            self.steps.reverse_buffers(&self.system);
        }
        Ok(())
    }

    /// One step in place, allocation-free: z ← S_h(z) or R_h(z).
    ///
    /// Like [`step`](Self::step), the checks of nondegeneracy compare the new
    /// state with `z`. On error `z` is left unchanged.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake();
    /// let mut z = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// integ.step_in_place(&mut z).unwrap();
    /// let mut g = [0.0];
    /// integ.system().constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    /// assert!(g[0].abs() < 1e-15);
    /// ```
    pub fn step_in_place(&mut self, z: &mut State) -> Result<StepInfo, StepError> {
        self.step_in_place_projecting(z, self.method == Method::Rattle)
    }

    /// [`step_in_place`](Self::step_in_place), with Π (R_h) or without
    /// (S_h).
    fn step_in_place_projecting(
        &mut self,
        z: &mut State,
        project: bool,
    ) -> Result<StepInfo, StepError> {
        self.check_dims(z)?;
        let d = self.system.dof();
        if self.steps.map.fast_paths
            && self.checked_valid
            && self.system.constraint_count() > 0
            && z.q.as_slice() == &self.checked[..d]
            && z.p.as_slice() == &self.checked[d..]
        {
            // The result of the last step, checked there (finite, on M,
            // N's condition relative to the step before, which bounds the
            // condition begin() would compute): take its N as this step's
            // reference instead of evaluating and factorising it again.
            // h and the options, validated once for as long as they stay.
            if self.valid_h != self.h {
                self.check_h()?;
                self.valid_h = self.h;
            }
            self.guard.resume(self.checked_norm, self.checked_det);
        } else {
            self.checked_valid = false;
            self.begin(z.q.as_slice(), z.p.as_slice(), 0, 0.0)?;
        }
        self.carrying = false;
        // One substep a step: the fixed-size classical step straight on
        // z's numbers, the same substep `advance` reaches through the
        // step's layers (`tests/suite/run_lane.rs` compares the two).
        if self.steps.composition.stages() == 1 {
            let map = &mut self.steps.map;
            let fast = crate::run::lane::single(
                map,
                &self.system,
                &mut self.guard,
                z,
                &mut self.checked,
                self.h,
                project,
            );
            if let Some(res) = fast {
                self.checked_valid = res.is_ok();
                if res.is_ok() {
                    (self.checked_norm, self.checked_det) = self.guard.last();
                }
                return res;
            }
        }
        self.out_q.copy_from_slice(z.q.as_slice());
        self.out_p.copy_from_slice(z.p.as_slice());
        let mut q = std::mem::take(&mut self.out_q);
        let mut p = std::mem::take(&mut self.out_p);
        let res = self.advance(&mut q, &mut p, project, 1, self.h);
        if res.is_ok() {
            z.q.as_mut_slice().copy_from_slice(&q);
            z.p.as_mut_slice().copy_from_slice(&p);
            self.checked[..d].copy_from_slice(&q);
            self.checked[d..].copy_from_slice(&p);
            self.checked_valid = true;
            (self.checked_norm, self.checked_det) = self.guard.last();
        } else {
            // The guard now describes the refused state: a retry from z
            // must start afresh (`begin`), not resume from it.
            self.checked_valid = false;
        }
        self.out_q = q;
        self.out_p = p;
        res
    }

    /// Takes over `other`'s record of the last state its `step_in_place`
    /// returned and checked (finite, on M, ‖N‖₁ and det N there), so that
    /// a `step_in_place` of this integrator from that state resumes instead
    /// of checking it and factorising N again. For two integrators of one
    /// system and options that differ in h alone (the sampler's steps
    /// forward and back): N = {{H,g_i},g_j} does not depend on h.
    pub(crate) fn adopt_checked(&mut self, other: &Self) {
        self.checked.copy_from_slice(&other.checked);
        self.checked_valid = other.checked_valid;
        (self.checked_norm, self.checked_det) = (other.checked_norm, other.checked_det);
        // Π of this integrator's own last state is not Π of that one.
        (self.steps.map.show, self.steps.map.shown_fresh) = (false, false);
    }

    /// S_h(z) in place, whatever this integrator's method: for RATTLE the
    /// step without its Π, with every check of the new state that R_h
    /// makes (its solve, on M, N's condition, fibre and component jumps),
    /// so it fails exactly where R_h(z) would. For a caller that reads only
    /// the new positions, which S_h and R_h share (the sampler's step
    /// back, which must return to the start of the step it checks). On
    /// error z is left unchanged.
    pub(crate) fn shake_in_place(&mut self, z: &mut State) -> Result<(), StepError> {
        let res = self.step_in_place_projecting(z, false).map(|_| ());
        // z is S_h(z), off M^H for RATTLE: no step resumes from it.
        self.checked_valid = false;
        res
    }

    /// One step: S_h(z) for SHAKE (z ∈ M), R_h(z) for RATTLE (z ∈ M^H).
    ///
    /// The input must lie on M to [`Options::constraint_tolerance`] (relative to g's scale);
    /// errors report step 1 and t = h (the step from t0 = 0).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, ImplicitMidpoint, State, ConstrainedSystem, examples::Pendulum};
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
}

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// One step from (q, p), in place (the step map's `Composed::advance`), with this
    /// integrator's system, guard, h, and (inside a run) Kahan carry.
    /// `step` is the index of the new state, `t` the time t0 + k·h of the
    /// state it computes.
    pub(crate) fn advance(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        project: bool,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        let at = Within {
            carry: (self.compensated && self.carrying).then_some(self.carry.as_mut_slice()),
            in_run: self.carrying,
            diagnostics: self.diagnostics,
            step,
            t,
        };
        self.steps
            .advance(&self.system, &mut self.guard, self.h, q, p, project, at)
    }
}

#[cfg(test)]
mod tests {
    use crate::examples::Pendulum;
    use crate::{ConstrainedSystem, Integrator, State, StormerVerlet};

    /// `shake_in_place` (the sampler's step back) is S_h: R_h's positions
    /// bit for bit, its momenta before Π (off M^H), on each path the step
    /// can take; and it fails where R_h fails, leaving z as it was.
    #[test]
    fn shake_in_place_has_the_positions_of_the_rattle_step() {
        for (fast, fixed) in [(true, true), (true, false), (false, true)] {
            let make = |h: f64| {
                Integrator::new(Pendulum::default(), StormerVerlet, h)
                    .fast_paths(fast)
                    .fixed_size(fixed)
                    .rattle()
            };
            let (mut r, mut s) = (make(0.1), make(0.1));
            let mut z = r
                .project_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.0, 1.0]))
                .unwrap();
            for _ in 0..50 {
                let zr = r.step(&z).unwrap();
                let mut zs = z.clone();
                s.shake_in_place(&mut zs).unwrap();
                assert_eq!(zs.q, zr.q, "fast {fast}, fixed {fixed}");
                let mut gh = [0.0];
                r.system()
                    .hidden_constraints(zs.q.as_slice(), zs.p.as_slice(), &mut gh);
                assert!(gh[0].abs() > 1e-6, "Π was applied: {gh:?}");
                z = zr;
            }
            // h|p| ≈ 100 times the rod: no solution near the start.
            let (mut r, mut s) = (make(50.0), make(50.0));
            let z = r
                .project_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.6, 1.2]))
                .unwrap();
            let e = r.step(&z).unwrap_err();
            let mut zs = z.clone();
            let es = s.shake_in_place(&mut zs).unwrap_err();
            assert_eq!(std::mem::discriminant(&e), std::mem::discriminant(&es));
            assert_eq!(zs, z);
        }
    }
}
