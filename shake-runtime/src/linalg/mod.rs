//! Small dense and banded linear algebra on workspace slices, without
//! allocation.
//!
//! This is the seam behind which every linear solve of the runtime happens
//! (the m×m Newton matrices of SHAKE and RATTLE, the 2d×2d and d×d stage
//! matrices of the implicit base maps). Everything works in place on
//! column-major slices (entry (i, j) at `a[i + j*n]`) with partial pivoting.
//!
//! # Banded matrices
//!
//! The Newton matrices of a chain are banded: constraint i couples only to
//! its neighbours, so g_z g_zᵀ, N = {{H,g_i},g_j} and SHAKE's Jacobian have a
//! few diagonals. A dense LU costs n³/3 flops for them; the banded LU of
//! [`band_lu_factor`] costs about n·l·(l + u) (LAPACK's `dgbtrf` without the
//! packed storage: the matrix stays in its dense column-major slice, only
//! the band is touched). [`lu_factor`] picks it by itself when the matrix
//! is banded and its pivot vector has two spare slots (length ≥ n + 2), in
//! which it records the bandwidths for [`lu_solve`] and
//! [`lu_solve_transpose`]; callers that know the band in advance (SHAKE's
//! structured Jacobian) call the banded functions directly.

mod tridiagonal;

/// `$e` with `$n` as the constant `$N` when n is 2 to 8, else `$other`:
/// the small Newton matrices (a few constraints) get kernels whose loops
/// the compiler unrolls, computing the same operations in the same order.
macro_rules! small_n {
    ($n:expr, $N:ident => $e:expr, _ => $other:expr) => {
        match $n {
            2 => {
                const $N: usize = 2;
                $e
            }
            3 => {
                const $N: usize = 3;
                $e
            }
            4 => {
                const $N: usize = 4;
                $e
            }
            5 => {
                const $N: usize = 5;
                $e
            }
            6 => {
                const $N: usize = 6;
                $e
            }
            7 => {
                const $N: usize = 7;
                $e
            }
            8 => {
                const $N: usize = 8;
                $e
            }
            _ => $other,
        }
    };
}

/// The matrix was exactly singular (a zero pivot) or not finite.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct Singular;

/// Bandwidths of a square matrix: a_ij = 0 when i > j + lower or
/// j > i + upper.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) struct Band {
    pub(crate) lower: usize,
    pub(crate) upper: usize,
}

impl Band {
    /// The band of a full n×n matrix.
    pub(crate) fn full(n: usize) -> Band {
        let w = n.saturating_sub(1);
        Band { lower: w, upper: w }
    }

    /// The smallest band holding every nonzero entry of `a` (n×n).
    pub(crate) fn of(a: &[f64], n: usize) -> Band {
        let mut band = Band { lower: 0, upper: 0 };
        for j in 0..n {
            let col = &a[j * n..(j + 1) * n];
            // The farthest nonzero above and below the diagonal.
            if let Some(i) = col[..j].iter().position(|v| *v != 0.0) {
                band.upper = band.upper.max(j - i);
            }
            if let Some(i) = col[j + 1..].iter().rposition(|v| *v != 0.0) {
                band.lower = band.lower.max(i + 1);
            }
        }
        band
    }

    /// Whether a banded factorisation pays: LU with partial pivoting fills
    /// U up to lower + upper diagonals, so the band (with its fill) must
    /// cover well under half of the matrix.
    pub(crate) fn pays(self, n: usize) -> bool {
        n >= 12 && 4 * (2 * self.lower + self.upper + 1) <= n
    }
}

/// The band recorded by [`lu_factor`] in the spare slots of `piv`, if the
/// factors are banded.
fn recorded_band(piv: &[usize], n: usize) -> Option<Band> {
    if piv.len() >= n + 2 && piv[n + 1] != 0 {
        Some(Band {
            lower: piv[n],
            upper: piv[n + 1] - 1,
        })
    } else {
        None
    }
}

/// LU factorisation with partial pivoting, in place: afterwards `a` holds
/// L (unit lower, below the diagonal) and U, and `piv[k]` is the row swapped
/// with row k at elimination step k.
///
/// When `piv` has two spare slots (length ≥ n + 2) and `a` is banded
/// narrowly enough ([`Band::pays`]), this is [`band_lu_factor`] and the band
/// is recorded in `piv[n]`, `piv[n + 1]`; [`lu_solve`],
/// [`lu_solve_transpose`] and [`lu_det`] read it from there.
pub(crate) fn lu_factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> Result<(), Singular> {
    debug_assert!(a.len() >= n * n && piv.len() >= n);
    if piv.len() >= n + 2 {
        piv[n + 1] = 0;
        if n >= 12 {
            let band = Band::of(a, n);
            if band.pays(n) {
                band_lu_factor(a, n, band, piv)?;
                piv[n] = band.lower;
                piv[n + 1] = band.upper + 1;
                return Ok(());
            }
        }
    }
    small_n!(n, N => dense_lu_factor(a, N, piv), _ => dense_lu_factor(a, n, piv))
}

/// Banded LU with partial pivoting (LAPACK's `dgbtrf`), in place in the
/// dense column-major slice `a` whose nonzeros lie in `band`. Row
/// interchanges are applied only to the columns from the pivot column on,
/// so the multipliers of L stay where they were computed and the solves
/// interleave them with the interchanges ([`band_lu_solve`]). U gets
/// `band.lower + band.upper` superdiagonals (the fill of pivoting), and its
/// diagonal is stored as reciprocals (read by the banded solves and by
/// [`lu_det`] through the recorded band); entries outside the band must be
/// zero on entry.
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
fn band_lu_factor_w(
    a: &mut [f64],
    n: usize,
    kl: usize,
    kv: usize,
    piv: &mut [usize],
) -> Result<(), Singular> {
    debug_assert!(a.len() >= n * n && piv.len() >= n);
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
fn band_lu_solve_w(lu: &[f64], n: usize, kl: usize, kv: usize, piv: &[usize], b: &mut [f64]) {
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
fn band_lu_solve_transpose_w(
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

/// The dense LU of [`lu_factor`] (rows swapped across the whole matrix).
#[inline(always)]
fn dense_lu_factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> Result<(), Singular> {
    for k in 0..n {
        // Pivot: the largest entry of column k on or below the diagonal.
        let mut p = k;
        let mut max = a[k + k * n].abs();
        for i in k + 1..n {
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
            for j in 0..n {
                a.swap(k + j * n, p + j * n);
            }
        }
        let inv = 1.0 / a[k + k * n];
        for i in k + 1..n {
            a[i + k * n] *= inv;
        }
        for j in k + 1..n {
            let akj = a[k + j * n];
            if akj != 0.0 {
                for i in k + 1..n {
                    a[i + j * n] -= a[i + k * n] * akj;
                }
            }
        }
    }
    Ok(())
}

/// Solves A x = b in place (b becomes x) from the factors of [`lu_factor`].
pub(crate) fn lu_solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    if let Some(band) = recorded_band(piv, n) {
        return band_lu_solve(lu, n, band, piv, b);
    }
    small_n!(n, N => dense_lu_solve(lu, N, piv, b), _ => dense_lu_solve(lu, n, piv, b))
}

/// The dense part of [`lu_solve`].
#[inline(always)]
fn dense_lu_solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    for k in 0..n {
        b.swap(k, piv[k]);
    }
    // L y = b (unit diagonal).
    for j in 0..n {
        let bj = b[j];
        if bj != 0.0 {
            for i in j + 1..n {
                b[i] -= lu[i + j * n] * bj;
            }
        }
    }
    // U x = y.
    for j in (0..n).rev() {
        b[j] /= lu[j + j * n];
        let bj = b[j];
        if bj != 0.0 {
            for i in 0..j {
                b[i] -= lu[i + j * n] * bj;
            }
        }
    }
}

/// Solves Aᵀ x = b in place from the factors of [`lu_factor`].
pub(crate) fn lu_solve_transpose(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    if let Some(band) = recorded_band(piv, n) {
        return band_lu_solve_transpose(lu, n, band, piv, b);
    }
    small_n!(n, N => dense_lu_solve_transpose(lu, N, piv, b), _ => dense_lu_solve_transpose(lu, n, piv, b))
}

/// The dense part of [`lu_solve_transpose`].
#[inline(always)]
fn dense_lu_solve_transpose(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    // Aᵀ = Uᵀ Lᵀ P, so solve Uᵀ y = b, Lᵀ w = y, x = Pᵀ w.
    for j in 0..n {
        let mut s = b[j];
        for i in 0..j {
            s -= lu[i + j * n] * b[i];
        }
        b[j] = s / lu[j + j * n];
    }
    for j in (0..n).rev() {
        let mut s = b[j];
        for i in j + 1..n {
            s -= lu[i + j * n] * b[i];
        }
        b[j] = s;
    }
    for k in (0..n).rev() {
        b.swap(k, piv[k]);
    }
}

/// The determinant from the factors of [`lu_factor`].
pub(crate) fn lu_det(lu: &[f64], n: usize, piv: &[usize]) -> f64 {
    // Banded factors keep U's diagonal inverted.
    let banded = recorded_band(piv, n).is_some();
    let mut det = 1.0;
    for k in 0..n {
        det *= if banded {
            1.0 / lu[k + k * n]
        } else {
            lu[k + k * n]
        };
        if piv[k] != k {
            det = -det;
        }
    }
    det
}

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

/// [`inverse_norm1_estimate`] started from the unit vector e_start instead
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

/// Largest absolute entry of a slice (NaN entries are skipped, as by
/// `f64::max`).
///
/// Four running maxima instead of one: a single one chains every entry's
/// `max` on the previous one's latency, and `max` is exact in any order,
/// so the lanes give the same number and vectorise.
#[inline]
pub(crate) fn norm_inf(v: &[f64]) -> f64 {
    let mut lanes = [0.0f64; 4];
    let chunks = v.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for (l, x) in lanes.iter_mut().zip(c) {
            *l = l.max(x.abs());
        }
    }
    for x in rest {
        lanes[0] = lanes[0].max(x.abs());
    }
    lanes[0].max(lanes[1]).max(lanes[2].max(lanes[3]))
}

/// `v.fill(0.0)` for the few entries of a band's column: up to eight
/// stores written out, where `fill` would call `memset` (whose call costs
/// more than the stores in a narrow band, once per column and step).
#[inline(always)]
pub(crate) fn zero_short(v: &mut [f64]) {
    if v.len() > 8 {
        return v.fill(0.0);
    }
    for i in 0..8 {
        if i < v.len() {
            v[i] = 0.0;
        }
    }
}

/// `dst.copy_from_slice(src)` for a band's column, as [`zero_short`].
#[inline(always)]
pub(crate) fn copy_short(dst: &mut [f64], src: &[f64]) {
    if dst.len() > 8 || dst.len() != src.len() {
        return dst.copy_from_slice(src);
    }
    for i in 0..8 {
        if i < dst.len() {
            dst[i] = src[i];
        }
    }
}

/// Whether every entry is finite. (Without short-circuiting: a flag that
/// every entry `and`s into vectorises, and a run's vectors are finite.)
#[inline]
pub(crate) fn all_finite(v: &[f64]) -> bool {
    v.iter().fold(true, |ok, x| ok & x.is_finite())
}

/// Matrix product c = a b of n×n column-major matrices.
pub(crate) fn matmul(a: &[f64], b: &[f64], c: &mut [f64], n: usize) {
    c[..n * n].fill(0.0);
    for j in 0..n {
        for k in 0..n {
            let bkj = b[k + j * n];
            if bkj != 0.0 {
                for i in 0..n {
                    c[i + j * n] += a[i + k * n] * bkj;
                }
            }
        }
    }
}

/// exp(A) of an n×n column-major matrix, by scaling and squaring with a
/// Taylor series summed until its terms stop contributing (to round-off,
/// after scaling ‖A‖₁ ≤ 1/2). `a` is overwritten with exp(A); `t1`, `t2`, `t3`
/// are scratch of n² entries each.
pub(crate) fn expm(a: &mut [f64], n: usize, t1: &mut [f64], t2: &mut [f64], t3: &mut [f64]) {
    let nn = n * n;
    let norm = norm1(a, n);
    let mut s = 0u32;
    if norm > 0.5 {
        s = (norm / 0.5).log2().ceil() as u32;
    }
    let scale = 0.5f64.powi(s as i32);
    for v in a[..nn].iter_mut() {
        *v *= scale;
    }
    // t1 = term, t2 = sum.
    t1[..nn].fill(0.0);
    t2[..nn].fill(0.0);
    for i in 0..n {
        t1[i + i * n] = 1.0;
        t2[i + i * n] = 1.0;
    }
    for k in 1..40 {
        matmul(t1, a, t3, n);
        let inv_k = 1.0 / k as f64;
        let mut term_norm = 0.0f64;
        for i in 0..nn {
            t1[i] = t3[i] * inv_k;
            t2[i] += t1[i];
            term_norm = term_norm.max(t1[i].abs());
        }
        if term_norm <= f64::EPSILON * 1e-3 * norm_inf(&t2[..nn]) {
            break;
        }
    }
    for _ in 0..s {
        matmul(t2, t2, t3, n);
        t2[..nn].copy_from_slice(&t3[..nn]);
    }
    a[..nn].copy_from_slice(&t2[..nn]);
}

#[cfg(test)]
mod tests;
