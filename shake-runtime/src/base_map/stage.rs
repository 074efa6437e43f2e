//! Pieces shared by the built-in base maps: Hessian block products, the
//! implicit momentum stage, and the Newton solve of a stage equation.

use crate::linalg::{lu_factor, lu_solve, norm_inf};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::system::Hamiltonian;
use crate::SolveError;

/// out += alpha · B x, where B is the d×d block of the 2d×2d column-major
/// Hessian `hz` starting at row `r0`, column `c0`.
#[inline]
pub(super) fn block_mul_add(
    hz: &[f64],
    d: usize,
    r0: usize,
    c0: usize,
    x: &[f64],
    alpha: f64,
    out: &mut [f64],
) {
    let n = 2 * d;
    for (j, xj) in x.iter().enumerate().take(d) {
        let s = alpha * xj;
        if s != 0.0 {
            let col = &hz[(c0 + j) * n + r0..(c0 + j) * n + r0 + d];
            for (o, b) in out.iter_mut().zip(col) {
                *o += b * s;
            }
        }
    }
}

/// mat (d×d) = I + alpha · B, B the block at (r0, c0) of the Hessian.
pub(super) fn identity_plus_block(
    mat: &mut [f64],
    hz: &[f64],
    d: usize,
    r0: usize,
    c0: usize,
    alpha: f64,
) {
    let n = 2 * d;
    for j in 0..d {
        for i in 0..d {
            mat[i + j * d] = alpha * hz[(r0 + i) + (c0 + j) * n] + if i == j { 1.0 } else { 0.0 };
        }
    }
}

pub(super) fn check_finite(v: &[f64], iterations: usize) -> Result<(), SolveError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(SolveError::NonFinite { iterations })
    }
}

/// The implicit momentum stage x = p0 − c H_q(q0, x) (Störmer–Verlet's
/// first half kick with c = h/2, symplectic Euler's kick with c = h), by
/// Newton's method with the matrix I + c H_qp (∂H_q/∂p). It
/// starts from the previous stage shifted by the change of p0 when
/// `prev_p0` is given (warm start), else from the explicit kick.
#[allow(clippy::too_many_arguments)]
pub(super) fn momentum_stage<S: Hamiltonian>(
    sys: &S,
    q0: &[f64],
    p0: &[f64],
    c: f64,
    prev_p0: Option<&[f64]>,
    x: &mut [f64],
    res: &mut [f64],
    mat: &mut [f64],
    piv: &mut [usize],
    h_q: &mut [f64],
    hess_a: &mut [f64],
    opts: &NewtonOptions,
) -> Result<usize, SolveError> {
    let d = q0.len();
    match prev_p0 {
        Some(prev) => {
            for i in 0..d {
                x[i] += p0[i] - prev[i];
            }
        }
        None => {
            sys.grad_q(q0, p0, h_q);
            for i in 0..d {
                x[i] = p0[i] - c * h_q[i];
            }
        }
    }
    solve_stage(
        x,
        res,
        mat,
        piv,
        opts,
        |x, r| {
            sys.grad_q(q0, x, h_q);
            for i in 0..d {
                r[i] = x[i] - p0[i] + c * h_q[i];
            }
        },
        |x, a| {
            sys.hessian(q0, x, hess_a);
            identity_plus_block(a, hess_a, d, 0, d, c);
        },
    )
}

/// Newton's method for a d-dimensional stage equation R(x) = 0 where
/// `residual(x, res)` writes R and `matrix(x, mat)` writes dR/dx (d×d).
pub(super) fn solve_stage(
    x: &mut [f64],
    res: &mut [f64],
    mat: &mut [f64],
    piv: &mut [usize],
    opts: &NewtonOptions,
    mut residual: impl FnMut(&[f64], &mut [f64]),
    mut matrix: impl FnMut(&[f64], &mut [f64]),
) -> Result<usize, SolveError> {
    let n = x.len();
    let mut mon = Monitor::new(*opts);
    loop {
        residual(x, res);
        let r = norm_inf(res);
        if !r.is_finite() {
            return Err(SolveError::NonFinite {
                iterations: mon.iterations,
            });
        }
        if r == 0.0 {
            return Ok(mon.iterations);
        }
        if mon.exhausted() {
            return Err(SolveError::NotConverged {
                iterations: mon.iterations,
                residual: r,
            });
        }
        matrix(x, mat);
        lu_factor(mat, n, piv).map_err(|_| SolveError::Singular {
            iterations: mon.iterations,
        })?;
        lu_solve(mat, n, piv, res);
        for (xi, di) in x.iter_mut().zip(res.iter()) {
            *xi -= di;
        }
        if mon.update(norm_inf(res), norm_inf(x)) == Verdict::Converged {
            check_finite(x, mon.iterations)?;
            return Ok(mon.iterations);
        }
    }
}
