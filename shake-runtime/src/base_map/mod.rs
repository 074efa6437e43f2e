//! Base maps φ_h: symplectic one-step maps of R^{2d} approximating the
//! unconstrained flow exp(h X_H).
//!
//! SHAKE and RATTLE are built on top of any of them (the paper's Definitions
//! 1.1 and 1.2). Each base map also provides its *tangent map* Dφ_h(y),
//! obtained by linearising its stage equations; SHAKE's Newton matrix needs
//! it (see SHAKE in the crate docs).
//!
//! - [`ImplicitMidpoint`]: z1 = z0 + h X_H((z0 + z1)/2), for any H;
//!   symmetric, order 2.
//! - [`StormerVerlet`]: the form of the paper's Section 5.1.3,
//!   p½ = p0 − (h/2) H_q(q0, p½),
//!   q1 = q0 + (h/2)(H_p(q0, p½) + H_p(q1, p½)),
//!   p1 = p½ − (h/2) H_q(q1, p½);
//!   explicit when H is separable ([`Hamiltonian::separable`]), implicit otherwise;
//!   symmetric, order 2.
//! - [`SymplecticEuler`]: p1 = p0 − h H_q(q0, p1), q1 = q0 + h H_p(q0, p1)
//!   (the paper's Section 5.1.3 variant); explicit when separable; order 1.
//!
//! Implicit stage equations are solved by Newton's method with the Hessian
//! of H, to round-off (see [`newton`](crate::newton)). Within one SHAKE step
//! the base map is applied to a sequence of nearby points; each solve starts
//! from the previous solution shifted by the change of the input point.

mod euler;
mod midpoint;
mod stage;
mod verlet;
mod workspace;

pub use euler::SymplecticEuler;
pub use midpoint::ImplicitMidpoint;
pub use verlet::StormerVerlet;
pub use workspace::BaseMapWorkspace;

use crate::newton::NewtonOptions;
use crate::system::Hamiltonian;
use crate::SolveError;

/// A symplectic map φ_h of R^{2d} approximating exp(h X_H), with its
/// tangent map. Implemented by [`ImplicitMidpoint`], [`StormerVerlet`] and
/// [`SymplecticEuler`], and by anyone: a map written outside this crate
/// brings its own buffers as [`BaseMap::Workspace`] (the crate's
/// `examples/custom_base_map.rs` composes Störmer–Verlet into Yoshida's
/// fourth-order map and runs RATTLE over it).
///
/// ```
/// use geoshake_runtime::{BaseMap, ImplicitMidpoint, NewtonOptions};
/// use geoshake_runtime::examples::HarmonicOscillator;
/// // One midpoint step of q'' = −q conserves the quadratic energy exactly.
/// let sys = HarmonicOscillator;
/// let mut ws = ImplicitMidpoint.workspace(1);
/// let (mut q, mut p) = ([1.0], [0.0]);
/// ImplicitMidpoint.apply(&sys, 0.1, &mut q, &mut p, &mut ws, &NewtonOptions::default()).unwrap();
/// assert!((q[0] * q[0] + p[0] * p[0] - 1.0).abs() < 1e-15);
/// ```
pub trait BaseMap: Copy + Clone + std::fmt::Debug + Send + Sync + 'static {
    /// The buffers of one application and of its tangent map (stage values,
    /// Newton matrices), allocated once by [`workspace`](BaseMap::workspace)
    /// so that a step allocates nothing.
    type Workspace: Clone + std::fmt::Debug + Send + Sync;

    /// A short name for reports ("midpoint", ...).
    const NAME: &'static str;
    /// φ_{−h} = φ_h⁻¹: RATTLE on top of it is symmetric (Section 4).
    const SYMMETRIC: bool;
    /// The order of φ_h as an approximation of exp(h X_H).
    const ORDER: u32;

    /// Buffers for a system with `d` degrees of freedom.
    ///
    /// ```
    /// use geoshake_runtime::{BaseMap, StormerVerlet};
    /// assert_eq!(StormerVerlet.workspace(3).dof(), 3);
    /// ```
    fn workspace(&self, d: usize) -> Self::Workspace;

    /// Forget the stage values of the last application, so that the next
    /// one starts its Newton iteration from an explicit predictor (SHAKE
    /// calls it at the start of each step). The provided version does
    /// nothing (a map without warm starts).
    fn reset_warm_start(&self, ws: &mut Self::Workspace) {
        let _ = ws;
    }

    /// Whether φ_h is explicit for this H (no stage equations to solve):
    /// Störmer–Verlet and symplectic Euler when H is separable. SHAKE then
    /// forms its Jacobian from difference quotients of its cheap residual
    /// (see `shake`). A structural fact, not a count of iterations: an
    /// implicit map whose first guess happens to be exact is still implicit.
    ///
    /// ```
    /// use geoshake_runtime::{BaseMap, ImplicitMidpoint, StormerVerlet, examples::Pendulum};
    /// assert!(StormerVerlet.explicit_for(&Pendulum::default()));
    /// assert!(!ImplicitMidpoint.explicit_for(&Pendulum::default()));
    /// ```
    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        let _ = sys;
        false
    }

    /// For a separable H = T(p) + V(q), this map as a kick–drift–kick
    /// p* = p0 − a h ∇V(q0), q1 = q0 + h ∇T(p*), p1 = p* − b h ∇V(q1):
    /// `Some((a, b))`, or `None` when it is not of that form. SHAKE and
    /// RATTLE then take the classical path for holonomic constraints and a
    /// quadratic T (see `classical`): one equation in the positions, no
    /// base-map or fibre-flow call in its Newton iteration.
    ///
    /// ```
    /// use geoshake_runtime::{BaseMap, ImplicitMidpoint, StormerVerlet, SymplecticEuler};
    /// assert_eq!(StormerVerlet.kick_drift_kick(), Some((0.5, 0.5)));
    /// assert_eq!(SymplecticEuler.kick_drift_kick(), Some((1.0, 0.0)));
    /// assert_eq!(ImplicitMidpoint.kick_drift_kick(), None);
    /// ```
    fn kick_drift_kick(&self) -> Option<(f64, f64)> {
        None
    }

    /// z ← φ_h(z) in place; returns the number of Newton iterations of its
    /// stage equations (0 when explicit).
    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut Self::Workspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError>;

    /// Evaluates and factorises the linearised stage equations at the stage
    /// values of the last [`apply`](BaseMap::apply), so that
    /// [`apply_tangent`](BaseMap::apply_tangent) gives Dφ_h at its input.
    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut Self::Workspace,
    ) -> Result<(), SolveError>;

    /// v ← Dφ_h(y) v for v = (δq, δp) of length 2d, y the input of the last
    /// [`apply`](BaseMap::apply), after [`prepare_tangent`](BaseMap::prepare_tangent).
    fn apply_tangent(&self, h: f64, ws: &mut Self::Workspace, v: &mut [f64]);

    /// The increment (δq, δp) = φ_h(z) − z, without changing z, computed as
    /// a small quantity in its own right (not as a difference of two
    /// rounded states), so that its rounding error is O(ε h) rather than
    /// O(ε |z|): what compensated summation of the state needs (see
    /// [`compensated`](crate::compensated)). Leaves the workspace as
    /// [`apply`](BaseMap::apply) does, so the tangent map is available.
    ///
    /// The provided implementation applies the map to a copy and subtracts
    /// (rounding O(ε|z|)); the midpoint rule and explicit Störmer–Verlet
    /// override it with increment forms of their stage equations.
    ///
    /// ```
    /// use geoshake_runtime::{BaseMap, ImplicitMidpoint, NewtonOptions};
    /// use geoshake_runtime::examples::HarmonicOscillator;
    /// let mut ws = ImplicitMidpoint.workspace(1);
    /// let (mut dq, mut dp) = ([0.0], [0.0]);
    /// ImplicitMidpoint
    ///     .increment(&HarmonicOscillator, 1e-3, &[1.0], &[0.0], &mut dq, &mut dp, &mut ws, &NewtonOptions::default())
    ///     .unwrap();
    /// // q1 − q0 = −h²/2 /(1 + h²/4) for the midpoint rule on q'' = −q.
    /// assert!((dq[0] + 0.5e-6 / (1.0 + 0.25e-6)).abs() < 1e-21);
    /// ```
    #[allow(clippy::too_many_arguments)]
    fn increment<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
        ws: &mut Self::Workspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        dq.copy_from_slice(q);
        dp.copy_from_slice(p);
        let it = self.apply(sys, h, dq, dp, ws, opts)?;
        for (d, x) in dq.iter_mut().zip(q) {
            *d -= x;
        }
        for (d, x) in dp.iter_mut().zip(p) {
            *d -= x;
        }
        Ok(it)
    }
}
