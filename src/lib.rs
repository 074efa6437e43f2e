//! This facade re-exports the two crates: [`constrained_system!`] (from
//! `geoshake-macros`) declares a system and generates its derivatives at compile
//! time; [`runtime`] (`geoshake-runtime`) integrates it. [`prelude`] gathers
//! what a first program needs (`use geoshake::prelude::*;`). The README below is
//! the crate's front page, and its example is compiled and run as a doctest.
//!
//! # Non-autonomous systems: time as a coordinate
//!
//! The methods integrate autonomous H(q, p). A Hamiltonian or constraint that
//! depends on time is declared in *extended phase space*: q₀ = t, its
//! conjugate momentum p₀ = p_t, and H̃ = H(q, p, t) + p_t. Then
//! t' = ∂H̃/∂p_t = 1, −p_t follows the energy (p_t' = −∂H/∂t − g_tᵀλ), and a
//! constraint g(q, t) is an ordinary one in the extended q. H̃ is autonomous,
//! so the paper's results (symplecticity on Mᴴ, order 2, no drift in H̃) hold
//! as they are. Details in `docs/non_autonomous.md`; a worked example in
//! `examples/forced_pendulum.rs`; a convergence test against an independent
//! solution in `tests/suite/forced_pendulum.rs`.
//!
//! ```
//! use geoshake::prelude::*;
//!
//! constrained_system! {
//!     /// A pendulum whose pivot moves as y = amplitude·cos(omega·t).
//!     pub struct ShakenPendulum {
//!         parameters { length, gravity, amplitude, omega }
//!         coordinates t, x, y;
//!         momenta p_t, p_x, p_y;
//!         hamiltonian = (p_x^2 + p_y^2) / 2 + gravity * y + p_t;
//!         constraints { rod: x^2 + (y - amplitude * cos(omega * t))^2 - length^2 }
//!     }
//! }
//!
//! # fn main() -> Result<(), StepError> {
//! let sys = ShakenPendulum::new(1.0, 9.81, 0.1, 5.0);
//! let mut rattle = Integrator::new(sys, StormerVerlet, 0.01).rattle();
//! // t = 0, bob beside the pivot (at y = 0.1) and at rest; p_t is free.
//! let z0 = rattle.project_to_hidden(&State::from_slices(&[0.0, 1.0, 0.1], &[0.0; 3]))?;
//! let out = rattle.run(z0, Stop::Steps(100)).execute();
//! let z = out.trajectory.last().unwrap();
//! assert!((z.q[0] - 1.0).abs() < 1e-12); // q₀ is the time: 100 steps of 0.01
//! # Ok(())
//! # }
//! ```
//!
#![doc = include_str!("../README.md")]

// Generated code names `::geoshake::...`; this lets the facade declare systems
// (the `models` below) with the macro too.
extern crate self as geoshake;

pub mod declared;
pub mod models;
#[cfg(feature = "plot")]
pub mod plot;
pub mod prelude;

pub use geoshake_macros::constrained_system;
pub use geoshake_runtime as runtime;
pub use geoshake_runtime::*;

/// Re-exported so that generated code and users name one `nalgebra`.
pub use nalgebra;
