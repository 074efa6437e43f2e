//! N at round-off relative to its terms is singular (Section 5.2).
//!
//! For one constraint the condition number of N is always 1, so a start
//! where N = {{H,g},g} is a rounding error away from 0 passed every
//! run-time check: the runtime then solved with N⁻¹ of size 1/ε. The test
//! system is the Hopf constraint g = |q|² + |p|² − 1 with H = |p|²/2
//! (`HopfHarmonic`): at q = (a, 0), p = (0, b) with a² + b² = 1 the state is
//! on M^H ({g,H} = 2 q·p = 0) and N = 4(a² − b²), while the terms of N
//! (4a² and 4b²) sum to 4 (derived in `rattle::nondegeneracy_terms`). With
//! a² − b² = δ the condition relative to the terms is 1/δ: above the
//! default limit 1e10 for δ = 1e-13, a rounding error's worth of N, and
//! below it for δ = 1e-6, a genuinely small but solvable N.

use geoshake::examples::HopfHarmonic;
use geoshake::prelude::*;
use geoshake::runtime::Stage;

/// The state on M^H with a² − b² = δ, N = 4δ.
fn near_exceptional_fibre(delta: f64) -> State {
    let a = ((1.0 + delta) / 2.0).sqrt();
    let b = ((1.0 - delta) / 2.0).sqrt();
    State::from_slices(&[a, 0.0], &[0.0, b])
}

fn integrator() -> Integrator<HopfHarmonic, ImplicitMidpoint> {
    Integrator::new(HopfHarmonic::unit(), ImplicitMidpoint, 0.01)
}

#[test]
fn a_projection_onto_an_n_at_round_off_is_refused() {
    let z = near_exceptional_fibre(1e-13);
    match integrator().project_to_hidden(&z) {
        Err(StepError::NondegeneracyLost {
            stage: Stage::Rattle,
            step: 0,
            condition,
            ..
        }) => {
            // 1/δ up to the rounding of δ itself (a² − b² is computed).
            assert!((5e12..2e13).contains(&condition), "{condition:e}");
        }
        other => panic!("N = 4e-13 against terms of 4 was accepted: {other:?}"),
    }
}

#[test]
fn a_run_and_a_step_from_an_n_at_round_off_are_refused_at_step_0() {
    let z = near_exceptional_fibre(1e-13);
    let out = integrator().run(z.clone(), Stop::Steps(3)).execute();
    assert!(
        matches!(
            out.error,
            Some(StepError::NondegeneracyLost { step: 0, .. })
        ),
        "{:?}",
        out.error
    );
    assert!(
        matches!(
            integrator().step(&z),
            Err(StepError::NondegeneracyLost { step: 0, .. })
        ),
        "a single step"
    );
}

/// The start is accepted; how far a run then gets is another matter: near
/// the exceptional fibre λ = N⁻¹b is of size h/δ, and Newton needs h well
/// below δ (at h = 0.01 the first step does not converge, a typed error at
/// step 1).
#[test]
fn a_small_n_well_above_its_round_off_is_accepted() {
    let z = near_exceptional_fibre(1e-6);
    let mut integ = integrator();
    let z = integ
        .project_to_hidden(&z)
        .expect("N = 4e-6 against terms of 4");
    let mut integ = Integrator::new(HopfHarmonic::unit(), ImplicitMidpoint, 1e-8);
    let out = integ.run(z, Stop::Steps(3)).execute();
    assert!(out.error.is_none(), "{:?}", out.error);
}
