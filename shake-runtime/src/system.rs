//! The traits that a declared system implements.
//!
//! `constrained_system!` emits an impl of [`Hamiltonian`] and of
//! [`ConstrainedSystem`] for the struct it declares; hand-written systems (the
//! benchmarks' baselines, the tests' reference models) implement the same
//! traits. The split follows capability: a base map φ_h needs only
//! [`Hamiltonian`]; SHAKE and RATTLE need [`ConstrainedSystem`].
//!
//! # Conventions (MISSION.md, the paper's Example 1.1)
//!
//! - Phase space R^{2d}, z = (q, p), symplectic form ω = Σ dq_k ∧ dp_k.
//! - Hamiltonian vector field X_F = (∂F/∂p, −∂F/∂q).
//! - Poisson bracket {F,G} = Σ_k (∂F/∂q_k ∂G/∂p_k − ∂F/∂p_k ∂G/∂q_k), so that
//!   dF·X_G = {F,G} and dF/dt = {F,H} along the flow of H.
//! - Constraints g: R^{2d} → R^m, M = {g = 0}; hidden constraints {g_i, H} = 0
//!   define M^H; N_ij = {{H,g_i},g_j} must be invertible on M^H.
//!
//! # Storage
//!
//! Every output is a flat `&mut [f64]`. Matrices are **column-major**, as in
//! nalgebra, so a `DMatrix::as_mut_slice()` can be passed directly: entry
//! (i, j) of an r×c matrix is `out[i + j*r]`. Gradients and Jacobians with
//! respect to z = (q, p) put the q-columns first: column k < d is ∂/∂q_k,
//! column d + k is ∂/∂p_k.
//!
//! Generated code writes only the entries that are not identically zero
//! (the *sparsity pattern*); the caller zeroes each output buffer once when it
//! allocates it and never writes into it otherwise. This is what lets a
//! structurally zero block (g_p of a holonomic constraint, H_qp of a separable
//! H) cost nothing at run time.
//!
//! Slices of the wrong length are a programming error, not a numerical
//! failure: implementations may panic on them.

/// How the constraint functions depend on the state. This decides how the
/// fibre flow exp(Σ λ_i X_{g_i}) is computed (see the `fibre` module).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum ConstraintKind {
    /// m = 0: a plain Hamiltonian system, no fibres.
    None,
    /// g = g(q) (Section 5.1): the fibre flow is the momentum kick
    /// p ↦ p − g_q(q)ᵀλ, exact in closed form. Takes precedence over
    /// [`ConstraintKind::Quadratic`] when both hold (the pendulum).
    Holonomic,
    /// Every g_i is a polynomial of degree ≤ 2 in z = (q, p) (the Hopf
    /// constraint of Section 5.4): the fibre flow is the flow of a linear
    /// (affine) vector field, computed as a matrix exponential.
    Quadratic,
    /// Anything else: the fibre flow is integrated numerically to round-off
    /// (the paper's Discussion).
    General,
}

impl ConstraintKind {
    /// True when no constraint depends on the momenta (or there is none).
    pub const fn is_holonomic(self) -> bool {
        matches!(self, ConstraintKind::None | ConstraintKind::Holonomic)
    }
}

/// What [`ConstrainedSystem::fibre_flow`] did.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
#[must_use]
pub enum ClosedForm {
    /// exp(Σ λ_i X_{g_i}) was applied to (q, p) in closed form.
    Applied,
    /// The system has no closed form; q and p are untouched and the caller
    /// integrates the fibre flow itself.
    Unavailable,
}

impl ClosedForm {
    /// True when the flow was applied.
    pub const fn applied(self) -> bool {
        matches!(self, ClosedForm::Applied)
    }
}

/// A Hamiltonian H(q, p) on R^{2d} and its derivatives.
///
/// This is all a base map φ_h needs.
pub trait Hamiltonian {
    /// The number d of degrees of freedom: q and p are in R^d.
    ///
    /// A method, not a constant, so that a system whose size is only known
    /// at run time (declared from a string, read from a file) implements the
    /// trait too; the runtime reads it once when it builds its workspaces.
    fn dof(&self) -> usize;

    /// H = T(p) + V(q): H_qp ≡ 0, H_q depends on q only and H_p on p only,
    /// which makes Störmer–Verlet and symplectic Euler explicit.
    fn separable(&self) -> bool;

    /// H = ½ pᵀ A p + V(q) with a constant matrix A (T quadratic in p, with
    /// coefficients independent of q): H_pp is constant, so `grad_p` is the
    /// linear map v ↦ A v. The classical SHAKE path (`classical`) relies on
    /// it; `false` (the default) is always safe and selects the general path.
    fn quadratic_kinetic(&self) -> bool {
        false
    }

    /// The declared name of z_k, the k-th entry of z = (q, p) (k < 2d):
    /// `theta`, `p_theta` for `coordinates theta; momenta p_theta;`, or
    /// `q[3]`, `p[3]` for `dof q[d], p[d];`. Exports name their columns
    /// with it ([`Trajectory::write_csv`](crate::Trajectory::write_csv)).
    /// The default numbers them `q[k]` and `p[k−d]`.
    ///
    /// ```
    /// use geoshake_runtime::{Hamiltonian, examples::Pendulum};
    /// let pendulum = Pendulum::default();
    /// assert_eq!(pendulum.variable_name(0), "q[0]");
    /// assert_eq!(pendulum.variable_name(3), "p[1]");
    /// ```
    fn variable_name(&self, k: usize) -> std::borrow::Cow<'_, str> {
        let d = self.dof();
        if k < d {
            format!("q[{k}]").into()
        } else {
            format!("p[{}]", k - d).into()
        }
    }

    /// H(q, p).
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64;

    /// ∂H/∂q, written into `h_q` (length d).
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]);

    /// ∂H/∂p, written into `h_p` (length d).
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]);

    /// Both halves of ∇H at once; generated code shares their common
    /// subexpressions.
    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        self.grad_q(q, p, h_q);
        self.grad_p(q, p, h_p);
    }

    /// The Hessian H_zz (2d × 2d, column-major, z = (q, p)); only its
    /// structurally nonzero entries are written.
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]);
}

/// A Hamiltonian with constraints g_1, ..., g_m (m = [`Self::constraint_count`]).
///
/// Everything SHAKE and RATTLE need: the constraints and their Jacobian, the
/// hidden constraints {g_i, H} and their Jacobian, the nondegeneracy matrix
/// N_ij = {{H,g_i},g_j}, the λ-weighted Hessian Σ λ_i ∇²g_i, and (where one
/// exists in closed form) the fibre flow.
pub trait ConstrainedSystem: Hamiltonian {
    /// The number m of constraints.
    fn constraint_count(&self) -> usize;

    /// How g depends on z; picks the fibre flow.
    fn kind(&self) -> ConstraintKind;

    /// Whether every g_i is a polynomial of degree at most 2 in z (a
    /// distance constraint |q_a − q_b|² − ℓ²): then Σ λ_i ∇²g_i is
    /// constant, and for holonomic g and a quadratic T SHAKE's residual
    /// along its line is exactly quadratic in λ, which the classical step
    /// of one constraint solves in closed form (`classical`).
    /// `constrained_system!` and the run-time declarations decide it from
    /// the expressions. `false` (the default) is always safe; `true` is
    /// read only where g's Hessian, evaluated at two points, agrees. A
    /// wrapper that changes g must not forward `true` for a g that is not.
    fn quadratic_constraints(&self) -> bool {
        false
    }

    /// Whether each evaluation runs an interpreter over the system's
    /// expressions (a declaration read at run time, `geoshake::declared`)
    /// rather than compiled code. A cost hint: kernels then reuse values
    /// they already hold where compiled code would be as cheap to call
    /// again (classical SHAKE forms its kick −G0ᵀλ from the G0 it keeps,
    /// not by the closed-form fibre flow, which evaluates G0 anew). Results
    /// agree to round-off either way. A wrapper forwards its inner system's.
    fn interpreted(&self) -> bool {
        false
    }

    /// The structurally nonzero entries (i, k) of g_z (m × 2d), k < d for
    /// ∂g_i/∂q_k and k ≥ d for ∂g_i/∂p_{k−d}, sorted by i then k. Banded
    /// patterns (chains) let the runtime pick a structured solve.
    fn jacobian_pattern(&self) -> &[(usize, usize)];

    /// The declared name of constraint i (0 ≤ i < m), for error messages
    /// and diagnostics: an error caused by one constraint names it.
    fn constraint_name(&self, i: usize) -> &str;

    /// g(q, p), written into `g` (length m).
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]);

    /// g_z = [g_q  g_p] (m × 2d, column-major); only entries of
    /// [`Self::jacobian_pattern`] are written.
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]);

    /// The entries of g_z at the positions of
    /// [`Self::jacobian_pattern`], in its order, packed into `values` (one
    /// per entry of the pattern): the numbers
    /// [`Self::constraint_jacobian`] writes, to the bit. Returns `false`
    /// (the default), leaving `values` untouched, when the system does not
    /// provide them or `values` does not have the pattern's length; the
    /// runtime then reads them out of `constraint_jacobian`.
    /// `constrained_system!` and the run-time declarations
    /// (`geoshake::declared`) provide them. They
    /// matter for long chains: the nonzeros of the dense m × 2d g_z lie a
    /// column (8m bytes) apart, so writing and reading them touches a
    /// cache line each, in buffers that outgrow the caches from a few
    /// hundred constraints on. A wrapper that changes `constraint_jacobian`,
    /// `jacobian_pattern` or `constraint_count` must not forward this (the
    /// packed values would no longer match the pattern the runtime reads
    /// them by).
    fn constraint_jacobian_values(&self, q: &[f64], p: &[f64], values: &mut [f64]) -> bool {
        let _ = (q, p, values);
        false
    }

    /// Σ_i λ_i ∇²g_i (2d × 2d, column-major): the derivative of the fibre
    /// vector field Σ λ_i X_{g_i}, needed for tangent maps and for the
    /// numerical fibre flow. Only structurally nonzero entries are written.
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]);

    /// The hidden constraints {g_i, H} (length m); M^H is where they and g
    /// vanish.
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]);

    /// The Jacobian of z ↦ {g_i, H}(z) (m × 2d, column-major).
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]);

    /// N_ij = {{H, g_i}, g_j} (m × m, column-major). The nondegeneracy
    /// assumption of the paper (Assumption 1.1, in the form of Example 1.2)
    /// is that N is invertible on M^H. Note d/dσ_j {g_i,H}(exp(σ X_{g_j})z)
    /// = {{g_i,H},g_j} = −N_ij: RATTLE's Newton matrix is −N.
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]);

    /// The fibre flow z ↦ exp(Σ λ_i X_{g_i})(z) in closed form, applied in
    /// place. Returns [`ClosedForm::Unavailable`], leaving q and p
    /// untouched, when the system has none; the runtime then uses its own
    /// (see `fibre`).
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        let _ = (lambda, q, p);
        ClosedForm::Unavailable
    }

    /// Hands `v` this system's sizes d and m as constants when the system
    /// knows them at compile time and offers them, else asks it to work
    /// with run-time sizes ([`SizeVisitor::dynamic`], the default).
    /// `constrained_system!` offers them to the systems the runtime has
    /// a fixed-size step for (holonomic g, separable H with quadratic T,
    /// one to eight constraints), which then step on stack arrays of
    /// their own size; both give the same map. A wrapper that changes any
    /// of the wrapped system's functions must not forward this with the
    /// wrapped system (the visitor would call the wrapped functions, not
    /// the wrapper's): it may offer its own sizes, `v.fixed::<D, M>(self)`.
    ///
    /// ```
    /// use geoshake_runtime::{ConstrainedSystem, SizeVisitor, examples::Pendulum};
    /// struct Sizes;
    /// impl<S> SizeVisitor<S> for Sizes {
    ///     type Output = Option<(usize, usize)>;
    ///     fn fixed<const D: usize, const M: usize>(self, _: &S) -> Self::Output {
    ///         Some((D, M))
    ///     }
    ///     fn dynamic(self, _: &S) -> Self::Output {
    ///         None
    ///     }
    /// }
    /// assert_eq!(Pendulum::default().with_sizes(Sizes), Some((2, 1)));
    /// ```
    #[inline]
    fn with_sizes<V: SizeVisitor<Self>>(&self, v: V) -> V::Output
    where
        Self: Sized,
    {
        v.dynamic(self)
    }
}

/// A computation over a system that can use the system's sizes as
/// constants (array lengths the compiler knows) when the system has them:
/// [`ConstrainedSystem::with_sizes`] calls [`fixed`](Self::fixed) with
/// d = `D` and m = `M`, or [`dynamic`](Self::dynamic). The system trait
/// names no kernel: the runtime's fixed-size step is one such visitor.
pub trait SizeVisitor<S: ?Sized> {
    /// What the computation returns.
    type Output;
    /// The computation with d = `D` degrees of freedom and m = `M`
    /// constraints known at compile time.
    fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output;
    /// The computation with the sizes read at run time.
    fn dynamic(self, sys: &S) -> Self::Output;
}
