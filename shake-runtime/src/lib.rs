//! # shake-runtime
//!
//! The numerical half of shake: the traits a declared system implements
//! ([`Hamiltonian`], [`ConstrainedSystem`]), base maps, fibre flows, and the
//! geometric SHAKE and RATTLE drivers of McLachlan, Modin, Verdier and
//! Wilkins.
#![warn(missing_docs)]

pub mod system;

pub use system::{ConstrainedSystem, ConstraintKind, Hamiltonian};
