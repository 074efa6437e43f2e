//! Every failure the runtime knows is provoked here and must come back as
//! its typed error, with the numbers that explain it, and — from `run` —
//! with the trajectory computed before it: nothing is lost.

use crate::common;

use common::models::*;
use geoshake::{
    ImplicitMidpoint, Integrator, Options, Stage, State, StepError, Stop, StormerVerlet,
    SymplecticEuler,
};

const PAPER_Z_A: [f64; 4] = [
    -0.78652612,
    -0.4043988,
    -0.3880746864163783,
    0.2173391755798215,
];

#[test]
fn newton_not_converged_mid_run_keeps_the_trajectory() {
    // A pendulum swinging over the top with a step far too large: after a
    // few steps there is no λ with g(φ_h(y)) = 0 near 0.
    let sys = Pendulum::default();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.5);
    let out = integ.run(sys.state(1.0, 2.0), Stop::Steps(50)).execute();
    let Some(StepError::NewtonNotConverged {
        stage,
        step,
        t,
        source,
        ..
    }) = out.error.clone()
    else {
        panic!("expected NewtonNotConverged, got {:?}", out.error);
    };
    assert_eq!(stage, Stage::Shake);
    assert!(step > 1, "the failure should come mid-run (step {step})");
    // The time of the step attempted, t0 + k·h, not its start.
    assert_eq!(t, step as f64 * 0.5);
    assert!(
        matches!(source, geoshake::SolveError::NotConverged { iterations: 50, residual } if residual > 1e-3)
    );
    // States 0, 1, …, step − 1 are all there, on M^H.
    assert_eq!(out.trajectory.steps(), (0..step).collect::<Vec<_>>());
    for z in out.trajectory.states() {
        let z = &z;
        assert!((z.q.norm_squared() - 1.0).abs() < 1e-14);
        assert!(z.q.dot(&z.p).abs() < 1e-13);
    }
    let msg = out.error.unwrap().to_string();
    assert!(
        msg.contains("Newton did not converge") && msg.contains("residual"),
        "{msg}"
    );
}

#[test]
fn newton_budget_is_typed() {
    let sys = Pendulum::default();
    let opts = Options {
        newton: geoshake::NewtonOptions {
            max_iterations: 1,
            ..Default::default()
        },
        ..Options::default()
    };
    let mut integ = Integrator::new(sys, ImplicitMidpoint, 0.1).with_options(opts);
    let err = integ.step(&sys.state(0.5, 0.5)).unwrap_err();
    assert!(
        matches!(err, StepError::NewtonNotConverged { .. }),
        "{err:?}"
    );
}

#[test]
fn nondegeneracy_fails_for_the_index_five_example() {
    // Section 5.2: g = q̄, H = p²/2 + p̄ q. N ≡ 0.
    let z0 = State::from_slices(&[0.0, 0.0], &[0.3, 0.0]);
    for out in [
        Integrator::new(IndexFive, ImplicitMidpoint, 0.1)
            .run(z0.clone(), Stop::Steps(5))
            .execute(),
        Integrator::new(IndexFive, StormerVerlet, 0.1)
            .shake()
            .run(z0.clone(), Stop::Steps(5))
            .execute(),
    ] {
        match out.error {
            Some(StepError::SingularNondegeneracyMatrix { step: 0, .. }) => {}
            e => panic!("expected SingularNondegeneracyMatrix at step 0, got {e:?}"),
        }
        assert!(out.trajectory.is_empty());
    }
    let err = Integrator::new(IndexFive, ImplicitMidpoint, 0.1)
        .project_to_hidden(&z0)
        .unwrap_err();
    assert!(
        matches!(err, StepError::SingularNondegeneracyMatrix { .. }),
        "{err:?}"
    );
}

#[test]
fn nondegeneracy_fails_for_flat_fibres() {
    // Section 5.2 with H = p²/2: H is constant on the fibres, N ≡ 0 and
    // SHAKE's Newton matrix is exactly singular.
    let z0 = State::from_slices(&[0.0, 0.0], &[0.3, 0.0]);
    let err = Integrator::new(FlatFibres, SymplecticEuler, 0.1)
        .step(&z0)
        .unwrap_err();
    assert!(
        matches!(err, StepError::SingularNondegeneracyMatrix { .. }),
        "{err:?}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("is singular") && msg.contains("nondegeneracy assumption fails"),
        "{msg}"
    );
}

#[test]
fn nondegeneracy_lost_along_a_trajectory() {
    // N = q shrinks linearly as q → 0 (SignChange): with the limit at 40,
    // the run stops once N has shrunk forty-fold, keeping what came before.
    let opts = Options {
        max_condition: 40.0,
        ..Options::default()
    };
    let z0 = State::from_slices(&[-1.0, 0.0], &[1.0, 0.0]);
    let mut integ = Integrator::new(SignChange, ImplicitMidpoint, 0.01).with_options(opts);
    let out = integ.run(z0, Stop::Steps(200)).stride(10).execute();
    match out.error {
        Some(StepError::NondegeneracyLost {
            condition,
            limit,
            step,
            ..
        }) => {
            assert_eq!(limit, 40.0);
            assert!(condition > 40.0 && condition < 60.0, "{condition}");
            assert_eq!(step, 98, "q = −1 + 0.01 k first below 1/40 at k = 98");
        }
        e => panic!("expected NondegeneracyLost, got {e:?}"),
    }
    // Stored: 0, 10, …, 90 and the last good state 97.
    assert_eq!(*out.trajectory.steps().last().unwrap(), 97);
    assert_eq!(out.trajectory.len(), 11);
}

#[test]
fn component_jump_when_det_n_changes_sign() {
    // SignChange with a step that jumps over q = 0, where N = q changes sign.
    let z0 = State::from_slices(&[-1.0, 0.0], &[1.0, 0.0]);
    let mut integ = Integrator::new(SignChange, ImplicitMidpoint, 0.3);
    let out = integ.run(z0, Stop::Steps(10)).execute();
    match out.error {
        Some(StepError::ComponentJump {
            step,
            det_before,
            det_after,
            ..
        }) => {
            assert_eq!(step, 4);
            assert!(det_before < 0.0 && det_after > 0.0);
        }
        e => panic!("expected ComponentJump, got {e:?}"),
    }
    assert_eq!(out.trajectory.steps(), vec![0, 1, 2, 3]);
}

#[test]
fn component_jump_on_the_hopf_scene_with_a_large_step() {
    // Section 5.4.2 (the paper's claim 9): with h = 0.5 the SHAKE solution for
    // z_a jumps to the other component of M^H after a few steps.
    let sys = Hopf::gravity();
    let mut integ = Integrator::new(sys, ImplicitMidpoint, 0.5);
    let z0 = integ
        .project_to_hidden(&State::from_slices(&PAPER_Z_A[..2], &PAPER_Z_A[2..]))
        .unwrap();
    let out = integ.run(z0, Stop::Steps(200)).execute();
    let err = out.error.expect("the run must stop");
    assert!(matches!(err, StepError::ComponentJump { .. }), "{err:?}");
    assert_eq!(out.trajectory.len() as u64, err.step());
    assert!(err.to_string().contains("another component of M^H"));
}

#[test]
fn fibre_jump_from_far_off_the_hidden_constraint() {
    // Hopf, H = |p|²/2: a point of M far from M^H (q·p = 0.5). Newton lands
    // on a λ twice its own linear prediction: not the O(h) solution.
    let (a, tilt) = (0.8f64, 1.0f64);
    let b = (1.0 - a * a).sqrt();
    let z = State::from_slices(&[a, 0.0], &[b * tilt.sin(), b * tilt.cos()]);
    let mut integ = Integrator::new(Hopf::free(), ImplicitMidpoint, 0.1).shake();
    match integ.step(&z) {
        Err(StepError::FibreJump {
            lambda, predicted, ..
        }) => assert!(lambda > 1.5 * predicted, "{lambda} {predicted}"),
        r => panic!("expected FibreJump, got {r:?}"),
    }
    // The check can be switched off: the step is then accepted.
    let opts = Options {
        jump_ratio: f64::INFINITY,
        check_component: false,
        ..Options::default()
    };
    integ = integ.with_options(opts);
    assert!(integ.step(&z).is_ok());
}

#[test]
fn non_finite_input_and_state() {
    let sys = Pendulum::default();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.1);
    let bad = State::from_slices(&[f64::NAN, -1.0], &[0.0, 0.0]);
    assert!(matches!(
        integ.step(&bad),
        Err(StepError::NonFinite {
            what: "initial state",
            ..
        })
    ));
    let out = integ.run(bad.clone(), Stop::Steps(3)).execute();
    assert!(matches!(
        out.error,
        Some(StepError::NonFinite { step: 0, .. })
    ));
    assert!(integ.project_to_hidden(&bad).is_err());

    // Overflow mid-run: a free fall in an absurd field reaches ∞ at step 2.
    let free = geoshake::Unconstrained(Pendulum {
        gravity: 1e308,
        length: 1.0,
    });
    let mut integ = Integrator::new(free, StormerVerlet, 1.0);
    let out = integ
        .run(
            State::from_slices(&[0.0, 0.0], &[0.0, 0.0]),
            Stop::Steps(10),
        )
        .execute();
    match out.error {
        Some(StepError::NonFinite {
            what: "state",
            step,
            ..
        }) => assert_eq!(step, 2),
        e => panic!("expected NonFinite, got {e:?}"),
    }
    assert_eq!(out.trajectory.steps(), vec![0, 1]);
}

#[test]
fn initial_data_not_on_m() {
    let sys = Pendulum::default();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.1);
    let off = State::from_slices(&[1.1, 0.0], &[0.0, 0.3]);
    match integ.step(&off) {
        Err(StepError::NotOnConstraint {
            residual,
            tolerance,
            ..
        }) => {
            assert!((residual - 0.21).abs() < 1e-12);
            // Relative to g's size, s = ‖∂g/∂q‖₁ = 2.2: 1e-8 · (s/2)² plus
            // g's round-off 64ε · s · ‖q‖∞.
            let bound = 1e-8 * 1.1 * 1.1 + 64.0 * f64::EPSILON * 2.2 * 1.1;
            assert!((tolerance - bound).abs() < 1e-22, "{tolerance}");
        }
        r => panic!("expected NotOnConstraint, got {r:?}"),
    }
    let out = integ.run(off.clone(), Stop::Steps(3)).execute();
    assert!(matches!(
        out.error,
        Some(StepError::NotOnConstraint { step: 0, .. })
    ));
    // It can be brought onto M^H …
    let z = integ.project_to_hidden(&off).unwrap();
    assert!((z.q.norm() - 1.0).abs() < 1e-15 && z.q.dot(&z.p).abs() < 1e-15);
    // … except from the origin, where g_q = 0 and no direction leads to M.
    let err = integ
        .project_to_hidden(&State::from_slices(&[0.0, 0.0], &[0.1, 0.0]))
        .unwrap_err();
    assert!(matches!(err, StepError::NotOnConstraint { .. }), "{err:?}");
}

#[test]
fn invalid_inputs_never_panic() {
    let sys = Pendulum::default();
    let z0 = sys.state(0.3, 0.0);
    for h in [0.0, f64::NAN, f64::INFINITY] {
        let mut integ = Integrator::new(sys, ImplicitMidpoint, h);
        assert!(
            matches!(integ.step(&z0), Err(StepError::InvalidInput { .. })),
            "h = {h}"
        );
        let out = integ.run(z0.clone(), Stop::Steps(3)).execute();
        assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    }
    let mut integ = Integrator::new(sys, ImplicitMidpoint, 0.1);
    let out = integ.run(z0.clone(), Stop::Steps(3)).stride(0).execute();
    assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    let out = integ.run(z0.clone(), Stop::Time(-1.0)).execute();
    assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    let wrong = State::from_slices(&[1.0, 0.0, 0.0], &[0.0, 0.0, 0.0]);
    assert!(matches!(
        integ.step(&wrong),
        Err(StepError::InvalidInput { .. })
    ));
    // Negative h with a stop time in the past is fine.
    let mut back = Integrator::new(sys, ImplicitMidpoint, -0.1);
    let out = back.run(z0, Stop::Time(-1.0)).execute();
    assert!(out.error.is_none());
    assert_eq!(out.trajectory.len(), 11);
    assert!((out.trajectory.time(10) + 1.0).abs() < 1e-15);
}
