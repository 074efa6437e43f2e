//! Claims 7, 8 and 9 of MISSION.md (the harmonic constraint, the paper's
//! Section 5.4) as tests.
//!
//! They measure what the `paper` scenes `hopf_free` and `hopf_gravity`
//! measure, with the same bounds and for the same reasons: both use
//! `geoshake_testkit::hopf_lab`, which runs shake and compares with
//! the independent reference (`geoshake_testkit::reference`). The runs here are
//! shorter than the scene's full runs, so that the tests stay fast in a debug
//! build; none of the bounds depends on the length of a run except where the
//! bound says so (steps·ε).

use crate::common;

use common::reference;
use geoshake_testkit::hopf_lab;

use geoshake::{ConstrainedSystem, Method, Options};
use hopf_lab as lab;
use nalgebra::DVector;
use reference as r;

const EPS: f64 = f64::EPSILON;
const H: f64 = 0.1;

// ===========================================================================
// Claim 7: H = |p|²/2, RATTLE is exact up to a time reparametrisation
// ===========================================================================

/// eq hopf_dea_exact_solution is right with α = −sign(q0∧p0)|p0|/|q0| on
/// both components of M^H and for both orientations, and wrong with the
/// other sign: the sign follows the orientation, not the component.
#[test]
fn claim7_exact_solution_needs_alpha_of_the_sign_opposite_to_q_wedge_p() {
    for (name, z0) in lab::free_starts() {
        let (right, wrong) = lab::alpha_sign_errors(&z0);
        assert!(right <= 1e-11, "{name}: formula off by {right:e}");
        assert!(
            wrong >= 0.1,
            "{name}: the other sign of α is off by only {wrong:e}"
        );
    }
}

/// eq hopf_lambda (λ_paper = 2λ) is the DAE's multiplier, and the runtime's
/// fibre displacement per RATTLE step converges to it at order 2, SHAKE
/// supplying exactly half of it.
#[test]
fn claim7_multiplier_formula_and_the_runtime_displacements() {
    let sys = r::HopfFree { radius2: 1.0 };
    for (name, z0) in lab::free_starts() {
        let lam = r::hopf_lambda([z0[0], z0[1]], [z0[2], z0[3]]);
        let reference = r::multipliers(&sys, &DVector::from_row_slice(&z0))[0];
        assert!(
            (lam - reference).abs() <= 1e-14 * lam.abs(),
            "{name}: eq hopf_lambda gives {lam}, the index reduction {reference}"
        );
        let err = |h: f64| {
            let (mu, sigma) = lab::free_step_multipliers(&z0, h).unwrap();
            assert!(
                (mu - sigma).abs() <= 1e-12 * mu.abs(),
                "{name}: SHAKE's μ = {mu} is not half of μ + σ (σ = {sigma})"
            );
            ((mu + sigma) / h - lam).abs() / lam.abs()
        };
        let ratio = err(0.1) / err(0.05);
        assert!(
            (3.5..=4.5).contains(&ratio),
            "{name}: error ratio {ratio}, not 4"
        );
    }
}

/// Every RATTLE point lies on the exact trajectory (a great circle) to
/// round-off, and the fibre of every SHAKE point meets it; the timing is off
/// by an O(h²) change of frequency.
#[test]
fn claim7_rattle_points_lie_on_the_exact_trajectory_with_another_timing() {
    let steps = |h: f64| (40.0 / h).round() as u64;
    for (name, z0) in lab::free_starts() {
        let omega = lab::free_omega(&z0);
        let mut freq = Vec::new();
        for h in [0.1, 0.05] {
            let run = lab::free_run(&z0, h, steps(h)).unwrap();
            let bound = steps(h) as f64 * EPS;
            let on = lab::max_abs(&run.curve_distance);
            assert!(
                on <= bound,
                "{name}, h = {h}: {on:e} off the exact trajectory"
            );
            let off = lab::max_abs(&run.shake_offset);
            assert!(
                off <= bound,
                "{name}, h = {h}: SHAKE's fibre misses it by {off:e}"
            );
            freq.push((run.omega() / omega - 1.0).abs());
        }
        assert!(
            freq[0] >= 1e-4,
            "{name}: no reparametrisation visible ({:e})",
            freq[0]
        );
        let ratio = freq[0] / freq[1];
        assert!(
            (3.5..=4.5).contains(&ratio),
            "{name}: ω error ratio {ratio}, not 4"
        );
    }
}

// ===========================================================================
// Claim 8: H = |p|²/2 − g·q, g = (0, −1), midpoint, h = 0.1
// ===========================================================================

/// The paper's table lies on M^H of the sphere through it (|z|² =
/// 0.98000000636, not 1); the unit-sphere versions are on the unit M^H and
/// agree with the reference's own construction.
#[test]
fn claim8_initial_data_on_the_printed_sphere_and_on_the_unit_sphere() {
    for s in lab::paper_starts() {
        assert!(
            (s.radius2 - 0.98).abs() < 1e-8,
            "{}: |z|² = {}",
            s.name,
            s.radius2
        );
        let mut hidden = [0.0];
        s.system()
            .hidden_constraints(&s.z[..2], &s.z[2..], &mut hidden);
        assert!(
            hidden[0].abs() <= 1e-15,
            "{}: {{g,H}} = {:e}",
            s.name,
            hidden[0]
        );
    }
    for s in lab::unit_starts().unwrap() {
        let (mut g, mut hidden) = ([0.0], [0.0]);
        s.system().constraints(&s.z[..2], &s.z[2..], &mut g);
        s.system()
            .hidden_constraints(&s.z[..2], &s.z[2..], &mut hidden);
        assert!(
            g[0].abs() <= 4.0 * EPS && hidden[0].abs() <= 4.0 * EPS,
            "{}",
            s.name
        );
        let refd = r::hopf_onto_mh(&s.z, lab::GRAVITY, 1.0);
        let d = (0..4).map(|k| (refd[k] - s.z[k]).abs()).fold(0.0, f64::max);
        assert!(
            d <= 1e-14,
            "{}: the runtime's projection and the reference's differ by {d:e}",
            s.name
        );
    }
}

/// Without the constraint the motion is uniformly accelerated and the
/// midpoint rule is exact: all error of the scene is the constraint's.
#[test]
fn claim8_midpoint_rule_is_exact_for_the_unconstrained_flow() {
    let err = lab::unconstrained_midpoint_error(&lab::paper_starts()[0], H, 100);
    assert!(err <= 1e-13, "{err:e}");
}

/// The projected trajectories of z_a, z_b, z_c (on both spheres), for SHAKE
/// and RATTLE alike, return to their start after every period to far less
/// than the O(h²)·size a non-structure-preserving method would drift.
#[test]
fn claim8_projected_trajectories_are_closed() {
    let mut starts = lab::paper_starts();
    starts.extend(lab::unit_starts().unwrap());
    for s in &starts {
        let mut periods = Vec::new();
        let mut projected = Vec::new();
        for method in [Method::Rattle, Method::Shake] {
            let run = lab::gravity_run(s, method, H, 400).unwrap();
            projected.push(
                run.z
                    .iter()
                    .map(|z| r::hopf_plane_point(z))
                    .collect::<Vec<_>>(),
            );
            let c = lab::closure(&run.t, &run.z);
            assert!(
                c.gaps.len() >= 10,
                "{}: only {} periods",
                s.name,
                c.gaps.len()
            );
            let worst = c.gaps.iter().fold(0.0f64, |a, &b| a.max(b)) / c.size;
            assert!(
                worst <= H * H,
                "{} {method:?}: returns {worst:e}·size away",
                s.name
            );
            periods.push(c.period);
        }
        assert!(
            (periods[0] - periods[1]).abs() <= 1e-9,
            "{}: {periods:?}",
            s.name
        );
    }
}

/// |g| at round-off for both methods, {g,H} at round-off for RATTLE and
/// (h/2)|{{g,H},H}|·(1 + O(h)) for SHAKE, which halves with h.
#[test]
fn claim8_constraint_and_hidden_constraint_residuals() {
    let za = &lab::paper_starts()[0];
    let shake = lab::gravity_run(za, Method::Shake, H, 300).unwrap();
    let rattle = lab::gravity_run(za, Method::Rattle, H, 300).unwrap();
    for (name, run) in [("SHAKE", &shake), ("RATTLE", &rattle)] {
        let g = lab::max_abs(&run.g);
        assert!(g <= 1e-14, "{name}: |g| = {g:e}");
    }
    let hidden = lab::max_abs(&rattle.hidden);
    assert!(hidden <= 1e-14, "RATTLE: |{{g,H}}| = {hidden:e}");
    let rs = za.reference();
    for k in 1..shake.z.len() {
        let ratio = shake.hidden[k] / lab::predicted_shake_hidden(&rs, &rattle.z[k], H);
        assert!(
            (0.8..=1.25).contains(&ratio),
            "step {k}: SHAKE residual / prediction = {ratio}"
        );
    }
    let half = lab::gravity_run(za, Method::Shake, H / 2.0, 600).unwrap();
    let ratio = lab::max_abs(&shake.hidden) / lab::max_abs(&half.hidden);
    assert!(
        (1.8..=2.2).contains(&ratio),
        "SHAKE residual ratio {ratio}, not 2"
    );
}

/// Energy: no drift for either method, and RATTLE's error is O(h²).
#[test]
fn claim8_energy_has_no_drift_and_rattle_error_is_second_order() {
    let za = &lab::paper_starts()[0];
    for method in [Method::Shake, Method::Rattle] {
        let run = lab::gravity_run(za, method, H, 4000).unwrap();
        let (first, last) = lab::energy_windows(&run.energy);
        let ratio = last / first;
        assert!(
            (0.5..=2.0).contains(&ratio),
            "{method:?}: last/first tenth {ratio}"
        );
    }
    let e_of = |h: f64| {
        let run = lab::gravity_run(za, Method::Rattle, h, (30.0 / h).round() as u64).unwrap();
        let e0 = run.energy[0];
        run.energy.iter().fold(0.0f64, |m, e| m.max((e - e0).abs()))
    };
    let ratio = e_of(0.1) / e_of(0.05);
    assert!(
        (3.2..=4.8).contains(&ratio),
        "energy error ratio {ratio}, not 4"
    );
}

/// fig_fibres: the SHAKE point sits off M^H along its fibre by the
/// predicted angle h|{{g,H},H}|/|N| after every step, and the fibres above
/// the trajectory show both case (i) (four crossings) and case (ii) (two).
#[test]
fn claim8_fibres_above_the_shake_trajectory() {
    let za = &lab::paper_starts()[0];
    let shake = lab::gravity_run(za, Method::Shake, H, 106).unwrap();
    let rattle = lab::gravity_run(za, Method::Rattle, H, 106).unwrap();
    let rs = za.reference();
    let mut cases = [0usize; 5];
    for (k, z) in shake.z.iter().enumerate() {
        cases[lab::crossings(z).min(4)] += 1;
        if k == 0 {
            assert!(lab::fibre_offset(z).abs() < 1e-12, "z_a is on M^H");
            continue;
        }
        let offset = lab::fibre_offset(z).abs();
        let zr = &rattle.z[k];
        let predicted = H * lab::double_bracket(&rs, zr).abs() / lab::nondegeneracy(zr).abs();
        let ratio = offset / predicted;
        assert!(
            (0.8..=1.25).contains(&ratio),
            "step {k}: offset / prediction = {ratio}"
        );
    }
    assert!(
        cases[4] >= 1 && cases[2] >= 1,
        "crossings per fibre: {cases:?}"
    );
    // The image is black (|Hr'| = 0) at the RATTLE point of the fibre: the
    // darkest row near the SHAKE point (|y| < 0.05; the fibre meets M^H
    // elsewhere too) is the one of its fibre offset.
    let rows = 2000;
    let img = lab::fibre_image(&shake.z[..2], rows, -0.5, 0.5);
    let y_of = |j: usize| -0.5 + (j as f64 + 0.5) / rows as f64;
    let jmin = (0..rows)
        .filter(|&j| y_of(j).abs() < 0.05)
        .min_by(|&a, &b| img[a][1].partial_cmp(&img[b][1]).unwrap())
        .unwrap();
    let theta = lab::fibre_offset(&shake.z[1]);
    let y = y_of(jmin);
    assert!(
        (y - theta / (2.0 * std::f64::consts::PI)).abs() <= 1.0 / rows as f64,
        "{y} vs {theta}"
    );
}

// ===========================================================================
// Claim 9: a trajectory that runs into a fold (case iii)
// ===========================================================================

/// The start lies on M^H, on the branch of maxima (N < 0), and the exact
/// solution from it reaches N = 0 in finite time in both directions.
#[test]
fn claim9_the_exact_solution_reaches_a_fold() {
    let start = lab::fold_start();
    let mut hidden = [0.0];
    start
        .system()
        .hidden_constraints(&start.z[..2], &start.z[2..], &mut hidden);
    assert!(hidden[0].abs() <= 1e-14, "{{g,H}} = {:e}", hidden[0]);
    assert!(lab::nondegeneracy(&start.z) < -1.0);
    for direction in [1.0, -1.0] {
        let (t_star, samples) = lab::fold_approach(&start, direction);
        assert!(
            t_star * direction > 0.5 && t_star.abs() < 3.0,
            "t* = {t_star}"
        );
        let n_end = samples.last().unwrap().1;
        assert!(n_end < 0.0 && n_end.abs() < lab::nondegeneracy(&start.z).abs() / 8.0);
    }
}

fn check_fold_runs(options: Options, mode: &str) {
    let start = lab::fold_start();
    let mut failures = Vec::new();
    for h in [H, H / 2.0, -H, -H / 2.0] {
        let t_star = lab::fold_time(&start, h);
        let run = lab::fold_run(&start, h, options, (3.0 / h.abs()).round() as u64);
        if !run.typed_error() {
            failures.push(format!(
                "h = {h}: no typed error (error: {:?}), last state at t = {} past t* = {t_star}",
                run.error,
                run.t_last()
            ));
        }
        if !run.off_branch.is_empty() {
            failures.push(format!(
                "h = {h}: silent jump, stored states {:?} at t = {:?} have N = {:?} (N before: {:?}; t* = {t_star}); error reported: {:?}",
                run.off_branch,
                run.off_branch.iter().map(|&k| run.t[k]).collect::<Vec<_>>(),
                run.off_branch.iter().map(|&k| run.n[k]).collect::<Vec<_>>(),
                run.off_branch.iter().map(|&k| run.n[k - 1]).collect::<Vec<_>>(),
                run.error.as_ref().map(|e| e.to_string())
            ));
        }
        if run.typed_error() && (t_star - run.t_last()).abs() > 3.0 * h.abs() {
            failures.push(format!(
                "h = {h}: stopped at t = {}, t* = {t_star}",
                run.t_last()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "RATTLE into a fold ({mode}):\n{}",
        failures.join("\n")
    );
}

/// A RATTLE run (the default: Π only at the stored states) into a fold
/// stops with a typed error at the fold and never returns a state of another
/// branch of M^H.
#[test]
fn claim9_rattle_run_into_a_fold_stops_with_a_typed_error_default_options() {
    check_fold_runs(Options::default(), "default options");
}

/// The same with Π after every step.
#[test]
fn claim9_rattle_run_into_a_fold_stops_with_a_typed_error_projecting_every_step() {
    let options = Options {
        project_every_step: true,
        ..Options::default()
    };
    check_fold_runs(options, "project_every_step");
}

/// What the checks are for: with them off, Newton silently converges to a
/// point of another branch past the fold (the paper's spurious solution).
#[test]
fn claim9_without_the_checks_newton_jumps_to_another_component() {
    let run = lab::fold_run(&lab::fold_start(), H, lab::unchecked_options(), 30);
    assert!(run.error.is_none(), "{:?}", run.error);
    assert!(!run.off_branch.is_empty(), "no jump: N = {:?}", run.n);
}
