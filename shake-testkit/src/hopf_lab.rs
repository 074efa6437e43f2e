//! The computations behind the two Hopf scenes (the paper's Section 5.4) and
//! their tests: runs of shake's SHAKE and RATTLE on
//! `geoshake::models::{HopfFree, HopfGravity}`, measured against the independent
//! reference of [`crate::reference`].
//!
//! Nothing here draws or keeps the claims table: the `paper` scenes
//! (`hopf_free.rs`, `hopf_gravity.rs`) and `tests/suite/paper_hopf.rs` both use
//! this module, so the figure, the claims table and the tests measure the same
//! quantities against the same bounds.
//!
//! Conventions (those of geoshake_runtime::system): z = (q₀, q₁, p₀, p₁), X_F = (F_p, −F_q),
//! {F,G} = F_q·G_p − F_p·G_q, q' = H_p + g_pᵀλ, p' = −H_q − g_qᵀλ. With
//! g = |q|² + |p|² − r², X_g = (2p, −2q), so the fibre flow exp(σX_g) is the
//! rotation z_k ↦ e^{−2iσ} z_k of z_k = q_k + i p_k, and the paper's multiplier
//! is twice ours (λ_paper = 2λ).
#![allow(dead_code)]

use std::f64::consts::PI;

use geoshake::models::{HopfFree, HopfGravity};
use geoshake::{
    ImplicitMidpoint, Integrator, Method, Options, State, StepError, Stop, Unconstrained,
};
use nalgebra::DVector;

use crate::reference as r;

/// A point z = (q₀, q₁, p₀, p₁) of R⁴.
pub type Z = [f64; 4];

pub fn state(z: &Z) -> State {
    State::from_slices(&z[..2], &z[2..])
}

pub fn arr(s: &State) -> Z {
    [s.q[0], s.q[1], s.p[0], s.p[1]]
}

fn dist(a: &Z, b: &Z) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

fn dvec(z: &Z) -> DVector<f64> {
    DVector::from_row_slice(z)
}

fn of_dvec(v: &DVector<f64>) -> Z {
    [v[0], v[1], v[2], v[3]]
}

/// Σ_k a_k conj(b_k) with a_k = q_k + i p_k, as (re, im).
fn hermitian(a: &Z, b: &Z) -> (f64, f64) {
    (
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3],
        a[2] * b[0] + a[3] * b[1] - a[0] * b[2] - a[1] * b[3],
    )
}

/// The fibre parameter σ with a = exp(σ X_g)(b) = e^{−2iσ} b, for two points
/// of one fibre of g = |z|² − r² (|σ| ≤ π/2).
pub fn fibre_parameter(a: &Z, b: &Z) -> f64 {
    let (re, im) = hermitian(a, b);
    -0.5 * im.atan2(re)
}

// ===========================================================================
// 5.4.1: H = |p|²/2 on the unit sphere
// ===========================================================================

/// A point of M^H of H = |p|²/2 on |q|² + |p|² = 1: q = a(cos φ, sin φ),
/// p = s·b(−sin φ, cos φ) with b = √(1 − a²), so q·p = 0 and q∧p = s·a·b.
/// |q| = a > 1/√2 is the component {|q| > |p|} of M^H, a < 1/√2 the other.
pub fn free_start(a: f64, phi: f64, s: f64) -> Z {
    let b = (1.0 - a * a).sqrt();
    let (sn, cs) = phi.sin_cos();
    [a * cs, a * sn, -s * b * sn, s * b * cs]
}

/// Initial data on both components of M^H, with both orientations of q∧p.
pub fn free_starts() -> [(&'static str, Z); 4] {
    [
        ("|q| > |p|, q∧p > 0", free_start(0.8, 0.3, 1.0)),
        ("|q| > |p|, q∧p < 0", free_start(0.8, 0.3, -1.0)),
        ("|q| < |p|, q∧p > 0", free_start(0.6, 1.1, 1.0)),
        ("|q| < |p|, q∧p < 0", free_start(0.6, 1.1, -1.0)),
    ]
}

/// The unit-sphere system of Section 5.4.1.
pub fn free_system() -> HopfFree {
    HopfFree::new(1.0)
}

/// The exact trajectory through z0 ∈ M^H is the circle θ ↦ (R(θ)q0, R(θ)p0)
/// (eq hopf_dea_exact_solution). Returns the angle θ of its point nearest to
/// z and the distance from z to it.
///
/// In closed form: |z − c(θ)|² = |z|² + |z0|² − 2(a cos θ + b sin θ) with
/// a = q·q0 + p·p0 and b = q·Jq0 + p·Jp0 (J the rotation by π/2, R(θ)v =
/// cos θ v + sin θ Jv), smallest at θ = atan2(b, a). The distance is formed
/// from the difference vector, not from the expanded square, so it is exact
/// to round-off.
pub fn exact_curve_nearest(z0: &Z, z: &Z) -> (f64, f64) {
    let j = |x: f64, y: f64| (-y, x);
    let (jq0, jp0) = (j(z0[0], z0[1]), j(z0[2], z0[3]));
    let a = z[0] * z0[0] + z[1] * z0[1] + z[2] * z0[2] + z[3] * z0[3];
    let b = z[0] * jq0.0 + z[1] * jq0.1 + z[2] * jp0.0 + z[3] * jp0.1;
    let theta = b.atan2(a);
    let q = r::rot(theta, [z0[0], z0[1]]);
    let p = r::rot(theta, [z0[2], z0[3]]);
    (theta, dist(z, &[q[0], q[1], p[0], p[1]]))
}

/// The exact angular speed ω = (q0∧p0)/(|q0|² − |p0|²) of the trajectory.
pub fn free_omega(z0: &Z) -> f64 {
    let (qq, pp) = (z0[0] * z0[0] + z0[1] * z0[1], z0[2] * z0[2] + z0[3] * z0[3]);
    r::wedge([z0[0], z0[1]], [z0[2], z0[3]]) / (qq - pp)
}

/// A RATTLE run of the free system measured against the exact solution.
pub struct FreeRun {
    pub h: f64,
    pub t: Vec<f64>,
    /// Distance of each RATTLE point to the exact trajectory through z0 (the
    /// circle as a set).
    pub curve_distance: Vec<f64>,
    /// |z_k − z(t_k)|: the same points against the exact solution at their
    /// own time.
    pub time_error: Vec<f64>,
    /// The angle θ_k of the nearest point of the circle, unwrapped: z_k =
    /// (R(θ_k)q0, R(θ_k)p0) up to `curve_distance`.
    pub angle: Vec<f64>,
    /// For the SHAKE run from the same z0: |Im ζ(z_k⁻) − Im ζ(z0)|, ζ the
    /// first component of the Hopf map. Im ζ = −2 q∧p is constant on fibres
    /// and along the exact trajectory, and the torus Im ζ = const is the union
    /// of the fibres through the trajectory: zero exactly when the fibre of
    /// the SHAKE point meets the exact trajectory of z0.
    pub shake_offset: Vec<f64>,
}

impl FreeRun {
    /// The numerical angular speed θ_N / t_N (RATTLE turns by the same angle
    /// each step: the method commutes with the rotations (q, p) ↦ (Rq, Rp),
    /// a linear symplectic symmetry of H and g).
    pub fn omega(&self) -> f64 {
        self.angle.last().unwrap() / self.t.last().unwrap()
    }
}

/// RATTLE (and SHAKE) with the midpoint rule from z0 ∈ M^H for `steps`
/// steps of size h, measured against the exact trajectory.
pub fn free_run(z0: &Z, h: f64, steps: u64) -> Result<FreeRun, StepError> {
    let mut rattle = Integrator::new(free_system(), ImplicitMidpoint, h).rattle();
    let traj = rattle
        .run(state(z0), Stop::Steps(steps))
        .execute()
        .into_result()
        .map_err(|(_, e)| e)?;
    let mut shake = Integrator::new(free_system(), ImplicitMidpoint, h).shake();
    let straj = shake
        .run(state(z0), Stop::Steps(steps))
        .execute()
        .into_result()
        .map_err(|(_, e)| e)?;
    let im_zeta = |z: &Z| r::hopf_map(z).0[1];
    let im0 = im_zeta(z0);
    let mut run = FreeRun {
        h,
        t: traj.times(),
        curve_distance: Vec::new(),
        time_error: Vec::new(),
        angle: Vec::new(),
        shake_offset: straj
            .states()
            .map(|s| (im_zeta(&arr(&s)) - im0).abs())
            .collect(),
    };
    let mut prev = 0.0;
    for (s, t) in traj.states().zip(traj.times()) {
        let z = arr(&s);
        let (theta, d) = exact_curve_nearest(z0, &z);
        // Unwrap: one step turns by |ω h| < π.
        let turns = ((prev - theta) / (2.0 * PI)).round();
        let theta = theta + 2.0 * PI * turns;
        prev = theta;
        run.curve_distance.push(d);
        run.angle.push(theta);
        run.time_error.push(dist(&z, &r::hopf_exact_z(z0, t)));
    }
    Ok(run)
}

/// The fibre displacements of one RATTLE step from z0 ∈ M^H: SHAKE's μ
/// (y = exp(μ X_g) z0 before the base map, the runtime's `last_multipliers`)
/// and the projection's σ (z1 = exp(σ X_g) z1⁻, measured from z1⁻ and z1).
/// μ + σ is the step's whole displacement along the fibres, h·λ + O(h³) for
/// the symmetric midpoint rule; SHAKE alone supplies only about half of it.
pub fn free_step_multipliers(z0: &Z, h: f64) -> Result<(f64, f64), StepError> {
    let mut shake = Integrator::new(free_system(), ImplicitMidpoint, h).shake();
    let z1m = shake.step(&state(z0))?;
    let mu = shake.last_multipliers()[0];
    let z1 = shake.project(&z1m)?;
    Ok((mu, fibre_parameter(&arr(&z1), &arr(&z1m))))
}

/// The paper's exact solution (eq hopf_dea_exact_solution) with a chosen α:
/// q(t) = R(t/(α − 1/α)) q0, p(t) = R(t/(α − 1/α)) p0.
pub fn paper_exact(z0: &Z, alpha: f64, t: f64) -> Z {
    let theta = t / (alpha - 1.0 / alpha);
    let q = r::rot(theta, [z0[0], z0[1]]);
    let p = r::rot(theta, [z0[2], z0[3]]);
    [q[0], q[1], p[0], p[1]]
}

/// The paper's formula with α = −sign(q0∧p0)|p0|/|q0| and with the opposite
/// sign, each against the reference DAE integrator (order 12, independent of
/// shake) at t = 0.5, 1, …, 3: (largest error of the first, smallest error
/// of the second over those times).
pub fn alpha_sign_errors(z0: &Z) -> (f64, f64) {
    let times: Vec<f64> = (1..=6).map(|k| 0.5 * k as f64).collect();
    let sys = r::HopfFree { radius2: 1.0 };
    let refs = r::reference_trajectory(&sys, &dvec(z0), &times);
    let ratio = (z0[2].hypot(z0[3])) / (z0[0].hypot(z0[1]));
    let sign = -r::wedge([z0[0], z0[1]], [z0[2], z0[3]]).signum();
    let (mut right, mut wrong) = (0.0f64, f64::INFINITY);
    for (t, zr) in times.iter().zip(&refs) {
        let zr = of_dvec(zr);
        right = right.max(dist(&paper_exact(z0, sign * ratio, *t), &zr));
        wrong = wrong.min(dist(&paper_exact(z0, -sign * ratio, *t), &zr));
    }
    (right, wrong)
}

// ===========================================================================
// 5.4.2: H = |p|²/2 − g·q, g = (0, −1)
// ===========================================================================

/// The paper's gravity vector g = (0, −1).
pub const GRAVITY: [f64; 2] = [0.0, -1.0];

/// H = |p|²/2 − g·q on the sphere |q|² + |p|² = radius2.
pub fn gravity_system(radius2: f64) -> HopfGravity {
    HopfGravity::new(GRAVITY[0], GRAVITY[1], radius2)
}

/// Initial data of the gravity scene and the sphere it lies on.
#[derive(Clone, Debug)]
pub struct GravityStart {
    pub name: String,
    pub z: Z,
    pub radius2: f64,
}

impl GravityStart {
    pub fn system(&self) -> HopfGravity {
        gravity_system(self.radius2)
    }

    /// The reference (num-dual) system of the same sphere.
    pub fn reference(&self) -> r::HopfGravity {
        r::HopfGravity::with_radius2(self.radius2)
    }
}

/// |z|².
pub fn norm2(z: &Z) -> f64 {
    z.iter().map(|v| v * v).sum()
}

/// The table of the paper (z_a, z_b, z_c) on the sphere through the printed
/// points. The three satisfy {g,H} = 0 to 3e-16 and lie on one sphere to
/// 2e-16, of radius² |z|² = 0.98000000636 (0.98 to the printed digits, not
/// 1): each is run on the sphere through itself, where it lies on M^H
/// exactly.
pub fn paper_starts() -> Vec<GravityStart> {
    [
        ("z_a", r::PAPER_Z_A),
        ("z_b", r::PAPER_Z_B),
        ("z_c", r::PAPER_Z_C),
    ]
    .into_iter()
    .map(|(name, z)| GravityStart {
        name: format!("{name} (printed, radius² {:.10})", norm2(&z)),
        z,
        radius2: norm2(&z),
    })
    .collect()
}

/// The same points brought onto the unit M^H: scaled radially onto |z| = 1
/// (the same complex line, so the same point of the plotted sphere), then
/// moved along the fibre onto M^H by the runtime's `project_to_hidden` on
/// the radius² = 1 system.
pub fn unit_starts() -> Result<Vec<GravityStart>, StepError> {
    let mut integ = Integrator::new(gravity_system(1.0), ImplicitMidpoint, 0.1);
    [
        ("z_a", r::PAPER_Z_A),
        ("z_b", r::PAPER_Z_B),
        ("z_c", r::PAPER_Z_C),
    ]
    .into_iter()
    .map(|(name, z)| {
        let k = 1.0 / norm2(&z).sqrt();
        let scaled = [k * z[0], k * z[1], k * z[2], k * z[3]];
        let on = integ.project_to_hidden(&state(&scaled))?;
        Ok(GravityStart {
            name: format!("{name} (on the unit Mᴴ)"),
            z: arr(&on),
            radius2: 1.0,
        })
    })
    .collect()
}

/// The midpoint rule for H = |p|²/2 − g·q *without* the constraint against
/// its exact flow q0 + p0 t + g t²/2, p0 + g t: the largest deviation over
/// `steps` steps of size h from the start.
pub fn unconstrained_midpoint_error(start: &GravityStart, h: f64, steps: u64) -> f64 {
    let mut integ = Integrator::new(Unconstrained(start.system()), ImplicitMidpoint, h);
    let out = integ.run(state(&start.z), Stop::Steps(steps)).execute();
    let z0 = start.z;
    let mut worst = 0.0f64;
    for (s, t) in out.trajectory.states().zip(out.trajectory.times()) {
        let exact = [
            z0[0] + z0[2] * t + 0.5 * GRAVITY[0] * t * t,
            z0[1] + z0[3] * t + 0.5 * GRAVITY[1] * t * t,
            z0[2] + GRAVITY[0] * t,
            z0[3] + GRAVITY[1] * t,
        ];
        worst = worst.max(dist(&arr(&s), &exact));
    }
    if out.error.is_some() {
        return f64::NAN;
    }
    worst
}

/// Everything a run of the gravity system records, one entry per step.
pub struct GravityRun {
    pub t: Vec<f64>,
    pub z: Vec<Z>,
    pub energy: Vec<f64>,
    /// |g|.
    pub g: Vec<f64>,
    /// |{g,H}|.
    pub hidden: Vec<f64>,
}

/// SHAKE or RATTLE with the midpoint rule, every state kept.
pub fn gravity_run(
    start: &GravityStart,
    method: Method,
    h: f64,
    steps: u64,
) -> Result<GravityRun, StepError> {
    let mut integ = Integrator::new(start.system(), ImplicitMidpoint, h)
        .with_method(method)
        .with_diagnostics();
    let traj = integ
        .run(state(&start.z), Stop::Steps(steps))
        .execute()
        .into_result()
        .map_err(|(_, e)| e)?;
    let d = &traj.diagnostics;
    Ok(GravityRun {
        t: traj.times(),
        z: traj.states().map(|s| arr(&s)).collect(),
        energy: d.iter().map(|x| x.energy).collect(),
        g: d.iter().map(|x| x.constraint).collect(),
        hidden: d.iter().map(|x| x.hidden_constraint).collect(),
    })
}

/// max |E − E0| over the first and over the last tenth of a run.
pub fn energy_windows(energy: &[f64]) -> (f64, f64) {
    let e0 = energy[0];
    let w = (energy.len() / 10).max(1);
    let dev = |s: &[f64]| s.iter().map(|e| (e - e0).abs()).fold(0.0, f64::max);
    (dev(&energy[..w]), dev(&energy[energy.len() - w..]))
}

pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// {{g,H},H}(z) of the reference system, from num-dual derivatives only:
/// with k = {g,H} = ∇g·J∇H, ∇k = ∇²g J∇H − ∇²H J∇g and {k,H} = ∇k·J∇H.
pub fn double_bracket(sys: &r::HopfGravity, z: &Z) -> f64 {
    let (gh, hh) = r::hessian(sys, r::Fun::H, z);
    let (gg, hg) = r::hessian(sys, r::Fun::G(0), z);
    let grad_k = &hg * r::j_grad(&gh) - &hh * r::j_grad(&gg);
    r::bracket(&grad_k, &gh)
}

/// The leading term of SHAKE's hidden-constraint residual.
///
/// From z on M^H, SHAKE's λ only has to keep g = 0: g(φ_h(y)) =
/// h{g,H}(y) + (h²/2){{g,H},H} + O(h³) and {g,H}(exp(μX_g)z) = −Nμ + O(μ²)
/// (N = {{H,g},g}), so μ = (h/2){{g,H},H}/N + O(h²): half the displacement
/// h·λ = h{{g,H},H}/N of the exact flow. The state therefore lands O(h) off
/// M^H along its fibre, with {g,H}(z1⁻) = (h/2){{g,H},H} + O(h²) (RATTLE's
/// projection supplies the other half). Evaluated at the RATTLE point of the
/// same fibre.
pub fn predicted_shake_hidden(sys: &r::HopfGravity, z_rattle: &Z, h: f64) -> f64 {
    0.5 * h * double_bracket(sys, z_rattle).abs()
}

// ---------------------------------------------------------------------------
// Closed projected trajectories
// ---------------------------------------------------------------------------

/// How well a projected trajectory closes.
#[derive(Clone, Debug)]
pub struct Closure {
    /// The period of the projected motion, from the run (first return to
    /// the section through the start).
    pub period: f64,
    /// For each completed period k = 1, 2, …: the distance in the plane
    /// between the start and the return point after k periods.
    pub gaps: Vec<f64>,
    /// The diameter of the projected curve in the plane (for scale).
    pub size: f64,
}

/// Lagrange interpolation through (ts[i], ys[i]) at t.
fn lagrange(ts: &[f64], ys: &[[f64; 3]], t: f64) -> [f64; 3] {
    let mut out = [0.0; 3];
    for i in 0..ts.len() {
        let mut w = 1.0;
        for j in 0..ts.len() {
            if j != i {
                w *= (t - ts[j]) / (ts[i] - ts[j]);
            }
        }
        for c in 0..3 {
            out[c] += w * ys[i][c];
        }
    }
    out
}

/// The Hopf image of z scaled onto the unit 2-sphere.
fn sphere_point(z: &Z) -> [f64; 3] {
    let (zeta, rho) = r::hopf_map(z);
    let n = (zeta[0] * zeta[0] + zeta[1] * zeta[1] + rho * rho).sqrt();
    [zeta[0] / n, zeta[1] / n, rho / n]
}

fn plane_point(u: &[f64; 3]) -> [f64; 2] {
    r::stereographic([u[0], u[1]], u[2])
}

/// Measures how closely the projected trajectory (Hopf map, then the
/// stereographic projection of fig_numtests_grav) of a run closes.
///
/// The section is the plane through the start u0 of the curve on the unit
/// 2-sphere, normal to its first step. Each return through it (in the
/// direction of the start) is located on the degree-7 polynomial through
/// the 8 nearest steps (interpolation in time, in R³, then onto the plane).
///
/// Why this measures closure and not the interpolation: RATTLE is a
/// symplectic map of the 2-dimensional M^H (and SHAKE the same map on the
/// quotient by the fibres), so its points are samples at times kh of the
/// flow of a modified Hamiltonian up to an exponentially small error, and
/// that flow's orbits are closed curves of the 2-sphere. The interpolant
/// follows that flow to O(h⁸); a method without the structure leaves the
/// section at a distance growing with every period.
pub fn closure(t: &[f64], z: &[Z]) -> Closure {
    let u: Vec<[f64; 3]> = z.iter().map(sphere_point).collect();
    let w: Vec<[f64; 2]> = u.iter().map(plane_point).collect();
    let (u0, w0) = (u[0], w[0]);
    // Normal: the first step, made tangent to the sphere at u0.
    let mut n = [u[1][0] - u0[0], u[1][1] - u0[1], u[1][2] - u0[2]];
    let d: f64 = (0..3).map(|c| n[c] * u0[c]).sum();
    for c in 0..3 {
        n[c] -= d * u0[c];
    }
    let f = |v: &[f64; 3]| (0..3).map(|c| (v[c] - u0[c]) * n[c]).sum::<f64>();
    let mut size = 0.0f64;
    for a in &w {
        size = size.max(((a[0] - w0[0]).powi(2) + (a[1] - w0[1]).powi(2)).sqrt());
    }
    let mut crossings = Vec::new();
    for k in 1..u.len().saturating_sub(5) {
        let (fa, fb) = (f(&u[k]), f(&u[k + 1]));
        if !(fa < 0.0 && fb >= 0.0) || k < 3 {
            continue;
        }
        let nodes: Vec<usize> = (k - 3..=k + 4).collect();
        let ts: Vec<f64> = nodes.iter().map(|&i| t[i]).collect();
        let ys: Vec<[f64; 3]> = nodes.iter().map(|&i| u[i]).collect();
        // Bisection on the interpolant between t_k and t_{k+1}.
        let (mut lo, mut hi) = (t[k], t[k + 1]);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if f(&lagrange(&ts, &ys, mid)) < 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let tc = 0.5 * (lo + hi);
        let wc = plane_point(&lagrange(&ts, &ys, tc));
        let gap = ((wc[0] - w0[0]).powi(2) + (wc[1] - w0[1]).powi(2)).sqrt();
        // A return near the start, not the far side of a curve that crosses
        // the section twice in the same direction.
        if gap < 0.25 * size {
            crossings.push((tc - t[0], gap));
        }
    }
    Closure {
        period: crossings.first().map_or(f64::NAN, |c| c.0),
        gaps: crossings.iter().map(|c| c.1).collect(),
        size,
    }
}

// ---------------------------------------------------------------------------
// The fibres above a trajectory (fig_fibres)
// ---------------------------------------------------------------------------

/// |Hr'(θ)| over the fibre of each state (columns, left to right), at
/// θ = 2π·y for `rows` values of y evenly filling [y0, y1) (bottom to top):
/// the `Heatmap` layout `values[row][column]`. Hr' is the derivative of H
/// along the fibre, θ ↦ (q cos θ + p sin θ, −q sin θ + p cos θ)
/// (`reference::hr_prime`: the paper's eq_Hprime2 with the sign of its
/// g·q sin θ term corrected); it vanishes exactly where the fibre meets M^H.
pub fn fibre_image(z: &[Z], rows: usize, y0: f64, y1: f64) -> Vec<Vec<f64>> {
    (0..rows)
        .map(|j| {
            let y = y0 + (j as f64 + 0.5) * (y1 - y0) / rows as f64;
            z.iter()
                .map(|zi| r::hr_prime(zi, GRAVITY, 2.0 * PI * y).abs())
                .collect()
        })
        .collect()
}

/// The number of points where the fibre through z meets M^H, as counted by
/// the reference (4 in case (i), 2 in case (ii), 3 in case (iii)).
pub fn crossings(z: &Z) -> usize {
    r::fibre_critical_points(z, GRAVITY).len()
}

/// The fibre angle θ ∈ (−π, π] of the point of M^H nearest to z on its
/// fibre (0 when z ∈ M^H): SHAKE's offset from M^H along the fibre.
pub fn fibre_offset(z: &Z) -> f64 {
    r::fibre_critical_points(z, GRAVITY)
        .iter()
        .map(|c| {
            if c.theta > PI {
                c.theta - 2.0 * PI
            } else {
                c.theta
            }
        })
        .min_by(|a, b| a.abs().partial_cmp(&b.abs()).unwrap())
        .unwrap_or(f64::NAN)
}

// ---------------------------------------------------------------------------
// Case (iii): a trajectory that runs into a fold of M^H
// ---------------------------------------------------------------------------

/// N = {{H,g},g} at z. Along the fibre, {H,g}(exp(σX_g)z) = d/dσ
/// H(exp(σX_g)z) and exp(σX_g) is the fibre point at θ = 2σ, so N = 4 Hr''(0)
/// (from the reference's closed form).
pub fn nondegeneracy(z: &Z) -> f64 {
    4.0 * r::hr_second(z, GRAVITY, 0.0)
}

/// Initial data on M^H whose trajectory reaches a point where the
/// nondegeneracy assumption fails (case (iii) of Section 5.4.2): the second
/// critical point of H on the fibre through z_a, on the sphere through z_a.
/// It is a maximum of H along its fibre (N < 0), on the branch of M^H drawn
/// in the lower part of the fibre figure; that branch ends in folds where it
/// meets a branch of minima (N > 0), and its trajectory runs into one in
/// either direction of time.
pub fn fold_start() -> GravityStart {
    let z = r::PAPER_Z_A;
    let crit = r::fibre_critical_points(&z, GRAVITY);
    let max = crit
        .iter()
        .find(|c| c.second < 0.0)
        .expect("the fibre through z_a has a maximum of H");
    GravityStart {
        name: "second critical point on the fibre of z_a".into(),
        z: r::fibre_point(&z, max.theta),
        radius2: norm2(&z),
    }
}

/// The exact solution from z (on M^H) over time `t` (either sign) by the
/// reference DAE integrator (order 12, fixed steps of at most 1e-2), or
/// `None` if it reaches the fold first: N changes sign or |N| drops below
/// |N(z)|/20 (approaching a fold N ∝ √(t* − t), while the multiplier
/// λ = {{g,H},H}/N blows up).
pub fn exact_flow(start: &GravityStart, z: &Z, t: f64) -> Option<Z> {
    let sys = start.reference();
    let n = ((t.abs() / 1e-2).ceil() as usize).max(1);
    let dt = t / n as f64;
    let n0 = nondegeneracy(z);
    let mut f = |v: &DVector<f64>| r::dae_vector_field(&sys, v);
    let mut v = dvec(z);
    for _ in 0..n {
        v = r::gbs_step(&mut f, &v, dt, 6);
        let nk = nondegeneracy(&of_dvec(&v));
        if nk * n0 <= 0.0 || nk.abs() < n0.abs() / 20.0 {
            return None;
        }
    }
    Some(of_dvec(&v))
}

/// The exact solution from the start towards the fold, in the direction of
/// time `direction`: the reference integrator (order 12, step 1e-2) until
/// |N| < |N0|/8, then N² extrapolated linearly to 0, since N ∝ √(t* − t) at
/// a fold. Returns t* and the samples (t, N) on the way.
pub fn fold_approach(start: &GravityStart, direction: f64) -> (f64, Vec<(f64, f64)>) {
    let sys = start.reference();
    let dt = 1e-2 * direction.signum();
    let mut f = |v: &DVector<f64>| r::dae_vector_field(&sys, v);
    let mut v = dvec(&start.z);
    let n0 = nondegeneracy(&start.z);
    let (mut t, mut prev) = (0.0, n0 * n0);
    let mut samples = Vec::new();
    loop {
        let nk = nondegeneracy(&of_dvec(&v));
        samples.push((t, nk));
        if nk.abs() < n0.abs() / 8.0 {
            let slope = (nk * nk - prev) / dt;
            return (t - nk * nk / slope, samples);
        }
        prev = nk * nk;
        v = r::gbs_step(&mut f, &v, dt, 6);
        t += dt;
        assert!(t.abs() < 100.0, "fold_approach: no fold within |t| < 100");
    }
}

/// The time t* at which the exact solution from the start reaches the fold
/// (see [`fold_approach`]).
pub fn fold_time(start: &GravityStart, direction: f64) -> f64 {
    fold_approach(start, direction).0
}

/// A RATTLE run from [`fold_start`] towards the fold, checked step by step
/// against the exact solution.
#[derive(Clone, Debug)]
pub struct FoldRun {
    pub h: f64,
    pub options: Options,
    /// Why the run stopped (None: it did not).
    pub error: Option<StepError>,
    pub t: Vec<f64>,
    /// N at each stored state.
    pub n: Vec<f64>,
    /// Stored states that are not the continuation of the previous one (see
    /// [`fold_run`]), with their index.
    pub off_branch: Vec<usize>,
    /// The largest distance of a stored state from the exact solution from
    /// the previous state, over the steps where that exists.
    pub max_step_error: f64,
}

impl FoldRun {
    /// A typed error of the kinds that mean "nondegeneracy fails here".
    pub fn typed_error(&self) -> bool {
        matches!(
            self.error,
            Some(
                StepError::NondegeneracyLost { .. }
                    | StepError::SingularNondegeneracyMatrix { .. }
                    | StepError::SingularShakeJacobian { .. }
                    | StepError::ComponentJump { .. }
                    | StepError::FibreJump { .. }
                    | StepError::BranchJump { .. }
                    | StepError::NewtonNotConverged { .. }
            )
        )
    }

    pub fn t_last(&self) -> f64 {
        *self.t.last().unwrap()
    }
}

/// The distance beyond which a step is not the exact step's approximation
/// but another root of Hr' on the fibre: the local error of a regular step
/// is O(h³) ≈ 1e-3 at h = 0.1, while two critical points on one fibre, away
/// from a fold, are O(1) apart.
pub const JUMP_DISTANCE: f64 = 0.05;

/// RATTLE (midpoint, step h of either sign) from the start for at most
/// `steps` steps with the given options, every state stored.
///
/// Each stored state z_k is checked against the exact solution from the
/// previous stored state z_{k−1} over one step:
/// 1. N(z_k) must keep the sign of N at the start (the branch of maxima);
/// 2. if the exact step exists, z_k must be within [`JUMP_DISTANCE`] of it;
/// 3. if it does not (the fold lies within the step), z_k may only be closer
///    to the fold: |N(z_k)| ≤ |N(z_{k−1})|.
///
/// A state failing one of them is a silent jump to another branch of M^H.
pub fn fold_run(start: &GravityStart, h: f64, options: Options, steps: u64) -> FoldRun {
    let mut integ = Integrator::new(start.system(), ImplicitMidpoint, h)
        .rattle()
        .with_options(options);
    let out = integ.run(state(&start.z), Stop::Steps(steps)).execute();
    let z: Vec<Z> = out.trajectory.states().map(|s| arr(&s)).collect();
    let n: Vec<f64> = z.iter().map(nondegeneracy).collect();
    let mut run = FoldRun {
        h,
        options,
        error: out.error,
        t: out.trajectory.times(),
        n: n.clone(),
        off_branch: Vec::new(),
        max_step_error: 0.0,
    };
    for k in 1..z.len() {
        let ok = n[k] * n[0] > 0.0
            && match exact_flow(start, &z[k - 1], h) {
                Some(ze) => {
                    let e = dist(&ze, &z[k]);
                    run.max_step_error = run.max_step_error.max(e);
                    e <= JUMP_DISTANCE
                }
                None => n[k].abs() <= n[k - 1].abs(),
            };
        if !ok {
            run.off_branch.push(k);
        }
    }
    run
}

/// The runtime's checks switched off: no fibre-jump test, no component test,
/// no condition limit. What a plain Newton iteration does at a fold.
pub fn unchecked_options() -> Options {
    Options {
        jump_ratio: f64::INFINITY,
        check_component: false,
        max_condition: f64::INFINITY,
        ..Options::default()
    }
}
