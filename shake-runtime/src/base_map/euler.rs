//! Symplectic Euler.

use super::stage::*;
use super::{BaseMap, BaseMapWorkspace};
use crate::linalg::{lu_factor, lu_solve};
use crate::newton::NewtonOptions;
use crate::system::Hamiltonian;
use crate::SolveError;

/// Symplectic Euler p1 = p0 − h H_q(q0, p1), q1 = q0 + h H_p(q0, p1):
/// symplectic, not symmetric, order 1; explicit for separable H.
///
/// ```
/// use geoshake_runtime::{BaseMap, SymplecticEuler};
/// assert!(!SymplecticEuler::SYMMETRIC);
/// assert_eq!(SymplecticEuler::ORDER, 1);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct SymplecticEuler;

impl BaseMap for SymplecticEuler {
    type Workspace = BaseMapWorkspace;

    const NAME: &'static str = "symplectic Euler";
    const SYMMETRIC: bool = false;
    const ORDER: u32 = 1;

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
        Some((1.0, 0.0))
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
        let warm = ws.begin(q, p);
        if sys.separable() {
            let BaseMapWorkspace {
                stage, h_q, h_p, ..
            } = ws;
            let p1 = &mut stage[..d];
            sys.grad_q(q, p, h_q);
            for i in 0..d {
                p1[i] = p[i] - h * h_q[i];
            }
            sys.grad_p(q, p1, h_p);
            for i in 0..d {
                q[i] += h * h_p[i];
            }
            p.copy_from_slice(p1);
            ws.warm = true;
            return Ok(0);
        }
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        let p1 = &mut stage[..d];
        let (q0, p0) = y.split_at(d);
        // p1 = p0 − h H_q(q0, p1).
        let it = momentum_stage(
            sys,
            q0,
            p0,
            h,
            if warm { Some(&y_prev[d..]) } else { None },
            p1,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            h_q,
            hess_a,
            opts,
        );
        ws.warm = it.is_ok();
        let it = it?;
        let (q0, p1) = (&ws.y[..d], &ws.stage[..d]);
        sys.grad_p(q0, p1, &mut ws.h_p);
        for i in 0..d {
            q[i] = q0[i] + h * ws.h_p[i];
            p[i] = p1[i];
        }
        Ok(it)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        sys.hessian(&ws.y[..d], &ws.stage[..d], &mut ws.hess_a);
        if !sys.separable() {
            identity_plus_block(&mut ws.mat, &ws.hess_a, d, 0, d, h);
            lu_factor(&mut ws.mat[..d * d], d, &mut ws.piv)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
        }
        ws.tangent_separable = sys.separable();
        Ok(())
    }

    fn apply_tangent(&self, h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        let d = ws.d;
        let separable = ws.tangent_separable;
        let (dq, dp) = v.split_at_mut(d);
        let dp1 = &mut ws.tmp[..d];
        // (I + h H_qp) δp1 = δp0 − h H_qq δq0.
        dp1.copy_from_slice(dp);
        block_mul_add(&ws.hess_a, d, 0, 0, dq, -h, dp1);
        if !separable {
            lu_solve(&ws.mat[..d * d], d, &ws.piv, dp1);
        }
        // δq1 = δq0 + h (H_pq δq0 + H_pp δp1).
        ws.res[..d].copy_from_slice(dq);
        block_mul_add(&ws.hess_a, d, d, 0, dq, h, &mut ws.res[..d]);
        block_mul_add(&ws.hess_a, d, d, d, dp1, h, &mut ws.res[..d]);
        dq.copy_from_slice(&ws.res[..d]);
        dp.copy_from_slice(dp1);
    }
}
