//! A tolerance below what the coordinates resolve: far from the origin a
//! coordinate x is known to ε|x| only, and a member's relative residual
//! cannot go below ≈ ε ‖x‖ / extent (`tolerance::roundoff_floor`). The
//! Newton iterations accept a stalled residual there (reporting it as it
//! is) instead of spending their budget and failing.

use geoshake::declared::DeclaredParticles;
use geoshake::runtime::particles::{
    generate, stencils::Distance, Options, ParticleState, ParticleSystem, Rattle, SolverChoice,
    Table,
};

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

/// A bond of 1 at 4·10¹⁵, where a coordinate's ulp is 0.5: nothing can
/// resolve it, and its round-off floor (above 1) is capped at √ε, so a step
/// fails instead of passing a bond of any length.
#[test]
fn a_bond_beyond_resolution_fails_instead_of_passing() {
    let x = 4e15;
    let mut bond = Table::new(2, 1);
    bond.push(&[0, 1], &[1.0]).unwrap();
    let system = ParticleSystem::new(3, vec![1.0, 1.0])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bond)
        .unwrap();
    let mut rattle = Rattle::new(system, 0.1, Options::default()).unwrap();
    let mut state = ParticleState::new(
        vec![x, x, x, x + 1.0, x, x],
        vec![0.0, 3.0, 0.0, 0.0, -3.0, 0.0],
    );
    for step in 1..=5 {
        let before = state.clone();
        match rattle.step(&mut state) {
            Err(_) => {
                state = before;
            }
            Ok(info) => {
                let q = state.q();
                let r =
                    ((q[0] - q[3]).powi(2) + (q[1] - q[4]).powi(2) + (q[2] - q[5]).powi(2)).sqrt();
                panic!(
                    "step {step} passed: residual {:?}, |r| = {r}",
                    info.residual
                );
            }
        }
    }
}

/// A dimer projected onto M from 100 bond lengths away, at 10⁸ from the
/// origin (floor ≈ 1.5e-8, the cap): the stall is judged and reported at
/// the result's own scale, not at the far start's (which is 10⁴ times
/// smaller and reported 1e-12 for a bond error of 1e-8).
#[test]
fn a_projection_reports_the_residual_at_its_own_scale() {
    let (x, far) = (1e8, 100.0);
    let mut bond = Table::new(2, 1);
    bond.push(&[0, 1], &[1.0]).unwrap();
    let system = ParticleSystem::new(3, vec![1.0, 1.0])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bond)
        .unwrap();
    let mut rattle = Rattle::new(system, 0.1, Options::default()).unwrap();
    let mut state =
        ParticleState::new(vec![x, x, x, x + 0.6 * far, x + 0.8 * far, x], vec![0.0; 6]);
    let info = rattle.project(&mut state).unwrap();
    {
        let q = state.q();
        let r = ((q[0] - q[3]).powi(2) + (q[1] - q[4]).powi(2) + (q[2] - q[5]).powi(2)).sqrt();
        let actual = (r - 1.0).abs();
        let reported = info.residual.unwrap();
        assert!(
            reported >= 0.5 * actual,
            "reported {reported:e}, bond error {actual:e}"
        );
    }
}

/// The dimer of the string declaration (a tape stencil), as from Python.
const DIMER: &str = "struct Dimer {
    particles x[3];
    constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
}";

/// A free dimer (masses 2 and 1, a bond of 1, RATTLE at h = 0.02, the
/// default tolerance 1e-12) turning in the plane at 10⁴, 10⁵ and 10⁶ from
/// the origin. Once its axis is a degree off the x axis, Newton's update
/// along the bond is below half an ulp of the large x coordinates and is
/// lost; only the small y coordinates move, by the ≈ 2 % of ∇g they carry,
/// and the residual creeps down by a few 1e-4 per iteration without ever
/// failing to go down: the budget ran out (step 10 at 10⁴, step 2 at 10⁶)
/// at a residual far inside the round-off floor. Every step must pass, by
/// the fixed-size kernel and by the general one, for the hand-written
/// stencil and the declared one, with the bond at its coordinates'
/// round-off.
#[test]
fn a_turning_dimer_far_from_the_origin_runs_with_its_bond_at_round_off() {
    let d = 1.0;
    for x in [1e4, 1e5, 1e6] {
        for declared in [false, true] {
            for general in [false, true] {
                let mut bond = Table::new(2, 1);
                bond.push(&[0, 1], &[d]).unwrap();
                let masses = vec![2.0, 1.0];
                let system = if declared {
                    let dimer = DeclaredParticles::new(DIMER, &[]).unwrap();
                    dimer.system(masses, vec![bond]).unwrap()
                } else {
                    ParticleSystem::new(3, masses)
                        .unwrap()
                        .with_constraints("bond", Distance::<3>, bond)
                        .unwrap()
                };
                let mut rattle = Rattle::new(system, 0.02, Options::default()).unwrap();
                if general {
                    rattle.use_general_cluster_kernel();
                }
                let mut state = ParticleState::new(
                    vec![x, 0.0, 0.0, x + d, 0.0, 0.0],
                    vec![0.0, 0.0, 0.0, 0.0, 0.1, 0.0],
                );
                rattle.project(&mut state).unwrap();
                let tol = rattle.options().tol;
                for step in 1..=2000 {
                    let info = rattle.step(&mut state).unwrap_or_else(|e| {
                        panic!("x = {x:e}, declared {declared}, general {general}: {e}")
                    });
                    let q = state.q();
                    let norm = |a: &[f64]| a.iter().map(|v| v * v).sum::<f64>().sqrt();
                    let xmax = norm(&q[..3]).max(norm(&q[3..]));
                    // The stall is accepted at the floor 4ε ‖x_member‖ /
                    // extent (`tolerance::roundoff_floor`). For a dimer the
                    // relative residual | |r|² − d² | / (|∇g| · extent),
                    // with |∇g| = 2√2 |r| and extent = |r| / √2, is
                    // | |r| − d | / d to first order, and ‖x_member‖ ≤
                    // √2 · xmax: so the bond error is at most
                    // 4ε · √2 xmax · √2 / d = 8ε xmax / d, plus the few ε
                    // of measuring |r| below (its differences are exact or
                    // of small coordinates), far inside it here.
                    let bound = 8.0 * f64::EPSILON * xmax / d;
                    assert!(tol < bound, "the floor must be above the tolerance");
                    let r = ((q[0] - q[3]).powi(2) + (q[1] - q[4]).powi(2) + (q[2] - q[5]).powi(2))
                        .sqrt();
                    let err = (r - d).abs() / d;
                    assert!(
                        err <= bound && info.residual.unwrap() <= bound,
                        "x = {x:e}, declared {declared}, general {general}, step {step}: \
                         bond error {err:e}, residual {:?}, bound {bound:e}",
                        info.residual
                    );
                }
            }
        }
    }
}
