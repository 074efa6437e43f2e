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

mod band;
mod estimate;
mod expm;
mod lu;
mod vector;

pub(crate) use band::{band_lu_factor, band_lu_solve};

/// [`band_lu_factor`] for a full band of `N` rows known at compile time
/// (the fixed-size steps): the kernel `small_n!` dispatches to, inlined.
#[inline(always)]
pub(crate) fn full_band_lu_factor<const N: usize>(
    a: &mut [f64],
    piv: &mut [usize],
) -> Result<(), Singular> {
    band::band_lu_factor_w(a, N, N - 1, 2 * N - 2, piv)
}

/// [`band_lu_solve`] for the factors of [`full_band_lu_factor`].
#[inline(always)]
pub(crate) fn full_band_lu_solve<const N: usize>(lu: &[f64], piv: &[usize], b: &mut [f64]) {
    band::band_lu_solve_w(lu, N, N - 1, 2 * N - 2, piv, b)
}
#[cfg(test)]
pub(crate) use estimate::inverse_norm1_estimate;
pub(crate) use estimate::inverse_norm1_estimate_from;
pub(crate) use expm::{expm, matmul};
pub(crate) use lu::{
    dense_lu_factor, dense_lu_solve, lu_det, lu_factor, lu_solve, lu_solve_transpose,
};
pub(crate) use vector::{all_finite, norm_inf, zero_short};
#[cfg(test)]
use {
    band::{band_lu_factor_w, band_lu_solve_transpose, band_lu_solve_transpose_w, band_lu_solve_w},
    lu::{dense_lu_solve_transpose, recorded_band},
};

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
    /// cover well under half of the matrix. A diagonal always pays (n
    /// reciprocals, and it tells SHAKE its constraints are decoupled). A
    /// tridiagonal band pays from
    /// three rows on: its kernel (`tridiagonal`) carries the recursion in
    /// registers, O(n) against the dense LU's O(n³) (a 4-link chain's
    /// SHAKE Jacobian and N).
    pub(crate) fn pays(self, n: usize) -> bool {
        if self == (Band { lower: 0, upper: 0 }) {
            return true;
        }
        if self == (Band { lower: 1, upper: 1 }) {
            return n >= 3;
        }
        n >= 12 && 4 * (2 * self.lower + self.upper + 1) <= n
    }
}

#[cfg(test)]
mod tests;
