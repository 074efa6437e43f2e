//! The closed-form velocity stage of a rigid triangle: RATTLE's
//! projection, and its judgement by the hidden constraint.
//!
//! Velocity stage: p1 = p − G(x1)ᵀ μ with N μ = G(x1) W p, N = G W Gᵀ; for
//! three bonds e_k = x1_i − x1_j, N/4 has entries Σ_c w_c (±e_k)·(±e_l)
//! over the particles c the bonds share, inverted by its adjugate.

use super::real::*;
use super::PAIRS;
use crate::tolerance::{relative_dot_after, worse, HIDDEN_LIMIT};

/// What [`project`] gives for a batch: the projected momenta, N's
/// determinant (> 0 when N is positive definite), and per pair the bond
/// e_k, the hidden constraint e_k · (v_i − v_j) after the projection and
/// its scale |∇g_k|² |v|² (up to the common factor 4).
pub(super) struct Projected<T> {
    pub(super) p: [V3<T>; 3],
    det: T,
    e: [V3<T>; 3],
    dots: V3<T>,
    aa: V3<T>,
    bb: V3<T>,
}

/// RATTLE's projection of a batch's momenta `p` (local order) at positions
/// `x`: p ← p − G(x)ᵀ μ with G(x) W p = 0, the 3×3 N inverted by its
/// adjugate. [`Projected::judge`] then says, per lane, how well.
#[inline(always)]
pub(super) fn project<T: Real>(x: &[V3<T>; 3], w: V3<T>, p: &[V3<T>; 3]) -> Projected<T> {
    let e = [sub(x[0], x[1]), sub(x[0], x[2]), sub(x[1], x[2])];
    let v = [scale(w[0], p[0]), scale(w[1], p[1]), scale(w[2], p[2])];
    let r = [
        dot(e[0], sub(v[0], v[1])),
        dot(e[1], sub(v[0], v[2])),
        dot(e[2], sub(v[1], v[2])),
    ];
    let l2 = [dot(e[0], e[0]), dot(e[1], e[1]), dot(e[2], e[2])];
    // N/4: diagonal (w_i + w_j)|e_k|²; pairs (0,1),(0,2) share 0 (signs
    // +,+), (0,1),(1,2) share 1 (−,+), (0,2),(1,2) share 2 (−,−).
    let n00 = (w[0] + w[1]) * l2[0];
    let n11 = (w[0] + w[2]) * l2[1];
    let n22 = (w[1] + w[2]) * l2[2];
    let n01 = w[0] * dot(e[0], e[1]);
    let n02 = -w[1] * dot(e[0], e[2]);
    let n12 = w[2] * dot(e[1], e[2]);
    let c00 = n11 * n22 - n12 * n12;
    let c01 = n02 * n12 - n01 * n22;
    let c02 = n01 * n12 - n02 * n11;
    let c11 = n00 * n22 - n02 * n02;
    let c12 = n01 * n02 - n00 * n12;
    let c22 = n00 * n11 - n01 * n01;
    let det = n00 * c00 + n01 * c01 + n02 * c02;
    let inv = T::splat(1.0) / det;
    let mu = [
        (c00 * r[0] + c01 * r[1] + c02 * r[2]) * inv,
        (c01 * r[0] + c11 * r[1] + c12 * r[2]) * inv,
        (c02 * r[0] + c12 * r[1] + c22 * r[2]) * inv,
    ];
    let mut out = *p;
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        for c in 0..3 {
            out[i][c] = out[i][c] - mu[k] * e[k][c];
            out[j][c] = out[j][c] + mu[k] * e[k][c];
        }
    }
    let mut dots = [T::splat(0.0); 3];
    let mut aa = dots;
    let mut bb = dots;
    for (k, &(i, j)) in PAIRS.iter().enumerate() {
        let (vi, vj) = (scale(w[i], out[i]), scale(w[j], out[j]));
        dots[k] = dot(e[k], sub(vi, vj));
        aa[k] = T::splat(2.0) * l2[k];
        bb[k] = dot(vi, vi) + dot(vj, vj);
    }
    Projected {
        p: out,
        det,
        e,
        dots,
        aa,
        bb,
    }
}

impl<T: Real> Projected<T> {
    /// Lane l's largest relative hidden residual after the projection and
    /// its pair, relative to |∇g_k| · the velocity of the pair after it,
    /// or if that fails before it (`relative_dot_after`), as the Newton
    /// kernels judge them; `None` where N is not positive definite (or
    /// NaN). `w` and `before` are the inverse masses and the momenta the
    /// projection started from.
    #[inline(always)]
    pub(super) fn judge(&self, l: usize, w: &V3<T>, before: &[V3<T>; 3]) -> Option<(f64, usize)> {
        let det = self.det.lane(l);
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let (mut worst2, mut at) = (0.0f64, 0);
        for k in 0..3 {
            let (d, aa, bb) = (self.dots[k].lane(l), self.aa[k].lane(l), self.bb[k].lane(l));
            let ab = aa * bb;
            let mut rel2 = if aa > 1e-200 && bb > 1e-200 && ab < f64::INFINITY {
                d * d / ab
            } else {
                f64::NAN
            };
            if !(rel2 <= HIDDEN_LIMIT * HIDDEN_LIMIT) {
                rel2 = self.hidden_after(l, k, w, before).powi(2);
            }
            if worse(rel2, worst2) {
                (worst2, at) = (rel2, k);
            }
        }
        Some((worst2.sqrt(), at))
    }

    /// The lanes that [`judge`](Self::judge) passes on the simple ratio
    /// alone (N positive definite, every pair's d² / (aa bb) in range and
    /// within `HIDDEN_LIMIT`²), and on them the largest squared ratio:
    /// judge's worst, squared.
    #[inline(always)]
    pub(super) fn plain(&self) -> (T::Mask, T) {
        let zero = T::splat(0.0);
        let (tiny, lim2) = (T::splat(1e-200), T::splat(HIDDEN_LIMIT * HIDDEN_LIMIT));
        let mut ok = zero.lt(self.det) & self.det.finite();
        let mut worst2 = zero;
        for k in 0..3 {
            let (d, aa, bb) = (self.dots[k], self.aa[k], self.bb[k]);
            let ab = aa * bb;
            let rel2 = d * d / ab;
            ok = ok & tiny.lt(aa) & tiny.lt(bb) & ab.lt(T::splat(f64::INFINITY)) & rel2.le(lim2);
            worst2 = worst2.max(rel2);
        }
        (ok, worst2)
    }

    /// Lane l's hidden residual of pair k judged in full
    /// (`relative_dot_after`: its scaled form outside the range of safe
    /// squares, and the velocity before the projection as the scale when
    /// the one after it is all round-off).
    #[cold]
    fn hidden_after(&self, l: usize, k: usize, w: &V3<T>, before: &[V3<T>; 3]) -> f64 {
        let (i, j) = PAIRS[k];
        let e = self.e[k].map(|v| v.lane(l));
        let (wi, wj) = (w[i].lane(l), w[j].lane(l));
        let vi = self.p[i].map(|v| wi * v.lane(l));
        let vj = self.p[j].map(|v| wj * v.lane(l));
        let g = [e[0], e[1], e[2], -e[0], -e[1], -e[2]];
        let v = [vi[0], vi[1], vi[2], vj[0], vj[1], vj[2]];
        let rel = relative_dot_after(&g, &v, 0.0);
        if rel <= HIDDEN_LIMIT {
            return rel;
        }
        let bi = before[i].map(|v| wi * v.lane(l));
        let bj = before[j].map(|v| wj * v.lane(l));
        relative_dot_after(&g, &v, dot(bi, bi) + dot(bj, bj))
    }
}
