//! Störmer–Verlet (Section 5.1.3).

use super::stage::*;
use super::{BaseMap, BaseMapWorkspace};
use crate::linalg::{lu_factor, lu_solve};
use crate::newton::NewtonOptions;
use crate::system::Hamiltonian;
use crate::SolveError;

/// Störmer–Verlet in the form of the paper's Section 5.1.3 (half kick,
/// drift, half kick), explicit for separable H and the generalised implicit
/// method otherwise; symplectic, symmetric, order 2. With holonomic
/// constraints, SHAKE/RATTLE over it are the classical methods.
///
/// ```
/// use geoshake_runtime::{BaseMap, StormerVerlet};
/// assert!(StormerVerlet::SYMMETRIC);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct StormerVerlet;

impl BaseMap for StormerVerlet {
    type Workspace = BaseMapWorkspace;

    const NAME: &'static str = "Störmer–Verlet";
    const SYMMETRIC: bool = true;
    const ORDER: u32 = 2;

    fn workspace(&self, d: usize) -> BaseMapWorkspace {
        BaseMapWorkspace::new(d)
    }

    fn reset_warm_start(&self, ws: &mut BaseMapWorkspace) {
        ws.reset_warm_start();
    }

    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        sys.separable()
    }

    fn kick_drift_kick(&self) -> Option<(f64, f64)> {
        Some((0.5, 0.5))
    }

    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let d = ws.d;
        let hh = 0.5 * h;
        let warm = ws.begin(q, p);
        if sys.separable() {
            // Explicit: kick, drift, kick. The stage keeps p½ and q1.
            let BaseMapWorkspace {
                stage, h_q, h_p, ..
            } = ws;
            let (p_half, q1) = stage.split_at_mut(d);
            sys.grad_q(q, p, h_q);
            for i in 0..d {
                p_half[i] = p[i] - hh * h_q[i];
            }
            sys.grad_p(q, p_half, h_p);
            for i in 0..d {
                q1[i] = q[i] + h * h_p[i];
            }
            sys.grad_q(q1, p_half, h_q);
            for i in 0..d {
                q[i] = q1[i];
                p[i] = p_half[i] - hh * h_q[i];
            }
            ws.warm = true;
            return Ok(0);
        }
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            h_p_a,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        let (p_half, q1) = stage.split_at_mut(d);
        let (q0, p0) = y.split_at(d);
        // p½ = p0 − (h/2) H_q(q0, p½).
        let it1 = momentum_stage(
            sys,
            q0,
            p0,
            hh,
            if warm { Some(&y_prev[d..]) } else { None },
            p_half,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            h_q,
            hess_a,
            opts,
        );
        let it1 = match it1 {
            Ok(it) => it,
            Err(e) => {
                ws.warm = false;
                return Err(e);
            }
        };
        // q1 = q0 + (h/2)(H_p(q0, p½) + H_p(q1, p½)).
        sys.grad_p(q0, p_half, h_p_a);
        if warm {
            for i in 0..d {
                q1[i] += q0[i] - y_prev[i];
            }
        } else {
            for i in 0..d {
                q1[i] = q0[i] + h * h_p_a[i];
            }
        }
        let p_half: &[f64] = p_half;
        let h_p_a: &[f64] = h_p_a;
        let it2 = solve_stage(
            q1,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            opts,
            |x, r| {
                sys.grad_p(x, p_half, h_p);
                for i in 0..d {
                    r[i] = x[i] - q0[i] - hh * (h_p_a[i] + h_p[i]);
                }
            },
            |x, a| {
                sys.hessian(x, p_half, hess_a);
                identity_plus_block(a, hess_a, d, d, 0, -hh);
            },
        );
        let it2 = match it2 {
            Ok(it) => it,
            Err(e) => {
                ws.warm = false;
                return Err(e);
            }
        };
        // p1 = p½ − (h/2) H_q(q1, p½).
        sys.grad_q(q1, p_half, h_q);
        for i in 0..d {
            q[i] = q1[i];
            p[i] = p_half[i] - hh * h_q[i];
        }
        ws.warm = true;
        Ok(it1 + it2)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        let hh = 0.5 * h;
        let (p_half, q1) = ws.stage.split_at(d);
        sys.hessian(&ws.y[..d], p_half, &mut ws.hess_a);
        sys.hessian(q1, p_half, &mut ws.hess_b);
        if !sys.separable() {
            identity_plus_block(&mut ws.mat, &ws.hess_a, d, 0, d, hh);
            lu_factor(&mut ws.mat[..d * d], d, &mut ws.piv)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
            identity_plus_block(&mut ws.mat_b, &ws.hess_b, d, d, 0, -hh);
            lu_factor(&mut ws.mat_b[..d * d], d, &mut ws.piv_b)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
        }
        ws.tangent_separable = sys.separable();
        Ok(())
    }

    fn apply_tangent(&self, h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        let d = ws.d;
        let hh = 0.5 * h;
        let separable = ws.tangent_separable;
        let (dq, dp) = v.split_at_mut(d);
        let (dp_half, dq1) = ws.tmp.split_at_mut(d);
        // (I + (h/2) H_qp^a) δp½ = δp0 − (h/2) H_qq^a δq0.
        dp_half.copy_from_slice(dp);
        block_mul_add(&ws.hess_a, d, 0, 0, dq, -hh, dp_half);
        if !separable {
            lu_solve(&ws.mat[..d * d], d, &ws.piv, dp_half);
        }
        // (I − (h/2) H_pq^b) δq1 = δq0 + (h/2)(H_pq^a δq0 + (H_pp^a + H_pp^b) δp½).
        dq1.copy_from_slice(dq);
        block_mul_add(&ws.hess_a, d, d, 0, dq, hh, dq1);
        block_mul_add(&ws.hess_a, d, d, d, dp_half, hh, dq1);
        block_mul_add(&ws.hess_b, d, d, d, dp_half, hh, dq1);
        if !separable {
            lu_solve(&ws.mat_b[..d * d], d, &ws.piv_b, dq1);
        }
        // δp1 = δp½ − (h/2)(H_qq^b δq1 + H_qp^b δp½).
        dp.copy_from_slice(dp_half);
        block_mul_add(&ws.hess_b, d, 0, 0, dq1, -hh, dp);
        block_mul_add(&ws.hess_b, d, 0, d, dp_half, -hh, dp);
        dq.copy_from_slice(dq1);
    }

    /// Separable H: δq = h H_p(p½), δp = −(h/2)(H_q(q0) + H_q(q1)), each a
    /// small quantity computed directly. Non-separable H: the provided
    /// difference form.
    fn increment<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        if !sys.separable() {
            dq.copy_from_slice(q);
            dp.copy_from_slice(p);
            let it = self.apply(sys, h, dq, dp, ws, opts)?;
            for (x, x0) in dq.iter_mut().zip(q) {
                *x -= x0;
            }
            for (x, x0) in dp.iter_mut().zip(p) {
                *x -= x0;
            }
            return Ok(it);
        }
        let d = ws.d;
        let hh = 0.5 * h;
        ws.begin(q, p);
        let BaseMapWorkspace {
            stage,
            h_q,
            h_p,
            res,
            ..
        } = ws;
        let (p_half, q1) = stage.split_at_mut(d);
        let hq0 = &mut res[..d];
        sys.grad_q(q, p, hq0);
        for i in 0..d {
            p_half[i] = p[i] - hh * hq0[i];
        }
        sys.grad_p(q, p_half, h_p);
        for i in 0..d {
            dq[i] = h * h_p[i];
            q1[i] = q[i] + dq[i];
        }
        sys.grad_q(q1, p_half, h_q);
        for i in 0..d {
            // Two half kicks, as in `apply` (a sum first could overflow).
            dp[i] = -hh * hq0[i] - hh * h_q[i];
        }
        ws.warm = true;
        Ok(0)
    }
}
