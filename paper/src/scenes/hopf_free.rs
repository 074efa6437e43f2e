//! The harmonic (Hopf) constraint with H = |p|²/2, the paper's Section 5.4.1
//! (claim 7 in the README's table).
//!
//! g = |q|² + |p|² − 1 on R⁴ = C² (z_k = q_k + i p_k), H = |p|²/2, SHAKE and
//! RATTLE over the implicit midpoint rule. The fibres are the great circles
//! z ↦ e^{−2iσ}z of the Hopf fibration and M^H = {q·p = 0} has two
//! components, {|q| > |p|} and {|q| < |p|}, separated by the exceptional
//! fibres |q| = |p| where nondegeneracy fails. Everything is measured against
//! `shake-testkit/src/reference.rs`, which shares no code with shake.
//!
//! - **The multiplier** (eq hopf_lambda): λ_paper = |p|²/(|q|² − |p|²). The
//!   paper writes q' = (1 + λ)p; our convention q' = H_p + g_pᵀλ with
//!   g_p = 2p gives λ = λ_paper/2. It is checked against the multiplier of the
//!   index-reduced DAE (N λ = {{g,H},H}, from num-dual derivatives), and
//!   against the runtime: the whole displacement along the fibres of one
//!   RATTLE step, SHAKE's μ plus the projection's σ, is hλ + O(h³) (SHAKE
//!   alone supplies exactly half of it here).
//! - **The exact solution** (eq hopf_dea_exact_solution), q(t) =
//!   R(t/(α − 1/α))q0 and p(t) = R(t/(α − 1/α))p0 with α = ±|p0|/|q0|, against
//!   the reference DAE integrator (order 12). **The sign of α** is not set by
//!   the component of M^H, as the paper says, but by the orientation of the
//!   initial data: the formula is right with α = −sign(q0∧p0)·|p0|/|q0|
//!   (q∧p = q₀p₁ − q₁p₀) on *both* components, i.e. 1/(α − 1/α) =
//!   (q0∧p0)/(|q0|² − |p0|²). On {|q| > |p|} (|α| < 1) α has the sign opposite
//!   to q0∧p0, and on {|q| < |p|} (|α| > 1) too. Each component holds both
//!   orientations: q∧p changes sign through p = 0 on the first and through
//!   q = 0 on the second. The scene runs one point of each orientation on
//!   each component, and the other sign of α is off by O(1) on all four.
//! - **RATTLE on the exact trajectory**: every RATTLE point lies on the
//!   circle θ ↦ (R(θ)q0, R(θ)p0) to round-off, over thousands of steps,
//!   while |z_k − z(kh)| grows like t·h²: the method turns by a slightly
//!   wrong angle per step (a time reparametrisation, ω_h = ω(1 + O(h²))).
//!   SHAKE's points lie on fibres through that circle.
//! - fig_Hopf_fibre: one fibre, its four points on M^H and the two exact
//!   trajectories through them, drawn in R³ after a stereographic
//!   projection of S³; and H along that fibre.

use std::f64::consts::PI;

pub(super) use geoshake_testkit::hopf_lab as lab;

use lab::{FreeRun, Z};
use nalgebra::DVector;

use crate::claims::{Bound, Claims};
use crate::plot::{envelope, Figure, Mark, PlotResult, PALETTE};
use crate::reference as r;
use crate::Ctx;
use plotters::prelude::SeriesLabelPosition;

const EPS: f64 = f64::EPSILON;
/// Length of the runs: 1000 steps of h = 0.1 and 2000 of h = 0.05.
const T_END: f64 = 100.0;

pub fn run(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    exact_solution(claims);
    multiplier(claims)?;
    on_the_trajectory(ctx, claims)?;
    fibre_figures(ctx)?;
    Ok(())
}

/// eq hopf_dea_exact_solution against the reference, with both signs of α.
fn exact_solution(claims: &mut Claims) {
    let (mut right, mut wrong) = (0.0f64, f64::INFINITY);
    for (name, z0) in lab::free_starts() {
        let (e_right, e_wrong) = lab::alpha_sign_errors(&z0);
        println!(
            "   {name}: α = −sign(q∧p)|p|/|q| off by {e_right:.1e}, the other sign by {e_wrong:.2}"
        );
        right = right.max(e_right);
        wrong = wrong.min(e_wrong);
    }
    claims.check(
        "7",
        "H = |p|²/2: the exact solution (eq hopf_dea_exact_solution) with α = −sign(q0∧p0)|p0|/|q0| solves the DAE, on both components of Mᴴ and for both orientations",
        "max |formula − reference DAE solution|, t ≤ 3, 4 initial data",
        right,
        Bound::AtMost(1e-11),
        "the reference integrator's own accuracy (its error estimate is held below 1e-11)",
    );
    claims.check(
        "7",
        "the sign of α is set by the orientation of q0∧p0, not by the component of Mᴴ: the other sign is wrong on both components",
        "min |formula with −α − reference|, same data",
        wrong,
        Bound::AtLeast(0.1),
        "the wrong sign turns the circle backwards: an O(1) error by t = 0.5",
    );
}

/// eq hopf_lambda: against the reference multiplier and the runtime's
/// fibre displacements.
fn multiplier(claims: &mut Claims) -> PlotResult<()> {
    let sys = r::HopfFree { radius2: 1.0 };
    let mut formula_err = 0.0f64;
    let (mut err1, mut err2, mut half) = (0.0f64, 0.0f64, 0.0f64);
    let (h1, h2) = (0.1, 0.05);
    for (_, z0) in lab::free_starts() {
        let lam = r::hopf_lambda([z0[0], z0[1]], [z0[2], z0[3]]);
        let reference = r::multipliers(&sys, &DVector::from_row_slice(&z0))[0];
        formula_err = formula_err.max((lam - reference).abs() / lam.abs());
        let (mu1, sigma1) = lab::free_step_multipliers(&z0, h1)?;
        let (mu2, sigma2) = lab::free_step_multipliers(&z0, h2)?;
        err1 = err1.max(((mu1 + sigma1) / h1 - lam).abs() / lam.abs());
        err2 = err2.max(((mu2 + sigma2) / h2 - lam).abs() / lam.abs());
        half = half.max((mu1 / (mu1 + sigma1) - 0.5).abs());
        println!(
            "   λ = {lam:+.6} (λ_paper = {:+.6}); h = 0.1: μ/h = {:+.6}, σ/h = {:+.6}",
            2.0 * lam,
            mu1 / h1,
            sigma1 / h1
        );
    }
    claims.check(
        "7",
        "eq hopf_lambda: λ = |p|²/(2(|q|²−|p|²)) (= λ_paper/2 in our convention q' = H_p + g_pᵀλ) is the multiplier of the DAE",
        "max relative |formula − reference multiplier (N λ = {{g,H},H})|",
        formula_err,
        Bound::AtMost(1e-14),
        "two evaluations of the same number: round-off",
    );
    claims.check(
        "7",
        "RATTLE's displacement along the fibres per step is hλ + O(h³): it converges to eq hopf_lambda at order 2",
        "max |(μ+σ)/h − λ|/|λ| at h = 0.1 over its value at h = 0.05",
        err1 / err2,
        Bound::Within(3.5, 4.5),
        "midpoint RATTLE is symmetric, so the error is even in h: ratio 2² = 4",
    );
    println!(
        "   relative error of (μ+σ)/h: {err1:.2e} (h = 0.1), {err2:.2e} (h = 0.05); SHAKE's share μ/(μ+σ) = 1/2 to {half:.1e}"
    );
    Ok(())
}

/// RATTLE's points against the exact trajectory, and the figure.
fn on_the_trajectory(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    let (h1, h2) = (0.1, 0.05);
    let steps = |h: f64| (T_END / h).round() as u64;
    let (mut on_curve, mut shake_off) = (0.0f64, 0.0f64);
    let (mut freq1, mut freq2) = (0.0f64, 0.0f64);
    let mut shown: Vec<FreeRun> = Vec::new();
    for (i, (name, z0)) in lab::free_starts().into_iter().enumerate() {
        let omega = lab::free_omega(&z0);
        for h in [h1, h2] {
            let run = lab::free_run(&z0, h, steps(h))?;
            on_curve = on_curve.max(lab::max_abs(&run.curve_distance));
            shake_off = shake_off.max(lab::max_abs(&run.shake_offset));
            let rel = (run.omega() / omega - 1.0).abs();
            if h == h1 {
                freq1 = freq1.max(rel);
            } else {
                freq2 = freq2.max(rel);
            }
            println!(
                "   {name}, h = {h}: distance to the exact trajectory ≤ {:.1e}, |z − z(t)| at t = {T_END} is {:.3}, ω_h/ω − 1 = {:+.3e}",
                lab::max_abs(&run.curve_distance),
                run.time_error.last().unwrap(),
                run.omega() / omega - 1.0
            );
            if i == 0 {
                shown.push(run);
            }
        }
    }
    let n_max = steps(h2) as f64;
    claims.check(
        "7",
        "RATTLE (midpoint) reproduces the exact solution up to a time reparametrisation: every point lies on the exact trajectory",
        "max distance of z_k to the circle θ ↦ (R(θ)q0, R(θ)p0), 4 initial data, 2000 steps",
        on_curve,
        Bound::AtMost(n_max * EPS),
        "round-off, one rounding per step at worst: steps·ε",
    );
    claims.check(
        "7",
        "SHAKE maps between fibres that meet the same exact trajectory",
        "max |Im ζ(z_k⁻) − Im ζ(z0)| (ζ = 2 z0 z̄1 is constant on fibres and on the trajectory)",
        shake_off,
        Bound::AtMost(n_max * EPS),
        "round-off: steps·ε",
    );
    claims.check(
        "7",
        "… but not with the exact timing: RATTLE turns by a wrong angle per step",
        "max |ω_h/ω − 1| at h = 0.1",
        freq1,
        Bound::AtLeast(1e-4),
        "a time reparametrisation of order h² ≈ 1e-2, far above round-off",
    );
    claims.check(
        "7",
        "the reparametrisation is O(h²)",
        "max |ω_h/ω − 1| at h = 0.1 over its value at h = 0.05",
        freq1 / freq2,
        Bound::Within(3.5, 4.5),
        "symmetric method of order 2: ratio 2² = 4",
    );

    let pts = |run: &FreeRun, v: &[f64]| -> Vec<(f64, f64)> {
        run.t.iter().copied().zip(v.iter().copied()).collect()
    };
    let (a, b) = (&shown[0], &shown[1]);
    Figure::new(
        "H = |p|²/2: RATTLE's points lie on the exact trajectory; only their timing is off",
        "time t",
        "distance",
    )
    .log_y()
    .y_range(1e-17, 10.0)
    .legend_at(SeriesLabelPosition::MiddleRight)
    .series_colored(
        "|z_k − z(t_k)|, h = 0.1 (timing)",
        pts(a, &a.time_error),
        Mark::Line,
        PALETTE[1],
    )
    .series_colored(
        "|z_k − z(t_k)|, h = 0.05",
        pts(b, &b.time_error),
        Mark::Line,
        PALETTE[4],
    )
    // Round-off is noise: drawn as its envelope (largest value per window).
    .series_colored(
        "distance of z_k to the exact trajectory, h = 0.1 (max per window)",
        envelope(&a.t, &a.curve_distance, 200),
        Mark::Line,
        PALETTE[0],
    )
    .series_colored(
        "distance of z_k to the exact trajectory, h = 0.05 (max per window)",
        envelope(&b.t, &b.curve_distance, 200),
        Mark::Line,
        PALETTE[5],
    )
    .series_colored(
        "steps·ε at h = 0.05 (round-off bound)",
        b.t.iter()
            .enumerate()
            .map(|(k, &t)| (t, k.max(1) as f64 * EPS))
            .collect(),
        Mark::Dashed,
        PALETTE[6],
    )
    .save(&ctx.out, "hopf_free_reparametrisation")?;
    Ok(())
}

// ---------------------------------------------------------------------------
// fig_Hopf_fibre
// ---------------------------------------------------------------------------

/// A closed curve on S³ sampled at n + 1 points.
fn circle(n: usize, f: impl Fn(f64) -> Z) -> Vec<Z> {
    (0..=n).map(|k| f(2.0 * PI * k as f64 / n as f64)).collect()
}

fn rotate_both(z: &Z, theta: f64) -> Z {
    let q = r::rot(theta, [z[0], z[1]]);
    let p = r::rot(theta, [z[2], z[3]]);
    [q[0], q[1], p[0], p[1]]
}

/// The orthographic image of the great circle θ ↦ cos θ u + sin θ v (u, v
/// orthonormal in R⁴) in the plane spanned by the orthonormal a, b: an
/// ellipse centred at 0.
fn ellipse(a: &Z, b: &Z, u: &Z, v: &Z) -> Vec<(f64, f64)> {
    circle(240, |t| {
        let (s, c) = t.sin_cos();
        [0, 1, 2, 3].map(|k| c * u[k] + s * v[k])
    })
    .iter()
    .map(|x| (dot4(x, a), dot4(x, b)))
    .collect()
}

fn dot4(x: &Z, y: &Z) -> f64 {
    x.iter().zip(y).map(|(u, v)| u * v).sum()
}

/// The projection plane for fig_Hopf_fibre: x along z0 (so ±z0 sit on
/// the outline), y along the unit vector b ⊥ z0 (from a grid on the unit
/// sphere of z0⊥) that makes the images of the fibre (span z0, z1) and of
/// the two trajectories (span z0, Jz0 and span z1, Jz1) ellipses as fat and
/// as different from one another as possible.
fn projection_plane(z0: &Z, z1: &Z, jz0: &Z, jz1: &Z) -> (Z, Z) {
    // An orthonormal frame z0, e1, e2, e3 of R⁴.
    let mut frame: Vec<Z> = vec![*z0];
    for v in [
        *z1,
        *jz0,
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
    ] {
        let mut w = v;
        for e in &frame {
            let d = dot4(&w, e);
            w = [0, 1, 2, 3].map(|k| w[k] - d * e[k]);
        }
        let n = dot4(&w, &w).sqrt();
        if n > 1e-6 && frame.len() < 4 {
            frame.push(w.map(|x| x / n));
        }
    }
    let semi_minor = |b: &Z, u: &Z, v: &Z| {
        nalgebra::Matrix2::new(dot4(z0, u), dot4(z0, v), dot4(b, u), dot4(b, v))
            .singular_values()
            .min()
    };
    let (mut best, mut plane) = (f64::MIN, (*z0, frame[1]));
    for i in 0..90 {
        for j in 0..180 {
            let (th, ph) = (PI * (i as f64 + 0.5) / 90.0, 2.0 * PI * j as f64 / 180.0);
            let c = [th.cos(), th.sin() * ph.cos(), th.sin() * ph.sin()];
            let b =
                [0, 1, 2, 3].map(|k| c[0] * frame[1][k] + c[1] * frame[2][k] + c[2] * frame[3][k]);
            let (f, a, tb) = (
                semi_minor(&b, z0, z1),
                semi_minor(&b, z0, jz0),
                semi_minor(&b, z1, jz1),
            );
            let score = f
                .min(a)
                .min(tb)
                .min(1.5 * (dot4(z1, &b).abs() - dot4(jz0, &b).abs()).abs());
            if score > best {
                best = score;
                plane = (*z0, b);
            }
        }
    }
    plane
}

/// fig_Hopf_fibre and H along the fibre.
fn fibre_figures(ctx: &Ctx) -> PlotResult<()> {
    // z0 on {|q| > |p|} (|q0| = 0.95: the fibre and the trajectory through
    // z0 are great circles whose planes meet at an angle acos(2 q0∧p0),
    // well apart here); the fibre through it is θ ↦ (q cos θ + p sin θ,
    // −q sin θ + p cos θ) = cos θ z0 + sin θ z1 with z1 = (p0, −q0), and it
    // meets M^H where Hr'(θ) = 0: at ±z0 (on the exact trajectory through
    // z0, a great circle θ ↦ cos θ z0 + sin θ Jz0 with Jz0 = (Jq0, Jp0)) and
    // at ±z1 (on the component {|q| < |p|}).
    let z0 = lab::free_start(0.95, 0.3, 1.0);
    let z1 = r::fibre_point(&z0, PI / 2.0);
    let (jz0, jz1) = (rotate_both(&z0, PI / 2.0), rotate_both(&z1, PI / 2.0));
    let neg = |z: &Z| z.map(|a| -a);
    let (a, b) = projection_plane(&z0, &z1, &jz0, &jz1);
    let view = |x: &Z| (dot4(x, &a), dot4(x, &b));
    let grey = plotters::style::RGBColor(200, 200, 200);
    let mut fig = Figure::new(
        "A fibre of the Hopf constraint meets Mᴴ in four points (S³, orthographic view)",
        "z·z0",
        "z·b  (b ⊥ z0, chosen to separate the circles)",
    )
    // Equal scales on both axes (about 354 pixels per unit), with room
    // for the legend on the right.
    .x_range(-1.1, 2.0)
    .y_range(-1.1, 1.1)
    .size(1210, 900);
    // Other fibres through the trajectory of z0: each meets it twice.
    for k in 1..4 {
        let zk = rotate_both(&z0, k as f64 * PI / 4.0);
        let vk = r::fibre_point(&zk, PI / 2.0);
        let name = if k == 1 {
            "other fibres through the trajectory of z0"
        } else {
            ""
        };
        fig = fig.series_colored(name, ellipse(&a, &b, &zk, &vk), Mark::Line, grey);
    }
    fig = fig
        .series_colored(
            "the fibre through z0 (a great circle)",
            ellipse(&a, &b, &z0, &z1),
            Mark::Line,
            PALETTE[7],
        )
        .series_colored(
            "exact trajectory through ±z0 (|q| > |p|)",
            ellipse(&a, &b, &z0, &jz0),
            Mark::Dashed,
            PALETTE[0],
        )
        .series_colored(
            "exact trajectory through ±z1 = ±(p0, −q0) (|q| < |p|)",
            ellipse(&a, &b, &z1, &jz1),
            Mark::Dashed,
            PALETTE[1],
        );
    fig = dots(
        fig,
        "fibre ∩ Mᴴ: ±z0",
        PALETTE[0],
        &[view(&z0), view(&neg(&z0))],
    );
    fig = dots(
        fig,
        "fibre ∩ Mᴴ: ±z1",
        PALETTE[1],
        &[view(&z1), view(&neg(&z1))],
    );
    fig.save(&ctx.out, "hopf_free_fibre")?;

    // H along the same fibre: its critical points are the four points above.
    let n = 400;
    let h_of = |z: &Z| 0.5 * (z[2] * z[2] + z[3] * z[3]);
    let curve: Vec<(f64, f64)> = (0..=n)
        .map(|k| {
            let t = 2.0 * PI * k as f64 / n as f64;
            (t / (2.0 * PI), h_of(&r::fibre_point(&z0, t)))
        })
        .collect();
    let mark = |ts: [f64; 2]| -> Vec<(f64, f64)> {
        ts.iter()
            .map(|&t| (t / (2.0 * PI), h_of(&r::fibre_point(&z0, t))))
            .collect()
    };
    let (h_min, h_max) = (h_of(&z0), h_of(&z1));
    let span = h_max - h_min;
    let fig = Figure::new(
        "H = |p|²/2 along the fibre through z0 = (q0, p0), |q0| > |p0|",
        "fibre angle θ/2π  (point q cos θ + p sin θ, −q sin θ + p cos θ)",
        "H",
    )
    .y_range(h_min - 0.05 * span, h_max + 0.35 * span)
    .legend_at(SeriesLabelPosition::UpperMiddle)
    .series_colored("H on the fibre", curve, Mark::Line, PALETTE[7]);
    let fig = dots(
        fig,
        "minima ±z0: the trajectory through z0",
        PALETTE[0],
        &mark([0.0, PI]),
    );
    let fig = dots(
        fig,
        "maxima ±(p0, −q0): the other component of Mᴴ",
        PALETTE[1],
        &mark([PI / 2.0, 1.5 * PI]),
    );
    fig.save(&ctx.out, "hopf_free_fibre_energy")?;
    Ok(())
}

/// Marks a few points with large filled dots, one legend entry.
pub(super) fn dots(
    fig: Figure,
    name: &str,
    color: plotters::style::RGBColor,
    pts: &[(f64, f64)],
) -> Figure {
    fig.series_colored(name, pts.to_vec(), Mark::BigDots, color)
}
