//! The integration tests, one module per subject, in one binary: linked
//! once instead of once per file (47 links took most of a fresh clone's test
//! build). Run one subject with `cargo test --release --test suite <module>::`.
//!
//! Allocation counts (the `*_alloc` modules) are per thread
//! (`geoshake_testkit::alloc`), so the harness may run the other modules
//! alongside them.

#[global_allocator]
static GLOBAL: geoshake_testkit::alloc::Counting = geoshake_testkit::alloc::Counting;

// The test kit under the name the tests use (`common::models`, …).
use geoshake_testkit as common;

mod banded_nondegeneracy;
mod capitalised_parameters;
mod classical_agrees;
mod constraint_forces;
mod custom_base_map;
mod declarations;
mod declared_particles;
mod declared_systems;
mod error_variants;
mod fast_paths;
mod fibre_closed_form;
mod forced_pendulum;
mod hard_degenerate;
mod hard_inputs;
mod hard_largest_step;
mod hard_random_systems;
mod hopf_pair;
mod keep_positions;
mod limit_agrees;
mod macro_systems;
mod macro_topology;
mod macro_topology_run;
mod macro_translation;
mod oracle;
mod order_compositions;
mod packed_jacobian;
mod paper_claims;
mod paper_hopf;
mod particles_adjust;
mod particles_alloc;
mod particles_driver;
mod particles_ensemble;
mod particles_errors;
mod particles_forces;
mod particles_io;
mod particles_langevin;
mod particles_overflow;
mod particles_paths;
mod particles_result_scale;
mod particles_review;
mod particles_rings;
mod particles_roundoff;
mod particles_settle;
mod particles_threads;
mod particles_virial;
mod perf_alloc;
mod perf_derivatives;
mod reference_selftest;
mod roundoff_nondegeneracy;
mod roundoff_projection;
mod run_lane;
mod runtime_alloc;
mod runtime_convergence;
mod runtime_errors;
mod runtime_invariants;
mod runtime_models;
mod runtime_proptest;
mod runtime_symplectic;
mod sampler;
mod scale_invariance;
mod trajectory_csv;
mod water_md;
