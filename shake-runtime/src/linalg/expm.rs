//! The matrix exponential of the quadratic fibre flows (`fibre::quadratic`).

use super::estimate::norm1;
use super::vector::norm_inf;

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
