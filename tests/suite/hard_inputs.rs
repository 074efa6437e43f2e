//! Hard inputs: absurd step sizes, NaN and infinite entries, initial data
//! off M or far from it, and the exceptional fibres of the Hopf constraint
//! (Section 5.4.1, |q| = |p|). Each gets a typed error or the documented
//! behaviour below; nothing panics, and no step returns a point off M.
//!
//! Documented behaviour:
//! - h = 0, −0, NaN, ±∞: [`StepError::InvalidInput`] before any work.
//! - h < 0: integrates backwards (RATTLE over a symmetric map is symmetric).
//! - |h| huge (10 … f64::MAX): SHAKE's Newton finds no root (or overflows):
//!   [`StepError::NewtonNotConverged`], or its matrix is
//!   singular: [`StepError::SingularShakeJacobian`] (or N's condition
//!   explodes: [`StepError::NondegeneracyLost`]) at step 1; a step whose Newton iteration stops
//!   on a point off M (it can, for h = 1e10 on the Hopf scene: the stopping
//!   rule looks at updates, not residuals) is refused the same way.
//! - |h| tiny (down to the smallest subnormal): the step succeeds and moves
//!   the state by O(h), i.e. not at all in floating point.
//! - `Stop::Time` needing more than 2^53 steps: [`StepError::InvalidInput`]
//!   (the run would never end and its times would not be exact).
//! - NaN/∞ in the state: [`StepError::NonFinite`] from `step`, `run`,
//!   `project` and `project_to_hidden`.
//! - Off M: `step`/`run` refuse with [`StepError::NotOnConstraint`];
//!   `project_to_hidden` brings points from as far as 1e8·radius onto M^H,
//!   and refuses (NotOnConstraint) where g overflows (|z| ≳ 1e150).
//! - On M but off M^H: SHAKE's fibre displacement is O(1) (it tends to a
//!   point of fibre ∩ M^H as h → 0); where Newton lands on another component
//!   the det N check refuses it ([`StepError::ComponentJump`]). Use
//!   `project_to_hidden` for initial data; from far off M^H see also
//!   `runtime_errors.rs` ([`StepError::FibreJump`]).
//! - On an exceptional fibre (N = 0 on the whole fibre):
//!   [`StepError::SingularNondegeneracyMatrix`] at step 0, for
//!   `step`, `run` and `project_to_hidden`. Near it (|q|² − |p|² = 2ε), N is
//!   O(ε) and SHAKE's Newton at h = 0.1 has no nearby root: a typed
//!   NewtonNotConverged at step 1.

use crate::common;

use common::models::*;
use geoshake::{
    Composition, ConstrainedSystem, ImplicitMidpoint, Integrator, Stage, State, StepError, Stop,
    StormerVerlet, SymplecticEuler,
};

fn g_norm<S: ConstrainedSystem>(sys: &S, z: &State) -> f64 {
    let mut g = vec![0.0; sys.constraint_count()];
    sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    g.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

fn hopf_point() -> State {
    // On M^H of both Hopf systems: |z| = 1, q·p = 0 and γ·p = −p₁ = 0.
    State::from_slices(&[0.0, 0.8], &[0.6, 0.0])
}

#[test]
fn zero_and_non_finite_step_sizes_are_invalid_input() {
    let sys = Pendulum::default();
    let z0 = sys.state(0.3, 0.5);
    for h in [0.0, -0.0, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for c in [Composition::SINGLE, Composition::TRIPLE_JUMP] {
            let mut integ = Integrator::new(sys, ImplicitMidpoint, h).composed(c);
            let e = integ.step(&z0).unwrap_err();
            assert!(
                matches!(e, StepError::InvalidInput { .. }),
                "h = {h}: {e:?}"
            );
            let out = integ.run(z0.clone(), Stop::Steps(3)).execute();
            assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
            assert!(out.trajectory.is_empty());
        }
    }
}

#[test]
fn huge_step_sizes_are_typed_errors_never_a_point_off_m() {
    let pendulum = Pendulum::default();
    let zp = pendulum.state(0.3, 0.5);
    let hopf = Hopf::gravity();
    let zh = hopf_point();
    for h in [10.0, 1e3, 1e10, 1e100, 1e300, f64::MAX, -1e10, -f64::MAX] {
        for c in [Composition::SINGLE, Composition::TRIPLE_JUMP] {
            let results = [
                Integrator::new(pendulum, StormerVerlet, h)
                    .composed(c)
                    .step(&zp)
                    .map(|z| g_norm(&pendulum, &z)),
                Integrator::new(pendulum, ImplicitMidpoint, h)
                    .composed(c)
                    .step(&zp)
                    .map(|z| g_norm(&pendulum, &z)),
                Integrator::new(pendulum, SymplecticEuler, h)
                    .composed(c)
                    .shake()
                    .step(&zp)
                    .map(|z| g_norm(&pendulum, &z)),
                Integrator::new(hopf, ImplicitMidpoint, h)
                    .composed(c)
                    .step(&zh)
                    .map(|z| g_norm(&hopf, &z)),
            ];
            for (k, r) in results.into_iter().enumerate() {
                match r {
                    // A success is a point of M.
                    Ok(g) => assert!(g < 1e-12, "case {k}, h = {h:e}: |g| = {g:e}"),
                    // SHAKE's Newton finds no root, or its matrix is
                    // singular there, or N's condition explodes.
                    Err(StepError::NewtonNotConverged { .. })
                    | Err(StepError::SingularShakeJacobian { .. })
                    | Err(StepError::NondegeneracyLost { .. }) => {}
                    Err(e) => panic!("case {k}, h = {h:e}: unexpected {e:?}"),
                }
            }
        }
    }
    // The case that used to slip through: Newton "converges" on a huge λ.
    let e = Integrator::new(hopf, ImplicitMidpoint, 1e10)
        .step(&zh)
        .unwrap_err();
    match e {
        StepError::NewtonNotConverged {
            stage: Stage::Shake,
            source: geoshake::SolveError::NotConverged { residual, .. },
            ..
        } => assert!(residual > 1.0, "{residual:e}"),
        e => panic!("{e:?}"),
    }
}

#[test]
fn tiny_step_sizes_succeed_and_do_not_move() {
    let sys = Pendulum::default();
    let z0 = sys.state(0.3, 0.5);
    for h in [1e-300, 5e-324, -5e-324] {
        for c in [Composition::SINGLE, Composition::MCLACHLAN_8] {
            let z1 = Integrator::new(sys, StormerVerlet, h)
                .composed(c)
                .step(&z0)
                .unwrap();
            assert!(z1.distance(&z0) < 1e-15, "h = {h:e}");
            let z1 = Integrator::new(Hopf::gravity(), ImplicitMidpoint, h)
                .composed(c)
                .step(&hopf_point())
                .unwrap();
            assert!(z1.distance(&hopf_point()) < 1e-15, "h = {h:e}");
        }
    }
    // A stop time that needs more than 2^53 steps is refused, not run.
    let out = Integrator::new(sys, StormerVerlet, 1e-300)
        .run(z0.clone(), Stop::Time(1.0))
        .execute();
    assert!(
        matches!(out.error, Some(StepError::InvalidInput { value, .. }) if value > 1e299),
        "{:?}",
        out.error
    );
    // 2^53 steps exactly would be allowed (not run here); 2^53 + 2 is not.
    let out = Integrator::new(sys, StormerVerlet, 1.0)
        .run(z0, Stop::Time(9007199254740994.0))
        .execute();
    assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
}

#[test]
fn negative_step_sizes_integrate_backwards() {
    let sys = Pendulum::default();
    let z0 = sys.state(0.3, 0.5);
    for c in [Composition::SINGLE, Composition::SUZUKI_5] {
        let mut fwd = Integrator::new(sys, ImplicitMidpoint, 0.1).composed(c);
        let z1 = fwd.run(z0.clone(), Stop::Time(2.0)).execute();
        let z1 = z1.trajectory.last().unwrap();
        let mut back = Integrator::new(sys, ImplicitMidpoint, -0.1).composed(c);
        let out = back.run(z1, Stop::Time(-2.0)).execute();
        let zb = &out.trajectory.last().unwrap();
        assert!(zb.distance(&z0) < 1e-13, "{}", zb.distance(&z0));
        assert!((out.trajectory.time(20) + 2.0).abs() < 1e-15);
    }
}

#[test]
fn nan_and_infinite_entries_are_non_finite() {
    let sys = Pendulum::default();
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for (q, p) in [([bad, -1.0], [0.0, 0.0]), ([0.0, -1.0], [0.0, bad])] {
            let z = State::from_slices(&q, &p);
            let mut integ = Integrator::new(sys, StormerVerlet, 0.1);
            assert!(matches!(
                integ.step(&z),
                Err(StepError::NonFinite { step: 0, .. })
            ));
            assert!(matches!(
                integ.run(z.clone(), Stop::Steps(2)).execute().error,
                Some(StepError::NonFinite { step: 0, .. })
            ));
            assert!(matches!(
                integ.project(&z),
                Err(StepError::NonFinite { .. })
            ));
            assert!(matches!(
                integ.project_to_hidden(&z),
                Err(StepError::NonFinite { .. })
            ));
            let mut hopf = Integrator::new(Hopf::gravity(), ImplicitMidpoint, 0.1).shake();
            assert!(matches!(
                hopf.step(&State::from_slices(&[p[1], 0.8], &[0.6, q[0]])),
                Err(StepError::NonFinite { .. })
            ));
        }
    }
}

#[test]
fn initial_data_off_m_and_far_from_it() {
    let sys = Pendulum::default();
    let hopf = Hopf::gravity();
    // Slightly off M: refused by step and run, with the residual.
    let off = State::from_slices(&[0.0, -1.0 - 1e-6], &[0.3, 0.0]);
    match Integrator::new(sys, StormerVerlet, 0.1).step(&off) {
        Err(StepError::NotOnConstraint { residual, .. }) => {
            assert!((residual - 2e-6).abs() < 1e-11)
        }
        r => panic!("{r:?}"),
    }
    // Far from M: project_to_hidden brings it onto M^H …
    for s in [10.0, 1e3, 1e8] {
        let z = State::from_slices(&[s, 0.5 * s], &[s, -s]);
        let zp = Integrator::new(sys, StormerVerlet, 0.1)
            .project_to_hidden(&z)
            .unwrap();
        assert!((zp.q.norm() - 1.0).abs() < 1e-15 && zp.q.dot(&zp.p).abs() < 1e-14 * s);
        let zh = Integrator::new(hopf, ImplicitMidpoint, 0.1)
            .project_to_hidden(&z)
            .unwrap();
        assert!(g_norm(&hopf, &zh) < 1e-15);
        // … and a run from there is well behaved.
        let out = Integrator::new(hopf, ImplicitMidpoint, 0.1)
            .run(zh, Stop::Steps(20))
            .execute();
        assert!(out.error.is_none(), "{:?}", out.error);
    }
    // … unless g overflows.
    for s in [1e150, 1e300] {
        let z = State::from_slices(&[s, 0.5 * s], &[s, -s]);
        for r in [
            Integrator::new(sys, StormerVerlet, 0.1).project_to_hidden(&z),
            Integrator::new(hopf, ImplicitMidpoint, 0.1).project_to_hidden(&z),
        ] {
            assert!(matches!(r, Err(StepError::NotOnConstraint { .. })), "{r:?}");
        }
    }
}

#[test]
fn exceptional_fibres_are_refused() {
    // Section 5.4.1: on |q| = |p| (with q·p = 0) H = |p|²/2 is constant on
    // the whole fibre, N = {{H,g},g} = 0: the exceptional fibres.
    let a = 0.5f64.sqrt();
    for z in [
        State::from_slices(&[a, 0.0], &[0.0, a]),
        State::from_slices(&[0.0, -a], &[a, 0.0]),
        State::from_slices(&[a, 0.0], &[a, 0.0]), // q ∥ p: also on M, q·p ≠ 0
    ] {
        let mut integ = Integrator::new(Hopf::free(), ImplicitMidpoint, 0.1);
        assert!(matches!(
            integ.project_to_hidden(&z),
            Err(StepError::SingularNondegeneracyMatrix { step: 0, .. })
        ));
        for c in [Composition::SINGLE, Composition::TRIPLE_JUMP] {
            let mut integ = Integrator::new(Hopf::free(), ImplicitMidpoint, 0.1).composed(c);
            assert!(matches!(
                integ.step(&z),
                Err(StepError::SingularNondegeneracyMatrix { step: 0, .. })
            ));
            let out = integ.run(z.clone(), Stop::Steps(5)).execute();
            assert!(matches!(
                out.error,
                Some(StepError::SingularNondegeneracyMatrix { step: 0, .. })
            ));
        }
    }
    // Near an exceptional fibre: |q|² − |p|² = 2ε, N = O(ε).
    for eps in [1e-2, 1e-4, 1e-8] {
        let z = State::from_slices(&[(0.5f64 + eps).sqrt(), 0.0], &[0.0, (0.5f64 - eps).sqrt()]);
        let out = Integrator::new(Hopf::free(), ImplicitMidpoint, 0.1)
            .run(z, Stop::Steps(50))
            .execute();
        assert!(
            matches!(
                out.error,
                Some(StepError::NewtonNotConverged { step: 1, .. })
            ),
            "ε = {eps:e}: {:?}",
            out.error
        );
        assert_eq!(out.trajectory.len(), 1);
    }
}

#[test]
fn initial_data_on_m_but_off_m_h() {
    // z ∈ M with {g,H}(z) = 0.96 for the Hopf scene. SHAKE is defined on M,
    // but its fibre displacement is then O(1), not O(h): as h → 0 it tends
    // to the projection of z along its fibre onto M^H, wherever Newton
    // lands. From this z (det N = 1.12) it lands on the other component
    // (det N ≈ −4) for small and large h alike, and the det N check refuses
    // the step.
    let sys = Hopf::gravity();
    let z = State::from_slices(&[0.8, 0.0], &[0.6, 0.0]);
    for h in [0.1, 1e-3] {
        for integ in [
            Integrator::new(sys, ImplicitMidpoint, h).shake(),
            Integrator::new(sys, ImplicitMidpoint, h).rattle(),
        ] {
            let e = integ.clone().step(&z).unwrap_err();
            assert!(
                matches!(e, StepError::ComponentJump { det_before, det_after, .. } if det_before > 0.0 && det_after < 0.0),
                "h = {h:e}: {e:?}"
            );
        }
    }
    // Below the resolution of g (h = 1e-300) SHAKE's residual at λ = 0 is
    // already 0 and z comes back unchanged; RATTLE's projection still
    // lands on the other component and is refused.
    let z1 = Integrator::new(sys, ImplicitMidpoint, 1e-300)
        .shake()
        .step(&z)
        .unwrap();
    assert!(z1.distance(&z) <= 1e-300);
    assert!(matches!(
        Integrator::new(sys, ImplicitMidpoint, 1e-300).step(&z),
        Err(StepError::ComponentJump { .. })
    ));
    // project_to_hidden is the way onto M^H (the nearest critical point).
    let zp = Integrator::new(sys, ImplicitMidpoint, 0.1)
        .project_to_hidden(&z)
        .unwrap();
    let mut gh = [0.0];
    sys.hidden_constraints(zp.q.as_slice(), zp.p.as_slice(), &mut gh);
    assert!(gh[0].abs() < 1e-15);
}
