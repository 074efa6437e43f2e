//! Geometric SHAKE (the paper's Definition 1.1):
//! S_h: z0 ∈ M ↦ z1⁻ = φ_h(y), y = exp(Σ λ_i X_{g_i})(z0), with λ ∈ R^m
//! chosen so that g(z1⁻) = 0.
//!
//! # The equation for λ
//!
//! r(λ) = g(φ_h(F_λ(z0))) with F_λ = exp(Σ λ_i X_{g_i}) is solved by Newton's
//! method from λ = 0, to round-off (see [`newton`](crate::newton)). Its
//! Jacobian is
//!
//! ∂r/∂λ_j = g_z(z1⁻) · Dφ_h(y) · ∂F_λ(z0)/∂λ_j,
//!
//! with the base map's tangent map Dφ_h (its linearised stage equations) and
//! ∂F_λ/∂λ_j = X_{g_j}(F_λ(z0)). That last identity is exact when the X_{g_i}
//! commute (holonomic g, m = 1, or {g_i, g_j} = 0 identically) and otherwise
//! a simplified-Newton approximation: it is exact at λ = 0 and the error is
//! O(‖λ‖) = O(h), so convergence stays fast, and the converged λ is the
//! exact solution regardless. Note that Dφ_h ≈ I would give g_z X_{g_j} =
//! {g_i, g_j} = 0 on M: the O(h) part of Dφ_h carries the whole Jacobian.
//!
//! Each evaluation of r solves the base map's own stage equations (for an
//! implicit φ_h), warm-started from the previous evaluation: a nested
//! iteration.
//!
//! # The multiplier
//!
//! λ is the fibre parameter itself (y = exp(Σ λ_i X_{g_i})(z0)); it comes out
//! O(h). For holonomic g and Störmer–Verlet, y = (q0, p0 − g_q(q0)ᵀλ), so
//! λ = (h/2) λ_classical of the paper's Section 5.1.3 (h λ_classical for
//! symplectic Euler).

use crate::base_map::{BaseMap, BaseMapWorkspace};
use crate::error::{Stage, StepError};
use crate::fibre::FibreFlow;
use crate::linalg::{lu_factor, lu_solve, norm_inf};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::system::ConstrainedSystem;
use crate::SolveError;

/// All buffers of a SHAKE/RATTLE step, allocated once.
///
/// Buffers that receive a system's output are written only by the system
/// (they are zeroed here, once), as the contract in `system` requires.
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    pub(crate) d: usize,
    pub(crate) m: usize,
    pub(crate) base: BaseMapWorkspace,
    pub(crate) fibre: FibreFlow,
    // States.
    pub(crate) z0: Vec<f64>,
    pub(crate) y: Vec<f64>,
    pub(crate) z1: Vec<f64>,
    pub(crate) tv: Vec<f64>,
    // Multipliers.
    pub(crate) lambda: Vec<f64>,
    pub(crate) lambda_first: Vec<f64>,
    pub(crate) delta: Vec<f64>,
    pub(crate) sigma: Vec<f64>,
    // System outputs.
    pub(crate) g: Vec<f64>,
    pub(crate) g_z_y: Vec<f64>,
    pub(crate) g_z_1: Vec<f64>,
    pub(crate) hidden: Vec<f64>,
    pub(crate) n_mat: Vec<f64>,
    // Our matrices.
    pub(crate) jac: Vec<f64>,
    pub(crate) piv: Vec<usize>,
    pub(crate) s1: Vec<f64>,
    pub(crate) s2: Vec<f64>,
    // Projection onto M (initial data).
    pub(crate) gram: Vec<f64>,
}

impl Workspace {
    pub(crate) fn new<S: ConstrainedSystem>(sys: &S) -> Self {
        let d = S::DOF;
        let m = S::CONSTRAINTS;
        let n = 2 * d;
        Workspace {
            d,
            m,
            base: BaseMapWorkspace::new(d),
            fibre: FibreFlow::new(sys),
            z0: vec![0.0; n],
            y: vec![0.0; n],
            z1: vec![0.0; n],
            tv: vec![0.0; n],
            lambda: vec![0.0; m],
            lambda_first: vec![0.0; m],
            delta: vec![0.0; m],
            sigma: vec![0.0; m],
            g: vec![0.0; m],
            g_z_y: vec![0.0; m * n],
            g_z_1: vec![0.0; m * n],
            hidden: vec![0.0; m],
            n_mat: vec![0.0; m * m],
            jac: vec![0.0; m * m],
            piv: vec![0; m.max(1)],
            s1: vec![0.0; m.max(1)],
            s2: vec![0.0; m.max(1)],
            gram: vec![0.0; m * m],
        }
    }
}

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

/// One SHAKE step in place: (q, p) = z0 ∈ M becomes z1⁻ = S_h(z0).
/// The final λ is left in `ws.lambda`.
pub(crate) fn shake_step<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    opts: &NewtonOptions,
) -> Result<ShakeReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    let mut report = ShakeReport::default();
    ws.base.reset_warm_start();
    if m == 0 {
        report.base_iterations = base
            .apply(sys, h, q, p, &mut ws.base, opts)
            .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
        return Ok(report);
    }
    ws.z0[..d].copy_from_slice(q);
    ws.z0[d..].copy_from_slice(p);
    ws.lambda.fill(0.0);
    let mut mon = Monitor::new(*opts);
    let mut converged = false;
    loop {
        // y = F_λ(z0), z1⁻ = φ_h(y), r = g(z1⁻).
        ws.y.copy_from_slice(&ws.z0);
        {
            let (yq, yp) = ws.y.split_at_mut(d);
            ws.fibre
                .apply(sys, &ws.lambda, yq, yp)
                .map_err(|e| StepError::from_solve(Stage::Fibre, e))?;
        }
        ws.z1.copy_from_slice(&ws.y);
        {
            let (zq, zp) = ws.z1.split_at_mut(d);
            report.base_iterations += base
                .apply(sys, h, zq, zp, &mut ws.base, opts)
                .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
        }
        sys.constraints(&ws.z1[..d], &ws.z1[d..], &mut ws.g);
        let r = norm_inf(&ws.g);
        if !r.is_finite() || !ws.z1.iter().all(|x| x.is_finite()) {
            return Err(StepError::from_solve(
                Stage::Shake,
                SolveError::NonFinite {
                    iterations: mon.iterations,
                },
            ));
        }
        if converged || r == 0.0 {
            break;
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
        // Jacobian: column j = g_z(z1⁻) · Dφ_h(y) · X_{g_j}(y).
        sys.constraint_jacobian(&ws.y[..d], &ws.y[d..], &mut ws.g_z_y);
        sys.constraint_jacobian(&ws.z1[..d], &ws.z1[d..], &mut ws.g_z_1);
        base.prepare_tangent(sys, h, &mut ws.base)
            .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
        for j in 0..m {
            hamiltonian_field_of_constraint(&ws.g_z_y, d, m, j, &mut ws.tv);
            base.apply_tangent(h, &mut ws.base, &mut ws.tv);
            for i in 0..m {
                let mut s = 0.0;
                for k in 0..2 * d {
                    s += ws.g_z_1[i + k * m] * ws.tv[k];
                }
                ws.jac[i + j * m] = s;
            }
        }
        lu_factor(&mut ws.jac, m, &mut ws.piv).map_err(|_| {
            StepError::from_solve(
                Stage::Shake,
                SolveError::Singular {
                    iterations: mon.iterations,
                },
            )
        })?;
        ws.delta.copy_from_slice(&ws.g);
        lu_solve(&ws.jac, m, &ws.piv, &mut ws.delta);
        for (l, dl) in ws.lambda.iter_mut().zip(&ws.delta) {
            *l -= dl;
        }
        if mon.iterations == 0 {
            ws.lambda_first.copy_from_slice(&ws.lambda);
        }
        converged = mon.update(norm_inf(&ws.delta), norm_inf(&ws.lambda)) == Verdict::Converged;
    }
    q.copy_from_slice(&ws.z1[..d]);
    p.copy_from_slice(&ws.z1[d..]);
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

/// v ← X_{g_j}(z) = (∂g_j/∂p, −∂g_j/∂q) from g_z (m × 2d, column-major).
pub(crate) fn hamiltonian_field_of_constraint(
    g_z: &[f64],
    d: usize,
    m: usize,
    j: usize,
    v: &mut [f64],
) {
    for k in 0..d {
        v[k] = g_z[j + (d + k) * m];
        v[d + k] = -g_z[j + k * m];
    }
}
