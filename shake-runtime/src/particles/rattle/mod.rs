//! RATTLE and SHAKE with Störmer–Verlet on a [`ParticleSystem`]: the
//! solver [`Rattle`], its construction (the symbolic phase: the constraint
//! graph, its clusters and the choice of solver) and the stamps that tie a
//! state to the solver's caches. The step, the stages and the projection,
//! the input checks, the forces and the solver's description are its
//! submodules.

use std::sync::atomic::{AtomicU64, Ordering};

use super::global::Global;
use super::graph::{self, Numbering};
use super::options::{Method, Options, SolverChoice};
use super::plan::{parallel, FamilyClusters, PARALLEL_PARTICLES};
use super::thermostat::Langevin;
use super::ParticleSystem;
use crate::error::StepError;
use crate::report::StepInfo;
use crate::solver::SpdSolver;

mod checks;
mod potential;
mod solver_info;
mod stages;
mod step;

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
}
