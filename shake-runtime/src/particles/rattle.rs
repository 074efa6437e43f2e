//! RATTLE and SHAKE with Störmer–Verlet on a [`ParticleSystem`]: the step,
//! the projection of initial data, and the choice of solver.

use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

use super::global::Global;
use super::graph::{self, Numbering};
use super::options::{Method, Options, SolverChoice};
use super::plan::{ClusterArgs, ClusterFailure, ClusterReport, FailureKind, FamilyClusters};
use super::thermostat::Langevin;
use super::{ParticleState, ParticleSystem};
use crate::error::{SolveError, Stage, StepError};
use crate::report::StepInfo;
use crate::solver::SpdSolver;

/// What a particle step reports before its stages fill it in: the fields
/// its kernels do not gather are NaN (see [`StepInfo`]).
pub(super) fn particle_report() -> StepInfo {
    StepInfo {
        lambda: f64::NAN,
        condition: f64::NAN,
        det_n: f64::NAN,
        fold: f64::NAN,
        ..StepInfo::default()
    }
}

/// Unique stamps tie a state to the caches (forces, N's factor) of the
/// solver that produced it.
static STAMPS: AtomicU64 = AtomicU64::new(1);

/// The solver proper.
#[derive(Clone)]
enum Path {
    Clusters {
        plans: Vec<FamilyClusters>,
        /// ν of every constraint at the last step (warm start).
        nu: Vec<f64>,
        /// `nu` belongs to the state with this stamp.
        nu_stamp: u64,
    },
    Global(Box<Global>),
}

/// RATTLE (or SHAKE) with Störmer–Verlet for H = Σ_a |p_a|²/(2 m_a) + V(x)
/// and holonomic g, on systems of 10³–10⁶ constraints (the paper's Section
/// 5.1.3, classical formulas):
///
/// - p½ = p0 − (h/2) ∇V(q0) − G(q0)ᵀ λ,  q1 = q0 + h M⁻¹ p½,  g(q1) = 0;
/// - p1 = p½ − (h/2) ∇V(q1) − G(q1)ᵀ μ,  G(q1) M⁻¹ p1 = 0 (RATTLE only).
///
/// `new` is the symbolic phase: the constraint graph, its clusters, the
/// checks that need the topology, the solver and every workspace. A step
/// allocates nothing.
///
/// ```
/// use geoshake_runtime::particles::{generate, Options, Rattle};
/// let (system, mut state) = generate::water(8, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// generate::set_temperature(rattle.system(), &mut state, 300.0);
/// for _ in 0..10 {
///     let r = rattle.step(&mut state).unwrap();
///     assert!(r.residual.unwrap() <= 1e-10 && r.hidden.unwrap() < 1e-12);
/// }
/// assert_eq!(rattle.solver_name(), "clusters");
/// assert_eq!(state.step(), 10);
/// ```
pub struct Rattle {
    pub(super) system: ParticleSystem,
    pub(super) h: f64,
    options: Options,
    num: Numbering,
    path: Path,
    pub(super) qn: Vec<f64>,
    pub(super) pn: Vec<f64>,
    pub(super) force: Vec<f64>,
    pub(super) has_potential: bool,
    /// The forces in `force` are ∇V(q), and `potential` is V(q), of the
    /// state with this stamp.
    force_stamp: u64,
    potential: f64,
    /// The last state this solver made (0: none). Every call that
    /// overwrites the caches clears it first.
    pub(super) stamp: u64,
    /// In a run on the driver: the start time t0 and the stamp of the
    /// state the last step made (the driver holds that state's buffers).
    pub(super) run_t0: f64,
    pub(super) run_stamp: u64,
    /// The stamp of the state a run was asked to start from: a state this
    /// solver made and nobody changed since continues with its caches.
    pub(super) start_stamp: u64,
    /// The step count of the state a run was asked to start from, and of
    /// the run's start: the driver numbers a run's steps from 1, the
    /// thermostat's noise by the state's own count (`step_offset` during a
    /// driver's step, 0 otherwise).
    pub(super) start_step: u64,
    pub(super) run_step0: u64,
    pub(super) step_offset: u64,
    /// With a thermostat, a step is (g-)BAOAB (`langevin.rs`).
    pub(super) thermostat: Option<Langevin>,
    /// The drift substeps' start positions (empty without a thermostat).
    pub(super) q0: Vec<f64>,
    /// The state with this stamp was made by a RATTLE or SHAKE step whose
    /// multipliers ν are still held, its start positions in `qn`.
    multipliers_stamp: u64,
}

/// A solver that takes the same steps as this one, bit for bit, with
/// workspaces and caches of its own: the system's families and masses and
/// the coupled path's symbolic factorisation are shared, not copied, and
/// the brought forces are a copy ([`ParticleSystem::with_forces`]). This
/// is what an [`ensemble`](crate::ensemble()) gives each thread.
///
/// ```
/// use geoshake_runtime::particles::{generate, Options, Rattle};
/// let (system, mut state) = generate::water(8, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// generate::set_temperature(rattle.system(), &mut state, 300.0);
/// let (mut a, mut b) = (state.clone(), state);
/// let mut twin = rattle.clone();
/// for _ in 0..10 {
///     rattle.step(&mut a).unwrap();
///     twin.step(&mut b).unwrap();
/// }
/// assert_eq!((a.q(), a.p()), (b.q(), b.p()));
/// ```
impl Clone for Rattle {
    fn clone(&self) -> Self {
        Rattle {
            system: self.system.share(),
            h: self.h,
            options: self.options,
            num: self.num.clone(),
            path: self.path.clone(),
            qn: self.qn.clone(),
            pn: self.pn.clone(),
            force: self.force.clone(),
            has_potential: self.has_potential,
            force_stamp: self.force_stamp,
            potential: self.potential,
            stamp: self.stamp,
            run_t0: self.run_t0,
            run_stamp: self.run_stamp,
            start_stamp: self.start_stamp,
            start_step: self.start_step,
            run_step0: self.run_step0,
            step_offset: self.step_offset,
            thermostat: self.thermostat,
            q0: self.q0.clone(),
            multipliers_stamp: self.multipliers_stamp,
        }
    }
}

impl Rattle {
    /// The symbolic phase. Refuses h not finite or ≤ 0, options out of
    /// their range ([`Options::validate`]), a cluster with more
    /// constraints than coordinates, and a forced solver that cannot take
    /// the graph.
    pub fn new(system: ParticleSystem, h: f64, options: Options) -> Result<Self, StepError> {
        if !(h.is_finite() && h > 0.0 && (1.0 / h).is_finite()) {
            return Err(StepError::InvalidInput {
                what: "the step size h must be finite and positive (and 1/h finite)",
                value: h,
            });
        }
        options.validate()?;
        let num = Numbering::new(&system);
        let comps = graph::components(&system, &num)?;
        let m = system.constraints();
        let small = comps.all_small(&system, &num);
        let choice = match options.solver {
            SolverChoice::Auto if small => SolverChoice::Clusters,
            SolverChoice::Clusters if !small => {
                return Err(StepError::Solver {
                    solver: "clusters",
                    why: format!(
                        "a cluster has more than {} constraints or spans families",
                        super::plan::MAX_CLUSTER
                    ),
                })
            }
            c => c,
        };
        let path = if choice == SolverChoice::Clusters {
            let mut plans = comps.cluster_plans(&system, &num);
            let families = system.constraint_families().iter();
            for (plan, f) in plans.iter_mut().zip(families) {
                plan.detect_shape();
                f.choose_kernel(plan);
                let (n, members) = (system.particles(), f.table().len());
                plan.detect_blocks(n, members, super::plan::BLOCK_CLUSTERS);
            }
            Path::Clusters {
                plans,
                nu: vec![0.0; m],
                nu_stamp: 0,
            }
        } else {
            let (pattern, b) = comps.pattern(m);
            let solver = match choice {
                SolverChoice::Band if b > 64 => {
                    return Err(StepError::Solver {
                        solver: "band",
                        why: format!("N's half-bandwidth is {b} (at most 64)"),
                    })
                }
                SolverChoice::Band => SpdSolver::band(m, &pattern),
                SolverChoice::Auto if b <= 16 => SpdSolver::band(m, &pattern),
                _ => SpdSolver::sparse(m, &pattern).map_err(|why| StepError::Solver {
                    solver: "sparse",
                    why,
                })?,
            };
            drop(pattern);
            Path::Global(Box::new(Global::new(&system, &num, &comps, solver)))
        };
        let d = system.particles() * system.dim();
        let has_potential = system.has_potential();
        Ok(Rattle {
            h,
            options,
            num,
            path,
            qn: vec![0.0; d],
            pn: vec![0.0; d],
            force: if has_potential {
                vec![0.0; d]
            } else {
                Vec::new()
            },
            has_potential,
            force_stamp: 0,
            potential: f64::NAN,
            stamp: 0,
            run_t0: 0.0,
            run_stamp: 0,
            start_stamp: 0,
            start_step: 0,
            run_step0: 0,
            step_offset: 0,
            thermostat: None,
            q0: Vec::new(),
            multipliers_stamp: 0,
            system,
        })
    }

    /// The system.
    pub fn system(&self) -> &ParticleSystem {
        &self.system
    }

    /// The step size h.
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// The options.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Makes the cluster path use its general kernel (any cluster shape,
    /// run-time sizes) even where a fixed-size kernel applies (every
    /// cluster of a family with the same small shape, e.g. rigid water).
    /// Both give the same steps to round-off; this exists to compare them
    /// (tests, benchmarks). No effect on the coupled paths.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2, 1).unwrap();
    /// let mut rattle = Rattle::new(system, 1e-3, Options::default()).unwrap();
    /// rattle.use_general_cluster_kernel();
    /// ```
    pub fn use_general_cluster_kernel(&mut self) {
        if let Path::Clusters { plans, .. } = &mut self.path {
            plans
                .iter_mut()
                .for_each(|p| (p.fixed, p.settle) = (None, false));
        }
    }

    /// Makes the cluster path solve rigid triangles of distance
    /// constraints (rigid water) by Newton, with the fixed-size kernel,
    /// instead of in closed form (SETTLE). Both solve the same SHAKE and
    /// RATTLE equations and give the same steps to round-off; this exists
    /// to compare them (tests, benchmarks). No effect elsewhere.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2, 1).unwrap();
    /// let mut rattle = Rattle::new(system, 1e-3, Options::default()).unwrap();
    /// assert!(rattle.closed_form_clusters());
    /// rattle.use_newton_cluster_kernel();
    /// assert!(!rattle.closed_form_clusters());
    /// ```
    pub fn use_newton_cluster_kernel(&mut self) {
        if let Path::Clusters { plans, .. } = &mut self.path {
            plans.iter_mut().for_each(|p| p.settle = false);
        }
    }

    /// True when some family's clusters are solved in closed form (rigid
    /// triangles of distance constraints in R³, [`Stencil::DISTANCE`]).
    ///
    /// [`Stencil::DISTANCE`]: super::Stencil::DISTANCE
    pub fn closed_form_clusters(&self) -> bool {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().any(|p| p.settle),
            Path::Global(_) => false,
        }
    }

    /// Independent clusters on the cluster path (1 on the coupled path).
    pub fn clusters(&self) -> usize {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().map(|p| p.len()).sum(),
            Path::Global(_) => 1,
        }
    }

    /// Blocks of clusters the cluster path hands to threads, summed over the
    /// constraint families (0 on the coupled path, and for a family too
    /// small to split or numbered so that no run of its clusters owns a
    /// range of particles of its own). A step runs on the threads of the
    /// rayon pool it is called in (the global pool: all cores, or
    /// `RAYON_NUM_THREADS`) and gives the same numbers, bit for bit, on
    /// any number of them.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, _) = generate::water(2000, 1).unwrap();
    /// let rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// assert!(rattle.cluster_blocks() > 1);
    /// ```
    pub fn cluster_blocks(&self) -> usize {
        match &self.path {
            Path::Clusters { plans, .. } => plans.iter().map(|p| p.blocks.len()).sum(),
            Path::Global(_) => 0,
        }
    }

    /// "clusters", "band" or "sparse": the solver chosen.
    pub fn solver_name(&self) -> &'static str {
        match &self.path {
            Path::Clusters { .. } => "clusters",
            Path::Global(g) => g.solver.name(),
        }
    }

    /// Bytes held by the solver and its workspaces (not the system's tables
    /// or the state).
    pub fn workspace_bytes(&self) -> usize {
        let mut b = (self.qn.capacity() + self.pn.capacity() + self.force.capacity()) * 8;
        match &self.path {
            Path::Clusters { plans, nu, .. } => {
                b += plans.iter().map(|p| p.bytes()).sum::<usize>() + nu.capacity() * 8;
            }
            Path::Global(g) => b += g.bytes(),
        }
        b
    }

    /// True when the cluster path does the velocity stage inside the
    /// position stage (RATTLE without potential: p′ = p½, so each cluster
    /// is projected while its numbers are in L1).
    pub(super) fn fused(&self) -> bool {
        matches!(self.path, Path::Clusters { .. })
            && !self.has_potential
            && self.options.method == Method::Rattle
    }

    fn new_stamp(&mut self) -> u64 {
        self.stamp = STAMPS.fetch_add(1, Ordering::Relaxed);
        self.stamp
    }

    /// A run starts at t0 from the state [`run`](Self::run) was given:
    /// the caches (forces, N's factor, ν) stay in use when that state is
    /// the last one this solver made, so that a run continued from where
    /// the last one stopped takes the same steps as one run.
    pub(super) fn run_from(&mut self, t0: f64) {
        self.run_t0 = t0;
        self.run_stamp = std::mem::take(&mut self.start_stamp);
        self.run_step0 = std::mem::take(&mut self.start_step);
    }

    /// Makes no state count as the last one this solver made: the next
    /// step or run starts from its state as from a new one (the caches
    /// are recomputed, not reused).
    pub(crate) fn forget_last_state(&mut self) {
        self.stamp = 0;
    }

    /// The stamp of the state the last successful step made (0 when the
    /// last step failed or the caches were overwritten since).
    pub(super) fn last_stamp(&self) -> u64 {
        self.stamp
    }

    pub(super) fn check_shape(&self, q: &[f64], p: &[f64]) -> Result<(), StepError> {
        self.check_lengths([("q", q.len()), ("p", p.len())])
    }

    /// `Ok` when every array, given by name and length, has the system's
    /// n·D entries, else [`StepError::Shape`] naming the first that does
    /// not.
    pub(super) fn check_lengths<const K: usize>(
        &self,
        arrays: [(&'static str, usize); K],
    ) -> Result<(), StepError> {
        let expected = self.qn.len();
        match arrays.into_iter().find(|&(_, got)| got != expected) {
            Some((what, got)) => Err(StepError::Shape {
                what,
                got,
                expected,
            }),
            None => Ok(()),
        }
    }

    /// `Ok` when every entry of `v` is finite, else [`StepError::NonFinite`]
    /// at step k naming `what` and the entry of z = (q, p) it is (`v` holds
    /// q, or p or a force on p when `offset` = d).
    pub(super) fn not_finite(
        step: u64,
        time: f64,
        what: &'static str,
        v: &[f64],
        offset: usize,
    ) -> Result<(), StepError> {
        let bad = |x: &f64| !x.is_finite();
        let first = if parallel(v.len()) {
            let n = PARALLEL_PARTICLES;
            let chunk = |(k, c): (usize, &[f64])| c.iter().position(bad).map(|e| k * n + e);
            v.par_chunks(n).enumerate().find_map_first(chunk)
        } else {
            v.iter().position(bad)
        };
        match first {
            Some(entry) => Err(StepError::NonFinite {
                what,
                step,
                t: time,
                entry: offset + entry,
            }),
            None => Ok(()),
        }
    }

    /// ∇V(q) into `self.force` and V(q) into `self.potential`; a
    /// non-finite force is reported at the entry of p it would change.
    pub(super) fn forces(&mut self, q: &[f64], step: u64, time: f64) -> Result<(), StepError> {
        // Until the caller says whose they are, the forces are nobody's.
        self.force_stamp = 0;
        self.potential = self.system.potential_gradient(q, &mut self.force);
        Self::not_finite(step, time, "forces ∇V(q)", &self.force, q.len())
    }

    /// The potential energy V(q) = Σ_fam V_fam(q) + V_ext(q) of `state`
    /// (0 without a potential): read from the last step when `state` is
    /// the one it made, else one evaluation of the forces, which the next
    /// step from `state` then reuses. With
    /// [`ParticleSystem::kinetic_energy`] this gives H along a run at no
    /// extra cost.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, mut state) = generate::water(8, 1).unwrap();
    /// // A weak harmonic tether of every atom to the origin, brought as forces.
    /// let system = system.with_forces(|q: &[f64], f: &mut [f64]| {
    ///     f.iter_mut().zip(q).for_each(|(f, q)| *f -= 1e-3 * q);
    ///     0.5e-3 * q.iter().map(|q| q * q).sum::<f64>()
    /// });
    /// let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// let energy = |r: &mut Rattle, s: &_| {
    ///     r.potential_energy(s).unwrap() + r.system().kinetic_energy(s.p())
    /// };
    /// let h0 = energy(&mut rattle, &state);
    /// assert!(rattle.run_in_place(&mut state, 100).error.is_none());
    /// assert!(((energy(&mut rattle, &state) - h0) / h0).abs() < 1e-3);
    /// ```
    pub fn potential_energy(&mut self, state: &ParticleState) -> Result<f64, StepError> {
        self.check_shape(&state.q, &state.p)?;
        if !self.has_potential {
            return Ok(0.0);
        }
        if state.stamp == 0 || self.force_stamp != state.stamp {
            self.forces(&state.q, state.step, state.time)?;
            // The forces now held are this state's (a state changed by hand
            // has stamp 0 and ties to nothing).
            self.force_stamp = state.stamp;
        }
        // Finite forces do not make V finite (a field of 1e300 times a
        // coordinate of 1e10).
        if !self.potential.is_finite() {
            return Err(StepError::NonFinite {
                what: "potential energy V(q)",
                step: state.step,
                t: state.time,
                entry: 0,
            });
        }
        Ok(self.potential)
    }

    /// The position stage's multipliers ν (one per constraint, in the
    /// families' order) of the RATTLE or SHAKE step that made `state`, and
    /// that step's start positions q0; `None` when `state` is not the last
    /// state this solver made by such a step (a thermostatted step, a
    /// projection or another step since, a state changed by hand).
    pub(super) fn last_position_stage(&self, state: &ParticleState) -> Option<(&[f64], &[f64])> {
        let made = state.stamp != 0 && state.stamp == self.stamp;
        if !(made && self.multipliers_stamp == state.stamp) {
            return None;
        }
        // The step swapped its buffers: `qn` holds the state it started from.
        let nu = match &self.path {
            Path::Clusters { nu, .. } => nu.as_slice(),
            Path::Global(g) => g.nu.as_slice(),
        };
        Some((nu, &self.qn))
    }

    /// A cluster kernel's failure in `stage`, at its family's member.
    fn cluster_error(
        &self,
        f: usize,
        e: ClusterFailure,
        stage: Stage,
        step: u64,
        time: f64,
    ) -> StepError {
        let iterations = e.iterations;
        let (stage, source) = match e.kind {
            FailureKind::NotConverged => (
                stage,
                SolveError::NotConverged {
                    iterations,
                    residual: e.residual,
                },
            ),
            // G(q1) M⁻¹ G(q0)ᵀ, the Newton matrix of the position stage.
            FailureKind::SingularNewton => (stage, SolveError::Singular { iterations }),
            // N = G M⁻¹ Gᵀ: the matrix of the projection onto M^H.
            FailureKind::SingularN => (Stage::Rattle, SolveError::Singular { iterations }),
            FailureKind::NotFinite => (stage, SolveError::NonFinite { iterations }),
        };
        Numbering::member_error(&self.system, f, e.member, stage, step, time, source)
    }

    /// One step of the method from `state` (step k − 1 at t0 + (k−1)h) to
    /// step k at t0 + k·h, in place: RATTLE (or SHAKE), or with a
    /// [`Langevin`] thermostat ([`set_thermostat`](Self::set_thermostat))
    /// a (g-)BAOAB step. On failure the state is left as it was and the
    /// error names step k and time t0 + k·h.
    pub fn step(&mut self, state: &mut ParticleState) -> Result<StepInfo, StepError> {
        self.check_shape(&state.q, &state.p)?;
        let k = state.step + 1;
        let time = state.t0 + k as f64 * self.h;
        // A NaN or infinite t0, or t0 + k·h past f64's range, would be
        // stamped on the state and on every error from here on.
        if !time.is_finite() {
            return Err(StepError::InvalidInput {
                what: "the step's time t0 + k·h must be finite",
                value: time,
            });
        }
        let continued = state.stamp != 0 && state.stamp == self.stamp;
        // The caches (N's factor, ν, forces) are about to be overwritten: a
        // step that fails half-way must not leave them claiming a state.
        self.stamp = 0;
        if !continued {
            Self::not_finite(k, time, "initial state", &state.q, 0)?;
            Self::not_finite(k, time, "initial state", &state.p, state.q.len())?;
        }
        if self.has_potential && !(continued && self.force_stamp == state.stamp) {
            self.forces(&state.q, k, time)?;
        }
        let mut report = particle_report();
        match self.thermostat {
            Some(th) => self.langevin_step(th, state, k, time, &mut report)?,
            None => self.rattle_step(state, continued, k, time, &mut report)?,
        }
        Self::not_finite(k, time, "state", &self.qn, 0)?;
        Self::not_finite(k, time, "state", &self.pn, self.qn.len())?;
        std::mem::swap(&mut state.q, &mut self.qn);
        std::mem::swap(&mut state.p, &mut self.pn);
        state.step = k;
        state.time = time;
        let s = self.new_stamp();
        state.stamp = s;
        self.force_stamp = if self.has_potential { s } else { 0 };
        let projected = self.options.method == Method::Rattle;
        let langevin = self.thermostat.is_some();
        self.multipliers_stamp = if langevin { 0 } else { s };
        match &mut self.path {
            // RATTLE factorised N(q1): the next step's N(q0).
            Path::Global(g) => g.factor_stamp = if projected { s } else { 0 },
            // ν of a full step's position stage (not of a drift's), the
            // next step's first guess.
            Path::Clusters { nu_stamp, .. } => *nu_stamp = if langevin { 0 } else { s },
        }
        Ok(report)
    }

    /// One RATTLE (or SHAKE) step into `self.qn`, `self.pn` from `state`,
    /// the forces of `state.q` already in `self.force`:
    /// p̃ = p0 − (h/2) ∇V(q0), q̃ = q0 + h M⁻¹ p̃, the position stage,
    /// p′ = p½ − (h/2) ∇V(q1), the velocity stage.
    fn rattle_step(
        &mut self,
        state: &ParticleState,
        continued: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let (h, half) = (self.h, 0.5 * self.h);
        let d = self.system.dim();
        let inv_m = self.system.inverse_masses();
        let kick = self.has_potential;
        // p̃ and q̃ particle by particle, in chunks on threads when large.
        let drift = |(((qn, pn), (q, p)), (f, w)): Chunk<'_>| {
            for (a, &wa) in w.iter().enumerate() {
                let w = h * wa;
                for c in a * d..(a + 1) * d {
                    let pt = if kick { p[c] - half * f[c] } else { p[c] };
                    pn[c] = pt;
                    qn[c] = q[c] + w * pt;
                }
            }
        };
        let n = PARALLEL_PARTICLES;
        // (Without a potential the drift reads no force: p stands in.)
        let force: &[f64] = if kick { &self.force } else { &state.p };
        if parallel(inv_m.len()) {
            let (qn, pn) = (self.qn.par_chunks_mut(n * d), self.pn.par_chunks_mut(n * d));
            let (q, p) = (state.q.par_chunks(n * d), state.p.par_chunks(n * d));
            let (f, w) = (force.par_chunks(n * d), inv_m.par_chunks(n));
            qn.zip(pn).zip(q.zip(p)).zip(f.zip(w)).for_each(drift);
        } else {
            drift((
                ((&mut self.qn, &mut self.pn), (&state.q, &state.p)),
                (force, inv_m),
            ));
        }
        self.position_stage(&state.q, state.stamp, continued, 1.0 / h, k, time, report)?;
        if self.options.method == Method::Shake {
            // RATTLE's velocity stage judges q1 at its own scale; without
            // it, the coupled solvers' test at q0's scale is all there is.
            self.confirm_positions(k, time, report)?;
        }
        if self.has_potential {
            self.closing_kick(k, time)?;
        }
        if self.options.method == Method::Rattle {
            if !self.fused() {
                self.velocity_stage(true, k, time, report)?;
            }
            // One linear solve with N = G M⁻¹ Gᵀ.
            report.rattle_iterations = 1;
        }
        Ok(())
    }

    /// p′ = p½ − (h/2) ∇V(q1) on (`self.qn`, `self.pn`): the step's last
    /// kick, with the forces at the new positions, which the next step's
    /// first kick reuses.
    pub(super) fn closing_kick(&mut self, k: u64, time: f64) -> Result<(), StepError> {
        let half = 0.5 * self.h;
        let q1 = std::mem::take(&mut self.qn);
        let r = self.forces(&q1, k, time);
        self.qn = q1;
        r?;
        if parallel(self.force.len()) {
            let kick = |(p, f): (&mut f64, &f64)| *p -= half * f;
            self.pn.par_iter_mut().zip(&self.force).for_each(kick);
        } else {
            for (p, f) in self.pn.iter_mut().zip(&self.force) {
                *p -= half * f;
            }
        }
        Ok(())
    }

    /// Brings initial data onto M and then onto M^H: q ← the point of M
    /// reached by Newton along M⁻¹ G(q)ᵀ (the fibre direction), then
    /// p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0. p is projected even for SHAKE.
    /// Errors report step 0 and the state's time.
    pub fn project(&mut self, state: &mut ParticleState) -> Result<StepInfo, StepError> {
        self.check_shape(&state.q, &state.p)?;
        // The projection overwrites N's factor, G and ν: no state may count
        // as "continued" afterwards (a step of another state would reuse
        // this one's factor: found by the hostile review).
        self.stamp = 0;
        let (k, time) = (state.step, state.time);
        Self::not_finite(k, time, "initial state", &state.q, 0)?;
        Self::not_finite(k, time, "initial state", &state.p, state.q.len())?;
        self.qn.copy_from_slice(&state.q);
        self.pn.copy_from_slice(&state.p);
        let mut report = particle_report();
        self.position_stage(&state.q, 0, false, 0.0, k, time, &mut report)?;
        self.velocity_stage(true, k, time, &mut report)?;
        report.rattle_iterations = 1;
        // As after a step: velocities that overflow (momenta of 1e300 on a
        // mass of 1e-300) make the projection NaN without a failed solve.
        Self::not_finite(k, time, "projected state", &self.qn, 0)?;
        Self::not_finite(k, time, "projected state", &self.pn, self.qn.len())?;
        std::mem::swap(&mut state.q, &mut self.qn);
        std::mem::swap(&mut state.p, &mut self.pn);
        state.stamp = 0;
        Ok(report)
    }

    /// qn: q̃ → q1 with g(q1) = 0; pn: p̃ → p½ (unless inv_h = 0).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn position_stage(
        &mut self,
        q0: &[f64],
        stamp: u64,
        continued: bool,
        inv_h: f64,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let stage = if inv_h != 0.0 {
            Stage::Shake
        } else {
            Stage::ProjectionOntoM
        };
        let args = ClusterArgs {
            q0,
            inv_mass: self.system.inverse_masses(),
            inv_h,
            tol: self.options.tol,
            max_iter: self.options.max_iter,
        };
        let fuse = self.fused() && inv_h != 0.0;
        match &mut self.path {
            Path::Clusters {
                plans,
                nu,
                nu_stamp,
            } => {
                let mut rep = ClusterReport::default();
                // Warm start only along a trajectory (not for projections).
                let warm = inv_h != 0.0 && continued && *nu_stamp == stamp && stamp != 0;
                for (f, fam) in self.system.constraint_families().iter().enumerate() {
                    let (c0, c1) = (self.num.offsets[f], self.num.offsets[f + 1]);
                    let store = if inv_h != 0.0 {
                        Some(&mut nu[c0..c1])
                    } else {
                        None
                    };
                    if let Err(e) = fam.shake_clusters(
                        &plans[f],
                        &args,
                        fuse,
                        store,
                        warm,
                        &mut self.qn,
                        &mut self.pn,
                        &mut rep,
                    ) {
                        return Err(self.cluster_error(f, e, stage, k, time));
                    }
                }
                report.residual = Some(rep.max_rel);
                // (Measured here when the velocity stage ran inside.)
                report.hidden = fuse.then_some(rep.max_hidden);
                report.shake_iterations = rep.max_iter;
                report.shake_iterations_total = rep.iterations;
                Ok(())
            }
            Path::Global(g) => {
                let reuse = continued && g.factor_stamp == stamp && stamp != 0;
                g.position_stage(
                    &self.system,
                    &self.num,
                    &args,
                    reuse,
                    &mut self.qn,
                    &mut self.pn,
                    k,
                    time,
                    report,
                )
            }
        }
    }

    /// On the coupled path, the position stage's result in `qn` judged at
    /// its own scale (the clusters judge every iterate at its own).
    pub(super) fn confirm_positions(
        &mut self,
        k: u64,
        time: f64,
        report: &StepInfo,
    ) -> Result<(), StepError> {
        match &mut self.path {
            Path::Clusters { .. } => Ok(()),
            Path::Global(g) => g.confirm_positions(
                &self.system,
                &self.num,
                &self.qn,
                self.options.tol,
                report.shake_iterations,
                k,
                time,
            ),
        }
    }

    /// pn ← pn − G(qn)ᵀ μ with G(qn) M⁻¹ pn = 0. With
    /// `after_position_stage` (qn was just solved for by a position stage)
    /// the coupled path also confirms g(qn) at qn's own scale, from the
    /// gradients it evaluates there anyway; momenta projected at positions
    /// someone else made are projected wherever those positions are.
    pub(super) fn velocity_stage(
        &mut self,
        after_position_stage: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        // The projection is linear in p: it is solved for p scaled by a
        // power of two (exact) to a largest entry near 1, so that the
        // velocities M⁻¹p it solves with and judges by cannot underflow
        // where p itself is representable (momenta of 1e-283 on masses of
        // 1e91 read as velocities of 0, "on M^H" whatever their direction).
        let scale = power_of_two_near(crate::tolerance::max_abs(&[], &self.pn));
        if scale != 1.0 {
            self.pn.iter_mut().for_each(|p| *p /= scale);
        }
        let r = self.velocity_stage_scaled(after_position_stage, k, time, report);
        if scale != 1.0 {
            self.pn.iter_mut().for_each(|p| *p *= scale);
        }
        r
    }

    /// [`velocity_stage`](Self::velocity_stage) on momenta already scaled.
    fn velocity_stage_scaled(
        &mut self,
        after_position_stage: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        match &mut self.path {
            Path::Clusters { plans, .. } => {
                let mut rep = ClusterReport::default();
                for (f, fam) in self.system.constraint_families().iter().enumerate() {
                    if let Err(e) = fam.project_clusters(
                        &plans[f],
                        self.system.inverse_masses(),
                        &self.qn,
                        &mut self.pn,
                        &mut rep,
                    ) {
                        return Err(self.cluster_error(f, e, Stage::Rattle, k, time));
                    }
                }
                report.hidden = Some(rep.max_hidden);
                Ok(())
            }
            Path::Global(g) => g.velocity_stage(
                &self.system,
                &self.num,
                &self.qn,
                &mut self.pn,
                after_position_stage.then_some(self.options.tol),
                k,
                time,
                report,
            ),
        }
    }
}

/// 2^e with 2^e ≤ x < 2^(e+1) for a positive normal x, so that x / 2^e
/// lies in [1, 2) and dividing or multiplying by it is exact; 1 for 0, a
/// subnormal, ∞ or NaN (nothing to gain, or nothing to scale).
fn power_of_two_near(x: f64) -> f64 {
    if !x.is_normal() {
        return 1.0;
    }
    // The exponent bits alone: the power of two at or below x.
    f64::from_bits(x.to_bits() & 0x7ff0_0000_0000_0000)
}

/// The chunk of the passes over every particle that run on threads:
/// particles per chunk of the drift, entries (particles × D) per chunk of
/// the closing kick and the finiteness checks.
const PARALLEL_PARTICLES: usize = 8192;

/// True when a pass over `n` items (particles or entries, as the pass
/// counts them) is worth handing to threads: more than one chunk of
/// [`PARALLEL_PARTICLES`], and more than one thread.
/// Each entry is computed as on one thread, so the numbers do not depend
/// on the number of threads.
fn parallel(n: usize) -> bool {
    n > PARALLEL_PARTICLES && rayon::current_num_threads() > 1
}

/// One chunk of the drift: (q̃, p̃) out, (q0, p0) and (force, 1/m) in.
type Chunk<'a> = (
    ((&'a mut [f64], &'a mut [f64]), (&'a [f64], &'a [f64])),
    (&'a [f64], &'a [f64]),
);
