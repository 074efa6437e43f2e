//! The test kit of shake: what the tests, examples and benches share, in one
//! crate instead of `#[path]` includes. Not published.
//!
//! - [`models`]: hand-written systems (pendulum, spherical and double
//!   pendulum, the Hopf constraint, degenerate and index-five cases), with
//!   derivatives checked against finite differences in `tests/suite/runtime_models.rs`;
//! - [`reference`](mod@reference): an integrator and exact solutions independent of the
//!   runtime (dual-number derivatives, high-order collocation, closed forms);
//! - [`alloc`]: a counting global allocator for the no-allocation tests;
//! - [`fuzz`]: the hostile-input suites' driver (seeded cases, a watchdog,
//!   counts by verdict);
//! - [`hopf_lab`]: the computations behind the Section 5.4 scenes and
//!   `tests/suite/paper_hopf.rs`;
//! - [`plot`]: the figure helpers of the paper scene (`paper/`) and
//!   `shake-bench/benches/work_precision.rs`;
//! - [`bench`](mod@bench): chains, dual-number baselines, the hand-written limit and the
//!   report tables of `shake-bench/benches/step_cost.rs`, `shake-bench/benches/scaling.rs` and
//!   `examples/overhead.rs`.
#![allow(clippy::needless_range_loop)]
// The macro's generated docs for the bench chains quote index expressions
// (`q[2*k]`) that rustdoc reads as links, and some moved module docs show
// formulas in indented blocks; the crate is not published and its docs are
// read in the source.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_rust_codeblocks)]

pub mod alloc;
pub mod bench;
#[cfg(feature = "fuzz")]
pub mod fuzz;
pub mod hopf_lab;
pub mod models;
pub mod plot;
pub mod reference;
pub mod same_bits;
pub mod starts;
