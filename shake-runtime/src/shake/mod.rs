//! Geometric SHAKE (the paper's Definition 1.1):
//! S_h: z0 ∈ M ↦ z1⁻ = φ_h(y), y = exp(Σ λ_i X_{g_i})(z0), with λ ∈ R^m
//! chosen so that g(z1⁻) = 0.
//!
//! # The equation for λ
//!
//! r(λ) = g(φ_h(F_λ(z0))) with F_λ = exp(Σ λ_i X_{g_i}) is solved to
//! round-off (see [`newton`](crate::newton)), in one of two ways:
//!
//! - *Explicit base map* (Störmer–Verlet or symplectic Euler on a separable
//!   H, recognised by a first application that needed no stage
//!   iterations): r costs a fibre flow, a few gradients and g. The
//!   Jacobian ∂r/∂λ is formed by forward differences of r itself,
//!   (r(λ + ε s) − r(λ))/ε, ε ≈ √ε_mach times the scale of λ, once, at
//!   λ = 0, and kept for the whole step: a *simplified* Newton method,
//!   evaluated again at the current iterate only if the iteration stops
//!   contracting fast ([`Monitor::update_frozen`]). Because λ = O(h) the
//!   Jacobian changes by O(h) over the step, and the difference quotients
//!   are accurate to ~1e-8: the iteration contracts by O(h) per iteration,
//!   one or two more residual evaluations than Newton, and no Hessian, no
//!   g_z and no tangent map is evaluated. Difference quotients of the true
//!   F_λ are right for non-commuting X_{g_i} too. The converged λ solves
//!   r(λ) = 0 to round-off whatever Jacobian led there.
//! - *Implicit base map*: Newton's method with the Jacobian from the
//!   tangent map at every iterate (its iterates decide which solution is
//!   found far from M^H or for large h, and the runtime's checks of fibre
//!   and component jumps judge them), column j being
//!   g_z(z1⁻) · Dφ_h(y) · X_{g_j}(y) (Dφ_h from the base map's linearised
//!   stage equations; ∂F_λ/∂λ_j = X_{g_j}(F_λ(z0)) is exact when the X_{g_i}
//!   commute and an O(h) approximation otherwise). Note that Dφ_h ≈ I would
//!   give g_z X_{g_j} = {g_i, g_j} = 0 on M: the O(h) part of Dφ_h carries
//!   the whole Jacobian.
//!
//! # Structure: chains
//!
//! Column j of the Jacobian is nonzero only in the rows of the constraints
//! that share a variable with X_{g_j} or with its image under one
//! application of the Hessian of H (Dφ_h = I + h J H_zz + O(h²)). From the
//! macro's `JACOBIAN_PATTERN` and the entries that `hessian` writes, the
//! workspace predicts once a band |i − j| ≤ b of the Jacobian (b = 1 for a
//! chain). Columns j ≡ c (mod 2b+1) then have disjoint rows and are
//! obtained together, from one difference quotient or one tangent map along
//! Σ_j X_{g_j} (Curtis–Powell–Reid compression): 2b+1 evaluations instead
//! of m, and the banded LU of [`linalg`](crate::linalg) in O(m b²) instead
//! of O(m³). A chain of N links costs O(N) per step. Terms of order h² may
//! reach outside the predicted band (an implicit base map on a Hessian that
//! couples neighbours); the simplified iteration then contracts more
//! slowly, asks for a refresh, and the second refresh within a step is the
//! full, uncompressed tangent Jacobian.
//!
//! # The multiplier
//!
//! λ is the fibre parameter itself (y = exp(Σ λ_i X_{g_i})(z0)); it comes out
//! O(h). For holonomic g and Störmer–Verlet, y = (q0, p0 − g_q(q0)ᵀλ), so
//! λ = (h/2) λ_classical of the paper's Section 5.1.3 (h λ_classical for
//! symplectic Euler).

pub(crate) mod classical;
mod workspace;

pub(crate) use workspace::Workspace;

use crate::base_map::BaseMap;
use crate::compensated::kahan_add;
use crate::error::{Stage, StepError};
use crate::fibre::FibreFlow;
use crate::linalg::{band_lu_factor, band_lu_solve, norm_inf, Band};
use crate::newton::{Finish, Monitor, NewtonOptions, Polish, Verdict};
use crate::system::ConstrainedSystem;
use crate::SolveError;

/// What one SHAKE step did.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) struct ShakeReport {
    /// Newton iterations on λ.
    pub(crate) iterations: usize,
    /// Newton iterations of the base map's stage equations, summed.
    pub(crate) base_iterations: usize,
    /// ‖λ‖∞.
    pub(crate) lambda: f64,
    /// ‖λ₁‖∞ of the first Newton iterate (the linear prediction).
    pub(crate) lambda_predicted: f64,
    /// ‖λ − λ₁‖∞: how far Newton went beyond its linear prediction.
    pub(crate) lambda_correction: f64,
}

/// How SHAKE's Jacobian is evaluated (module docs).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
enum JacobianMode {
    /// Difference quotients of r, columns compressed by the band.
    Differences,
    /// Tangent maps, columns compressed by the band.
    Tangent,
    /// Tangent maps, one column at a time (the fallback).
    TangentDense,
}

/// One SHAKE step in place: (q, p) = z0 ∈ M becomes z1⁻ = S_h(z0).
/// The final λ is left in `ws.lambda`.
///
/// The step is computed in increment form, z1⁻ = z0 + Δ (see
/// [`increment`]), and with a `carry` the increment is added to the state
/// by Kahan's compensated summation (see [`compensated`](crate::compensated)).
#[allow(clippy::too_many_arguments)]
pub(crate) fn shake_step<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    base_ws: &mut B::Workspace,
    opts: &NewtonOptions,
    carry: Option<&mut [f64]>,
) -> Result<ShakeReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    let mut report = ShakeReport::default();
    base.reset_warm_start(base_ws);
    ws.z0[..d].copy_from_slice(q);
    ws.z0[d..].copy_from_slice(p);
    ws.lambda.fill(0.0);
    if m == 0 {
        report.base_iterations = residual(sys, base, h, ws, base_ws, opts, false)?;
        add_increment(q, p, &ws.dz, carry);
        return Ok(report);
    }
    let mut mon = Monitor::new(*opts);
    let mut converged = false;
    // r(0): y = z0 (the fibre flow at λ = 0 is the identity).
    report.base_iterations += residual(sys, base, h, ws, base_ws, opts, false)?;
    // An explicit base map makes the residual cheap: difference quotients
    // of it beat the tangent map.
    let explicit = base.explicit_for(sys);
    let mut need_jacobian = true;
    let mut refreshes = 0;
    let mut prev_step = f64::INFINITY;
    let mut polish = Polish::new(2);
    loop {
        let r = norm_inf(&ws.g);
        if !r.is_finite() || !ws.z1.iter().all(|x| x.is_finite()) {
            return Err(StepError::from_solve(
                Stage::Shake,
                SolveError::NonFinite {
                    iterations: mon.iterations,
                },
            ));
        }
        if r == 0.0 {
            break;
        }
        if converged {
            // Newton stopped on its update. Where g is not yet at its
            // round-off (an ill-conditioned λ, a stale or difference
            // Jacobian at the noise floor of λ) up to two more iterations
            // with a fresh Jacobian are spent; one that does not lower the
            // residual is undone. The guard refuses what is still above
            // the round-off bound.
            match polish.judge(r, || residual_at_roundoff(sys, ws)) {
                Finish::Done => break,
                Finish::Undo => {
                    keep_iterate(ws, false);
                    break;
                }
                Finish::Again => {
                    keep_iterate(ws, true);
                    converged = false;
                    need_jacobian = true;
                }
            }
        }
        if mon.exhausted() {
            return Err(StepError::from_solve(
                Stage::Shake,
                SolveError::NotConverged {
                    iterations: mon.iterations,
                    residual: r,
                },
            ));
        }
        let fresh = need_jacobian;
        if need_jacobian {
            let mode = if refreshes >= 2 {
                JacobianMode::TangentDense
            } else if explicit {
                JacobianMode::Differences
            } else {
                JacobianMode::Tangent
            };
            report.base_iterations += jacobian(sys, base, h, ws, base_ws, opts, mode)?;
            let band = if mode == JacobianMode::TangentDense {
                Band::full(m)
            } else {
                ws.jac_band
            };
            band_lu_factor(&mut ws.jac, m, band, &mut ws.piv_j).map_err(|_| {
                StepError::from_solve(
                    Stage::Shake,
                    SolveError::Singular {
                        iterations: mon.iterations,
                    },
                )
            })?;
            ws.jac_factored = band;
            need_jacobian = false;
        }
        ws.delta.copy_from_slice(&ws.g);
        band_lu_solve(&ws.jac, m, ws.jac_factored, &ws.piv_j, &mut ws.delta);
        for (l, dl) in ws.lambda.iter_mut().zip(&ws.delta) {
            *l -= dl;
        }
        if mon.iterations == 0 {
            ws.lambda_first.copy_from_slice(&ws.lambda);
        }
        let (step, size) = (norm_inf(&ws.delta), norm_inf(&ws.lambda));
        if explicit {
            match mon.update_frozen(step, size, fresh) {
                Verdict::Converged => converged = true,
                Verdict::Refresh => {
                    need_jacobian = true;
                    // Only slow contraction far from round-off says the
                    // band missed a coupling; a refresh at the noise floor
                    // just confirms convergence.
                    if step > opts.stagnation_threshold * size.max(1.0) {
                        refreshes += 1;
                    }
                }
                Verdict::Continue => {}
            }
        } else {
            // Newton proper: the far-from-M^H and large-h cases of implicit
            // base maps are told apart by where Newton's own iterates lead
            // (error tests: fibre and component jumps), so the iteration
            // keeps that path; the Jacobian stays compressed.
            converged = mon.update(step, size) == Verdict::Converged;
            need_jacobian = true;
            if step > 0.25 * prev_step && ws.groups < m && !polish.active() {
                // Slow for Newton: the band missed O(h²) couplings.
                refreshes = 2;
            }
        }
        prev_step = step;
        // y = F_λ(z0), z1⁻ = φ_h(y), r = g(z1⁻).
        report.base_iterations += residual(sys, base, h, ws, base_ws, opts, true)?;
    }
    add_increment(q, p, &ws.dz, carry);
    report.iterations = mon.iterations;
    report.lambda = norm_inf(&ws.lambda);
    if mon.iterations > 0 {
        report.lambda_predicted = norm_inf(&ws.lambda_first);
        report.lambda_correction = ws
            .lambda
            .iter()
            .zip(&ws.lambda_first)
            .fold(0.0f64, |e, (a, b)| e.max((a - b).abs()));
    }
    Ok(report)
}

/// Every |g_i(z1⁻)| (in `ws.g`) within 16ε Σ_k |∂g_i/∂z_k| |z_k| at z1⁻:
/// what rounding z1⁻ and g's terms leaves, below which no update can go.
/// (Evaluates g_z at z1⁻ into `ws.g_z_1`, sums over its pattern only into
/// `ws.g_size`, which the caller recomputes after the step.)
fn residual_at_roundoff<S: ConstrainedSystem>(sys: &S, ws: &mut Workspace) -> bool {
    let d = ws.d;
    let (q, p) = ws.z1.split_at(d);
    sys.constraint_jacobian(q, p, &mut ws.g_z_1);
    crate::tolerance::g_within_roundoff(&ws.g, &ws.pattern, &ws.g_z_1, (q, p), 16.0, &mut ws.g_size)
}

/// Keeps (`save`) or brings back SHAKE's iterate: λ, z1⁻, Δ and g.
fn keep_iterate(ws: &mut Workspace, save: bool) {
    let (m, n) = (ws.m, 2 * ws.d);
    let keep = &mut ws.polish_keep;
    let parts: [(&mut Vec<f64>, usize); 4] = [
        (&mut ws.lambda, 0),
        (&mut ws.z1, m),
        (&mut ws.dz, m + n),
        (&mut ws.g, m + 2 * n),
    ];
    for (v, at) in parts {
        let slot = &mut keep[at..at + v.len()];
        if save {
            slot.copy_from_slice(v);
        } else {
            v.copy_from_slice(slot);
        }
    }
}

/// z ← z + Δ: plainly, or with Kahan's compensation when a run keeps a carry.
fn add_increment(q: &mut [f64], p: &mut [f64], dz: &[f64], carry: Option<&mut [f64]>) {
    let d = q.len();
    match carry {
        Some(c) => {
            let (cq, cp) = c.split_at_mut(d);
            for k in 0..d {
                kahan_add(&mut q[k], &mut cq[k], dz[k]);
                kahan_add(&mut p[k], &mut cp[k], dz[d + k]);
            }
        }
        None => {
            for k in 0..d {
                q[k] += dz[k];
                p[k] += dz[d + k];
            }
        }
    }
}

/// The SHAKE map in increment form: z1 = z0 + Δ(λ) with
///
/// Δ(λ) = [exp(Σ λ_i X_{g_i})(z0) − z0] + [φ_h(y) − y],  y = z0 + first bracket,
///
/// each bracket computed as a small quantity in its own right
/// ([`FibreFlow::increment`], [`BaseMap::increment`]), so that Δ carries a
/// rounding error O(ε|Δ|) rather than O(ε|z|): what compensated summation
/// needs. Writes Δ into `dz` (using `db` as scratch), y and z1. Returns the
/// base map's stage iterations. At λ = 0 (`flow` false) the fibre bracket is
/// 0.
#[allow(clippy::too_many_arguments)]
fn increment<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    lambda: &[f64],
    flow: bool,
    z0: &[f64],
    fibre: &mut FibreFlow,
    base_ws: &mut B::Workspace,
    opts: &NewtonOptions,
    dz: &mut [f64],
    db: &mut [f64],
    y: &mut [f64],
    z1: &mut [f64],
) -> Result<usize, StepError> {
    let d = z0.len() / 2;
    if flow {
        let (fq, fp) = dz.split_at_mut(d);
        fibre
            .increment(sys, lambda, &z0[..d], &z0[d..], fq, fp)
            .map_err(|e| StepError::from_solve(Stage::Fibre, e))?;
    } else {
        dz.fill(0.0);
    }
    for ((yi, zi), di) in y.iter_mut().zip(z0).zip(dz.iter()) {
        *yi = zi + di;
    }
    let (bq, bp) = db.split_at_mut(d);
    let iterations = base
        .increment(sys, h, &y[..d], &y[d..], bq, bp, base_ws, opts)
        .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
    for (((zi1, zi), di), bi) in z1.iter_mut().zip(z0).zip(dz.iter_mut()).zip(db.iter()) {
        *di += bi;
        *zi1 = zi + *di;
    }
    Ok(iterations)
}

/// r(λ) = g(z1⁻(λ)) for the λ in `ws.lambda` (λ = 0 when `flow` is false):
/// Δ in `ws.dz`, y in `ws.y`, z1⁻ in `ws.z1`, r in `ws.g`. Returns the base
/// map's stage iterations.
fn residual<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    ws: &mut Workspace,
    base_ws: &mut B::Workspace,
    opts: &NewtonOptions,
    flow: bool,
) -> Result<usize, StepError> {
    let d = ws.d;
    let iterations = increment(
        sys,
        base,
        h,
        &ws.lambda,
        flow,
        &ws.z0,
        &mut ws.fibre,
        base_ws,
        opts,
        &mut ws.dz,
        &mut ws.db,
        &mut ws.y,
        &mut ws.z1,
    )?;
    sys.constraints(&ws.z1[..d], &ws.z1[d..], &mut ws.g);
    Ok(iterations)
}

/// Evaluates SHAKE's Jacobian at the current λ (whose residual is in
/// `ws.y`, `ws.z1`, `ws.g` and the base map's workspace) into `ws.jac`, for
/// the band `ws.jac_band` (or all of it for [`JacobianMode::TangentDense`]).
/// Returns the stage iterations the difference quotients took.
fn jacobian<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    ws: &mut Workspace,
    base_ws: &mut B::Workspace,
    opts: &NewtonOptions,
    mode: JacobianMode,
) -> Result<usize, StepError> {
    let (d, m) = (ws.d, ws.m);
    let (band, groups) = if mode == JacobianMode::TangentDense {
        (Band::full(m), m)
    } else {
        (ws.jac_band, ws.groups)
    };
    // Zero the band and the fill of the banded LU (rows j − l − u ..= j + l
    // of column j); entries outside it are never read.
    let fill = band.lower + band.upper;
    for j in 0..m {
        let lo = j.saturating_sub(fill);
        let hi = (j + band.lower).min(m - 1);
        ws.jac[lo + j * m..=hi + j * m].fill(0.0);
    }
    let mut iterations = 0;
    if mode != JacobianMode::Differences {
        sys.constraint_jacobian(&ws.y[..d], &ws.y[d..], &mut ws.g_z_y);
        sys.constraint_jacobian(&ws.z1[..d], &ws.z1[d..], &mut ws.g_z_1);
        base.prepare_tangent(sys, h, base_ws)
            .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
    } else if ws.probe.lambda_scale == 0.0 {
        ws.probe.lambda_scale = lambda_scale(sys, ws);
    }
    let lam_norm = norm_inf(&ws.lambda);
    for c in 0..groups {
        if mode == JacobianMode::Differences {
            // λ + ε s_c, with the increment each λ_j actually got.
            let eps = f64::EPSILON.sqrt() * lam_norm.max(ws.probe.lambda_scale);
            ws.probe.lambda.copy_from_slice(&ws.lambda);
            for j in (c..m).step_by(groups) {
                ws.probe.lambda[j] += eps;
            }
            // The same increment form as the residual, so that the
            // quotient differences like with like.
            iterations += increment(
                sys,
                base,
                h,
                &ws.probe.lambda,
                true,
                &ws.z0,
                &mut ws.fibre,
                base_ws,
                opts,
                &mut ws.probe.dz,
                &mut ws.db,
                &mut ws.probe.y,
                &mut ws.probe.z1,
            )?;
            sys.constraints(&ws.probe.z1[..d], &ws.probe.z1[d..], &mut ws.probe.g);
            for i in 0..m {
                ws.jv[i] = ws.probe.g[i] - ws.g[i];
            }
            for j in (c..m).step_by(groups) {
                ws.probe.lambda[j] -= ws.lambda[j];
            }
        } else {
            // tv = Dφ_h(y) Σ_{j ≡ c} X_{g_j}(y), jv = g_z(z1⁻) tv, both
            // through the sparsity pattern of g_z.
            ws.tv.fill(0.0);
            for &(j, k) in &ws.pattern {
                if j % groups == c {
                    let v = ws.g_z_y[j + k * m];
                    if k < d {
                        ws.tv[d + k] -= v;
                    } else {
                        ws.tv[k - d] += v;
                    }
                }
            }
            base.apply_tangent(h, base_ws, &mut ws.tv);
            ws.jv.fill(0.0);
            for &(i, k) in &ws.pattern {
                ws.jv[i] += ws.g_z_1[i + k * m] * ws.tv[k];
            }
        }
        // Row i of the compressed column belongs to the one column j ≡ c
        // of its band.
        for i in 0..m {
            let lo = i.saturating_sub(band.lower);
            let j = lo + (c + groups - lo % groups) % groups;
            if j > i + band.upper || j >= m {
                continue;
            }
            let scale = if mode == JacobianMode::Differences {
                1.0 / ws.probe.lambda[j]
            } else {
                1.0
            };
            ws.jac[i + j * m] = ws.jv[i] * scale;
        }
    }
    Ok(iterations)
}

/// The scale of λ at which the fibre flow moves z by about ‖z0‖ (its
/// inverse speed), so that λ ± √ε_mach·scale perturbs z in its leading
/// half of the digits: one application of the fibre flow along Σ_j λ_j = 1.
fn lambda_scale<S: ConstrainedSystem>(sys: &S, ws: &mut Workspace) -> f64 {
    let d = ws.d;
    let unit = 1e-3;
    ws.probe.lambda.fill(unit);
    ws.probe.y.copy_from_slice(&ws.z0);
    let (yq, yp) = ws.probe.y.split_at_mut(d);
    let moved = match ws.fibre.apply(sys, &ws.probe.lambda, yq, yp) {
        Ok(()) => ws
            .probe
            .y
            .iter()
            .zip(&ws.z0)
            .fold(0.0f64, |e, (a, b)| e.max((a - b).abs())),
        Err(_) => 0.0,
    };
    let size = norm_inf(&ws.z0);
    if moved > 0.0 && moved.is_finite() && size > 0.0 {
        unit * size / moved
    } else {
        1.0
    }
}
