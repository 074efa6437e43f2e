//! The banded LU with partial pivoting (LAPACK's `dgbtrf`/`dgbtrs`) on
//! the dense column-major slice: the chain's Newton matrices, whose
//! nonzeros lie within a few diagonals (module docs of `linalg`).

use super::{tridiagonal, Band, Singular};

/// Banded LU with partial pivoting (LAPACK's `dgbtrf`), in place in the
/// dense column-major slice `a` whose nonzeros lie in `band`. Row
/// interchanges are applied only to the columns from the pivot column on,
/// so the multipliers of L stay where they were computed and the solves
/// interleave them with the interchanges ([`band_lu_solve`]). U gets
/// `band.lower + band.upper` superdiagonals (the fill of pivoting), and its
/// diagonal is stored as reciprocals (read by the banded solves and by
/// [`lu_det`](super::lu_det) through the recorded band); entries outside
/// the band must be zero on entry (the (1, 1) kernel reads row k's entry in
/// column k + 2 and nothing further out).
pub(crate) fn band_lu_factor(
    a: &mut [f64],
    n: usize,
    band: Band,
    piv: &mut [usize],
) -> Result<(), Singular> {
    // The chain's bands get kernels with the widths as constants (their
    // inner loops unrolled); the band itself is found once per system.
    match (band.lower, band.upper) {
        (1, 1) => tridiagonal::factor(a, n, piv),
        (2, 2) => band_lu_factor_w(a, n, 2, 4, piv),
        (l, u) if l + 1 == n && u + 1 == n => {
            small_n!(n, N => band_lu_factor_w(a, N, N - 1, 2 * N - 2, piv),
            _ => band_lu_factor_w(a, n, l, l + u, piv))
        }
        (l, u) => band_lu_factor_w(a, n, l, l + u, piv),
    }
}

#[inline(always)]
pub(super) fn band_lu_factor_w(
    a: &mut [f64],
    n: usize,
    kl: usize,
    kv: usize,
    piv: &mut [usize],
) -> Result<(), Singular> {
    // (Slices of the exact lengths: with n a constant (`small_n!`) the
    // compiler then proves every index in bounds and unrolls.)
    let (a, piv) = (&mut a[..n * n], &mut piv[..n]);
    for k in 0..n {
        let last_row = (k + kl).min(n - 1);
        let last_col = (k + kv).min(n - 1);
        let mut p = k;
        let mut max = a[k + k * n].abs();
        for i in k + 1..=last_row {
            let v = a[i + k * n].abs();
            if v > max {
                max = v;
                p = i;
            }
        }
        piv[k] = p;
        if max == 0.0 || !max.is_finite() {
            return Err(Singular);
        }
        if p != k {
            for j in k..=last_col {
                a.swap(k + j * n, p + j * n);
            }
        }
        let inv = 1.0 / a[k + k * n];
        // Kept as its reciprocal: the solves multiply (a division on
        // their dependency chain costs as much as the rest of a row).
        a[k + k * n] = inv;
        for i in k + 1..=last_row {
            a[i + k * n] *= inv;
        }
        for j in k + 1..=last_col {
            let akj = a[k + j * n];
            if akj != 0.0 {
                for i in k + 1..=last_row {
                    a[i + j * n] -= a[i + k * n] * akj;
                }
            }
        }
    }
    Ok(())
}

/// Solves A x = b in place from the factors of [`band_lu_factor`].
pub(crate) fn band_lu_solve(lu: &[f64], n: usize, band: Band, piv: &[usize], b: &mut [f64]) {
    match (band.lower, band.upper) {
        (1, 1) => tridiagonal::solve(lu, n, piv, b),
        (2, 2) => band_lu_solve_w(lu, n, 2, 4, piv, b),
        (l, u) if l + 1 == n && u + 1 == n => {
            small_n!(n, N => band_lu_solve_w(lu, N, N - 1, 2 * N - 2, piv, b),
            _ => band_lu_solve_w(lu, n, l, l + u, piv, b))
        }
        (l, u) => band_lu_solve_w(lu, n, l, l + u, piv, b),
    }
}

#[inline(always)]
pub(super) fn band_lu_solve_w(
    lu: &[f64],
    n: usize,
    kl: usize,
    kv: usize,
    piv: &[usize],
    b: &mut [f64],
) {
    let (lu, piv, b) = (&lu[..n * n], &piv[..n], &mut b[..n]);
    // b ← L_k⁻¹ P_k b for k = 0, 1, …
    for k in 0..n {
        let p = piv[k];
        if p != k {
            b.swap(k, p);
        }
        // (No test for bk = 0: in a narrow band the branch costs more
        // than the few products it would skip.)
        let bk = b[k];
        for i in k + 1..=(k + kl).min(n - 1) {
            b[i] -= lu[i + k * n] * bk;
        }
    }
    // U x = b (U's diagonal is stored inverted).
    for j in (0..n).rev() {
        let bj = b[j] * lu[j + j * n];
        b[j] = bj;
        for i in j.saturating_sub(kv)..j {
            b[i] -= lu[i + j * n] * bj;
        }
    }
}

/// Solves Aᵀ x = b in place from the factors of [`band_lu_factor`]:
/// A = P₀L₀ ⋯ P_{n−1}L_{n−1} U, so Aᵀ x = b is Uᵀ y = b followed by
/// y ← P_k L_k⁻ᵀ y for k = n−1, …, 0.
pub(crate) fn band_lu_solve_transpose(
    lu: &[f64],
    n: usize,
    band: Band,
    piv: &[usize],
    b: &mut [f64],
) {
    match (band.lower, band.upper) {
        (1, 1) => tridiagonal::solve_transpose(lu, n, piv, b),
        (2, 2) => band_lu_solve_transpose_w(lu, n, 2, 4, piv, b),
        (l, u) if l + 1 == n && u + 1 == n => {
            small_n!(n, N => band_lu_solve_transpose_w(lu, N, N - 1, 2 * N - 2, piv, b),
            _ => band_lu_solve_transpose_w(lu, n, l, l + u, piv, b))
        }
        (l, u) => band_lu_solve_transpose_w(lu, n, l, l + u, piv, b),
    }
}

#[inline(always)]
pub(super) fn band_lu_solve_transpose_w(
    lu: &[f64],
    n: usize,
    kl: usize,
    kv: usize,
    piv: &[usize],
    b: &mut [f64],
) {
    for j in 0..n {
        let mut s = b[j];
        for i in j.saturating_sub(kv)..j {
            s -= lu[i + j * n] * b[i];
        }
        b[j] = s * lu[j + j * n];
    }
    for k in (0..n).rev() {
        let mut s = b[k];
        for i in k + 1..=(k + kl).min(n - 1) {
            s -= lu[i + k * n] * b[i];
        }
        b[k] = s;
        let p = piv[k];
        if p != k {
            b.swap(k, p);
        }
    }
}
