//! What a first program needs, in one import: `use geoshake::prelude::*;`.
//!
//! The macro that declares a system ([`constrained_system!`]), the
//! integrator and its run controls ([`Integrator`], [`Method`], [`Options`],
//! [`Stop`], [`Trajectory`], [`RunOutcome`]), the base maps the paper builds
//! SHAKE and RATTLE on ([`ImplicitMidpoint`], [`StormerVerlet`],
//! [`SymplecticEuler`]) and their higher-order compositions
//! ([`Composition`]), the phase-space point [`State`], the per-step record
//! [`DiagnosticRecord`], the typed errors ([`StepError`], [`SolveError`]),
//! and the traits whose methods a user calls on a declared system
//! ([`ConstrainedSystem`], [`Hamiltonian`], [`BaseMap`]).
//!
//! Everything else stays under [`crate::runtime`] (Newton options, fibre
//! flows, ensembles, the particle path) and [`crate::models`] (the paper's
//! systems, ready-made).
//!
//! ```
//! use geoshake::prelude::*;
//!
//! constrained_system! {
//!     /// A planar pendulum: unit mass on a rod of length `length`.
//!     pub struct Pendulum {
//!         parameters { length, gravity }
//!         dof q[2], p[2];
//!         hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
//!         constraints { rod: q[0]^2 + q[1]^2 - length^2 }
//!     }
//! }
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut rattle = Integrator::new(Pendulum::new(1.0, 9.81), StormerVerlet, 0.01)
//!     .rattle()
//!     .with_diagnostics();
//! // A rough start, brought onto Mᴴ = {g = 0, {g,H} = 0}.
//! let z0: State = rattle.project_to_hidden(&State::from_slices(&[1.0, 0.1], &[0.0, 0.0]))?;
//! let traj: Trajectory = rattle
//!     .run(z0, Stop::Time(1.0))
//!     .execute()
//!     .into_result()
//!     .map_err(|(_partial, e): (Trajectory, StepError)| e)?;
//! let last: &DiagnosticRecord = traj.diagnostics.last().unwrap();
//! // RATTLE keeps both the constraint and the hidden constraint to round-off.
//! assert!(last.constraint < 1e-13 && last.hidden_constraint < 1e-12);
//! # Ok(())
//! # }
//! ```

pub use geoshake_macros::constrained_system;
pub use geoshake_runtime::{
    BaseMap, ClosedForm, Composition, ConstrainedSystem, DiagnosticRecord, Hamiltonian,
    ImplicitMidpoint, Integrator, Method, Options, RunOutcome, SolveError, State, StepError, Stop,
    StormerVerlet, SymplecticEuler, Trajectory,
};
