//! Small dense solvers for one cluster's c×c matrices (c ≤ 12): LU with
//! partial pivoting for the nonsymmetric Newton matrix, Cholesky for the
//! symmetric positive definite N, on stack arrays.

/// The largest matrix order these solvers take: their pivots and
/// reciprocal diagonals live on the stack.
pub(crate) const CAPACITY: usize = 12;

/// LU factorisation with partial pivoting of an n×n row-major matrix, in
/// place. False when a pivot is zero or not finite.
#[inline(always)]
pub(super) fn lu_factor(n: usize, a: &mut [f64], piv: &mut [usize], dinv: &mut [f64]) -> bool {
    for k in 0..n {
        let mut p = k;
        let mut best = a[k * n + k].abs();
        for i in k + 1..n {
            let v = a[i * n + k].abs();
            if v > best {
                best = v;
                p = i;
            }
        }
        piv[k] = p;
        if !(best > 0.0 && best.is_finite()) {
            return false;
        }
        if p != k {
            for c in 0..n {
                a.swap(k * n + c, p * n + c);
            }
        }
        let inv = 1.0 / a[k * n + k];
        dinv[k] = inv;
        for i in k + 1..n {
            let f = a[i * n + k] * inv;
            a[i * n + k] = f;
            for c in k + 1..n {
                a[i * n + c] -= f * a[k * n + c];
            }
        }
    }
    true
}

/// b ← A⁻¹ b with the factors of [`lu_factor`] (divisions replaced by the
/// stored inverse pivots: they sat on the critical path).
#[inline(always)]
pub(super) fn lu_solve(n: usize, a: &[f64], piv: &[usize], dinv: &[f64], b: &mut [f64]) {
    // The factorisation swapped whole rows (multipliers included), so
    // P A = L U with P all the swaps in order: apply P first.
    for k in 0..n {
        if piv[k] != k {
            b.swap(k, piv[k]);
        }
    }
    for k in 0..n {
        let bk = b[k];
        for i in k + 1..n {
            b[i] -= a[i * n + k] * bk;
        }
    }
    for k in (0..n).rev() {
        let mut s = b[k];
        for c in k + 1..n {
            s -= a[k * n + c] * b[c];
        }
        b[k] = s * dinv[k];
    }
}

/// Solves N μ = b in place for symmetric positive definite N (row-major,
/// lower triangle used) by Cholesky. False when N is not numerically
/// positive definite.
#[inline(always)]
pub(super) fn cholesky_solve(n: usize, a: &mut [f64], b: &mut [f64]) -> bool {
    let mut dinv = [0.0; CAPACITY];
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        let inv = 1.0 / d;
        dinv[j] = inv;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s * inv;
        }
    }
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= a[i * n + k] * b[k];
        }
        b[i] = s * dinv[i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= a[k * n + i] * b[k];
        }
        b[i] = s * dinv[i];
    }
    true
}

/// For n ≤ 3: a ← a⁻¹ (row-major, in place) by the adjugate: one division
/// and independent products, where LU or Cholesky would chain n divisions
/// or square roots (the latency that bounds a water's step). False when
/// det a is zero or not finite, or (with `spd`) not positive.
#[inline(always)]
pub(super) fn small_inverse(n: usize, a: &mut [f64], spd: bool) -> bool {
    let ok = |det: f64| det.is_finite() && if spd { det > 0.0 } else { det != 0.0 };
    match n {
        1 => {
            let det = a[0];
            if !ok(det) {
                return false;
            }
            a[0] = 1.0 / det;
        }
        2 => {
            let (p, q, r, t) = (a[0], a[1], a[2], a[3]);
            let det = p * t - q * r;
            if !ok(det) {
                return false;
            }
            let i = 1.0 / det;
            a[0] = t * i;
            a[1] = -q * i;
            a[2] = -r * i;
            a[3] = p * i;
        }
        _ => {
            let m = [a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8]];
            let c00 = m[4] * m[8] - m[5] * m[7];
            let c01 = m[5] * m[6] - m[3] * m[8];
            let c02 = m[3] * m[7] - m[4] * m[6];
            let det = m[0] * c00 + m[1] * c01 + m[2] * c02;
            if !ok(det) {
                return false;
            }
            let i = 1.0 / det;
            a[0] = c00 * i;
            a[1] = (m[2] * m[7] - m[1] * m[8]) * i;
            a[2] = (m[1] * m[5] - m[2] * m[4]) * i;
            a[3] = c01 * i;
            a[4] = (m[0] * m[8] - m[2] * m[6]) * i;
            a[5] = (m[2] * m[3] - m[0] * m[5]) * i;
            a[6] = c02 * i;
            a[7] = (m[1] * m[6] - m[0] * m[7]) * i;
            a[8] = (m[0] * m[4] - m[1] * m[3]) * i;
        }
    }
    true
}

/// b ← a b for a small n×n row-major a.
#[inline(always)]
pub(super) fn small_apply(n: usize, a: &[f64], b: &mut [f64]) {
    let mut out = [0.0; 3];
    for i in 0..n {
        let mut s = 0.0;
        for j in 0..n {
            s += a[i * n + j] * b[j];
        }
        out[i] = s;
    }
    b[..n].copy_from_slice(&out[..n]);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A nonsymmetric matrix that needs pivoting, and an SPD one: each
    /// small solver against the residual of the system it solved.
    #[test]
    fn small_solvers_solve() {
        let a0 = [
            0.0, 2.0, 1.0, 3.0, //
            1.0, 1.0, 0.0, 2.0, //
            4.0, 0.5, 2.0, 1.0, //
            1.0, 3.0, 1.0, 0.0,
        ];
        let b0 = [1.0, -2.0, 0.5, 3.0];
        for n in 1..=4 {
            let mut a = [0.0; 16];
            for i in 0..n {
                for j in 0..n {
                    // Shift the diagonal for n = 1 (a00 = 0).
                    a[i * n + j] = a0[i * 4 + j] + if i == j { 0.25 } else { 0.0 };
                }
            }
            let orig = a;
            let mut x = b0;
            let (mut piv, mut dinv) = ([0; 4], [0.0; 4]);
            assert!(lu_factor(n, &mut a[..n * n], &mut piv, &mut dinv));
            lu_solve(n, &a[..n * n], &piv, &dinv, &mut x[..n]);
            let mut y = b0;
            let mut inv = orig;
            if n <= 3 {
                assert!(small_inverse(n, &mut inv[..n * n], false));
                small_apply(n, &inv[..n * n], &mut y[..n]);
            }
            for i in 0..n {
                let r: f64 = (0..n).map(|j| orig[i * n + j] * x[j]).sum::<f64>() - b0[i];
                assert!(r.abs() < 1e-14, "LU n={n} row {i}: {r:e}");
                if n <= 3 {
                    assert!((x[i] - y[i]).abs() < 1e-14, "inverse n={n}");
                }
            }
        }
        // SPD: Cholesky.
        let mut s = [4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0];
        let orig = s;
        let mut x = [1.0, 2.0, 3.0];
        assert!(cholesky_solve(3, &mut s, &mut x));
        for i in 0..3 {
            let r: f64 = (0..3).map(|j| orig[i * 3 + j] * x[j]).sum::<f64>() - [1.0, 2.0, 3.0][i];
            assert!(r.abs() < 1e-14);
        }
    }
}
