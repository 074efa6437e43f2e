//! A tolerance below what the coordinates resolve: far from the origin a
//! coordinate x is known to ε|x| only, and a member's relative residual
//! cannot go below ≈ ε ‖x‖ / extent (`tolerance::roundoff_floor`). The
//! Newton iterations accept a stalled residual there (reporting it as it
//! is) instead of spending their budget and failing.

use geoshake::runtime::particles::{generate, Options, ParticleState, Rattle, SolverChoice};

/// The state moved by `shift` in every coordinate.
fn shifted(state: &ParticleState, shift: f64) -> ParticleState {
    let q = state.q().iter().map(|x| x + shift).collect();
    ParticleState::new(q, state.p().to_vec())
}

/// `steps` steps at the default tolerance (1e-12) of a box moved 10⁶ Å
/// from the origin, where a bond of 1 Å is resolved to ≈ 1e-10 only: every
/// step succeeds, and the largest residual is above the tolerance but
/// within the round-off floor 4ε ‖x‖ / extent of one bond.
fn far_from_the_origin(
    (system, state): (geoshake::runtime::particles::ParticleSystem, ParticleState),
    solver: SolverChoice,
    bond: f64,
) -> u64 {
    let shift = 1e6;
    let options = Options {
        solver,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, 2.0, options).unwrap();
    let mut state = shifted(&state, shift);
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    let out = rattle.run_in_place(&mut state, 20);
    assert!(out.error.is_none(), "{:?}", out.error);
    let worst = out.summary.max_residual.unwrap();
    // Two particles of a bond at ≈ (10⁶, 10⁶, 10⁶): ‖x‖ ≈ √6 · 10⁶, and
    // extent = bond / √2.
    let floor = 4.0 * f64::EPSILON * 6f64.sqrt() * shift * 1.05 / (bond / 2f64.sqrt());
    assert!(
        worst <= floor,
        "residual {worst:e} above the floor {floor:e}"
    );
    // The case must put the floor above the tolerance (else it tests
    // nothing).
    let tol = rattle.options().tol;
    assert!(tol < floor, "tolerance {tol:e}, floor {floor:e}");
    out.summary.newton_iterations
}

#[test]
fn water_far_from_the_origin_converges_to_round_off_on_the_cluster_path() {
    far_from_the_origin(
        generate::water(50, 3).unwrap(),
        SolverChoice::Clusters,
        generate::R_OH,
    );
}

#[test]
fn a_chain_far_from_the_origin_converges_to_round_off_on_the_band_path() {
    far_from_the_origin(
        generate::chain(200, 3).unwrap(),
        SolverChoice::Band,
        generate::BOND,
    );
}

#[test]
fn a_chain_far_from_the_origin_converges_to_round_off_on_the_sparse_path() {
    far_from_the_origin(
        generate::chain(200, 3).unwrap(),
        SolverChoice::Sparse,
        generate::BOND,
    );
}
