//! A system of particles: masses, constraint families, potential families.

use super::plan::{ClusterArgs, ClusterFailure, ClusterReport, FamilyClusters};
use super::stencil::member_scale;
use super::{ForceField, Stencil, Table, TopologyError};
use std::sync::Arc;

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
    name: String,
    pub(crate) stencil: S,
    pub(crate) table: Table,
    dim: usize,
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
        let mut x = [0.0; MAX_LOCAL];
        let x = &mut x[..S::ARITY * S::DIM];
        for (k, gk) in g.iter_mut().enumerate().take(self.table.len()) {
            self.gather(q, k, x);
            *gk = self.stencil.value(x, self.table.data(k));
        }
    }
    fn gradients(&self, q: &[f64], g: &mut [f64], grad: &mut [f64]) {
        let w = S::ARITY * S::DIM;
        let mut x = [0.0; MAX_LOCAL];
        let x = &mut x[..w];
        for k in 0..self.table.len() {
            self.gather(q, k, x);
            g[k] = self
                .stencil
                .gradient(x, self.table.data(k), &mut grad[k * w..(k + 1) * w]);
        }
    }
    fn gradients_scaled(&self, q: &[f64], g: &mut [f64], grad: &mut [f64], inv_scale: &mut [f64]) {
        let w = S::ARITY * S::DIM;
        let mut x = [0.0; MAX_LOCAL];
        let x = &mut x[..w];
        for k in 0..self.table.len() {
            self.gather(q, k, x);
            let gr = &mut grad[k * w..(k + 1) * w];
            g[k] = self.stencil.gradient(x, self.table.data(k), gr);
            inv_scale[k] = member_scale::<S>(gr, x).0;
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
        let (d, ar) = (S::DIM, S::ARITY);
        let w = ar * d;
        let idx = self.table.all_particles();
        let mut worst = 0.0f64;
        for k in 0..self.table.len() {
            let gk = &grad[k * w..(k + 1) * w];
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
            out[k] = s;
            if ratio {
                use crate::tolerance::{relative_dot_from_sums, HIDDEN_LIMIT};
                let rel = |b0_sq: f64| {
                    relative_dot_from_sums(s, gg, vv, b0_sq)
                        .unwrap_or_else(|| hidden_scaled(gk, ik, d, inv_mass, p, b0_sq))
                };
                let mut r = rel(0.0);
                if !(r <= HIDDEN_LIMIT) {
                    r = rel(before[k]);
                }
                if crate::tolerance::worse(r, worst) {
                    worst = r;
                }
            } else {
                before[k] = vv;
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

/// n particles in R^D with masses, constraint families, potential
/// families and forces the user brings ([`ForceField`]):
/// H = Σ_a |p_a|²/(2 m_a) + Σ_fam V_fam(x) + V_ext(x), g = (g_fam)_fam.
///
/// Coordinates are stored particle by particle: x_a's c-th coordinate is
/// `q[a * D + c]`, and likewise for p. Constraints are numbered family by
/// family in the order they were added, member by member within a family.
///
/// ```
/// use geoshake_runtime::particles::{ParticleSystem, Stencil, Table};
/// # struct Distance;
/// # impl Stencil for Distance {
/// #     const ARITY: usize = 2; const DIM: usize = 3; const DATA: usize = 1;
/// #     fn value(&self, x: &[f64], c: &[f64]) -> f64 {
/// #         (0..3).map(|k| (x[k] - x[3 + k]).powi(2)).sum::<f64>() - c[0] * c[0] }
/// #     fn gradient(&self, x: &[f64], c: &[f64], g: &mut [f64]) -> f64 {
/// #         for k in 0..3 { let r = x[k] - x[3 + k]; g[k] = 2.0 * r; g[3 + k] = -2.0 * r; }
/// #         self.value(x, c) }
/// # }
/// let mut bonds = Table::new(2, 1);
/// bonds.push(&[0, 1], &[1.0]).unwrap();
/// let dimer = ParticleSystem::new(3, vec![1.0, 2.0])
///     .unwrap()
///     .with_constraints("bond", Distance, bonds)
///     .unwrap();
/// assert_eq!((dimer.particles(), dimer.constraints()), (2, 1));
/// ```
pub struct ParticleSystem {
    /// Everything but the brought forces, shared by the clones of a
    /// [`Rattle`](super::Rattle) (the threads of an ensemble): read-only
    /// once the system is built.
    parts: Arc<Parts>,
    /// The brought forces: each clone has its own copy, since a field may
    /// keep buffers it writes between calls.
    external: Option<Box<dyn Field>>,
}

/// The read-only part of a [`ParticleSystem`].
struct Parts {
    dim: usize,
    masses: Vec<f64>,
    inverse_masses: Vec<f64>,
    constraints: Vec<Box<dyn ConstraintFamily>>,
    potentials: Vec<Box<dyn PotentialFamily>>,
}

/// A brought force field as the system stores it: one that can be copied
/// for another clone of the solver, and shared by reference with the
/// threads that copy it.
trait Field: ForceField + Sync {
    fn clone_box(&self) -> Box<dyn Field>;
}

impl<F: ForceField + Clone + Sync + 'static> Field for F {
    fn clone_box(&self) -> Box<dyn Field> {
        Box::new(self.clone())
    }
}

impl ParticleSystem {
    /// Particles in R^`dim` with the given masses (finite and positive), no
    /// constraint and no potential yet.
    pub fn new(dim: usize, masses: Vec<f64>) -> Result<Self, TopologyError> {
        if let Some((a, &m)) = masses
            .iter()
            .enumerate()
            .find(|(_, m)| !(m.is_finite() && **m > 0.0))
        {
            return Err(TopologyError::BadValue {
                family: "masses".into(),
                member: a,
                value: m,
                why: "a mass must be finite and positive",
            });
        }
        let inverse_masses = masses.iter().map(|m| 1.0 / m).collect();
        let parts = Parts {
            dim,
            masses,
            inverse_masses,
            constraints: Vec::new(),
            potentials: Vec::new(),
        };
        Ok(ParticleSystem {
            parts: Arc::new(parts),
            external: None,
        })
    }

    /// The system for another clone of a solver: the same families and
    /// masses, shared, and a copy of the brought forces.
    pub(crate) fn share(&self) -> ParticleSystem {
        ParticleSystem {
            parts: Arc::clone(&self.parts),
            external: self.external.as_ref().map(|f| f.clone_box()),
        }
    }

    /// The parts, to add a family to.
    fn parts_mut(&mut self) -> &mut Parts {
        // A system is shared only inside a solver, which never hands it
        // out by value: a system being built is its parts' only owner.
        Arc::get_mut(&mut self.parts).expect("a system being built is not shared")
    }

    /// Adds a constraint family: `stencil` applied to every row of `table`.
    /// Refuses rows of the wrong shape, particles that do not exist, and a
    /// member that repeats another.
    pub fn with_constraints<S: Stencil + 'static>(
        mut self,
        name: &str,
        stencil: S,
        table: Table,
    ) -> Result<Self, TopologyError> {
        let family = self.family(name, stencil, table, true)?;
        self.parts_mut().constraints.push(Box::new(family));
        Ok(self)
    }

    /// Adds a potential family: V gains Σ_k f(x_{i_k}; c_k).
    pub fn with_potential<S: Stencil + 'static>(
        mut self,
        name: &str,
        stencil: S,
        table: Table,
    ) -> Result<Self, TopologyError> {
        let family = self.family(name, stencil, table, false)?;
        self.parts_mut().potentials.push(Box::new(family));
        Ok(self)
    }

    /// Adds the forces of an external potential V_ext, evaluated by the
    /// user's code ([`ForceField`]); replaces one given before. The field
    /// is `Clone` and `Sync` so that a solver can be cloned (one clone per
    /// thread of an [`ensemble`](crate::ensemble())): each clone calls its
    /// own copy.
    pub fn with_forces(mut self, field: impl ForceField + Clone + Sync + 'static) -> Self {
        self.external = Some(Box::new(field));
        self
    }

    /// Validates a table against a stencil and this system's particles.
    fn family<S: Stencil>(
        &self,
        name: &str,
        stencil: S,
        table: Table,
        unique: bool,
    ) -> Result<Family<S>, TopologyError> {
        let family = || name.to_string();
        if S::DIM != self.parts.dim {
            return Err(TopologyError::Dimension {
                family: family(),
                stencil: S::DIM,
                system: self.parts.dim,
            });
        }
        let shape = |what, got, expected| TopologyError::RowShape {
            family: family(),
            member: 0,
            what,
            got,
            expected,
        };
        if table.arity() != S::ARITY || S::ARITY * S::DIM > MAX_LOCAL {
            return Err(shape("particle list", table.arity(), S::ARITY));
        }
        if table.width() != S::DATA {
            return Err(shape("data", table.width(), S::DATA));
        }
        let n = self.particles();
        for k in 0..table.len() {
            if let Some(&i) = table.particles(k).iter().find(|&&i| i as usize >= n) {
                return Err(TopologyError::DanglingParticle {
                    family: family(),
                    member: k,
                    particle: i as usize,
                    particles: n,
                });
            }
        }
        if unique {
            // Members are equal when they touch the same set of particles
            // with the same numbers (a bond given as (i, j) and as (j, i)).
            let mut keys: Vec<(Vec<u32>, Vec<u64>, usize)> = (0..table.len())
                .map(|k| {
                    let mut p = table.particles(k).to_vec();
                    p.sort_unstable();
                    let c = table.data(k).iter().map(|v| v.to_bits()).collect();
                    (p, c, k)
                })
                .collect();
            keys.sort_unstable();
            if let Some(w) = keys
                .windows(2)
                .find(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1)
            {
                return Err(TopologyError::DuplicateMember {
                    family: family(),
                    first: w[0].2.min(w[1].2),
                    second: w[0].2.max(w[1].2),
                });
            }
        }
        Ok(Family {
            name: name.to_string(),
            stencil,
            table,
            dim: self.parts.dim,
        })
    }

    /// The dimension D of each particle's position.
    pub fn dim(&self) -> usize {
        self.parts.dim
    }

    /// The number n of particles (d = n·D degrees of freedom).
    pub fn particles(&self) -> usize {
        self.parts.masses.len()
    }

    /// The masses m_a.
    pub fn masses(&self) -> &[f64] {
        &self.parts.masses
    }

    /// 1/m_a.
    pub fn inverse_masses(&self) -> &[f64] {
        &self.parts.inverse_masses
    }

    /// The number m of constraints, all families together.
    pub fn constraints(&self) -> usize {
        self.parts.constraints.iter().map(|f| f.table().len()).sum()
    }

    /// The constraint families, in the order they were added.
    pub fn constraint_families(&self) -> &[Box<dyn ConstraintFamily>] {
        &self.parts.constraints
    }

    /// The potential families, in the order they were added.
    pub fn potential_families(&self) -> &[Box<dyn PotentialFamily>] {
        &self.parts.potentials
    }

    /// True when forces were brought with [`with_forces`](Self::with_forces).
    pub fn has_forces(&self) -> bool {
        self.external.is_some()
    }

    /// True when H has a potential: a potential family or brought forces.
    pub fn has_potential(&self) -> bool {
        !self.parts.potentials.is_empty() || self.external.is_some()
    }

    /// The kinetic energy Σ_a |p_a|²/(2 m_a) of momenta `p` (n·D entries).
    ///
    /// ```
    /// use geoshake_runtime::particles::ParticleSystem;
    /// let s = ParticleSystem::new(2, vec![1.0, 4.0]).unwrap();
    /// assert_eq!(s.kinetic_energy(&[1.0, 0.0, 0.0, 2.0]), 0.5 + 0.5);
    /// ```
    pub fn kinetic_energy(&self, p: &[f64]) -> f64 {
        let d = self.parts.dim;
        let mut two_k = 0.0;
        for (a, w) in self.parts.inverse_masses.iter().enumerate() {
            two_k += w * p[a * d..(a + 1) * d].iter().map(|p| p * p).sum::<f64>();
        }
        0.5 * two_k
    }

    /// V(q) = Σ_fam V_fam(q) + V_ext(q), with ∇V(q) written into `grad`
    /// (n·D entries): the brought forces (negated) first, then every
    /// family's gradient added.
    pub(crate) fn potential_gradient(&mut self, q: &[f64], grad: &mut [f64]) -> f64 {
        grad.fill(0.0);
        let mut v = 0.0;
        if let Some(field) = &mut self.external {
            v += field.forces(q, grad);
            for g in grad.iter_mut() {
                *g = -*g;
            }
        }
        for f in &self.parts.potentials {
            v += f.energy_gradient(q, grad);
        }
        v
    }
}
