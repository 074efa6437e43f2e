//! A particle run on the engine's one driver: the same states as the
//! particle step taken by hand (bit for bit), the driver's stride, observer,
//! `on_step` and partial trajectory on failure, and the trajectory through
//! CSV and back bit for bit (1000 rigid waters).

use std::ops::ControlFlow;

use geoshake::runtime::particles::{generate, Options, ParticleState, Rattle};
use geoshake::runtime::{StepError, Stop, Trajectory};
use geoshake_testkit::same_bits::assert_same_bits;

/// Every number of `a` and `b` has the same bits.
fn same(a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "entry {k}: {x} and {y}");
    }
}

/// 1000 rigid waters on M and M^H at 300 K, with h = 2 fs.
fn water_box() -> (Rattle, ParticleState) {
    let (system, mut state) = generate::water(1000, 12345).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    (rattle, state.with_time(100.0))
}

/// The driver adds nothing to the step: its stored states are those of
/// `Rattle::step` called by hand from the same state, bit for bit, at the
/// same times t0 + k·h; its summary is the steps' own reports.
#[test]
fn the_driver_stores_the_steps_of_the_particle_step() {
    let (mut rattle, state) = water_box();
    let out = rattle.run(&state, Stop::Steps(25)).stride(10).execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    let traj = &out.trajectory;
    assert_eq!(traj.steps(), vec![0, 10, 20, 25]);
    let mut by_hand = state.clone();
    let (mut worst, mut iterations) = (0.0f64, 0u64);
    let mut i = 0;
    for k in 0..=25u64 {
        if k > 0 {
            let info = rattle.step(&mut by_hand).unwrap();
            worst = worst.max(info.residual.unwrap());
            iterations += info.shake_iterations_total;
        }
        if traj.step(i) == k {
            same(traj.q(i), by_hand.q());
            same(traj.p(i), by_hand.p());
            assert_eq!(
                traj.time(i).to_bits(),
                by_hand.time().to_bits(),
                "t at step {k}"
            );
            i += 1;
        }
    }
    assert_eq!(i, traj.len());
    let s = out.summary;
    assert_eq!((s.steps, s.newton_iterations), (25, iterations));
    assert_eq!(s.max_residual, Some(worst));
    assert!(worst <= Options::default().tol);
    assert!(s.max_hidden.unwrap() < 1e-12, "{s:?}");
    // SHAKE does not project the momenta: nothing measured, not a 0.
    let (system, mut shake_state) = generate::water(8, 3).unwrap();
    let options = Options {
        method: geoshake::runtime::particles::Method::Shake,
        ..Options::default()
    };
    let mut shake = Rattle::new(system, 2.0, options).unwrap();
    shake.project(&mut shake_state).unwrap();
    generate::set_temperature(shake.system(), &mut shake_state, 300.0);
    let out = shake.run(&shake_state, Stop::Steps(3)).execute();
    assert!(out.error.is_none(), "{:?}", out.error);
    assert_eq!(out.summary.max_hidden, None);
    assert!(out.summary.max_residual.is_some());
}

/// `run_in_place` is the same run, leaving the state at its end: a run of
/// 25 steps in place, continued by 25 more, is a run of 50 (the stored end
/// states agree bit for bit).
#[test]
fn running_in_place_continues_where_it_stopped() {
    let (mut rattle, state) = water_box();
    let whole = rattle.run(&state, Stop::Steps(50)).stride(50).execute();
    let mut z = state.clone();
    for _ in 0..2 {
        let out = rattle.run_in_place(&mut z, 25);
        assert!(out.error.is_none() && out.summary.steps == 25);
    }
    let end = whole.trajectory.len() - 1;
    assert_eq!((z.step(), whole.trajectory.step(end)), (50, 50));
    same(whole.trajectory.q(end), z.q());
    same(whole.trajectory.p(end), z.p());
}

/// The observer sees every stored state, `on_step` every step, and a Break
/// ends the run at the state it saw, stored.
#[test]
fn observers_and_on_step_see_a_particle_run() {
    let (mut rattle, state) = water_box();
    let mut seen = Vec::new();
    let out = rattle
        .run(&state, Stop::Steps(12))
        .stride(4)
        .observe(|k, t, z| seen.push((k, t, z.q[0])))
        .execute();
    assert_eq!(seen.len(), out.trajectory.len());
    for (i, (k, t, q0)) in seen.iter().enumerate() {
        assert_eq!(
            (*k, t.to_bits()),
            (out.trajectory.step(i), out.trajectory.time(i).to_bits())
        );
        assert_eq!(q0.to_bits(), out.trajectory.q(i)[0].to_bits());
    }
    let mut steps = Vec::new();
    let mut hook = |e: &geoshake::runtime::StepEvent| {
        steps.push((e.step, e.info.residual.unwrap()));
        if e.step == 7 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let out = rattle
        .run(&state, Stop::Steps(12))
        .stride(4)
        .on_step(&mut hook)
        .execute();
    assert!(out.error.is_none());
    assert_eq!(
        steps.iter().map(|s| s.0).collect::<Vec<_>>(),
        (1..=7).collect::<Vec<_>>()
    );
    assert_eq!(out.trajectory.steps(), vec![0, 4, 7]);
    assert_eq!(out.summary.steps, 7);
}

/// A step that fails ends the run with the states before it and a typed
/// error naming the step, the family and the member (the off-stride last
/// state of a failure at k > 1: particles_errors.rs).
#[test]
fn a_failed_particle_run_keeps_its_start() {
    let (mut rattle, mut state) = water_box();
    // A momentum no step of 2 fs can follow along the fibre.
    state.p_mut()[3] = 1e9;
    let out = rattle.run(&state, Stop::Steps(7)).stride(3).execute();
    let e = out.error.clone().expect("the kick is too large");
    assert_eq!((e.step(), e.time()), (1, Some(102.0)), "{e}");
    assert!(
        matches!(e, StepError::AtMember { ref family, .. } if family == "bond"),
        "{e}"
    );
    assert_eq!(out.trajectory.steps(), vec![0]);
    same(out.trajectory.p(0), state.p());
    assert_eq!(out.summary.steps, 0);
}

/// The trajectory of 1000 waters through CSV and back: every number bit for
/// bit, the times and steps too.
#[test]
fn a_water_box_trajectory_round_trips_through_csv() {
    let (mut rattle, state) = water_box();
    let traj = rattle
        .run(&state, Stop::Steps(20))
        .stride(10)
        .execute()
        .into_result()
        .unwrap();
    assert_eq!((traj.len(), traj.q(0).len()), (3, 9000));
    let mut csv = Vec::new();
    traj.write_csv(&mut csv).unwrap();
    let back = Trajectory::read_csv(&csv[..]).unwrap();
    assert_eq!(back, traj);
    assert_same_bits(&back, &traj);
}

/// q and p of different lengths are refused with the step's own typed
/// error by every entry point, never a panic in building the start state.
#[test]
fn a_state_of_the_wrong_shape_is_refused_by_every_entry() {
    let (mut rattle, state) = water_box();
    let bad = ParticleState::new(state.q().to_vec(), state.p()[..3].to_vec());
    let shape = |e: Option<StepError>| {
        assert!(
            matches!(
                e,
                Some(StepError::Shape {
                    what: "p",
                    got: 3,
                    expected: 9000
                })
            ),
            "{e:?}"
        )
    };
    shape(rattle.step(&mut bad.clone()).err());
    let out = rattle.run(&bad, Stop::Steps(3)).stride(2).execute();
    assert!(out.trajectory.is_empty() && out.summary.steps == 0);
    shape(out.error);
    let mut in_place = bad.clone();
    shape(rattle.run_in_place(&mut in_place, 3).error);
    assert_eq!(in_place, bad);
}

/// A run in place in chunks reports a failure at the state's own step
/// count and time, as `Rattle::step` does, not at the chunk's.
#[test]
fn a_failure_in_a_later_chunk_names_the_states_step() {
    let (mut rattle, mut state) = water_box();
    let out = rattle.run_in_place(&mut state, 4);
    assert!(out.error.is_none());
    let mut by_hand = state.clone();
    by_hand.p_mut()[3] = 1e9;
    state.p_mut()[3] = 1e9;
    let e = rattle.run_in_place(&mut state, 3).error.unwrap();
    let expected = rattle.step(&mut by_hand).unwrap_err();
    assert_eq!((e.step(), e.time()), (5, Some(110.0)));
    assert_eq!(e, expected);
    assert_eq!(state.step(), 4);
}
