//! A constraint or potential family: the traits the solvers and the forces
//! see ([`ConstraintFamily`], its kernels [`ClusterKernel`],
//! [`PotentialFamily`]) and [`Family`], a stencil applied to every row of a
//! table, which implements them.

use super::plan::{ClusterArgs, ClusterFailure, ClusterReport, FamilyClusters};
use super::stencil::member_scale;
use super::{Stencil, Table};

/// A constraint family as the solvers see it: the rows of a [`Table`]
/// evaluated through one [`Stencil`]. Constraint k of the family is
/// g_k(x) = f(x_{i_k1}, …, x_{i_kA}; c_k).
pub trait ConstraintFamily: ClusterKernel + Send + Sync {
    /// The family's declared name (for errors and diagnostics).
    fn name(&self) -> &str;
    /// Its rows.
    fn table(&self) -> &Table;
    /// Every g_k, written into `g` (one entry per member).
    fn values(&self, q: &[f64], g: &mut [f64]);
    /// Every g_k into `g`, and its gradient with respect to the member's own
    /// particles into `grad` (`arity * dim` entries per member, member after
    /// member, in the layout of [`Stencil`]).
    fn gradients(&self, q: &[f64], g: &mut [f64], grad: &mut [f64]);
    /// As [`gradients`](Self::gradients), and the reciprocal of the
    /// residual scale, 1 / (|∇g_k| · extent_k), of every member into
    /// `inv_scale` (extent² = Σ_a |x_a − x̄|² over the member's particles,
    /// |x_a|² for one particle; `tolerance::inverse_scale`, the cluster
    /// kernels' own): the relative residual of member k is
    /// |g_k| · inv_scale_k.
    fn gradients_scaled(&self, q: &[f64], g: &mut [f64], grad: &mut [f64], inv_scale: &mut [f64]);
    /// As [`values`](Self::values) for the members `first..first +
    /// g.len()` only (a chunk of a pass on threads: each member's number
    /// is the one the whole pass computes).
    #[doc(hidden)]
    fn values_from(&self, q: &[f64], first: usize, g: &mut [f64]);
    /// As [`gradients`](Self::gradients) (with `inv_scale`,
    /// [`gradients_scaled`](Self::gradients_scaled)) for the members
    /// `first..first + g.len()` only, their blocks from the start of
    /// `grad`.
    #[doc(hidden)]
    fn gradients_from(
        &self,
        q: &[f64],
        first: usize,
        g: &mut [f64],
        grad: &mut [f64],
        inv_scale: Option<&mut [f64]>,
    );
    /// out ← out − factor · W^w Gᵀ x over this family's members: every
    /// member k's gradient block (in `grad`, the layout of
    /// [`gradients`](Self::gradients)) times x_k, scaled by the particle's
    /// inverse mass when `weighted`, subtracted from its particles' entries.
    #[doc(hidden)]
    fn scatter(
        &self,
        grad: &[f64],
        x: &[f64],
        inv_mass: &[f64],
        weighted: bool,
        factor: f64,
        out: &mut [f64],
    );
    /// As [`scatter`](Self::scatter) with the gradients recomputed at `q0`
    /// instead of read from a buffer: on systems too large for the caches,
    /// evaluating a stencil costs less than streaming its stored gradient.
    #[doc(hidden)]
    fn scatter_at(
        &self,
        q0: &[f64],
        x: &[f64],
        inv_mass: &[f64],
        weighted: bool,
        factor: f64,
        out: &mut [f64],
    );
    /// The forces of multipliers Λ on the particles and their virial:
    /// `force` ← `force` − factor · G(q)ᵀ Λ and `virial` += Σ_k Σ_a x_a ⊗
    /// f_{a,k} (D×D, row-major), each member's term taken about its first
    /// particle, r_a = x_a − x_{k,1}, plus x_{k,1} ⊗ Σ_a f_{a,k}: the same
    /// sum, without the cancellation of large absolute positions when the
    /// member's forces balance (every translation-invariant stencil).
    #[doc(hidden)]
    fn forces_virial(
        &self,
        q: &[f64],
        lambda: &[f64],
        factor: f64,
        force: &mut [f64],
        virial: &mut [f64],
    );
    /// out_k ← ∇g_k · M⁻¹ p for every member (gradients in `grad`).
    /// Without `ratio`, before a projection: `before_k` ← |M⁻¹ p|² over
    /// k's particles. With `ratio`, after it: returns max_k |out_k| /
    /// (|∇g_k| · |M⁻¹ p| over k's particles), the relative
    /// hidden-constraint residual (NaN if any is), where it fails the
    /// round-off limit with max(|M⁻¹ p|, √before_k) instead (the
    /// velocity the projection started from: `relative_dot_after`).
    #[doc(hidden)]
    fn hidden(
        &self,
        grad: &[f64],
        inv_mass: &[f64],
        p: &[f64],
        out: &mut [f64],
        before: &mut [f64],
        ratio: bool,
    ) -> f64;
    /// As [`hidden`](Self::hidden) for the members `first..first +
    /// out.len()` only, their gradient blocks from the start of `grad`.
    #[doc(hidden)]
    #[allow(clippy::too_many_arguments)]
    fn hidden_from(
        &self,
        grad: &[f64],
        inv_mass: &[f64],
        p: &[f64],
        first: usize,
        out: &mut [f64],
        before: &mut [f64],
        ratio: bool,
    ) -> f64;
}

/// The cluster kernels of a constraint family (`cluster`), a supertrait of
/// [`ConstraintFamily`] so that the solvers reach them through the family's
/// trait object; declared here with data types only and implemented where
/// the kernels are, so that the model names no kernel.
#[doc(hidden)]
pub trait ClusterKernel {
    /// The position stage of RATTLE on every independent cluster of this
    /// family (per-cluster Newton; monomorphic in the stencil); with `fuse`
    /// (no potential) the velocity stage too. `store` keeps every member's
    /// ν for a warm start of the next step (used when `warm`).
    #[doc(hidden)]
    #[allow(clippy::too_many_arguments)]
    fn shake_clusters(
        &self,
        plan: &FamilyClusters,
        args: &ClusterArgs<'_>,
        fuse: bool,
        store: Option<&mut [f64]>,
        warm: bool,
        q: &mut [f64],
        p: &mut [f64],
        report: &mut ClusterReport,
    ) -> Result<(), ClusterFailure>;
    /// The velocity stage (projection onto M^H) on every cluster; a
    /// hidden constraint left above round-off (`tolerance::HIDDEN_LIMIT`)
    /// is a singular N.
    #[doc(hidden)]
    #[allow(clippy::too_many_arguments)]
    fn project_clusters(
        &self,
        plan: &FamilyClusters,
        inv_mass: &[f64],
        q: &[f64],
        p: &mut [f64],
        report: &mut ClusterReport,
    ) -> Result<(), ClusterFailure>;
    /// Chooses the kernel of this family's clusters at plan time, after
    /// the plan's shape is known: the closed form for rigid triangles of
    /// distance constraints, else Newton.
    #[doc(hidden)]
    fn choose_kernel(&self, _plan: &mut FamilyClusters) {}
}

/// A potential family: V_fam(x) = Σ_k f(x_{i_k1}, …; c_k).
pub trait PotentialFamily: Send + Sync {
    /// The family's declared name.
    fn name(&self) -> &str;
    /// Its rows.
    fn table(&self) -> &Table;
    /// Σ_k f_k, with ∂/∂x of it *added* into `grad` (length n·D).
    fn energy_gradient(&self, q: &[f64], grad: &mut [f64]) -> f64;
}

/// A family: a stencil applied to every row of a table.
pub(crate) struct Family<S> {
    pub(super) name: String,
    pub(crate) stencil: S,
    pub(crate) table: Table,
    pub(super) dim: usize,
}

impl<S: Stencil> Family<S> {
    /// Gathers member k's coordinates into `x` (`ARITY * DIM` entries).
    #[inline(always)]
    fn gather(&self, q: &[f64], k: usize, x: &mut [f64]) {
        // S::DIM (= self.dim, checked when the family was added) is a
        // constant: the copies unroll.
        let d = S::DIM;
        for (a, &i) in self.table.particles(k).iter().enumerate() {
            let i = i as usize * d;
            x[a * d..(a + 1) * d].copy_from_slice(&q[i..i + d]);
        }
    }
}

impl<S: Stencil> Family<S> {
    /// out ← out − factor · W Gᵀ x with the gradients evaluated at `q0`
    /// (W the inverse masses when given, else I); with `virial`, also
    /// virial += Σ_k Σ_a x_a ⊗ f_{a,k} of those forces (without W), each
    /// member's term about its first particle (see
    /// [`ConstraintFamily::forces_virial`]).
    #[inline(always)]
    fn scatter_gradients_at(
        &self,
        q0: &[f64],
        x: &[f64],
        inv_mass: Option<&[f64]>,
        factor: f64,
        out: &mut [f64],
        mut virial: Option<&mut [f64]>,
    ) {
        let (d, ar) = (S::DIM, S::ARITY);
        let w = ar * d;
        let idx = self.table.all_particles();
        let mut xl = [0.0; MAX_LOCAL];
        let mut gk = [0.0; MAX_LOCAL];
        let mut fk = [0.0; MAX_LOCAL];
        for k in 0..self.table.len() {
            self.gather(q0, k, &mut xl[..w]);
            self.stencil
                .gradient(&xl[..w], self.table.data(k), &mut gk[..w]);
            let xk = x[k] * factor;
            let ik = &idx[k * ar..(k + 1) * ar];
            for a in 0..ar {
                let i = ik[a] as usize;
                let s = inv_mass.map_or(xk, |m| xk * m[i]);
                for c in 0..d {
                    fk[a * d + c] = -s * gk[a * d + c];
                    out[i * d + c] += fk[a * d + c];
                }
            }
            if let Some(v) = virial.as_deref_mut() {
                let mut total = [0.0; MAX_LOCAL];
                for a in 0..ar {
                    for r in 0..d {
                        total[r] += fk[a * d + r];
                        let rel = xl[a * d + r] - xl[r];
                        for c in 0..d {
                            v[r * d + c] += rel * fk[a * d + c];
                        }
                    }
                }
                for r in 0..d {
                    for c in 0..d {
                        v[r * d + c] += xl[r] * total[c];
                    }
                }
            }
        }
    }
}

/// Largest `ARITY * DIM` a stencil may have: its local coordinates live on
/// the stack.
pub(crate) const MAX_LOCAL: usize = 64;

impl<S: Stencil> ConstraintFamily for Family<S> {
    fn name(&self) -> &str {
        &self.name
    }
    fn table(&self) -> &Table {
        &self.table
    }
    fn values(&self, q: &[f64], g: &mut [f64]) {
        self.values_from(q, 0, g);
    }
    fn values_from(&self, q: &[f64], first: usize, g: &mut [f64]) {
        let mut x = [0.0; MAX_LOCAL];
        let x = &mut x[..S::ARITY * S::DIM];
        let members = self.table.len().saturating_sub(first);
        for (k, gk) in (first..).zip(g.iter_mut().take(members)) {
            self.gather(q, k, x);
            *gk = self.stencil.value(x, self.table.data(k));
        }
    }
    fn gradients(&self, q: &[f64], g: &mut [f64], grad: &mut [f64]) {
        self.gradients_from(q, 0, &mut g[..self.table.len()], grad, None);
    }
    fn gradients_scaled(&self, q: &[f64], g: &mut [f64], grad: &mut [f64], inv_scale: &mut [f64]) {
        let g = &mut g[..self.table.len()];
        self.gradients_from(q, 0, g, grad, Some(inv_scale));
    }
    fn gradients_from(
        &self,
        q: &[f64],
        first: usize,
        g: &mut [f64],
        grad: &mut [f64],
        mut inv_scale: Option<&mut [f64]>,
    ) {
        let w = S::ARITY * S::DIM;
        let mut x = [0.0; MAX_LOCAL];
        let x = &mut x[..w];
        for (l, gl) in g.iter_mut().enumerate() {
            let k = first + l;
            self.gather(q, k, x);
            let gr = &mut grad[l * w..(l + 1) * w];
            *gl = self.stencil.gradient(x, self.table.data(k), gr);
            if let Some(s) = inv_scale.as_deref_mut() {
                s[l] = member_scale::<S>(gr, x).0;
            }
        }
    }
    fn scatter(
        &self,
        grad: &[f64],
        x: &[f64],
        inv_mass: &[f64],
        weighted: bool,
        factor: f64,
        out: &mut [f64],
    ) {
        let (d, ar) = (S::DIM, S::ARITY);
        let w = ar * d;
        let idx = self.table.all_particles();
        for k in 0..self.table.len() {
            let xk = x[k] * factor;
            let gk = &grad[k * w..(k + 1) * w];
            let ik = &idx[k * ar..(k + 1) * ar];
            for a in 0..ar {
                let i = ik[a] as usize;
                let s = if weighted { xk * inv_mass[i] } else { xk };
                for c in 0..d {
                    out[i * d + c] -= s * gk[a * d + c];
                }
            }
        }
    }
    fn scatter_at(
        &self,
        q0: &[f64],
        x: &[f64],
        inv_mass: &[f64],
        weighted: bool,
        factor: f64,
        out: &mut [f64],
    ) {
        let w = weighted.then_some(inv_mass);
        self.scatter_gradients_at(q0, x, w, factor, out, None);
    }
    fn forces_virial(
        &self,
        q: &[f64],
        lambda: &[f64],
        factor: f64,
        force: &mut [f64],
        virial: &mut [f64],
    ) {
        self.scatter_gradients_at(q, lambda, None, factor, force, Some(virial));
    }
    fn hidden(
        &self,
        grad: &[f64],
        inv_mass: &[f64],
        p: &[f64],
        out: &mut [f64],
        before: &mut [f64],
        ratio: bool,
    ) -> f64 {
        let out = &mut out[..self.table.len()];
        self.hidden_from(grad, inv_mass, p, 0, out, before, ratio)
    }
    fn hidden_from(
        &self,
        grad: &[f64],
        inv_mass: &[f64],
        p: &[f64],
        first: usize,
        out: &mut [f64],
        before: &mut [f64],
        ratio: bool,
    ) -> f64 {
        let (d, ar) = (S::DIM, S::ARITY);
        let w = ar * d;
        let idx = self.table.all_particles();
        let mut worst = 0.0f64;
        for l in 0..out.len() {
            let k = first + l;
            let gk = &grad[l * w..(l + 1) * w];
            let ik = &idx[k * ar..(k + 1) * ar];
            // The velocities v = M⁻¹p of the member's particles are formed
            // on the fly: a local copy of them (zeroed per member) cost as
            // much as the rest of this loop on a chain.
            let (mut s, mut gg, mut vv) = (0.0, 0.0, 0.0);
            for a in 0..ar {
                let i = ik[a] as usize;
                for c in 0..d {
                    let (g, v) = (gk[a * d + c], inv_mass[i] * p[i * d + c]);
                    s += g * v;
                    gg += g * g;
                    vv += v * v;
                }
            }
            out[l] = s;
            if ratio {
                use crate::tolerance::{relative_dot_from_sums, HIDDEN_LIMIT};
                let rel = |b0_sq: f64| {
                    relative_dot_from_sums(s, gg, vv, b0_sq)
                        .unwrap_or_else(|| hidden_scaled(gk, ik, d, inv_mass, p, b0_sq))
                };
                let mut r = rel(0.0);
                if !(r <= HIDDEN_LIMIT) {
                    r = rel(before[l]);
                }
                if crate::tolerance::worse(r, worst) {
                    worst = r;
                }
            } else {
                before[l] = vv;
            }
        }
        worst
    }
}

/// A member's relative hidden constraint where the squares of
/// [`ConstraintFamily::hidden`]'s sums are not safe: the velocities
/// gathered, then `relative_dot_after`'s scaled form.
#[cold]
fn hidden_scaled(gk: &[f64], ik: &[u32], d: usize, inv_mass: &[f64], p: &[f64], b0_sq: f64) -> f64 {
    let mut v = [0.0; MAX_LOCAL];
    for (a, &i) in ik.iter().enumerate() {
        let i = i as usize;
        for c in 0..d {
            v[a * d + c] = inv_mass[i] * p[i * d + c];
        }
    }
    crate::tolerance::relative_dot_after(gk, &v[..gk.len()], b0_sq)
}

impl<S: Stencil> PotentialFamily for Family<S> {
    fn name(&self) -> &str {
        &self.name
    }
    fn table(&self) -> &Table {
        &self.table
    }
    fn energy_gradient(&self, q: &[f64], grad: &mut [f64]) -> f64 {
        let d = self.dim;
        let w = S::ARITY * S::DIM;
        let mut x = [0.0; MAX_LOCAL];
        let mut gl = [0.0; MAX_LOCAL];
        let mut v = 0.0;
        for k in 0..self.table.len() {
            self.gather(q, k, &mut x[..w]);
            v += self
                .stencil
                .gradient(&x[..w], self.table.data(k), &mut gl[..w]);
            for (a, &i) in self.table.particles(k).iter().enumerate() {
                let i = i as usize * d;
                for c in 0..d {
                    grad[i + c] += gl[a * d + c];
                }
            }
        }
        v
    }
}
