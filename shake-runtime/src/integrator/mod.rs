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
mod single_step;
mod stepper;

use crate::base_map::BaseMap;
use crate::composition::Composition;
use crate::guard::Guard;
use crate::step::{Composed, StepMap};
use crate::system::ConstrainedSystem;

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
    /// [`StepError::InvalidInput`]: crate::error::StepError::InvalidInput
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
}

#[cfg(test)]
mod tests;
