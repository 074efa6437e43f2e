//! # geoshake-runtime
//!
//! The numerical half of shake: the traits a declared system implements
//! ([`Hamiltonian`], [`ConstrainedSystem`]), base maps, fibre flows, and the
//! geometric SHAKE and RATTLE drivers of McLachlan, Modin, Verdier and
//! Wilkins.
//!
//! # From a system to a trajectory
//!
//! A system (declared with `constrained_system!`, or written by hand as in
//! [`examples`]) is integrated by an [`Integrator`] built from the system, a
//! [`BaseMap`] φ_h ([`ImplicitMidpoint`], [`StormerVerlet`],
//! [`SymplecticEuler`]) and a step size h:
//!
//! ```
//! use geoshake_runtime::{Integrator, ImplicitMidpoint, State, Stop, examples::Pendulum};
//!
//! let pendulum = Pendulum { gravity: 9.81, length: 1.0 };
//! let mut rattle = Integrator::new(pendulum, ImplicitMidpoint, 0.01).rattle().with_diagnostics();
//! // Bring a rough initial guess onto M^H = {g = 0, {g,H} = 0}.
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[0.7, -0.7], &[1.0, 1.0])).unwrap();
//! // Ten seconds, one stored state every 100 steps.
//! let out = rattle.run(z0, Stop::Time(10.0)).stride(100).execute();
//! let traj = out.into_result().expect("a pendulum is well posed");
//! let e0 = traj.diagnostics[0].energy;
//! for d in &traj.diagnostics {
//!     assert!(d.constraint < 1e-13 && d.hidden_constraint < 1e-12);
//!     assert!((d.energy - e0).abs() < 1e-3 * e0.abs());
//! }
//! ```
//!
//! # The methods (the paper's Sections 1 and 4)
//!
//! - SHAKE: S_h(z0) = φ_h(exp(Σ λ_i X_{g_i})(z0)) with g(S_h(z0)) = 0, λ found
//!   by Newton's method from λ = 0 with the Jacobian
//!   g_z(z1⁻) · Dφ_h(y) · X_{g_j}(y) (the base map's tangent map; exact when
//!   the X_{g_i} commute, a simplified Newton otherwise), nested with the base
//!   map's own stage iteration. λ is the fibre parameter itself: for holonomic
//!   g and Störmer–Verlet, λ = (h/2) λ_classical of Section 5.1.3. (The
//!   module is private: `geoshake::shake` would clash with the facade crate.)
//! - [`rattle`]: R_h = Π ∘ S_h, Π the projection along the fibre onto M^H.
//! - [`fibre`]: the fibre flows exp(Σ λ_i X_{g_i}), exact to round-off.
//! - [`newton`]: every implicit equation is solved to round-off.
//! - [`diagnostics`] and [`error`]: what a run measures, and how it fails.
//! - [`io`]: a trajectory as CSV and back; with the `arrow` feature,
//!   `io_arrow`: as an Arrow IPC (Feather v2) file and back.
//! - with the `progress` feature, `progress`: an indicatif bar on a run's
//!   per-step hook.
//!
//! # How a step is made
//!
//! Three layers, each a module that reads alone:
//!
//! - [`step`]: the step maps. A substep map (SHAKE S_{γh}, then Π when the
//!   substep is projected, so R_{γh}) owns its base map and its workspaces;
//!   a composed step (Section 4) holds one for the substeps γ_k h and a
//!   second for its reverse check. SHAKE's Newton iteration has a general
//!   path (`shake`: through the base map and the fibre flow) and, for
//!   holonomic g with separable H and a kick–drift–kick base map, the
//!   classical one (`classical`: positions only, an analytic Jacobian,
//!   on stack arrays for the systems `constrained_system!` declares with one
//!   to eight constraints).
//! - [`guard`]: every check a (sub)step's result must pass, configured by
//!   [`Options`]: finite, on M to round-off, N = {{H,g_i},g_j} well
//!   conditioned and on the same component, λ and σ near their linear
//!   predictions.
//! - [`run`]: the driver: stop rules, stride, storage, observers,
//!   diagnostics, the trajectory so far on error.
//!
//! [`Integrator`] is the facade that holds a system, a step map and a guard.
#![warn(missing_docs)]
// Numerical kernels index several arrays with one loop variable, as the
// formulas do; iterator chains would hide them.
#![allow(clippy::needless_range_loop)]
// `!(x <= limit)` is deliberate throughout: it is true for NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod base_map;
pub mod compensated;
pub mod composition;
pub mod diagnostics;
pub mod ensemble;
#[cfg(feature = "mpi")]
pub mod ensemble_mpi;
pub mod ensemble_store;
pub mod error;
pub mod examples;
pub mod fibre;
pub mod guard;
mod initial_data;
pub mod integrator;
pub mod io;
#[cfg(feature = "arrow")]
pub mod io_arrow;
mod keep_positions;
mod linalg;
pub mod newton;
pub mod particles;
#[cfg(feature = "progress")]
pub mod progress;
pub mod rattle;
pub mod report;
pub mod run;
pub mod sampler;
mod shake;
pub mod solver;
mod state;
pub mod step;
pub mod system;
mod tolerance;
mod trajectory;
mod unconstrained;
pub mod validate;

pub use base_map::{BaseMap, BaseMapWorkspace, ImplicitMidpoint, StormerVerlet, SymplecticEuler};
pub use composition::Composition;
pub use diagnostics::DiagnosticRecord;
pub use ensemble::{ensemble, run_ensemble};
pub use error::{SolveError, Stage, StepError};
pub use fibre::FibreFlow;
pub use integrator::{
    Integrator, Method, Options, Run, RunOutcome, RunSummary, StepEvent, StepInfo, Stop, Trajectory,
};
/// The MPI bindings (rsmpi) the distributed ensembles use, for initialising
/// MPI and naming communicators.
#[cfg(feature = "mpi")]
pub use mpi;
pub use nalgebra;
pub use newton::NewtonOptions;
/// Re-exported for [`ensemble()`]: its thread pools.
pub use rayon;
pub use state::{State, StateError};
pub use system::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, SizeVisitor};
pub use unconstrained::Unconstrained;
