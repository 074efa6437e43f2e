//! The implicit midpoint rule.

use super::stage::*;
use super::{BaseMap, BaseMapWorkspace};
use crate::linalg::{lu_factor, lu_solve};
use crate::newton::NewtonOptions;
use crate::system::Hamiltonian;
use crate::SolveError;

/// The implicit midpoint rule z1 = z0 + h X_H((z0 + z1)/2): symplectic and
/// symmetric for any H, order 2.
///
/// ```
/// use geoshake_runtime::{BaseMap, ImplicitMidpoint};
/// assert!(ImplicitMidpoint::SYMMETRIC);
/// assert_eq!(ImplicitMidpoint::ORDER, 2);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct ImplicitMidpoint;

impl BaseMap for ImplicitMidpoint {
    type Workspace = BaseMapWorkspace;

    const NAME: &'static str = "implicit midpoint";
    const SYMMETRIC: bool = true;
    const ORDER: u32 = 2;

    fn workspace(&self, d: usize) -> BaseMapWorkspace {
        BaseMapWorkspace::new(d)
    }

    fn reset_warm_start(&self, ws: &mut BaseMapWorkspace) {
        ws.reset_warm_start();
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
        let n = 2 * d;
        let warm = ws.begin(q, p);
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        // The unknown is the midpoint m = (z0 + z1)/2: m = y + (h/2) X_H(m).
        if warm {
            for i in 0..n {
                stage[i] += y[i] - y_prev[i];
            }
        } else {
            sys.gradient(&y[..d], &y[d..], h_q, h_p);
            for i in 0..d {
                stage[i] = y[i] + 0.5 * h * h_p[i];
                stage[d + i] = y[d + i] - 0.5 * h * h_q[i];
            }
        }
        let y: &[f64] = y;
        let iters = solve_stage(
            stage,
            res,
            mat,
            piv,
            opts,
            |m, r| {
                sys.gradient(&m[..d], &m[d..], h_q, h_p);
                for i in 0..d {
                    r[i] = m[i] - y[i] - 0.5 * h * h_p[i];
                    r[d + i] = m[d + i] - y[d + i] + 0.5 * h * h_q[i];
                }
            },
            |m, a| {
                sys.hessian(&m[..d], &m[d..], hess_a);
                midpoint_matrix(a, hess_a, d, -0.5 * h);
            },
        );
        ws.warm = iters.is_ok();
        let iters = iters?;
        for i in 0..d {
            q[i] = 2.0 * ws.stage[i] - ws.y[i];
            p[i] = 2.0 * ws.stage[d + i] - ws.y[d + i];
        }
        Ok(iters)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        sys.hessian(&ws.stage[..d], &ws.stage[d..], &mut ws.hess_a);
        midpoint_matrix(&mut ws.mat, &ws.hess_a, d, -0.5 * h);
        lu_factor(&mut ws.mat, 2 * d, &mut ws.piv)
            .map_err(|_| SolveError::Singular { iterations: 0 })
    }

    fn apply_tangent(&self, _h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        // δz1 = δz0 + h J H_zz(m) δm with δm = (δz0 + δz1)/2, i.e.
        // (I − (h/2) J H_zz) δm = δz0 and δz1 = 2 δm − δz0.
        let n = 2 * ws.d;
        ws.tmp.copy_from_slice(&v[..n]);
        lu_solve(&ws.mat, n, &ws.piv, &mut ws.tmp);
        for (vi, mi) in v.iter_mut().zip(&ws.tmp) {
            *vi = 2.0 * mi - *vi;
        }
    }

    /// The unknown is k = m − y, the half increment: k = (h/2) X_H(y + k),
    /// solved by Newton to stagnation; z1 − z0 = 2k.
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
        let d = ws.d;
        let n = 2 * d;
        let warm = ws.begin(q, p);
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            hess_a,
            mat,
            piv,
            res,
            tmp,
            ..
        } = ws;
        // tmp holds k (stage holds m = y + k for the tangent map).
        if warm {
            for i in 0..n {
                tmp[i] = stage[i] - y_prev[i];
            }
        } else {
            sys.gradient(&y[..d], &y[d..], h_q, h_p);
            for i in 0..d {
                tmp[i] = 0.5 * h * h_p[i];
                tmp[d + i] = -0.5 * h * h_q[i];
            }
        }
        let y: &[f64] = y;
        let iters = solve_stage(
            tmp,
            res,
            mat,
            piv,
            opts,
            |k, r| {
                for i in 0..n {
                    stage[i] = y[i] + k[i];
                }
                sys.gradient(&stage[..d], &stage[d..], h_q, h_p);
                for i in 0..d {
                    r[i] = k[i] - 0.5 * h * h_p[i];
                    r[d + i] = k[d + i] + 0.5 * h * h_q[i];
                }
            },
            |k, a| {
                // y_prev is free once the warm start has been read.
                for i in 0..n {
                    y_prev[i] = y[i] + k[i];
                }
                sys.hessian(&y_prev[..d], &y_prev[d..], hess_a);
                midpoint_matrix(a, hess_a, d, -0.5 * h);
            },
        );
        ws.warm = iters.is_ok();
        let iters = iters?;
        for i in 0..n {
            ws.stage[i] = ws.y[i] + ws.tmp[i];
        }
        for i in 0..d {
            dq[i] = 2.0 * ws.tmp[i];
            dp[i] = 2.0 * ws.tmp[d + i];
        }
        Ok(iters)
    }
}

/// a = I + alpha · J H_zz (2d×2d), J = [[0, I], [−I, 0]].
fn midpoint_matrix(a: &mut [f64], hz: &[f64], d: usize, alpha: f64) {
    let n = 2 * d;
    for j in 0..n {
        for i in 0..d {
            // (J H)[i, j] = H[d+i, j]; (J H)[d+i, j] = −H[i, j].
            a[i + j * n] = alpha * hz[(d + i) + j * n];
            a[(d + i) + j * n] = -alpha * hz[i + j * n];
        }
        a[j + j * n] += 1.0;
    }
}
