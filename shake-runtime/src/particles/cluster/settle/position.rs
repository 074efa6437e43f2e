//! The closed-form position stage of a rigid triangle (SETTLE), and the
//! residuals that judge its answer.
//!
//! Position stage. SHAKE (the paper's Section 5.1.3) asks for x1 =
//! x̃ − W G(x0)ᵀ ν with g(x1) = 0: each particle moves by m_a Δ_a = F_a,
//! F_a = −Σ_k ν_k ∇_a g_k(x0), pair forces along the old bonds x0_a − x0_b.
//! For a triangle that is not collinear at x0, these forces are exactly
//! the forces F in the old plane with Σ_a F_a = 0 and Σ_a x0_a × F_a = 0:
//! pair forces along the bonds have no net force and no torque about the
//! old positions; conversely the in-plane forces of 3 particles are 6
//! numbers, the two conditions take 3, and the 3 pair forces span what is
//! left (their span is 3-dimensional when x0 is not collinear). And
//! g(x1) = 0 says x1 is the reference triangle moved rigidly: x1_a = c +
//! R y_a, with y_a the triangle built from the d_ab about its centre of
//! mass. So SHAKE's equations are equivalent to
//!
//! - Σ_a m_a Δ_a = 0: the centre of mass of x1 is x̃'s, c = c̃;
//! - Δ_a ⊥ n0 (n0 the old triangle's normal): the heights of R y_a above
//!   the old plane are those of x̃_a − c̃;
//! - Σ_a (x0_a − c0) × m_a Δ_a = 0 (along n0, the one component left).
//!
//! This is SETTLE's construction, so SETTLE solves the SHAKE equations
//! exactly (not only as a first iterate): the same x1 and ν as Newton, to
//! round-off. With the old frame (e1 along the old bond 0→1, e3 = n0) and
//! R = R_z(θ) R_x(φ) R_y(ψ), the heights of R y_a are
//! Y2_a sin φ − Y1_a sin ψ cos φ, linear in (sin φ, sin ψ cos φ) and equal
//! to the heights of x̃ (three equations of rank two: both sides have zero
//! mass-weighted mean); the torque condition is then A cos θ + B sin θ = C
//! with A, B, C sums of 2-D cross and dot products of the old, tilted and
//! unconstrained in-plane coordinates. The branch taken is the one through
//! the identity (cos φ, cos ψ > 0, θ near 0 when x̃ is near x0), the one
//! Newton from x̃ converges to for the steps a simulation takes. At large
//! steps of light, flat triangles it can be another root of the same
//! equations: an answer that moves a particle by more than an eighth of
//! the shortest length from x̃ ([`near_branch`]) goes to Newton, and so
//! does a triangle whose masses lie more than [`MAX_MASS_RATIO`] apart
//! (the placement loses ~ε √(m_max / m_min) |x| out of the old plane).
//!
//! Where the closed form has no answer (an old triangle collinear to
//! working precision, a step so large that the heights or the torque
//! cannot be met, a reference that is not a strict triangle, NaN) or its
//! answer misses the tolerance, the cluster goes to the Newton kernel,
//! which solves it on another branch or returns its typed failure: the
//! failures are Newton's own.

use super::real::*;
use super::PAIRS;
use crate::tolerance::{roundoff_floor, worse};

/// The reference triangle of given inverse masses and squared lengths,
/// which every molecule of a kind shares: built once per kind, not per
/// molecule and step.
#[derive(Clone, Copy, Debug)]
pub(super) struct Shape {
    /// The inverse masses and squared lengths it was built for.
    key: [u64; 6],
    pub(super) w: V3,
    pub(super) d2: V3,
    /// Masses and 1 / their sum.
    m: V3,
    inv_mt: f64,
    /// Body coordinates about the centre of mass: 0 at the origin, 1 on
    /// the first axis, 2 above it, then shifted.
    y: [[f64; 2]; 3],
    /// The mass-weighted normal equations of the heights, Σ m Y1²,
    /// Σ m Y2², Σ m Y1 Y2, and 1 / their determinant.
    p11: f64,
    p22: f64,
    p12: f64,
    inv_det: f64,
    /// A strict triangle with finite masses (else no closed form).
    pub(super) ok: bool,
    /// The smallest squared length ([`near_branch`]).
    pub(super) min_d2: f64,
}

/// The largest ratio of two masses of a triangle taken in closed form. The
/// rigid placement loses about ε √(m_max / m_min) of |x| out of the old
/// plane (Newton: none); at 10⁴ that is ~100 ε, beyond it the triangle
/// goes to the Newton kernel. Water: 16.
const MAX_MASS_RATIO: f64 = 1e4;

/// The lanes whose x1 is within an eighth of the shortest length of the
/// unconstrained x̃ for every particle. The closed form takes the branch of
/// the torque equation nearest θ = 0, which at large steps of light,
/// flat triangles can be another SHAKE root than the one Newton from x̃
/// reaches (both solve the equations); within this bound, the correction
/// a simulation's step asks for (h²-small), the branch is the one through
/// the identity. Beyond it the triangle goes to the Newton kernel.
#[inline(always)]
pub(super) fn near_branch<T: Real>(x1: &[V3<T>; 3], xt: &[V3<T>; 3], min_d2: f64) -> T::Mask {
    // (Functions, not closures: a closure is not inlined into the kernel
    // compiled for AVX.)
    #[inline(always)]
    fn near<T: Real>(x1: V3<T>, xt: V3<T>, lim: T) -> T::Mask {
        let d = sub(x1, xt);
        dot(d, d).le(lim)
    }
    let lim = T::splat(min_d2 / 64.0);
    near(x1[0], xt[0], lim) & near(x1[1], xt[1], lim) & near(x1[2], xt[2], lim)
}

impl Shape {
    fn key(w: V3, d2: V3) -> [u64; 6] {
        [w[0], w[1], w[2], d2[0], d2[1], d2[2]].map(f64::to_bits)
    }

    /// The shape of inverse masses `w` and squared lengths `d2`.
    pub(super) fn new(w: V3, d2: V3) -> Shape {
        let m = [1.0 / w[0], 1.0 / w[1], 1.0 / w[2]];
        let inv_mt = 1.0 / (m[0] + m[1] + m[2]);
        let d01 = d2[0].sqrt();
        let px = (d2[0] + d2[1] - d2[2]) / (2.0 * d01);
        let h2 = d2[1] - px * px;
        let py = h2.sqrt();
        let (gx, gy) = ((m[1] * d01 + m[2] * px) * inv_mt, m[2] * py * inv_mt);
        let y = [[-gx, -gy], [d01 - gx, -gy], [px - gx, py - gy]];
        let (mut p11, mut p22, mut p12) = (0.0, 0.0, 0.0);
        for i in 0..3 {
            p11 += m[i] * y[i][0] * y[i][0];
            p22 += m[i] * y[i][1] * y[i][1];
            p12 += m[i] * y[i][0] * y[i][1];
        }
        let inv_det = 1.0 / (p11 * p22 - p12 * p12);
        let finite = m.iter().chain(y.iter().flatten()).all(|v| v.is_finite());
        Shape {
            key: Shape::key(w, d2),
            w,
            d2,
            m,
            inv_mt,
            y,
            p11,
            p22,
            p12,
            inv_det,
            ok: h2 > 0.0
                && finite
                && inv_det.is_finite()
                && inv_det > 0.0
                && m.iter().fold(0.0f64, |a, &v| a.max(v))
                    <= MAX_MASS_RATIO * m.iter().fold(f64::INFINITY, |a, &v| a.min(v)),
            min_d2: d2[0].min(d2[1]).min(d2[2]),
        }
    }

    /// Whether this is the shape of `w` and `d2`.
    #[inline(always)]
    pub(super) fn is(&self, w: V3, d2: V3) -> bool {
        // (Element by element: `==` on the arrays became a call to memcmp.)
        let k = Shape::key(w, d2);
        let mut same = true;
        for i in 0..6 {
            same &= self.key[i] == k[i];
        }
        same
    }
}

/// What [`solve`] gives for a batch: x1 and the multipliers ν of the
/// pairs, and the numbers whose signs say on which lanes the closed form
/// has an answer ([`Solution::valid`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Solution<T> {
    pub(super) x1: [V3<T>; 3],
    pub(super) nu: V3<T>,
    /// |n0|² − 10⁻²⁴ |r01|² |r02|² and |n0|²: the old triangle is not
    /// collinear (> 0) and finite.
    flat: T,
    nn: T,
    /// cos² φ, cos² ψ (> 0) and 1 − (C/r)² (≥ 0): the heights and the
    /// torque can be met.
    cos_phi2: T,
    cos_psi2: T,
    s2c: T,
}

impl<T: Real> Solution<T> {
    /// The lanes with an answer: every condition holds and x1 and ν are
    /// finite (NaN fails every comparison).
    #[inline(always)]
    pub(super) fn valid(&self) -> T::Mask {
        let zero = T::splat(0.0);
        let mut ok = zero.lt(self.flat)
            & self.nn.finite()
            & zero.lt(self.cos_phi2)
            & zero.lt(self.cos_psi2)
            & zero.le(self.s2c);
        for v in self.nu.iter().chain(self.x1.iter().flatten()) {
            ok = ok & v.finite();
        }
        ok
    }
}

/// SHAKE's x1 and ν in closed form on every lane (see the module's doc),
/// for triangles of one `shape`, old positions `x0`, unconstrained `xt`
/// (local order). Straight-line: a lane without an answer is flagged in
/// the [`Solution`], not branched on.
#[inline(always)]
pub(super) fn solve<T: Real>(shape: &Shape, x0: &[V3<T>; 3], xt: &[V3<T>; 3]) -> Solution<T> {
    // (Arrays written out: `map` here stayed a call.)
    let m = [
        T::splat(shape.m[0]),
        T::splat(shape.m[1]),
        T::splat(shape.m[2]),
    ];
    let inv_mt = T::splat(shape.inv_mt);
    let sy = |i: usize| [T::splat(shape.y[i][0]), T::splat(shape.y[i][1])];
    let y = [sy(0), sy(1), sy(2)];
    let one = T::splat(1.0);
    let two = T::splat(2.0);
    // The old frame, from the old bonds (differences, never absolute
    // positions: a box far from the origin keeps its precision).
    let r01 = sub(x0[1], x0[0]);
    let r02 = sub(x0[2], x0[0]);
    let n = cross(r01, r02);
    let (l01, nn) = (dot(r01, r01), dot(n, n));
    // A collinear old triangle: G(x0) has rank 2, the pair forces span too
    // little (Newton's matrix is singular there too).
    let flat = nn - T::splat(1e-24) * l01 * dot(r02, r02);
    let e1 = scale(one / l01.sqrt(), r01);
    let e3 = scale(one / nn.sqrt(), n);
    let e2 = cross(e3, e1);
    // Old in-plane coordinates about the old centre of mass, and x̃ about
    // its own in the old frame (t[i][2]: the heights).
    let zero = T::splat(0.0);
    let rel0 = [[zero; 3], r01, r02];
    let relt = [[zero; 3], sub(xt[1], xt[0]), sub(xt[2], xt[0])];
    let (mut cm0, mut cmt) = ([zero; 3], [zero; 3]);
    for k in 0..3 {
        cm0[k] = (m[1] * rel0[1][k] + m[2] * rel0[2][k]) * inv_mt;
        cmt[k] = (m[1] * relt[1][k] + m[2] * relt[2][k]) * inv_mt;
    }
    let mut a = [[zero; 2]; 3];
    let mut t = [[zero; 3]; 3];
    for i in 0..3 {
        let v = sub(rel0[i], cm0);
        a[i] = [dot(v, e1), dot(v, e2)];
        let v = sub(relt[i], cmt);
        t[i] = [dot(v, e1), dot(v, e2), dot(v, e3)];
    }
    // Heights: Y2 sin φ − Y1 (sin ψ cos φ) = t_z, by the mass-weighted
    // normal equations (exact: the system is consistent).
    let (mut b1, mut b2) = (zero, zero);
    for i in 0..3 {
        b1 = b1 + m[i] * y[i][0] * t[i][2];
        b2 = b2 + m[i] * y[i][1] * t[i][2];
    }
    let (p11, p22, p12) = (
        T::splat(shape.p11),
        T::splat(shape.p22),
        T::splat(shape.p12),
    );
    let inv_det = T::splat(shape.inv_det);
    let sin_phi = (p11 * b2 - p12 * b1) * inv_det;
    let sin_psi_cos_phi = (p12 * b2 - p22 * b1) * inv_det;
    let cos_phi2 = one - sin_phi * sin_phi;
    let cos_phi = cos_phi2.sqrt();
    let sin_psi = sin_psi_cos_phi / cos_phi;
    let cos_psi2 = one - sin_psi * sin_psi;
    let cos_psi = cos_psi2.sqrt();
    // The tilted triangle R_x(φ) R_y(ψ) y, and the torque about the old
    // positions: A cos θ + B sin θ = C.
    let mut b = [[zero; 3]; 3];
    let (mut aa, mut bb, mut cc) = (zero, zero, zero);
    for i in 0..3 {
        let (y1, y2) = (y[i][0], y[i][1]);
        b[i] = [
            y1 * cos_psi,
            y2 * cos_phi + y1 * sin_psi * sin_phi,
            y2 * sin_phi - y1 * sin_psi * cos_phi,
        ];
        let (ai, bi, ti) = (a[i], b[i], t[i]);
        aa = aa + m[i] * (ai[0] * bi[1] - ai[1] * bi[0]);
        bb = bb + m[i] * (ai[0] * bi[0] + ai[1] * bi[1]);
        cc = cc + m[i] * (ai[0] * ti[1] - ai[1] * ti[0]);
    }
    let inv_r = one / (aa * aa + bb * bb).sqrt();
    let c = cc * inv_r;
    let s2c = one - c * c;
    let s = s2c.sqrt();
    // θ = α − arccos(C/r), α = atan2(B, A): the root near 0.
    let cos_t = (aa * c + bb * s) * inv_r;
    let sin_t = (bb * c - aa * s) * inv_r;
    // Δ in the old frame, then x1 = x̃ + Δ.
    let mut x1 = [[zero; 3]; 3];
    let mut dl = [[zero; 3]; 3];
    for i in 0..3 {
        let d = [
            b[i][0] * cos_t - b[i][1] * sin_t - t[i][0],
            b[i][0] * sin_t + b[i][1] * cos_t - t[i][1],
            b[i][2] - t[i][2],
        ];
        dl[i] = d;
        for k in 0..3 {
            x1[i][k] = xt[i][k] + (d[0] * e1[k] + d[1] * e2[k] + d[2] * e3[k]);
        }
    }
    // ν from m_a Δ_a = −2 Σ_k ν_k (x0_a − x0_b) in the plane: particle 0
    // gives the pairs (0,1), (0,2); particle 1 then (1,2).
    let u01 = [a[0][0] - a[1][0], a[0][1] - a[1][1]];
    let u02 = [a[0][0] - a[2][0], a[0][1] - a[2][1]];
    let u12 = [a[1][0] - a[2][0], a[1][1] - a[2][1]];
    let f0 = [m[0] * dl[0][0], m[0] * dl[0][1]];
    let inv_k0 = T::splat(0.5) / cross2(u01, u02);
    let nu01 = -cross2(f0, u02) * inv_k0;
    let nu02 = -cross2(u01, f0) * inv_k0;
    // F1 + 2 ν01 u10 = −2 ν12 u12, u10 = −u01.
    let f1r = [
        m[1] * dl[1][0] - two * nu01 * u01[0],
        m[1] * dl[1][1] - two * nu01 * u01[1],
    ];
    let nu12 = -(f1r[0] * u12[0] + f1r[1] * u12[1]) / (two * (u12[0] * u12[0] + u12[1] * u12[1]));
    Solution {
        x1,
        nu: [nu01, nu02, nu12],
        flat,
        nn,
        cos_phi2,
        cos_psi2,
        s2c,
    }
}

/// The relative residual |g_k(x)| / (|∇g_k| · extent_k) of each pair of a
/// triangle at x (`tolerance::inverse_scale`: for a distance, |∇g|² =
/// 8|e|² and extent² = |e|²/2, so the scale is 2|e|²). NaN, or ∞ for a
/// collapsed pair, fails every tolerance.
#[inline(always)]
pub(super) fn residuals<T: Real>(x: &[V3<T>; 3], d2: V3) -> V3<T> {
    #[inline(always)]
    fn r<T: Real>(a: V3<T>, b: V3<T>, d2: f64) -> T {
        let e = sub(a, b);
        let l2 = dot(e, e);
        (l2 - T::splat(d2)).abs() / (T::splat(2.0) * l2)
    }
    [
        r(x[0], x[1], d2[0]),
        r(x[0], x[2], d2[1]),
        r(x[1], x[2], d2[2]),
    ]
}

/// The lanes on which some pair's [`residuals`] at x is certainly above
/// `thr` (> 0), decided by a product instead of the division: with
/// a = |l² − d²| and b = 2l² rounded as there, fl(c b) < a for c =
/// fl(thr (1 + 2⁻⁴⁰)). Then b is finite (c·∞ = ∞ is no smaller), a >
/// c b (1 − ε) (or a > c b outright where c b is subnormal: a is a number
/// above fl(c b)), and the residual fl(a / b) ≥ (a / b)(1 − ε) > thr (1 +
/// 2⁻⁴⁰)(1 − ε)³ > thr. A lane this misses (within 2⁻⁴⁰ of `thr`, NaN) is
/// left to the per-lane judgement on the residuals themselves.
#[inline(always)]
pub(super) fn beyond<T: Real>(x: &[V3<T>; 3], d2: V3, thr: f64) -> T::Mask {
    #[inline(always)]
    fn b<T: Real>(a: V3<T>, b: V3<T>, d2: f64, c: T) -> T::Mask {
        let e = sub(a, b);
        let l2 = dot(e, e);
        (c * (T::splat(2.0) * l2)).lt((l2 - T::splat(d2)).abs())
    }
    let c = T::splat(thr * (1.0 + 4096.0 * f64::EPSILON));
    b(x[0], x[1], d2[0], c) | b(x[0], x[2], d2[1], c) | b(x[1], x[2], d2[2], c)
}

/// The worst of lane l's [`residuals`], and its pair.
#[inline(always)]
pub(super) fn worst_of<T: Real>(r: &V3<T>, l: usize) -> (f64, usize) {
    let (mut worst, mut at) = (0.0f64, 0);
    for (k, r) in r.iter().enumerate() {
        if worse(r.lane(l), worst) {
            (worst, at) = (r.lane(l), k);
        }
    }
    (worst, at)
}

/// The largest of each lane's [`residuals`], on a lane none of which is
/// NaN ([`worst_of`]'s, there).
#[inline(always)]
pub(super) fn worst<T: Real>(r: &V3<T>) -> T {
    r[0].max(r[1]).max(r[2])
}

/// Whether every pair of lane l is within `tol` or the round-off floor of
/// its two particles' coordinates (`tolerance::roundoff_floor`): far from
/// the origin the coordinates cannot resolve a bond to `tol`, and the
/// closed form's answer is then as good as f64 holds it.
#[cold]
pub(super) fn at_roundoff<T: Real>(x: &[V3<T>; 3], r: &V3<T>, l: usize, tol: f64) -> bool {
    PAIRS.iter().enumerate().all(|(k, &(i, j))| {
        let (mut n2, mut e2) = (0.0, 0.0);
        for c in 0..3 {
            let (a, b) = (x[i][c].lane(l), x[j][c].lane(l));
            n2 += a * a + b * b;
            e2 += 0.5 * (a - b) * (a - b);
        }
        r[k].lane(l) <= tol.max(roundoff_floor(n2, e2))
    })
}
