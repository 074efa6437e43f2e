//! Compensated (Kahan) summation of the state: SHAKE in increment form.
//!
//! A step writes z_{n+1} = z_n + Δ_n with an increment Δ_n = O(h). Adding
//! it in floating point loses the low bits of Δ_n, an error of up to ε|z|
//! per step, which accumulates over a long run. Kahan's compensated
//! summation keeps those lost bits in a carry c_n and adds them back into
//! the next increment, so that the summation error per step drops to
//! O(ε|Δ|) = O(εh) — *provided Δ_n itself is computed as a small quantity*
//! and not as the difference of two rounded states. This module computes
//! SHAKE's increment that way:
//!
//! Δ(λ) = [exp(Σ λ_i X_{g_i})(z) − z] + [φ_h(y) − y],  y = z + first bracket,
//!
//! with the fibre increment from [`FibreFlow::increment`] and the base map's
//! from [`BaseMap::increment`] (the midpoint rule solves for its half
//! increment k = m − y; explicit Störmer–Verlet forms its kicks and drift
//! directly). λ is found by Newton's method on g(z + Δ(λ)) = 0 with the
//! Jacobian of the plain SHAKE step, iterated to round-off (stagnation), as
//! every implicit equation of the runtime. (Hairer, McLachlan and
//! Razakarivony 2008: with iterations to stagnation and compensated
//! summation, the round-off part of the energy error grows like √n.)
//!
//! What is not compensated: the directions normal to M and along the fibres
//! are re-imposed at every step (g = 0 is solved for, the fibre position is
//! irrelevant to SHAKE), so their rounding does not accumulate anyway; the
//! projection Π of a RATTLE state that is stored or observed is computed
//! from the rounded state. General (non-quadratic, momentum-dependent)
//! constraints and non-separable Störmer–Verlet fall back to difference
//! increments, so they gain nothing.
//!
//! It is on by default in runs ([`Integrator::compensated`](crate::Integrator::compensated)
//! turns it off); the carry lives in the integrator and is reset at the
//! start of every run (a single [`step`](crate::Integrator::step) has
//! nothing to carry and takes the plain SHAKE step).
//!
//! Measured (`cargo run --release --example stress`, pendulum, Störmer–
//! Verlet, h = 0.01; the round-off part of the energy error isolated by
//! running n steps forward and n back, RMS over an ensemble): plain
//! summation drifts, e(n) ∝ n¹·⁰ (8e-13 at n = 10⁵); compensated summation
//! follows Brouwer's √n law at a level ~1000 times lower (9e-16 at
//! n = 10⁵).
//!
//! ```
//! use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
//! let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
//! let plain = Integrator::new(Pendulum::default(), StormerVerlet, 0.01)
//!     .compensated(false)
//!     .run(z0.clone(), Stop::Steps(1000)).stride(1000).execute().trajectory;
//! let comp = Integrator::new(Pendulum::default(), StormerVerlet, 0.01)
//!     .run(z0, Stop::Steps(1000)).stride(1000).execute().trajectory;
//! // The same method: the two runs differ by round-off only.
//! assert!(plain.states[1].distance(&comp.states[1]) < 1e-12);
//! ```

use crate::base_map::{BaseMap, BaseMapWorkspace};
use crate::error::{Stage, StepError};
use crate::fibre::FibreFlow;
use crate::linalg::{lu_factor, lu_solve, norm_inf};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::system::ConstrainedSystem;
use crate::SolveError;

/// Buffers of the compensated SHAKE step and the Kahan carry.
#[derive(Clone, Debug)]
pub(crate) struct CompensatedWorkspace {
    d: usize,
    m: usize,
    base: BaseMapWorkspace,
    fibre: FibreFlow,
    /// The carry c of Kahan's summation (2d): minus the bits lost so far.
    pub(crate) carry: Vec<f64>,
    z0: Vec<f64>,
    y: Vec<f64>,
    z1: Vec<f64>,
    dz: Vec<f64>,
    db: Vec<f64>,
    tv: Vec<f64>,
    lambda: Vec<f64>,
    lambda_first: Vec<f64>,
    delta: Vec<f64>,
    g: Vec<f64>,
    g_z_y: Vec<f64>,
    g_z_1: Vec<f64>,
    jac: Vec<f64>,
    piv: Vec<usize>,
}

/// What a compensated SHAKE step did (the fields of the plain step's
/// report that the driver's checks use).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) struct CompensatedReport {
    pub(crate) iterations: usize,
    pub(crate) base_iterations: usize,
    pub(crate) lambda: f64,
    pub(crate) lambda_predicted: f64,
    pub(crate) lambda_correction: f64,
}

impl CompensatedWorkspace {
    pub(crate) fn new<S: ConstrainedSystem>(sys: &S) -> Self {
        let (d, m) = (S::DOF, S::CONSTRAINTS);
        let n = 2 * d;
        CompensatedWorkspace {
            d,
            m,
            base: BaseMapWorkspace::new(d),
            fibre: FibreFlow::new(sys),
            carry: vec![0.0; n],
            z0: vec![0.0; n],
            y: vec![0.0; n],
            z1: vec![0.0; n],
            dz: vec![0.0; n],
            db: vec![0.0; n],
            tv: vec![0.0; n],
            lambda: vec![0.0; m],
            lambda_first: vec![0.0; m],
            delta: vec![0.0; m],
            g: vec![0.0; m],
            g_z_y: vec![0.0; m * n],
            g_z_1: vec![0.0; m * n],
            jac: vec![0.0; m * m],
            piv: vec![0; m.max(1)],
        }
    }

    /// Forget the carry (start of a run).
    pub(crate) fn reset(&mut self) {
        self.carry.fill(0.0);
    }
}

/// s ← s + x with Kahan's compensation c (c holds minus the lost low bits).
#[inline]
fn kahan_add(s: &mut f64, c: &mut f64, x: f64) {
    let y = x - *c;
    let t = *s + y;
    *c = (t - *s) - y;
    *s = t;
}

/// One SHAKE step of size h in increment form, in place on (q, p), the
/// increment added with Kahan's compensation (carry in `ws.carry`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn compensated_shake_step<S: ConstrainedSystem, B: BaseMap>(
    sys: &S,
    base: &B,
    h: f64,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut CompensatedWorkspace,
    opts: &NewtonOptions,
) -> Result<CompensatedReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    let n = 2 * d;
    let mut report = CompensatedReport::default();
    ws.base.reset_warm_start();
    ws.z0[..d].copy_from_slice(q);
    ws.z0[d..].copy_from_slice(p);
    ws.lambda.fill(0.0);
    let mut mon = Monitor::new(*opts);
    let mut converged = false;
    loop {
        // Δ = fibre increment + base-map increment at y = z0 + fibre part.
        {
            let (fq, fp) = ws.dz.split_at_mut(d);
            ws.fibre
                .increment(sys, &ws.lambda, &ws.z0[..d], &ws.z0[d..], fq, fp)
                .map_err(|e| StepError::from_solve(Stage::Fibre, e))?;
        }
        for i in 0..n {
            ws.y[i] = ws.z0[i] + ws.dz[i];
        }
        {
            let (bq, bp) = ws.db.split_at_mut(d);
            report.base_iterations += base
                .increment(sys, h, &ws.y[..d], &ws.y[d..], bq, bp, &mut ws.base, opts)
                .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
        }
        for i in 0..n {
            ws.dz[i] += ws.db[i];
            ws.z1[i] = ws.z0[i] + ws.dz[i];
        }
        if m == 0 {
            // No constraint: the base map alone (the driver checks the
            // state for overflow, as after a plain step).
            break;
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
        // Jacobian column j = g_z(z1⁻) · Dφ_h(y) · X_{g_j}(y), as in SHAKE.
        sys.constraint_jacobian(&ws.y[..d], &ws.y[d..], &mut ws.g_z_y);
        sys.constraint_jacobian(&ws.z1[..d], &ws.z1[d..], &mut ws.g_z_1);
        base.prepare_tangent(sys, h, &mut ws.base)
            .map_err(|e| StepError::from_solve(Stage::BaseMap, e))?;
        for j in 0..m {
            for k in 0..d {
                ws.tv[k] = ws.g_z_y[j + (d + k) * m];
                ws.tv[d + k] = -ws.g_z_y[j + k * m];
            }
            base.apply_tangent(h, &mut ws.base, &mut ws.tv);
            for i in 0..m {
                let mut s = 0.0;
                for k in 0..n {
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
    // z ← z + Δ, compensated.
    for k in 0..d {
        kahan_add(&mut q[k], &mut ws.carry[k], ws.dz[k]);
        kahan_add(&mut p[k], &mut ws.carry[d + k], ws.dz[d + k]);
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kahan_keeps_the_low_bits() {
        // 1 + 10⁶ · 1e-16: plain summation loses every term, Kahan none.
        let (mut plain, mut s, mut c) = (1.0f64, 1.0f64, 0.0f64);
        for _ in 0..1_000_000 {
            plain += 1e-16;
            kahan_add(&mut s, &mut c, 1e-16);
        }
        assert_eq!(plain, 1.0);
        assert!((s - c - (1.0 + 1e-10)).abs() < 1e-22 || (s - (1.0 + 1e-10)).abs() < 2e-16);
    }
}
