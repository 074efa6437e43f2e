//! The planar pendulum of Example 1.3 (claims 1–4 in the README's table).
//!
//! H = |p|²/2 + G q₂ on M = {|q|² = ℓ²} with ℓ = G = 1, started at rest at
//! θ = 2 rad from the downward vertical (a large, nonlinear swing).
//!
//! - Claim 1: SHAKE and RATTLE over each base map keep |g| at round-off,
//!   RATTLE keeps |{g,H}| at round-off, SHAKE's |{g,H}| is O(h), energy shows
//!   no drift.
//! - Claim 2: the classical formulas of Section 5.1.3 (written independently
//!   in `shake-testkit/src/reference.rs`) give the same steps to round-off.
//! - Claim 3: RATTLE over a symmetric base map is symmetric; SHAKE is
//!   presymplectic on M and RATTLE symplectic on M^H (Prop. 4.3, Cor. 4.5).
//! - Claim 4: SHAKE's result does not depend on where on the fibre of z0 it
//!   starts (Section 4).
//! - The figure of one step (the paper's fig_pendulum).

use geoshake::models::{DoublePendulum, Pendulum};
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, State, Stop, StormerVerlet,
    SymplecticEuler,
};
use nalgebra::DVector;
use plotters::prelude::SeriesLabelPosition;

use super::util::{derivative_along, energy_windows, omega, state_of, tangent, z_of};
use crate::claims::{Bound, Claims};
use crate::plot::{arrow, envelope, Figure, Mark, PlotResult, PALETTE};
use crate::reference as r;
use crate::Ctx;

const EPS: f64 = f64::EPSILON;

/// How many windows the long-run figures are cut into (one point each).
const WINDOWS: usize = 250;

fn pendulum() -> Pendulum {
    Pendulum::new(1.0, 1.0)
}

fn start() -> State {
    state_of(&r::PlanarPendulum::default().state(2.0, 0.0))
}

pub fn run(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    long_runs(ctx, claims)?;
    classical(ctx, claims)?;
    symmetry(claims)?;
    symplecticity(claims)?;
    fibre_independence(claims)?;
    one_step_figure(ctx)?;
    Ok(())
}

/// What a long run records at every step.
struct Record {
    t: Vec<f64>,
    energy: Vec<f64>,
    g: Vec<f64>,
    hidden: Vec<f64>,
}

fn record<B: BaseMap>(base: B, shake: bool, h: f64, steps: u64) -> Result<Record, String> {
    let integ = Integrator::new(pendulum(), base, h).with_diagnostics();
    let mut integ = if shake { integ.shake() } else { integ.rattle() };
    let out = integ.run(start(), Stop::Steps(steps)).execute();
    if let Some(e) = out.error {
        return Err(format!("{} run failed: {e}", B::NAME));
    }
    let d = &out.trajectory.diagnostics;
    Ok(Record {
        t: d.iter().map(|x| x.t).collect(),
        energy: d.iter().map(|x| x.energy).collect(),
        g: d.iter().map(|x| x.constraint).collect(),
        hidden: d.iter().map(|x| x.hidden_constraint).collect(),
    })
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

fn long_runs(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    // T = 10⁴ in the full run: long enough that a drift (the mark of a
    // method that is not symplectic) would show against the O(h^p)
    // oscillation, which is all a symplectic method has.
    let h = 0.05;
    let steps: u64 = if ctx.quick { 20_000 } else { 200_000 };
    let t_end = h * steps as f64;
    println!("   h = {h}, {steps} steps (T = {t_end})");
    let window = t_end / WINDOWS as f64;
    let mut energy_fig = Figure::new(
        &format!("Pendulum, h = {h}, T = {t_end:.0}: energy error of RATTLE and of projected RK4"),
        "time t (units √(L/g); period ≈ 8.35)",
        &format!("max |E − E(0)| in windows of {window:.0} (units mgL)"),
    )
    .log_y()
    .y_range(1e-8, 10.0)
    .size(900, 700)
    .note("θ(0) = 2 rad, at rest; m = L = g = 1. Each point: the largest error in one window.")
    .note("RATTLE: flat envelopes, a bounded oscillating error with no drift (symplectic).")
    .note("RK4 + projection is more accurate at first but drifts ∝ t: not symplectic.")
    .note("Midpoint and Störmer–Verlet coincide here (H quadratic in p, linear in q): O(h²);")
    .note("symplectic Euler is first order: O(h).");
    let mut resid_fig = Figure::new(
        &format!("Pendulum: constraint residuals over the midpoint rule, h = {h}"),
        "time t (units √(L/g))",
        &format!("max residual in windows of {window:.0}"),
    )
    .log_y()
    .y_range(1e-18, 100.0)
    .legend_at(SeriesLabelPosition::MiddleRight)
    .notes_at(0.3)
    .note("g = |q|² − L², {g,H} = 2 q·p (hidden constraint). Both stay at round-off (~1e-16)")
    .note("for RATTLE; SHAKE keeps g but its {g,H} is O(h): it lives on M, not on Mᴴ.");
    // Every base map with each method: one generic body, three types.
    fn per_base<B: BaseMap>(
        base: B,
        h: f64,
        steps: u64,
        claims: &mut Claims,
        energy_fig: &mut Figure,
        resid_fig: &mut Figure,
        color: plotters::style::RGBColor,
    ) -> PlotResult<()> {
        let name = B::NAME;
        for shake in [true, false] {
            let m = if shake { "SHAKE" } else { "RATTLE" };
            let rec = record(base, shake, h, steps)?;
            claims.check(
                "1",
                &format!("pendulum, {m} over {name}: |g| at round-off after every step"),
                "max |g|",
                max(&rec.g),
                Bound::AtMost(100.0 * EPS),
                "round-off: Newton to stagnation, |q|² = 1 (100 ε)",
            );
            let (first, last) = energy_windows(&rec.energy);
            claims.check(
                "1",
                &format!("pendulum, {m} over {name}: no energy drift"),
                "max|E−E0| last tenth / first tenth",
                last / first,
                Bound::AtMost(1.5),
                "symplectic: bounded, oscillating energy error",
            );
            if shake {
                let half = record(base, true, h / 2.0, 2 * steps)?;
                claims.check(
                    "1",
                    &format!("pendulum, SHAKE over {name}: hidden residual |{{g,H}}| is O(h)"),
                    "max|{g,H}|(h) / max|{g,H}|(h/2)",
                    max(&rec.hidden) / max(&half.hidden),
                    Bound::Within(1.8, 2.2),
                    "O(h): halving h halves it (ratio 2)",
                );
            } else {
                claims.check(
                    "1",
                    &format!("pendulum, RATTLE over {name}: |{{g,H}}| at round-off"),
                    "max |{g,H}|",
                    max(&rec.hidden),
                    Bound::AtMost(400.0 * EPS),
                    "round-off: {g,H} = 2q·p with |q||p| ≤ 2 (100 ε · 4)",
                );
                let e0 = rec.energy[0];
                let err: Vec<f64> = rec.energy.iter().map(|e| e - e0).collect();
                let pts = envelope(&rec.t, &err, WINDOWS);
                // Over this H (quadratic in p, linear in q) the midpoint rule
                // and Störmer–Verlet are both the exact unconstrained flow:
                // their curves coincide, so the second is dashed.
                let mark = if B::NAME == StormerVerlet::NAME {
                    Mark::Dashed
                } else {
                    Mark::Line
                };
                *energy_fig = std::mem::replace(energy_fig, Figure::new("", "", ""))
                    .series_colored(&format!("RATTLE, {name}"), pts, mark, color);
            }
            if B::NAME == ImplicitMidpoint::NAME {
                // SHAKE solid, RATTLE dashed; one colour per residual.
                let mark = if shake { Mark::Line } else { Mark::Dashed };
                let k = if shake { 0 } else { 2 };
                let fig = std::mem::replace(resid_fig, Figure::new("", "", ""));
                *resid_fig = fig
                    .series_colored(
                        &format!("|{{g,H}}|, {m}"),
                        envelope(&rec.t, &rec.hidden, WINDOWS),
                        mark,
                        PALETTE[k],
                    )
                    .series_colored(
                        &format!("|g|, {m}"),
                        envelope(&rec.t, &rec.g, WINDOWS),
                        mark,
                        PALETTE[k + 1],
                    );
            }
        }
        Ok(())
    }
    per_base(
        ImplicitMidpoint,
        h,
        steps,
        claims,
        &mut energy_fig,
        &mut resid_fig,
        PALETTE[0],
    )?;
    per_base(
        StormerVerlet,
        h,
        steps,
        claims,
        &mut energy_fig,
        &mut resid_fig,
        PALETTE[1],
    )?;
    per_base(
        SymplecticEuler,
        h,
        steps,
        claims,
        &mut energy_fig,
        &mut resid_fig,
        PALETTE[2],
    )?;
    // For contrast, a method that is accurate but not symplectic: classical
    // RK4 on the index-1 equations, projected back onto Mᴴ after each step.
    // Its energy error grows linearly in t; RATTLE's does not grow at all.
    let (t, err) = projected_rk4(h, steps);
    energy_fig = energy_fig.series_colored(
        "RK4 + projection onto Mᴴ (order 4, not symplectic)",
        envelope(&t, &err, WINDOWS),
        Mark::Line,
        PALETTE[3],
    );
    energy_fig.save(&ctx.out, "pendulum_energy")?;
    resid_fig.save(&ctx.out, "pendulum_residuals")?;
    Ok(())
}

/// The pendulum (m = L = g = 1) by classical RK4 on the index-1 equations
/// q' = p, p' = −(0, 1) − λq with λ = (|p|² − q₁)/|q|² (from d²|q|²/dt² = 0),
/// each step followed by the projection q ← q/|q|, p ← p − (p·q)q onto Mᴴ:
/// fourth order, but not symplectic. Returns the times and E − E(0).
fn projected_rk4(h: f64, steps: u64) -> (Vec<f64>, Vec<f64>) {
    let z0 = start();
    let mut z = [z0.q[0], z0.q[1], z0.p[0], z0.p[1]];
    let f = |z: [f64; 4]| {
        let lam = (z[2] * z[2] + z[3] * z[3] - z[1]) / (z[0] * z[0] + z[1] * z[1]);
        [z[2], z[3], -lam * z[0], -1.0 - lam * z[1]]
    };
    let energy = |z: [f64; 4]| 0.5 * (z[2] * z[2] + z[3] * z[3]) + z[1];
    let add = |z: [f64; 4], d: [f64; 4], c: f64| std::array::from_fn(|i| z[i] + c * d[i]);
    let e0 = energy(z);
    let (mut t, mut err) = (Vec::with_capacity(steps as usize), Vec::new());
    for k in 1..=steps {
        let k1 = f(z);
        let k2 = f(add(z, k1, h / 2.0));
        let k3 = f(add(z, k2, h / 2.0));
        let k4 = f(add(z, k3, h));
        z = std::array::from_fn(|i| z[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
        let r = z[0].hypot(z[1]);
        z[0] /= r;
        z[1] /= r;
        let d = z[2] * z[0] + z[3] * z[1];
        z[2] -= d * z[0];
        z[3] -= d * z[1];
        t.push(k as f64 * h);
        err.push(energy(z) - e0);
    }
    (t, err)
}

/// Claim 2: geometric SHAKE/RATTLE over Störmer–Verlet and symplectic Euler
/// are the classical methods of Section 5.1.3.
fn classical(ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    let h = 0.05;
    let n = if ctx.quick { 200 } else { 1000 };
    /// One comparison: a system declared with the macro and the same system
    /// in the reference, from z0, n steps of size h.
    struct Case<'a, S, R> {
        what: &'a str,
        sys: S,
        refsys: R,
        z0: State,
        h: f64,
        n: usize,
    }
    fn compare<B: BaseMap, S: ConstrainedSystem + Clone, R: r::System>(
        base: B,
        cb: r::ClassicalBase,
        case: &Case<S, R>,
        claims: &mut Claims,
    ) -> PlotResult<()> {
        let Case {
            what,
            ref sys,
            ref refsys,
            ref z0,
            h,
            n,
        } = *case;
        let sys = sys.clone();
        let mut shake = Integrator::new(sys.clone(), base, h).shake();
        let mut rattle = Integrator::new(sys, base, h).rattle();
        // One step from each state of a trajectory: the maps themselves.
        let (mut d_shake, mut d_rattle) = (0.0f64, 0.0f64);
        let mut z = z0.clone();
        for _ in 0..n {
            let a = shake.step(&z)?;
            let b = r::classical_shake_z(refsys, cb, &z_of(&z), h);
            d_shake = d_shake.max((z_of(&a) - b).amax());
            let a = rattle.step(&z)?;
            let b = r::classical_rattle_z(refsys, cb, &z_of(&z), h);
            d_rattle = d_rattle.max((z_of(&a) - b).amax());
            z = a;
        }
        for (m, dist) in [("SHAKE", d_shake), ("RATTLE", d_rattle)] {
            claims.check(
                "2",
                &format!(
                    "{what}: geometric {m} over {} = classical {m} (5.1.3), one step",
                    B::NAME
                ),
                &format!("max over {n} states of |step difference|"),
                dist,
                Bound::AtMost(50.0 * EPS),
                "round-off: the same equations solved to stagnation (50 ε)",
            );
        }
        // Whole trajectories: round-off may accumulate, nothing else.
        let mut zr = z_of(z0);
        let mut zg = z0.clone();
        for _ in 0..n {
            zr = r::classical_rattle_z(refsys, cb, &zr, h);
            zg = rattle.step(&zg)?;
        }
        claims.check(
            "2",
            &format!(
                "{what}: RATTLE over {} = classical RATTLE over {n} steps",
                B::NAME
            ),
            "|z_n − z_n,classical|",
            (z_of(&zg) - zr).amax(),
            Bound::AtMost(n as f64 * 10.0 * EPS),
            "round-off accumulated over n steps (n · 10 ε)",
        );
        Ok(())
    }
    let dbl = r::DoublePendulum::default();
    let single = Case {
        what: "pendulum",
        sys: pendulum(),
        refsys: r::PlanarPendulum::default(),
        z0: start(),
        h,
        n,
    };
    let double = Case {
        what: "double pendulum",
        sys: DoublePendulum::new(1.0, 1.0, 1.0),
        refsys: dbl,
        z0: state_of(&dbl.state(1.0, -0.5, 0.3, 0.8)),
        h,
        n: n / 4,
    };
    use r::ClassicalBase::{StormerVerlet as CSV, SymplecticEuler as CSE};
    compare(StormerVerlet, CSV, &single, claims)?;
    compare(SymplecticEuler, CSE, &single, claims)?;
    compare(StormerVerlet, CSV, &double, claims)?;
    compare(SymplecticEuler, CSE, &double, claims)?;
    Ok(())
}

/// Claim 3: R_{−h} ∘ R_h = id when φ_h is symmetric (Section 4.5), and not
/// for symplectic Euler.
fn symmetry(claims: &mut Claims) -> PlotResult<()> {
    let h = 0.1;
    fn back_and_forth<B: BaseMap>(base: B, h: f64) -> PlotResult<f64> {
        let mut integ = Integrator::new(pendulum(), base, h).rattle();
        let mut worst = 0.0f64;
        let mut z = integ.project_to_hidden(&start())?;
        for _ in 0..50 {
            let z1 = integ.with_step_size(h).step(&z)?;
            let back = integ.with_step_size(-h).step(&z1)?;
            worst = worst.max(back.distance(&z));
            z = z1;
        }
        Ok(worst)
    }
    for (name, dist) in [
        (ImplicitMidpoint::NAME, back_and_forth(ImplicitMidpoint, h)?),
        (StormerVerlet::NAME, back_and_forth(StormerVerlet, h)?),
    ] {
        claims.check(
            "3",
            &format!("pendulum: RATTLE over {name} is symmetric, R_(−h)∘R_h = id"),
            "max |R_(−h)(R_h z) − z| over 50 states",
            dist,
            Bound::AtMost(50.0 * EPS),
            "exact symmetry: round-off only (50 ε)",
        );
    }
    claims.check(
        "3",
        "pendulum: RATTLE over symplectic Euler is not symmetric (control)",
        "max |R_(−h)(R_h z) − z|, h = 0.1",
        back_and_forth(SymplecticEuler, h)?,
        Bound::AtLeast(1e-4),
        "φ_h not symmetric: an O(h²) defect",
    );
    Ok(())
}

/// Claim 3: ω(DS u, DS v) = ω(u, v) for u, v ∈ T_z M (SHAKE, presymplectic)
/// and for u, v ∈ T_z M^H (RATTLE, symplectic), with D computed by
/// fourth-order central differences along curves in M (radial projection)
/// and in M^H (the runtime's projection Π after the radial one).
fn symplecticity(claims: &mut Claims) -> PlotResult<()> {
    let h = 0.1;
    let pend = r::PlanarPendulum::default();
    let delta = 1e-3;
    // Truncation O(δ⁴) ≈ 1e-12 times the fourth derivative, round-off ε/δ ≈
    // 2e-13 per entry: the defect is measured to about 1e-11.
    let tol = 1e-10;
    fn check<B: BaseMap>(
        base: B,
        h: f64,
        pend: &r::PlanarPendulum,
        delta: f64,
        claims: &mut Claims,
        tol: f64,
    ) -> PlotResult<()> {
        let z = start();
        let zv = z_of(&z);
        let gg = r::gradient(pend, r::Fun::G(0), zv.as_slice());
        let w1 = DVector::from_vec(vec![0.3, -0.2, 0.7, 0.1]);
        let w2 = DVector::from_vec(vec![-0.5, 0.4, 0.2, 0.9]);
        // A curve in M through z with velocity u: scale q back onto |q| = 1.
        let on_m = |v: DVector<f64>| {
            let s = 1.0 / (v[0] * v[0] + v[1] * v[1]).sqrt();
            DVector::from_vec(vec![v[0] * s, v[1] * s, v[2], v[3]])
        };
        // SHAKE on M.
        let (u, v) = (tangent(std::slice::from_ref(&gg), &w1), tangent(&[gg], &w2));
        let mut shake = Integrator::new(pendulum(), base, h).shake();
        let mut d_of = |u: &DVector<f64>| {
            derivative_along(
                |s| {
                    let p = state_of(&on_m(&zv + u * s));
                    shake.step(&p).map(|x| z_of(&x)).map_err(|e| e.to_string())
                },
                delta,
            )
        };
        let (du, dv) = (d_of(&u)?, d_of(&v)?);
        let defect = (omega(&du, &dv) - omega(&u, &v)).abs();
        claims.check(
            "3",
            &format!("pendulum: SHAKE over {} is presymplectic on M", B::NAME),
            "|ω(DS u, DS v) − ω(u, v)|, u, v ∈ TM",
            defect,
            Bound::AtMost(tol),
            "exact in theory; 4th-order differences, δ = 1e-3, resolve ~1e-11",
        );
        // RATTLE on M^H.
        let mut rattle = Integrator::new(pendulum(), base, h).rattle();
        let z_h = rattle.project(&z)?;
        let zhv = z_of(&z_h);
        let gg = r::gradient(pend, r::Fun::G(0), zhv.as_slice());
        // ∇{g,H} with {g,H} = g_q·H_p − g_p·H_q = 2 q·p, by num-dual.
        let gh = r::gradient_with(zhv.as_slice(), |x| (x[0] * x[2] + x[1] * x[3]) * 2.0);
        let (u, v) = (
            tangent(&[gg.clone(), gh.clone()], &w1),
            tangent(&[gg, gh], &w2),
        );
        let mut d_of = |u: &DVector<f64>| {
            derivative_along(
                |s| {
                    let p = rattle
                        .project(&state_of(&on_m(&zhv + u * s)))
                        .map_err(|e| e.to_string())?;
                    rattle.step(&p).map(|x| z_of(&x)).map_err(|e| e.to_string())
                },
                delta,
            )
        };
        let (du, dv) = (d_of(&u)?, d_of(&v)?);
        let w = omega(&u, &v);
        claims.check(
            "3",
            &format!("pendulum: RATTLE over {} is symplectic on Mᴴ", B::NAME),
            "|ω(DR u, DR v) − ω(u, v)| / |ω(u, v)|, u, v ∈ TMᴴ",
            (omega(&du, &dv) - w).abs() / w.abs(),
            Bound::AtMost(tol),
            "exact in theory; 4th-order differences, δ = 1e-3, resolve ~1e-11",
        );
        Ok(())
    }
    check(ImplicitMidpoint, h, &pend, delta, claims, tol)?;
    check(StormerVerlet, h, &pend, delta, claims, tol)?;
    check(SymplecticEuler, h, &pend, delta, claims, tol)?;
    Ok(())
}

/// Claim 4: S_h maps the whole fibre of z0 to one point (Section 4: "it is
/// not important where on the initial fibre one starts").
fn fibre_independence(claims: &mut Claims) -> PlotResult<()> {
    let h = 0.1;
    fn spread<B: BaseMap>(base: B, h: f64) -> PlotResult<f64> {
        let sys = pendulum();
        let mut integ = Integrator::new(sys, base, h).shake();
        let z0 = start();
        let s0 = integ.step(&z0)?;
        let mut worst = 0.0f64;
        for lambda in [-0.3, -0.1, 0.05, 0.2, 0.4] {
            let (mut q, mut p) = (z0.q.clone(), z0.p.clone());
            // Move along the fibre: the closed-form flow exp(λ X_g).
            assert!(sys
                .fibre_flow(&[lambda], q.as_mut_slice(), p.as_mut_slice())
                .applied());
            let s = integ.step(&State::new(q, p))?;
            worst = worst.max(s.distance(&s0));
        }
        Ok(worst)
    }
    for (name, dist) in [
        (ImplicitMidpoint::NAME, spread(ImplicitMidpoint, h)?),
        (StormerVerlet::NAME, spread(StormerVerlet, h)?),
        (SymplecticEuler::NAME, spread(SymplecticEuler, h)?),
    ] {
        claims.check(
            "4",
            &format!("pendulum: SHAKE over {name} gives one z1⁻ from anywhere on the fibre of z0"),
            "max |S_h(exp(λX_g)z0) − S_h(z0)|, λ ∈ [−0.3, 0.4]",
            dist,
            Bound::AtMost(50.0 * EPS),
            "exact (the sliding map is a projection): round-off (50 ε)",
        );
    }
    Ok(())
}

/// The paper's fig_pendulum: one SHAKE step and RATTLE's correction, drawn
/// in the plane of the mass. The base map is Störmer–Verlet, which for this
/// H (quadratic kinetic, linear potential) is the exact unconstrained flow:
/// the flight is the parabola of the caption.
fn one_step_figure(ctx: &Ctx) -> PlotResult<()> {
    let h = 0.6;
    let sys = pendulum();
    let th: f64 = 0.7;
    let q0 = [th.sin(), -th.cos()];
    // On M (|q| = 1) but not on M^H: the velocity points out of the circle.
    let p0 = [1.1, 0.35];
    let z0 = State::from_slices(&q0, &p0);
    let mut shake = Integrator::new(sys, StormerVerlet, h).shake();
    let z1m = shake.step(&z0)?;
    let lambda = shake.last_multipliers()[0];
    let (mut qp, mut pp) = (z0.q.clone(), z0.p.clone());
    let closed = sys.fibre_flow(&[lambda], qp.as_mut_slice(), pp.as_mut_slice());
    assert!(
        closed.applied(),
        "the pendulum's fibre flow has a closed form"
    );
    let mut rattle = Integrator::new(sys, StormerVerlet, h).rattle();
    let z1 = rattle.project(&z1m)?;
    // Velocity arrows drawn at this scale (position units per momentum unit).
    let s = 0.3;
    let head = 0.035;
    let tip = |q: &DVector<f64>, p: &DVector<f64>| (q[0] + s * p[0], q[1] + s * p[1]);
    let pt = |q: &DVector<f64>| (q[0], q[1]);
    // The arc of M around the step (angles measured from the downward vertical).
    let th1 = z1.q[0].atan2(-z1.q[1]);
    let arc: Vec<(f64, f64)> = (0..=100)
        .map(|k| {
            let a = th - 0.25 + (th1 - th + 0.5) * k as f64 / 100.0;
            (a.sin(), -a.cos())
        })
        .collect();
    // The exact unconstrained flight from (q0, p0⁺): q(t) = q0 + t p0⁺ − t²/2 (0, G).
    let flight: Vec<(f64, f64)> = (0..=60)
        .map(|k| {
            let t = h * k as f64 / 60.0;
            (qp[0] + t * pp[0], qp[1] + t * pp[1] - 0.5 * t * t)
        })
        .collect();
    let fig = Figure::new(
        "Pendulum: one SHAKE step and RATTLE's correction (h = 0.6)",
        "q₁",
        "q₂",
    )
    .equal_aspect()
    .legend_at(SeriesLabelPosition::UpperLeft)
    .series_colored("M: the circle |q| = 1", arc, Mark::Dashed, PALETTE[6])
    .series_colored(
        "z0 ∈ M, not on Mᴴ: velocity p0",
        arrow(pt(&z0.q), tip(&z0.q, &z0.p), head),
        Mark::Line,
        PALETTE[7],
    )
    .series_colored(
        "kick along the rod, z0⁺ = exp(λX_g) z0",
        arrow(tip(&z0.q, &z0.p), tip(&qp, &pp), head),
        Mark::Line,
        PALETTE[3],
    )
    .series_colored(
        "velocity p0⁺ after the kick",
        arrow(pt(&qp), tip(&qp, &pp), head),
        Mark::Line,
        PALETTE[4],
    )
    .series_colored(
        "φ_h: the unconstrained flight (a parabola)",
        flight,
        Mark::Dashed,
        PALETTE[0],
    )
    .series_colored(
        "z1⁻ = S_h(z0) ∈ M: velocity p1⁻",
        arrow(pt(&z1m.q), tip(&z1m.q, &z1m.p), head),
        Mark::Line,
        PALETTE[1],
    )
    .series_colored(
        "z1 = Π(z1⁻) ∈ Mᴴ (RATTLE): tangent velocity",
        arrow(pt(&z1.q), tip(&z1.q, &z1.p), head),
        Mark::Line,
        PALETTE[2],
    )
    .series_colored("", vec![pt(&z0.q), pt(&z1.q)], Mark::Points, PALETTE[7]);
    fig.save(&ctx.out, "pendulum_step")?;
    Ok(())
}
