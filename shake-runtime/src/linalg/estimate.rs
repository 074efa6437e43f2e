//! Norms of a matrix and of its inverse from its LU factors: what the
//! guard's condition estimate of N reads.

use super::{lu_solve, lu_solve_transpose};

/// ‖A‖₁, the largest column sum.
pub(crate) fn norm1(a: &[f64], n: usize) -> f64 {
    (0..n)
        .map(|j| a[j * n..(j + 1) * n].iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max)
}

/// An estimate of ‖A⁻¹‖₁ from the LU factors (Hager's method as refined by
/// Higham, at most five solve pairs); `x` and `z` are scratch of length n.
/// Exact for n = 1 and in practice within a small factor otherwise.
#[cfg(test)]
pub(crate) fn inverse_norm1_estimate(
    lu: &[f64],
    n: usize,
    piv: &[usize],
    x: &mut [f64],
    z: &mut [f64],
) -> f64 {
    let mut start = usize::MAX;
    inverse_norm1_estimate_from(lu, n, piv, x, z, &mut start)
}

/// `inverse_norm1_estimate` started from the unit vector e_start instead
/// of the uniform vector when `start < n`, and leaving in `start` the
/// column it ended on. Along a trajectory N changes little from step to
/// step, and the column that maximised ‖N⁻¹e_j‖₁ at the last step usually
/// still does: the estimate then costs one solve pair instead of two or
/// more (the test that ends Hager's iteration is the same, so the result
/// is as good an estimate as from the uniform start).
pub(crate) fn inverse_norm1_estimate_from(
    lu: &[f64],
    n: usize,
    piv: &[usize],
    x: &mut [f64],
    z: &mut [f64],
    start: &mut usize,
) -> f64 {
    let x = &mut x[..n];
    let z = &mut z[..n];
    let mut last_j = usize::MAX;
    if *start < n {
        x.fill(0.0);
        x[*start] = 1.0;
        last_j = *start;
    } else {
        x.fill(1.0 / n as f64);
    }
    let mut est = 0.0;
    for _ in 0..5 {
        lu_solve(lu, n, piv, x);
        est = x.iter().map(|v| v.abs()).sum::<f64>();
        for (zi, xi) in z.iter_mut().zip(x.iter()) {
            *zi = if *xi >= 0.0 { 1.0 } else { -1.0 };
        }
        lu_solve_transpose(lu, n, piv, z);
        let (mut j, mut zmax) = (0, 0.0);
        for (i, zi) in z.iter().enumerate() {
            if zi.abs() > zmax {
                zmax = zi.abs();
                j = i;
            }
        }
        // x was the previous unit vector e_{last_j} (or the uniform vector).
        let ztx = if last_j == usize::MAX {
            z.iter().sum::<f64>() / n as f64
        } else {
            z[last_j]
        };
        if zmax <= ztx || j == last_j {
            *start = if last_j == usize::MAX { j } else { last_j };
            break;
        }
        x.fill(0.0);
        x[j] = 1.0;
        last_j = j;
        *start = j;
    }
    est
}
