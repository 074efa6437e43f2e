//! Benchmark support: the systems benchmarked and the baselines they are
//! measured against.

pub mod chain;
pub mod dual;
pub mod limit;
pub mod report;
pub mod systems;
