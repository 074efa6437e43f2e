//! Large systems of particles with constraint families over run-time
//! topologies: 10³ to 10⁶ constraints.
//!
//! The dense path of [`ConstrainedSystem`](crate::ConstrainedSystem) is
//! unrolled at compile time: every constraint has its own straight-line
//! code and the Newton matrices are dense or banded. That cannot reach a box
//! of 10⁵ rigid waters. Here a constraint *family* is one small function, a
//! [`Stencil`] of the few particles one member touches, applied to every row
//! of a [`Table`] given at run time (the member's particle indices and its
//! numbers, such as a bond length). Code size does not depend on the number
//! of members, and every matrix is stored by its sparsity pattern, found once
//! from the table.
//!
//! # Scope
//!
//! - Positions x_a ∈ R^D of n particles with masses m_a; momenta p_a.
//! - H = Σ_a |p_a|²/(2 m_a) + V(x), V a sum of potential families and of
//!   forces the user brings ([`ForceField`]), possibly none: separable with
//!   quadratic kinetic energy, so Störmer–Verlet is explicit and the base
//!   map of these runs.
//! - Holonomic constraints g_k(x) = 0 only. Coisotropy then holds trivially
//!   ({g_i, g_j} = 0 for any g(q)), and N = G M⁻¹ Gᵀ (G = g_x) is
//!   symmetric positive definite exactly when G has full rank: the one
//!   nondegeneracy condition left, checked on the actual topology.
//!
//! Momentum-dependent constraints stay on the dense path.
//!
//! # Use
//!
//! ```
//! use geoshake_runtime::particles::{
//!     stencils::Distance, Options, ParticleState, ParticleSystem, Rattle, Table,
//! };
//! use geoshake_runtime::Stop;
//!
//! // A bent triatomic: two bonds of length 1 sharing particle 1.
//! let mut bonds = Table::new(2, 1);
//! bonds.push(&[0, 1], &[1.0]).unwrap();
//! bonds.push(&[1, 2], &[1.0]).unwrap();
//! let system = ParticleSystem::new(3, vec![1.0, 2.0, 1.0])
//!     .unwrap()
//!     .with_constraints("bond", Distance::<3>, bonds)
//!     .unwrap();
//! let q = vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
//! let p = vec![0.0, 0.3, 0.1, 0.0, 0.0, 0.0, 0.2, 0.0, -0.1];
//! let mut state = ParticleState::new(q, p);
//!
//! // The symbolic phase: clusters, checks, solver, workspaces.
//! let mut rattle = Rattle::new(system, 0.01, Options::default()).unwrap();
//! rattle.project(&mut state).unwrap(); // onto M, then onto M^H
//! // The engine's one driver: stride, observers, the partial trajectory on
//! // failure, CSV and Arrow files, as for any run.
//! let out = rattle.run(&state, Stop::Steps(1000)).stride(100).execute();
//! assert_eq!((out.trajectory.len(), rattle.solver_name()), (11, "clusters"));
//! let summary = out.summary;
//! assert!(summary.max_residual.unwrap() <= 1e-10 && summary.max_hidden.unwrap() < 1e-12);
//! ```
//!
//! Design, tolerances and measured costs: `docs/scale.md`.

mod adjust;
mod cluster;
mod error;
mod family;
mod forces;
pub mod generate;
mod global;
mod graph;
pub mod io;
mod langevin;
mod options;
mod plan;
mod rattle;
mod run;
mod state;
mod stencil;
pub mod stencils;
mod system;
mod table;
mod thermostat;
mod virial;

pub use crate::report::StepInfo;
pub use error::TopologyError;
pub use family::{ClusterKernel, ConstraintFamily, PotentialFamily};
pub use forces::ForceField;
pub use options::{Method, Options, SolverChoice};
#[doc(hidden)]
pub use plan::{ClusterArgs, ClusterFailure, ClusterReport, FamilyClusters};
pub use rattle::Rattle;
pub use state::ParticleState;
pub use stencil::Stencil;
pub use system::ParticleSystem;
pub use table::Table;
pub use thermostat::{Langevin, MAX_SUBSTEPS};
pub use virial::ConstraintForces;
