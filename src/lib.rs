//! This facade re-exports the two crates: [`constrained_system!`] (from
//! `shake-macros`) declares a system and generates its derivatives at compile
//! time; [`runtime`] (`shake-runtime`) integrates it. [`prelude`] gathers
//! what a first program needs (`use shake::prelude::*;`). The README below is
//! the crate's front page, and its example is compiled and run as a doctest.
//!
#![doc = include_str!("../README.md")]

// Generated code names `::shake::...`; this lets the facade declare systems
// (the `models` below) with the macro too.
extern crate self as shake;

pub mod models;
pub mod prelude;

pub use shake_macros::constrained_system;
pub use shake_runtime as runtime;
pub use shake_runtime::*;

/// Re-exported so that generated code and users name one `nalgebra`.
pub use nalgebra;
