//! The LU of a Newton matrix whose band is not known in advance: dense
//! with partial pivoting (LAPACK's `dgetrf`/`dgetrs`, rows swapped across
//! the whole matrix), or banded when the matrix turns out to be and the
//! band pays, recorded in the pivot vector's spare slots.

use super::band::{band_lu_factor, band_lu_solve, band_lu_solve_transpose};
use super::{Band, Singular};

/// The band recorded by [`lu_factor`] in the spare slots of `piv`, if the
/// factors are banded.
pub(super) fn recorded_band(piv: &[usize], n: usize) -> Option<Band> {
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
/// When `piv` has two spare slots (length ≥ n + 2), n ≥ 12 and `a` is
/// banded narrowly enough ([`Band::pays`]), this is [`band_lu_factor`] and
/// the band is recorded in `piv[n]`, `piv[n + 1]`. (Only from 12 rows: the
/// band is found here by scanning the matrix. The bands of N and of
/// SHAKE's Jacobian are known from the system's structure, and their
/// callers use them where [`Band::pays`] says so: a tridiagonal band from
/// 3 rows, any other from 12; SHAKE's Jacobian below 12 rows only on the
/// classical path.) [`lu_solve`],
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

/// The dense LU of [`lu_factor`] (rows swapped across the whole matrix).
#[inline(always)]
pub(crate) fn dense_lu_factor(a: &mut [f64], n: usize, piv: &mut [usize]) -> Result<(), Singular> {
    // (Exact lengths: with n a constant the indices are proved in bounds.)
    let (a, piv) = (&mut a[..n * n], &mut piv[..n]);
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
pub(crate) fn dense_lu_solve(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
    let (lu, piv, b) = (&lu[..n * n], &piv[..n], &mut b[..n]);
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
pub(super) fn dense_lu_solve_transpose(lu: &[f64], n: usize, piv: &[usize], b: &mut [f64]) {
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
