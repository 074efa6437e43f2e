//! The Gram-determinant correction: a system whose potential is
//! U + ½ log det(g_q g_qᵀ), for sampling a density on R^d conditioned on
//! M = {q : g(q) = 0} ([`Density::Ambient`](super::Density::Ambient)).
//!
//! # The correction
//!
//! By the co-area formula (Federer 1969, §3.2; Diaconis, Holmes and
//! Shahshahani 2013), for q with density π on R^d,
//!
//!   ∫ f(q) π(q) J(q) dq = ∫_{R^m} ∫_{g = c} f π dσ dc,  J = √det G,
//!   G(q) = g_q g_qᵀ (m × m, g_q = ∂g/∂q of size m × d),
//!
//! so q given g(q) = 0 has density π/√det G with respect to the surface
//! measure σ of M: the potential of the Hausdorff sampler becomes
//! U + Ψ with Ψ = ½ log det G. Its gradient, from dΨ = ½ tr(G⁻¹ dG) with
//! dG = dg_q g_qᵀ + g_q dg_qᵀ (the two terms have the same trace, G⁻¹
//! being symmetric), is
//!
//!   ∂Ψ/∂q_k = tr(G⁻¹ g_q ∂_k g_qᵀ) = Σ_i Σ_l W_{li} ∂²g_i/∂q_l∂q_k
//!           = Σ_i [∇²g_i w_i]_k,  W = g_qᵀ G⁻¹ (d × m),
//!
//! w_i the column i of W (the pseudo-inverse g_q⁺: the shortest v with
//! g_q v = e_i). It needs g's second derivatives, which every system gives
//! ([`ConstrainedSystem::constraint_hessian`], one call per constraint
//! with λ = e_i), and one LU of G.
//!
//! # What changes and what is forwarded
//!
//! Ψ is a function of q alone, added to H: H_p, H_pp and H_qp do not
//! change, and for holonomic g (the only kind the sampler takes) the
//! hidden constraints {g_i, H} = g_{i,q}·H_p, their Jacobian and
//! N = {{H,g_i},g_j} = g_q H_pp g_qᵀ read H only through H_p. So only
//! `hamiltonian`, `grad_q`, `gradient` and `hessian` are the wrapper's
//! own; g, its derivatives, its fibre flow and every structural flag are
//! the wrapped system's. `with_sizes` offers the wrapped system's sizes
//! to a visitor of the wrapper, so the fixed-size step runs on the
//! wrapper's functions.
//!
//! # The Hessian
//!
//! ∇²Ψ needs g's third derivatives, which no system provides. The
//! Hessian's q-block gets ∇²Ψ as central differences of the exact ∇Ψ
//! above (step ε^{1/3}‖q‖∞, the scale of q's round-off; error about 1e-10
//! of its size where M curves on the scale of ‖q‖; symmetrised), on the variables g reads (Ψ depends on no other); the
//! rest of the Hessian is the wrapped system's, exact. Neither the
//! classical RATTLE step nor the start-of-trajectory nondegeneracy check
//! reads H_qq for holonomic g (the check reads the p-columns of H_zz
//! only), so on the sampler's path the differences cost their evaluation
//! (2 gradients per variable g reads, once per trajectory) and change
//! nothing; elsewhere they are a consistent H_qq, not a silent zero.
//!
//! # Singular G
//!
//! Where g_q loses rank (G singular, or a determinant that rounds to ≤ 0)
//! Ψ is −∞ and ∇Ψ NaN: the sampler counts a trajectory through such a
//! point a `non_finite` rejection, and refuses such a start (its
//! potential is not finite).

use std::sync::{Mutex, TryLockError};

use crate::linalg::{lu_factor, lu_solve};
use crate::system::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, SizeVisitor};

/// A system with potential U + ½ log det(g_q g_qᵀ) (module docs).
///
/// The scratch of one evaluation lives in the wrapper behind a mutex: each
/// chain's integrators own their clone (a clone gets fresh scratch), so
/// the lock is never contended and no evaluation allocates; a call that
/// finds it taken (one wrapper shared across threads) works on scratch of
/// its own.
pub(crate) struct Gram<S> {
    inner: S,
    /// The q-variables g reads, sorted: the support of Ψ.
    vars: Vec<usize>,
    scratch: Mutex<Scratch>,
}

/// The buffers of Ψ and ∇Ψ at one q.
struct Scratch {
    /// g_z (m × 2d, column-major), zeroed once: `constraint_jacobian`
    /// writes the same entries at every q.
    g_z: Vec<f64>,
    /// G, then its LU factors.
    gram: Vec<f64>,
    piv: Vec<usize>,
    /// A column of G⁻¹, then w_i = g_qᵀ G⁻¹ e_i.
    column: Vec<f64>,
    w: Vec<f64>,
    /// ∇²g_i (2d × 2d) and the unit weight e_i that selects it.
    hess_g: Vec<f64>,
    unit: Vec<f64>,
}

impl Scratch {
    fn new(d: usize, m: usize) -> Self {
        Scratch {
            g_z: vec![0.0; m * 2 * d],
            gram: vec![0.0; m * m],
            piv: vec![0; m],
            column: vec![0.0; m],
            w: vec![0.0; d],
            hess_g: vec![0.0; 4 * d * d],
            unit: vec![0.0; m],
        }
    }
}

impl<S: ConstrainedSystem> Gram<S> {
    /// `inner` with the correction; `inner` must have holonomic
    /// constraints (the sampler checks it first).
    pub(crate) fn new(inner: S) -> Self {
        debug_assert!(inner.kind().is_holonomic());
        let d = inner.dof();
        let mut vars: Vec<usize> = inner
            .jacobian_pattern()
            .iter()
            .filter(|&&(_, k)| k < d)
            .map(|&(_, k)| k)
            .collect();
        vars.sort_unstable();
        vars.dedup();
        let scratch = Mutex::new(Scratch::new(d, inner.constraint_count()));
        Gram {
            inner,
            vars,
            scratch,
        }
    }

    /// `f` with this wrapper's scratch, or fresh scratch when another
    /// thread holds it. (A panic in the wrapped system while the scratch
    /// was held leaves nothing that a later evaluation reads unwritten.)
    fn with_scratch<R>(&self, f: impl FnOnce(&mut Scratch) -> R) -> R {
        match self.scratch.try_lock() {
            Ok(mut s) => f(&mut s),
            Err(TryLockError::Poisoned(p)) => f(&mut p.into_inner()),
            Err(TryLockError::WouldBlock) => f(&mut Scratch::new(
                self.inner.dof(),
                self.inner.constraint_count(),
            )),
        }
    }

    /// Ψ = ½ log det G at q, leaving the LU factors of G in `s`; −∞ where G
    /// is singular or its determinant is not positive (round-off of a
    /// singular one: a Gram matrix has det ≥ 0), NaN where g_q is not
    /// finite.
    fn half_log_det(&self, q: &[f64], p: &[f64], s: &mut Scratch) -> f64 {
        let m = self.inner.constraint_count();
        if m == 0 {
            return 0.0;
        }
        self.inner.constraint_jacobian(q, p, &mut s.g_z);
        for i in 0..m {
            for j in 0..=i {
                let mut sum = 0.0;
                for &k in &self.vars {
                    sum += s.g_z[i + k * m] * s.g_z[j + k * m];
                }
                s.gram[i + j * m] = sum;
                s.gram[j + i * m] = sum;
            }
        }
        if !s.gram.iter().all(|x| x.is_finite()) {
            return f64::NAN;
        }
        // (`piv` has no spare slots: the dense LU, whose diagonal is U's.)
        if lu_factor(&mut s.gram, m, &mut s.piv).is_err() {
            return f64::NEG_INFINITY;
        }
        let mut log_abs = 0.0;
        let mut negative = false;
        for k in 0..m {
            let u = s.gram[k + k * m];
            log_abs += u.abs().ln();
            negative ^= (u < 0.0) != (s.piv[k] != k);
        }
        if negative {
            f64::NEG_INFINITY
        } else {
            0.5 * log_abs
        }
    }

    /// h_q ← h_q + ∇Ψ(q) on the variables g reads; every entry of ∇Ψ is
    /// NaN where Ψ is not finite.
    fn add_gradient(&self, q: &[f64], p: &[f64], s: &mut Scratch, h_q: &mut [f64]) {
        let (d, m) = (self.inner.dof(), self.inner.constraint_count());
        if m == 0 {
            return;
        }
        if !self.half_log_det(q, p, s).is_finite() {
            for &k in &self.vars {
                h_q[k] = f64::NAN;
            }
            return;
        }
        let n = 2 * d;
        for i in 0..m {
            // w_i = g_qᵀ G⁻¹ e_i.
            s.column.fill(0.0);
            s.column[i] = 1.0;
            lu_solve(&s.gram, m, &s.piv, &mut s.column);
            for &l in &self.vars {
                let mut sum = 0.0;
                for j in 0..m {
                    sum += s.g_z[j + l * m] * s.column[j];
                }
                s.w[l] = sum;
            }
            // ∇²g_i w_i, from the q-block of Σ λ_j ∇²g_j with λ = e_i
            // (which writes only its structural entries: zeroed per call).
            s.unit.fill(0.0);
            s.unit[i] = 1.0;
            s.hess_g.fill(0.0);
            self.inner.constraint_hessian(q, p, &s.unit, &mut s.hess_g);
            for &k in &self.vars {
                let mut sum = 0.0;
                for &l in &self.vars {
                    sum += s.hess_g[k + l * n] * s.w[l];
                }
                h_q[k] += sum;
            }
        }
    }

    /// Zeroes h_q on the variables g reads, so that the wrapped system's
    /// `grad_q` (which writes only its structural entries, over whatever
    /// the buffer held) leaves there its own value or zero, to which ∇Ψ
    /// is then added.
    fn clear_support(&self, h_q: &mut [f64]) {
        for &k in &self.vars {
            h_q[k] = 0.0;
        }
    }
}

impl<S: ConstrainedSystem + Clone> Clone for Gram<S> {
    /// A clone has scratch of its own.
    fn clone(&self) -> Self {
        Gram::new(self.inner.clone())
    }
}

impl<S: ConstrainedSystem> Hamiltonian for Gram<S> {
    fn dof(&self) -> usize {
        self.inner.dof()
    }
    fn separable(&self) -> bool {
        self.inner.separable()
    }
    fn quadratic_kinetic(&self) -> bool {
        self.inner.quadratic_kinetic()
    }
    fn variable_name(&self, k: usize) -> std::borrow::Cow<'_, str> {
        self.inner.variable_name(k)
    }

    /// H + ½ log det G.
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        let psi = self.with_scratch(|s| self.half_log_det(q, p, s));
        self.inner.hamiltonian(q, p) + psi
    }

    /// H_q + ∇Ψ.
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        self.clear_support(h_q);
        self.inner.grad_q(q, p, h_q);
        self.with_scratch(|s| self.add_gradient(q, p, s, h_q));
    }

    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        self.inner.grad_p(q, p, h_p);
    }

    fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) {
        self.clear_support(h_q);
        self.inner.gradient(q, p, h_q, h_p);
        self.with_scratch(|s| self.add_gradient(q, p, s, h_q));
    }

    /// H_zz with ∇²Ψ, by central differences of ∇Ψ (module docs), added
    /// to the q-block on the variables g reads.
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        let (d, n) = (self.inner.dof(), 2 * self.inner.dof());
        for &k in &self.vars {
            for &l in &self.vars {
                h_zz[k + l * n] = 0.0;
            }
        }
        self.inner.hessian(q, p, h_zz);
        if self.inner.constraint_count() == 0 {
            return;
        }
        let v = self.vars.len();
        let scale = q.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let (mut x, mut plus, mut minus) = (q.to_vec(), vec![0.0; d], vec![0.0; d]);
        let mut diff = vec![0.0; v * v];
        self.with_scratch(|s| {
            for (c, &l) in self.vars.iter().enumerate() {
                let step = f64::EPSILON.cbrt() * scale.max(f64::MIN_POSITIVE);
                x[l] = q[l] + step;
                let up = x[l];
                plus.fill(0.0);
                self.add_gradient(&x, p, s, &mut plus);
                x[l] = q[l] - step;
                let down = x[l];
                minus.fill(0.0);
                self.add_gradient(&x, p, s, &mut minus);
                x[l] = q[l];
                for (r, &k) in self.vars.iter().enumerate() {
                    diff[r + c * v] = (plus[k] - minus[k]) / (up - down);
                }
            }
        });
        for (c, &l) in self.vars.iter().enumerate() {
            for (r, &k) in self.vars.iter().enumerate() {
                h_zz[k + l * n] += 0.5 * (diff[r + c * v] + diff[c + r * v]);
            }
        }
    }
}

/// A visitor of [`Gram`] carried through the wrapped system's
/// [`ConstrainedSystem::with_sizes`]: it takes the sizes the wrapped
/// system offers and hands the visitor the wrapper.
struct Sizes<'a, S, V> {
    outer: &'a Gram<S>,
    visitor: V,
}

impl<S: ConstrainedSystem, V: SizeVisitor<Gram<S>>> SizeVisitor<S> for Sizes<'_, S, V> {
    type Output = V::Output;
    #[inline]
    fn fixed<const D: usize, const M: usize>(self, _: &S) -> V::Output {
        self.visitor.fixed::<D, M>(self.outer)
    }
    #[inline]
    fn dynamic(self, _: &S) -> V::Output {
        self.visitor.dynamic(self.outer)
    }
}

impl<S: ConstrainedSystem> ConstrainedSystem for Gram<S> {
    fn constraint_count(&self) -> usize {
        self.inner.constraint_count()
    }
    fn kind(&self) -> ConstraintKind {
        self.inner.kind()
    }
    fn quadratic_constraints(&self) -> bool {
        self.inner.quadratic_constraints()
    }
    fn interpreted(&self) -> bool {
        self.inner.interpreted()
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        self.inner.jacobian_pattern()
    }
    fn constraint_name(&self, i: usize) -> &str {
        self.inner.constraint_name(i)
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.inner.constraints(q, p, g);
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        self.inner.constraint_jacobian(q, p, g_z);
    }
    fn constraint_jacobian_values(&self, q: &[f64], p: &[f64], values: &mut [f64]) -> bool {
        self.inner.constraint_jacobian_values(q, p, values)
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        self.inner.constraint_hessian(q, p, lambda, out);
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.inner.hidden_constraints(q, p, out);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.inner.hidden_constraint_jacobian(q, p, out);
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        self.inner.nondegeneracy_matrix(q, p, n);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        self.inner.fibre_flow(lambda, q, p)
    }
    #[inline]
    fn with_sizes<V: SizeVisitor<Self>>(&self, v: V) -> V::Output {
        self.inner.with_sizes(Sizes {
            outer: self,
            visitor: v,
        })
    }
}

#[cfg(test)]
mod tests;
