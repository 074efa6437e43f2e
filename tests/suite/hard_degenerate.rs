//! Near-degenerate trajectories (the paper's Section 5.4.2, case iii, and
//! the caption of fig_fibres): where a trajectory reaches a point of M^H at
//! which N = {{H,g},g} is singular, SHAKE and RATTLE are not defined and
//! Newton may fail or jump to another component of M^H. The runtime must
//! stop with a typed error before or at that point, and every state it
//! returned before must be the right one.
//!
//! # The scene
//!
//! Hopf constraint with gravity γ = (0, −1), midpoint rule. The fibres over
//! the paper's z_a, z_b, z_c meet M^H in two points (case ii): the start
//! point, a minimum of H on the fibre (Hr'' > 0, N > 0), and a maximum
//! (Hr'' < 0). The trajectory through the maximum lies on the component of
//! M^H whose inflexion points fig_fibres shows: along it Hr'' → 0 in finite
//! time (t ≈ 2.1 for z_a, 4.3 for z_b, 2.2 for z_c), the multiplier λ = N⁻¹b
//! blows up, and the DAE stops being well posed. (N = 4 Hr''(0): the fibre
//! angle θ of the oracle is twice the fibre parameter.)
//!
//! # What is checked, independently of the runtime
//!
//! With `common::reference` (num-dual derivatives, GBS on the index-reduced
//! ODE): t_s, the time at which |Hr''| has dropped to a quarter of its
//! start value along the exact solution. Then for several h and with and
//! without composition:
//! 1. the run ends with a typed error (NondegeneracyLost, ComponentJump,
//!    FibreJump, NewtonNotConverged, or BranchJump for a composed step),
//!    never by running through;
//! 2. every returned state is on M^H, and on the start's component
//!    (Hr''(0) keeps its sign) — no silent jump;
//! 3. every returned state up to t_s agrees with the reference to the
//!    method's accuracy (≤ 5·h^p·(1 + t));
//! 4. the run does not go on past the impasse (t_s + 0.3), where the DAE
//!    has no solution, and all along H stays at its start value (to
//!    0.5·h^p up to t_s, to 1e-2 beyond: a jump to another critical point
//!    of H on the fibre changes H by 0.04 here);
//! 5. the run is not stopped early: it gets past t_s − 2h.
//!
//! A *composed* step can bounce off the fold where no check of its
//! substeps sees it: the triple jump at h = 0.05 from z_c's maximum lands
//! on a neighbouring maximum (same sign of N, a λ its own Newton iteration
//! predicted). Stepping back with −h does not return (the step back finds
//! the nearby solution from the new state), and that check
//! (`Options::reverse_tolerance`) stops the run with BranchJump; with it
//! turned off the run goes on past the impasse (both are tested below).
//!
//! With `Options::max_condition = 4` the approach itself is the stop: the
//! run ends with NondegeneracyLost within a step or two of t_s.
//!
//! Thresholds (`Options`, see their docs): `max_condition` (default 1e10;
//! for m = 1 the factor by which |N| may shrink since the start),
//! `jump_ratio` (default 1: Newton's correction beyond its first, linear,
//! prediction of λ may not exceed that prediction), and the sign of det N
//! between consecutive steps (`check_component`). Near the singular point
//! the step that would cross it is refused by one of them or Newton fails
//! to converge; which one fires depends on h (recorded in the output).

use crate::common;

use common::models::SignChange;
use common::reference as oracle;
use geoshake::models::HopfGravity;
use geoshake::{Composition, ImplicitMidpoint, Integrator, Options, State, StepError, Stop};

const GV: [f64; 2] = [0.0, -1.0];

fn arr(z: &State) -> [f64; 4] {
    [z.q[0], z.q[1], z.p[0], z.p[1]]
}

/// The maximum of H on the fibre of the paper's point `zp` (brought onto
/// the unit M^H), and Hr'' there.
fn doomed_start(zp: [f64; 4]) -> (State, f64) {
    let z = oracle::hopf_onto_mh(&zp, GV, 1.0);
    let crit = oracle::fibre_critical_points(&z, GV);
    let c = crit
        .iter()
        .find(|c| c.second < 0.0 && !c.degenerate)
        .expect("a maximum of H on the fibre");
    let y = oracle::fibre_point(&z, c.theta);
    (
        State::from_slices(&y[..2], &y[2..]),
        oracle::hr_second(&y, GV, 0.0),
    )
}

/// t_s: |Hr''| along the exact solution first drops to |s0|/4 (to 1e-3).
fn quarter_time(z0: &State, s0: f64) -> f64 {
    let sys = oracle::HopfGravity::default();
    let dt = 0.01;
    let (mut t, mut z) = (0.0, z0.to_vector());
    loop {
        let zn = oracle::reference_solution_levels(&sys, &z, dt, 4, 6);
        let s = oracle::hr_second(&[zn[0], zn[1], zn[2], zn[3]], GV, 0.0);
        if s.abs() <= 0.25 * s0.abs() {
            return t + dt;
        }
        (t, z) = (t + dt, zn);
        assert!(t < 20.0, "no approach to a degenerate point");
    }
}

fn hopf_energy(z: &[f64; 4]) -> f64 {
    0.5 * (z[2] * z[2] + z[3] * z[3]) - (GV[0] * z[0] + GV[1] * z[1])
}

fn typed_stop(e: &Option<StepError>) -> &'static str {
    match e {
        Some(StepError::NondegeneracyLost { .. }) => "NondegeneracyLost",
        Some(StepError::ComponentJump { .. }) => "ComponentJump",
        Some(StepError::FibreJump { .. }) => "FibreJump",
        Some(StepError::NewtonNotConverged { .. }) => "NewtonNotConverged",
        Some(StepError::BranchJump { .. }) => "BranchJump",
        other => {
            panic!("the run must stop with a typed error near the degenerate point, got {other:?}")
        }
    }
}

#[test]
fn hopf_trajectories_into_a_degenerate_point_stop_typed_and_never_jump() {
    let sys = HopfGravity::new(0.0, -1.0, 1.0);
    for (name, zp) in [
        ("z_a", oracle::PAPER_Z_A),
        ("z_b", oracle::PAPER_Z_B),
        ("z_c", oracle::PAPER_Z_C),
    ] {
        let (z0, s0) = doomed_start(zp);
        let t_s = quarter_time(&z0, s0);
        for (c, hs) in [
            (Composition::SINGLE, &[0.1, 0.05, 0.02, 0.01, 0.005][..]),
            (Composition::TRIPLE_JUMP, &[0.1, 0.02][..]),
        ] {
            for &h in hs {
                let p = if c.stages() == 1 { 2 } else { c.order() } as i32;
                let out = Integrator::new(sys, ImplicitMidpoint, h)
                    .composed(c)
                    .run(z0.clone(), Stop::Time(20.0))
                    .execute();
                let why = typed_stop(&out.error);
                let traj = &out.trajectory;
                let t_last = traj.time(traj.len() - 1);
                // 2. On M^H, on the start's component, and at the start's
                // energy: the DAE conserves H and the method's error is
                // O(h^p), while a jump to another critical point of H on a
                // fibre (a maximum of the same sign, which exists past the
                // fold where the fibre is in case i) changes H by O(1).
                let e0 = hopf_energy(&arr(&z0));
                let mut de_max: f64 = 0.0;
                for (z, t) in traj.states().zip(traj.times()) {
                    let de = (hopf_energy(&arr(&z)) - e0).abs();
                    de_max = de_max.max(de);
                    // Past t_s λ blows up and so does the method's error
                    // constant; there only an O(1) jump is excluded.
                    let allowed = if t <= t_s { 0.5 * h.powi(p) } else { 1e-2 };
                    assert!(
                        de <= allowed,
                        "{name} h = {h} {}: |ΔH| = {de:.3e} at t = {t}: a silent jump",
                        c.name()
                    );
                    let a = arr(&z);
                    let s = oracle::hr_second(&a, GV, 0.0);
                    assert!(
                        s.signum() == s0.signum(),
                        "{name} h = {h} {}: Hr'' = {s} at t = {t} (start {s0})",
                        c.name()
                    );
                    assert!(oracle::hr_prime(&a, GV, 0.0).abs() < 1e-13);
                }
                // 3. Against the reference up to t_s.
                let upto: Vec<usize> = (0..traj.len()).filter(|&k| traj.time(k) <= t_s).collect();
                let times: Vec<f64> = upto.iter().map(|&k| traj.time(k)).collect();
                let exact = oracle::reference_trajectory(
                    &oracle::HopfGravity::default(),
                    &z0.to_vector(),
                    &times,
                );
                let mut worst: f64 = 0.0;
                for (&k, ze) in upto.iter().zip(&exact) {
                    let e: f64 = (traj.state(k).to_vector() - ze).amax();
                    let bound = 5.0 * h.powi(p) * (1.0 + traj.time(k));
                    worst = worst.max(e / bound);
                }
                assert!(
                    worst <= 1.0,
                    "{name} h = {h} {}: error {worst} × bound",
                    c.name()
                );
                // 4. Not run through: the impasse lies within 0.2 of t_s
                // for all three scenes (the DAE has no solution beyond it).
                assert!(
                    t_last <= t_s + 0.3,
                    "{name} h = {h} {}: ran on to t = {t_last}, t_s = {t_s}",
                    c.name()
                );
                // 5. Not stopped early.
                assert!(
                    t_last >= t_s - 2.0 * h,
                    "{name} h = {h} {}: stopped at {t_last}, t_s = {t_s}",
                    c.name()
                );
                println!(
                    "{name} {:<22} h = {h:<5}: t_s = {t_s:.3}, stopped at t = {t_last:.3} by {why}; error/bound ≤ {worst:.2}, max |ΔH| = {de_max:.1e}",
                    c.name()
                );
            }
        }
    }
}

#[test]
fn a_condition_limit_stops_the_approach_itself() {
    // max_condition = 4: for m = 1 the run stops once |N| has shrunk
    // four-fold, i.e. at t_s, with NondegeneracyLost.
    let sys = HopfGravity::new(0.0, -1.0, 1.0);
    let opts = Options {
        max_condition: 4.0,
        ..Options::default()
    };
    for zp in [oracle::PAPER_Z_A, oracle::PAPER_Z_B, oracle::PAPER_Z_C] {
        let (z0, s0) = doomed_start(zp);
        let t_s = quarter_time(&z0, s0);
        for h in [0.05, 0.01] {
            let out = Integrator::new(sys, ImplicitMidpoint, h)
                .with_options(opts)
                .run(z0.clone(), Stop::Time(20.0))
                .execute();
            match out.error {
                Some(StepError::NondegeneracyLost {
                    condition, limit, ..
                }) => {
                    assert_eq!(limit, 4.0);
                    assert!(condition > 4.0);
                }
                e => panic!("expected NondegeneracyLost, got {e:?}"),
            }
            let t_last = out.trajectory.time(out.trajectory.len() - 1);
            // The SHAKE state at which N is checked lies O(h) off M^H, and
            // t_s is known to 0.01: within a few steps.
            assert!(
                (t_last - t_s).abs() <= 3.0 * h + 0.01,
                "h = {h}: stopped at {t_last}, t_s = {t_s}"
            );
        }
    }
}

#[test]
fn crossing_a_sign_change_of_n_is_refused_at_every_step_size() {
    // SignChange: N = q changes sign at q = 0 and the exact solution (q
    // moving at unit speed) crosses it at t = 1. Whatever h and
    // composition, no state with q ≥ 0 is returned, and the run ends with a
    // typed error at the crossing.
    let z0 = State::from_slices(&[-1.0, 0.0], &[1.0, 0.0]);
    for c in [
        Composition::SINGLE,
        Composition::TRIPLE_JUMP,
        Composition::KAHAN_LI_6,
    ] {
        for h in [0.3, 0.1, 0.07, 0.01, 1e-3] {
            let out = Integrator::new(SignChange, ImplicitMidpoint, h)
                .composed(c)
                .run(z0.clone(), Stop::Time(3.0))
                .execute();
            let why = typed_stop(&out.error);
            assert!(
                matches!(why, "ComponentJump" | "NondegeneracyLost"),
                "{} h = {h}: {why}",
                c.name()
            );
            for z in out.trajectory.states() {
                let z = &z;
                assert!(z.q[0] < 0.0, "{} h = {h}: q = {}", c.name(), z.q[0]);
            }
            let t_last = out.trajectory.time(out.trajectory.len() - 1);
            assert!(
                t_last > 1.0 - 1.71 * h - 1e-12,
                "{} h = {h}: {t_last}",
                c.name()
            );
        }
    }
}

#[test]
fn a_composed_step_that_bounces_off_the_fold_is_refused_by_stepping_back() {
    // From the maximum of H on the fibre over z_c, triple jump, h = 0.05:
    // at t ≈ 2.13, a substep lands on the maximum of a neighbouring branch
    // of M^H (past the fold the fibre has four critical points, two of them
    // maxima close together). Newton's first iterate already predicts the
    // large λ (N is small there), so the fibre-jump test passes; N keeps
    // its sign, so the component test passes; |N| drops four-fold in that
    // substep and λ/h grows 3.6-fold, H changes by 1.4e-3. Without the
    // reverse check the run goes on to t = 20 on the other branch, past the
    // impasse where the DAE has no solution.
    let sys = HopfGravity::new(0.0, -1.0, 1.0);
    let (z0, s0) = doomed_start(oracle::PAPER_Z_C);
    let t_s = quarter_time(&z0, s0);
    let h = 0.05;
    let run = |opts: Options| {
        Integrator::new(sys, ImplicitMidpoint, h)
            .composed(Composition::TRIPLE_JUMP)
            .with_options(opts)
            .run(z0.clone(), Stop::Time(20.0))
            .execute()
    };
    let unchecked = run(Options {
        reverse_tolerance: f64::INFINITY,
        ..Options::default()
    });
    let t_unchecked = unchecked.trajectory.time(unchecked.trajectory.len() - 1);
    assert!(
        t_unchecked > t_s + 1.0,
        "without the reverse check the jump is expected to pass unseen (t = {t_unchecked}, t_s = {t_s}): {:?}",
        unchecked.error
    );
    let out = run(Options::default());
    let e = out.error.expect("the run must stop near the fold");
    let StepError::BranchJump {
        miss, tolerance, ..
    } = &e
    else {
        panic!("expected BranchJump, got {e:?}");
    };
    // The step back misses by the distance between the two maxima (O(0.1)
    // on the unit fibre), far above the reverse step's round-off.
    if let Some(miss) = miss {
        assert!(
            *miss > 1e3 * tolerance,
            "miss {miss:e}, tolerance {tolerance:e}"
        );
    }
    // Step k failed: the error says k and t0 + k·h, the last stored state
    // is k − 1, and the run stopped before the impasse.
    let k = e.step();
    assert_eq!(e.time(), Some(k as f64 * h));
    assert_eq!(*out.trajectory.steps().last().unwrap(), k - 1);
    let t_last = out.trajectory.time(out.trajectory.len() - 1);
    assert!(t_last <= t_s + 0.3, "ran on to t = {t_last}, t_s = {t_s}");
    assert!(
        t_last >= t_s - 0.5,
        "stopped early at t = {t_last}, t_s = {t_s}"
    );
    assert!(e.to_string().contains("branch jump"), "{e}");
    // From t0 = 0.5 the same run fails at the same step k, at t0 + k·h.
    let t0 = 0.5;
    let shifted = Integrator::new(sys, ImplicitMidpoint, h)
        .composed(Composition::TRIPLE_JUMP)
        .run(z0.clone(), Stop::Time(20.0 + t0))
        .start_time(t0)
        .execute();
    let e2 = shifted.error.expect("the shifted run stops too");
    assert!(matches!(e2, StepError::BranchJump { .. }), "{e2:?}");
    assert_eq!(e2.step(), k);
    assert_eq!(e2.time(), Some(t0 + k as f64 * h));
    assert_eq!(*shifted.trajectory.steps().last().unwrap(), k - 1);
}

/// `StepInfo::fold` = ‖N₁ − N₀‖‖N₁⁻¹‖ is h over the time left before N
/// would be singular: checked against the same ratio computed from the
/// reference solution (independent code: N = 4 Hr''(0) along the exact
/// trajectory, so the ratio is |s_k − s_{k−1}|/|s_k| with s = Hr''), and
/// it grows on the approach to the fold while a regular stretch keeps it
/// at O(h).
#[test]
fn the_fold_indicator_is_h_over_the_time_left_before_n_is_singular() {
    use std::ops::ControlFlow;
    let sys = HopfGravity::new(0.0, -1.0, 1.0);
    let (z0, s0) = doomed_start(oracle::PAPER_Z_A);
    let t_s = quarter_time(&z0, s0);
    for h in [0.01, 0.005] {
        let mut seen: Vec<(f64, f64)> = Vec::new();
        let mut watch = |e: &geoshake::StepEvent| {
            seen.push((e.t, e.info.fold));
            ControlFlow::Continue(())
        };
        let out = Integrator::new(sys, ImplicitMidpoint, h)
            .run(z0.clone(), Stop::Time(20.0))
            .on_step(&mut watch)
            .execute();
        assert!(out.error.is_some());
        let upto: Vec<(f64, f64)> = seen.iter().copied().filter(|(t, _)| *t <= t_s).collect();
        let mut times = vec![0.0];
        times.extend(upto.iter().map(|(t, _)| *t));
        let exact =
            oracle::reference_trajectory(&oracle::HopfGravity::default(), &z0.to_vector(), &times);
        let s: Vec<f64> = exact
            .iter()
            .map(|z| oracle::hr_second(&[z[0], z[1], z[2], z[3]], GV, 0.0))
            .collect();
        // The runtime's N is taken at the SHAKE states (on M, an O(h) fibre
        // displacement from M^H) and carries the method's O(h²) error, so
        // the two ratios (each O(h)) agree to O(h) relative plus O(h²).
        let mut worst: f64 = 0.0;
        for (k, &(_, fold)) in upto.iter().enumerate() {
            let reference = (s[k + 1] - s[k]).abs() / s[k + 1].abs();
            worst = worst.max((fold - reference).abs() / (h * reference + h * h));
        }
        let regular = upto
            .iter()
            .filter(|(t, _)| *t <= 0.5 * t_s)
            .fold(0.0f64, |a, (_, f)| a.max(*f));
        let last = seen[seen.len() - 1].1;
        println!(
            "h = {h}: |fold − reference| ≤ {worst:.2}·(h·reference + h²) up to t_s = {t_s}; \
             ≤ {regular:.1e} up to t_s/2; {last:.2} at the last step, t = {:.3}",
            seen[seen.len() - 1].0
        );
        assert!(worst <= 10.0, "h = {h}: {worst}");
        // O(h) on the regular stretch (h·|Ṅ/N| with |Ṅ/N| ≤ 0.3 there) …
        assert!(regular <= h, "h = {h}: {regular}");
        // … and within a few steps of the fold by the time a guard stops
        // the run.
        assert!(last >= 0.25, "h = {h}: {last}");
    }
}

/// Initial data off M within a loose `constraint_tolerance` is not a branch
/// jump: the step back lands on M, about the start's distance from it away,
/// and the reverse check allows for that distance (review of the check).
#[test]
fn a_start_off_m_within_the_tolerance_is_not_a_branch_jump() {
    use geoshake::examples::Pendulum;
    let opts = Options {
        constraint_tolerance: 1e-3,
        ..Options::default()
    };
    let z0 = State::from_slices(&[0.6 * 1.0001, -0.8 * 1.0001], &[0.8, 0.6]);
    for c in [Composition::TRIPLE_JUMP, Composition::YOSHIDA_6] {
        let mut integ = Integrator::new(Pendulum::default(), geoshake::StormerVerlet, 0.01)
            .composed(c)
            .with_options(opts);
        let z1 = integ.step(&z0);
        assert!(z1.is_ok(), "{c:?}: {z1:?}");
        let out = integ.run(z0.clone(), Stop::Steps(50)).execute();
        assert!(out.error.is_none(), "{c:?}: {:?}", out.error);
    }
}
