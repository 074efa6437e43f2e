//! The banded LU of a tridiagonal matrix (band 1, 1: a chain's SHAKE
//! Jacobian and its N), written out: LAPACK's `dgttrf`/`dgttrs` on the
//! dense column-major slice of [`super::band::band_lu_factor`].
//!
//! The factors are the general banded kernel's, entry for entry and in the
//! same order of operations (so the same bits): L's multiplier l_k below
//! the diagonal of column k, U's inverted diagonal, its first
//! superdiagonal and the second one that a row interchange fills. What
//! differs is the solves' data flow. The general kernel updates b[k + 1]
//! in memory at step k and loads it back at step k + 1, a store and a load
//! on the recursion's critical path at every row; here the running entry
//! stays in a register (x_{k+1} and x_{k+2} in the back substitution), as
//! in the Thomas algorithm. For a 16-link chain that halves a solve.

use super::Singular;

/// [`super::band::band_lu_factor`] for band (1, 1), with row k + 1 (its
/// diagonal and first superdiagonal as step k leaves them) carried to step
/// k + 1 in registers.
#[inline]
pub(super) fn factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> Result<(), Singular> {
    assert!(a.len() >= n * n && piv.len() >= n);
    if n == 0 {
        return Ok(());
    }
    // Row k at columns k, k + 1 as the steps before left it (column k + 2
    // they do not touch).
    let (mut d, mut u1) = (a[0], if n > 1 { a[n] } else { 0.0 });
    for k in 0..n - 1 {
        let kk = k + k * n;
        let wide = k + 2 < n;
        // Row k + 1 at columns k, k + 1, k + 2, as given, and row k's entry
        // in column k + 2 (outside the band: a zero, but with its sign).
        let below = a[kk + 1];
        let (b1, b2) = (a[kk + 1 + n], if wide { a[kk + 1 + 2 * n] } else { 0.0 });
        let u2 = if wide { a[kk + 2 * n] } else { 0.0 };
        let swap = below.abs() > d.abs();
        let max = if swap { below.abs() } else { d.abs() };
        piv[k] = if swap { k + 1 } else { k };
        if max == 0.0 || !max.is_finite() {
            return Err(Singular);
        }
        // The pivot row and the row it eliminates from.
        let (top, mut low) = if swap {
            ([below, b1, b2], [d, u1, u2])
        } else {
            ([d, u1, u2], [below, b1, b2])
        };
        let inv = 1.0 / top[0];
        let l = low[0] * inv;
        for j in 1..3 {
            if top[j] != 0.0 {
                low[j] -= l * top[j];
            }
        }
        a[kk] = inv;
        a[kk + 1] = l;
        a[kk + n] = top[1];
        if wide {
            a[kk + 2 * n] = top[2];
        }
        (d, u1) = (low[1], low[2]);
    }
    if d == 0.0 || !d.is_finite() {
        return Err(Singular);
    }
    let last = (n - 1) * (n + 1);
    piv[n - 1] = n - 1;
    a[last] = 1.0 / d;
    Ok(())
}

/// [`super::band::band_lu_solve`] for band (1, 1).
#[inline]
pub(super) fn solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    assert!(lu.len() >= n * n && piv.len() >= n && b.len() >= n);
    if n == 0 {
        return;
    }
    // b ← L_k⁻¹ P_k b, the running entry b[k] in `cur`.
    let mut cur = b[0];
    for k in 0..n - 1 {
        let next = b[k + 1];
        let (bk, bn) = if piv[k] != k {
            (next, cur)
        } else {
            (cur, next)
        };
        b[k] = bk;
        cur = bn - lu[k + 1 + k * n] * bk;
    }
    // U x = b, row by row with x_{j+1}, x_{j+2} in registers (the same
    // subtractions, in the same order, as the column sweep).
    let mut x1 = cur * lu[(n - 1) * (n + 1)];
    b[n - 1] = x1;
    let mut x2 = 0.0;
    for j in (0..n - 1).rev() {
        let mut s = b[j];
        if j + 2 < n {
            s -= lu[j + (j + 2) * n] * x2;
        }
        s -= lu[j + (j + 1) * n] * x1;
        let x = s * lu[j * (n + 1)];
        b[j] = x;
        x2 = x1;
        x1 = x;
    }
}

/// [`super::band::band_lu_solve_transpose`] for band (1, 1).
#[inline]
pub(super) fn solve_transpose(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    assert!(lu.len() >= n * n && piv.len() >= n && b.len() >= n);
    if n == 0 {
        return;
    }
    // Uᵀ y = b: y_j = (b_j − u_{j−2,j} y_{j−2} − u_{j−1,j} y_{j−1}) / u_jj.
    let (mut y2, mut y1) = (0.0, 0.0);
    for j in 0..n {
        let mut s = b[j];
        if j >= 2 {
            s -= lu[j - 2 + j * n] * y2;
        }
        if j >= 1 {
            s -= lu[j - 1 + j * n] * y1;
        }
        let y = s * lu[j * (n + 1)];
        b[j] = y;
        y2 = y1;
        y1 = y;
    }
    // y ← P_k L_k⁻ᵀ y for k = n − 1, …, 0, with the entry that step k
    // reads, y[k + 1], in `cur`: step k leaves in k + 1 either that entry
    // or (after an interchange) the new value, and in k the other one.
    let mut cur = b[n - 1];
    for k in (0..n - 1).rev() {
        let s = b[k] - lu[k + 1 + k * n] * cur;
        if piv[k] != k {
            b[k + 1] = s;
        } else {
            b[k + 1] = cur;
            cur = s;
        }
    }
    b[0] = cur;
}
