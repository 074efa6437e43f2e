//! The closed-form SHAKE and RATTLE steps of a rigid triangle: three
//! distance constraints g = |x_a − x_b|² − d_ab² among three particles in
//! R³, any lengths (a strict triangle) and any masses. The analytic
//! position solve is SETTLE's (Miyamoto & Kollman, J. Comput. Chem. 13,
//! 952 (1992)), written for a general triangle; the velocity solve is the
//! RATTLE projection with its 3×3 matrix inverted in closed form.
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
//!
//! Velocity stage: p1 = p − G(x1)ᵀ μ with N μ = G(x1) W p, N = G W Gᵀ; for
//! three bonds e_k = x1_i − x1_j, N/4 has entries Σ_c w_c (±e_k)·(±e_l)
//! over the particles c the bonds share, inverted by its adjugate.
//!
//! Both stages are straight-line code (a triangle without an answer is
//! flagged, not branched on), written once over [`Real`]: one triangle
//! (`f64`), or [`LANES`] consecutive triangles of one shape side by side
//! ([`Lanes`]), each lane bit for bit the triangle solved alone, so that
//! the square roots and divisions of several molecules overlap.

use super::*;
use crate::tolerance::{relative_dot_after, roundoff_floor, worse, HIDDEN_LIMIT, ROUNDOFF_CAP};
use std::ops::{Add, Div, Mul, Neg, Sub};

/// The pairs of local particles of a triangle, pair k = s0 + s1 − 1 for a
/// member on slots (s0, s1).
const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

/// Whether every cluster of a family is a triangle: three members of two
/// particles each, on the three distinct pairs of the cluster's three
/// particles (`slots` of a plan whose shape is (3, 3) and arity 2).
pub(crate) fn all_triangles(plan: &FamilyClusters, arity: usize) -> bool {
    if plan.fixed != Some((3, 3)) || arity != 2 {
        return false;
    }
    plan.slots.chunks_exact(6).all(|s| {
        let mut seen = 0u8;
        for m in s.chunks_exact(2) {
            let (a, b) = (m[0].min(m[1]), m[0].max(m[1]));
            if a == b || b > 2 {
                return false;
            }
            seen |= 1 << (a + b - 1);
        }
        seen == 0b111
    })
}

/// The arithmetic of the closed form on one triangle (`f64`) or on
/// [`LANES`] triangles side by side ([`Lanes`]): the same operations in
/// the same order on every lane (no fused multiply-add, no sum across
/// lanes), so that a triangle solved in a batch is solved bit for bit as
/// alone, whatever its neighbours, and the threads' blocks may cut the
/// batches anywhere.
pub(super) trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// Triangles side by side.
    const N: usize;
    fn splat(v: f64) -> Self;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    /// Lane l.
    fn lane(self, l: usize) -> f64;
    /// Sets lane l.
    fn set(&mut self, l: usize, v: f64);
}

impl Real for f64 {
    const N: usize = 1;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        v
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn lane(self, _: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn set(&mut self, _: usize, v: f64) {
        *self = v;
    }
}

/// Triangles per batch: four lanes fill two SSE2 registers (the baseline
/// of x86-64), whose independent chains of square roots and divisions
/// overlap.
pub(super) const LANES: usize = 4;

/// [`LANES`] numbers, one per triangle of a batch, with lane-wise
/// arithmetic (written out lane by lane for the vectoriser).
#[derive(Clone, Copy, Debug)]
pub(super) struct Lanes([f64; LANES]);

macro_rules! lanewise {
    ($tr:ident, $f:ident, $op:tt) => {
        impl $tr for Lanes {
            type Output = Lanes;
            #[inline(always)]
            fn $f(self, b: Lanes) -> Lanes {
                let a = self.0;
                let b = b.0;
                Lanes([a[0] $op b[0], a[1] $op b[1], a[2] $op b[2], a[3] $op b[3]])
            }
        }
    };
}
lanewise!(Add, add, +);
lanewise!(Sub, sub, -);
lanewise!(Mul, mul, *);
lanewise!(Div, div, /);

impl Neg for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn neg(self) -> Lanes {
        let a = self.0;
        Lanes([-a[0], -a[1], -a[2], -a[3]])
    }
}

impl Real for Lanes {
    const N: usize = LANES;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        Lanes([v; LANES])
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        let a = self.0;
        Lanes([a[0].sqrt(), a[1].sqrt(), a[2].sqrt(), a[3].sqrt()])
    }
    #[inline(always)]
    fn abs(self) -> Self {
        let a = self.0;
        Lanes([a[0].abs(), a[1].abs(), a[2].abs(), a[3].abs()])
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f64 {
        self.0[l]
    }
    #[inline(always)]
    fn set(&mut self, l: usize, v: f64) {
        self.0[l] = v;
    }
}

type V3<T = f64> = [T; 3];

#[inline(always)]
fn sub<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
fn dot<T: Real>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline(always)]
fn cross<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline(always)]
fn scale<T: Real>(s: T, a: V3<T>) -> V3<T> {
    [s * a[0], s * a[1], s * a[2]]
}
#[inline(always)]
fn cross2<T: Real>(p: [T; 2], q: [T; 2]) -> T {
    p[0] * q[1] - p[1] * q[0]
}

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
    ok: bool,
    /// The smallest squared length ([`near_branch`]).
    min_d2: f64,
}

/// The largest ratio of two masses of a triangle taken in closed form. The
/// rigid placement loses about ε √(m_max / m_min) of |x| out of the old
/// plane (Newton: none); at 10⁴ that is ~100 ε, beyond it the triangle
/// goes to the Newton kernel. Water: 16.
const MAX_MASS_RATIO: f64 = 1e4;

/// Whether lane l's x1 is within an eighth of the shortest length of the
/// unconstrained x̃ for every particle. The closed form takes the branch of
/// the torque equation nearest θ = 0, which at large steps of light,
/// flat triangles can be another SHAKE root than the one Newton from x̃
/// reaches (both solve the equations); within this bound, the correction
/// a simulation's step asks for (h²-small), the branch is the one through
/// the identity. Beyond it the triangle goes to the Newton kernel.
#[inline(always)]
fn near_branch<T: Real>(x1: &[V3<T>; 3], xt: &[V3<T>; 3], l: usize, min_d2: f64) -> bool {
    (0..3).all(|a| {
        let mut r2 = 0.0;
        for c in 0..3 {
            let d = x1[a][c].lane(l) - xt[a][c].lane(l);
            r2 += d * d;
        }
        r2 <= min_d2 / 64.0
    })
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
    fn is(&self, w: V3, d2: V3) -> bool {
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
    /// Whether lane l has an answer: every condition holds and x1 and ν
    /// are finite (NaN fails every comparison).
    #[inline(always)]
    pub(super) fn valid(&self, l: usize) -> bool {
        let finite = self.nu.iter().all(|v| v.lane(l).is_finite())
            && self.x1.iter().flatten().all(|v| v.lane(l).is_finite());
        self.flat.lane(l) > 0.0
            && self.nn.lane(l).is_finite()
            && self.cos_phi2.lane(l) > 0.0
            && self.cos_psi2.lane(l) > 0.0
            && self.s2c.lane(l) >= 0.0
            && finite
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
    let r = |k: usize, i: usize, j: usize| {
        let e = sub(x[i], x[j]);
        let l2 = dot(e, e);
        (l2 - T::splat(d2[k])).abs() / (T::splat(2.0) * l2)
    };
    [r(0, 0, 1), r(1, 0, 2), r(2, 1, 2)]
}

/// The worst of lane l's [`residuals`], and its pair.
#[inline(always)]
fn worst_of<T: Real>(r: &V3<T>, l: usize) -> (f64, usize) {
    let (mut worst, mut at) = (0.0f64, 0);
    for (k, r) in r.iter().enumerate() {
        if worse(r.lane(l), worst) {
            (worst, at) = (r.lane(l), k);
        }
    }
    (worst, at)
}

/// Whether every pair of lane l is within `tol` or the round-off floor of
/// its two particles' coordinates (`tolerance::roundoff_floor`): far from
/// the origin the coordinates cannot resolve a bond to `tol`, and the
/// closed form's answer is then as good as f64 holds it.
#[cold]
fn at_roundoff<T: Real>(x: &[V3<T>; 3], r: &V3<T>, l: usize, tol: f64) -> bool {
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

/// For each pair k of a cluster, the member on it (its row in the table).
#[inline(always)]
fn pair_members(plan: &FamilyClusters, c: usize) -> [usize; 3] {
    let mut on = [0usize; 3];
    for j in 0..3 {
        let s = &plan.slots[(3 * c + j) * 2..(3 * c + j) * 2 + 2];
        on[(s[0] + s[1] - 1) as usize] = plan.members[3 * c + j] as usize;
    }
    on
}

/// A triangle as the kernel reads it: its cluster, particles, the member
/// on each pair, inverse masses and squared lengths.
#[derive(Clone, Copy, Debug)]
struct Read {
    c: usize,
    parts: [usize; 3],
    on: [usize; 3],
    w: V3,
    d2: V3,
}

#[inline(always)]
fn read(plan: &FamilyClusters, table: &Table, inv_mass: &[f64], c: usize) -> Read {
    let p = &plan.particles[3 * c..3 * c + 3];
    let parts = [p[0] as usize, p[1] as usize, p[2] as usize];
    let on = pair_members(plan, c);
    let d2 = |k: usize| {
        let l = table.data(on[k])[0];
        l * l
    };
    Read {
        c,
        parts,
        on,
        w: [inv_mass[parts[0]], inv_mass[parts[1]], inv_mass[parts[2]]],
        d2: [d2(0), d2(1), d2(2)],
    }
}

/// The position stage (`shake_fixed`'s contract, the stencil a distance)
/// of T::N triangles of one `shape`, side by side: closed form, and the
/// Newton kernel, in the clusters' order, for a triangle the closed form
/// has no answer for within the tolerance.
#[inline(always)]
fn shake_batch<S: Stencil, T: Real>(
    w: &mut Work<'_>,
    f: &mut Fixed<3, 9>,
    shape: &Shape,
    batch: &[Read],
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    debug_assert_eq!(batch.len(), T::N);
    let zero = T::splat(0.0);
    let (mut x0, mut xt, mut pl) = ([[zero; 3]; 3], [[zero; 3]; 3], [[zero; 3]; 3]);
    for (l, r) in batch.iter().enumerate() {
        for s in 0..3 {
            let (i, j) = (r.parts[s], r.parts[s] - w.base);
            for c in 0..3 {
                x0[s][c].set(l, args.q0[3 * i + c]);
                xt[s][c].set(l, q[3 * j + c]);
                pl[s][c].set(l, p[3 * j + c]);
            }
        }
    }
    let sol = solve(shape, &x0, &xt);
    let res = residuals(&sol.x1, shape.d2);
    // x̃ already within the tolerance (or the round-off of its
    // coordinates): Newton takes it as it is, with ν = 0. The closed form
    // would solve exactly for the rounding of x̃ instead, and where a
    // step's displacement is below the resolution of the positions (a box
    // far from the origin) turn that rounding into an impulse of order
    // m·ulp(x)/h on the momenta.
    let res_t = residuals(&xt, shape.d2);
    let with_p = args.inv_h != 0.0;
    let wv = [
        T::splat(shape.w[0]),
        T::splat(shape.w[1]),
        T::splat(shape.w[2]),
    ];
    let mut projected = None;
    if with_p {
        // p½ = p̃ − G(x0)ᵀ ν / h, ∇_a g = 2 (x0_a − x0_b).
        let (two, inv_h) = (T::splat(2.0), T::splat(args.inv_h));
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            let e = sub(x0[i], x0[j]);
            let fk = two * sol.nu[k] * inv_h;
            for c in 0..3 {
                pl[i][c] = pl[i][c] - fk * e[c];
                pl[j][c] = pl[j][c] + fk * e[c];
            }
        }
        if fuse {
            projected = Some(project(&sol.x1, wv, &pl));
        }
    }
    for (l, r) in batch.iter().enumerate() {
        let (worst, _) = worst_of(&res, l);
        let met = worst <= args.tol || at_roundoff(&sol.x1, &res, l, args.tol);
        // (No floor above ROUNDOFF_CAP: an ordinary step's x̃, off by
        // O(h²), is decided without computing the floors.)
        let needed = worst_of(&res_t, l).0 > args.tol.max(ROUNDOFF_CAP)
            || !at_roundoff(&xt, &res_t, l, args.tol);
        if !(needed
            && shape.ok
            && sol.valid(l)
            && met
            && near_branch(&sol.x1, &xt, l, shape.min_d2))
        {
            shake_fixed::<S, 3, 3, 9>(w, f, r.c, stencil, table, plan, args, fuse, q, p)?;
            continue;
        }
        w.max_rel = w.max_rel.max(worst);
        for s in 0..3 {
            let j = r.parts[s] - w.base;
            for c in 0..3 {
                q[3 * j + c] = sol.x1[s][c].lane(l);
            }
        }
        if let Some(st) = w.store.as_deref_mut() {
            for k in 0..3 {
                st[r.on[k] - w.mbase] = sol.nu[k].lane(l);
            }
        }
        if !with_p {
            continue;
        }
        let out = match &projected {
            Some(pr) => match pr.judge(l, &wv, &pl) {
                Some((h, _)) if h <= HIDDEN_LIMIT => {
                    w.max_hidden = w.max_hidden.max(h);
                    &pr.p
                }
                h => {
                    return Err(ClusterFailure {
                        member: r.on[h.map_or(0, |h| h.1)],
                        residual: h.map_or(f64::NAN, |h| h.0),
                        iterations: 0,
                        kind: FailureKind::SingularN,
                    })
                }
            },
            None => &pl,
        };
        for s in 0..3 {
            let j = r.parts[s] - w.base;
            for c in 0..3 {
                p[3 * j + c] = out[s][c].lane(l);
            }
        }
    }
    Ok(())
}

/// The loop of [`shake_clusters`] over a family of triangles of distance
/// constraints in R³ ([`FamilyClusters::settle`]): [`LANES`] consecutive
/// triangles of one shape at a time, one at a time where the shape
/// changes or the block ends.
#[inline(never)]
pub(super) fn shake_triangles<S: Stencil>(
    w: &mut Work<'_>,
    stencil: &S,
    table: &Table,
    plan: &FamilyClusters,
    args: &ClusterArgs<'_>,
    fuse: bool,
    clusters: std::ops::Range<usize>,
    q: &mut [f64],
    p: &mut [f64],
) -> Result<(), ClusterFailure> {
    debug_assert!(S::DIM == 3 && S::ARITY == 2);
    let mut f = Fixed {
        sl: [[usize::MAX; FX]; 3],
        wg0d: [[0.0; 9]; 3],
        grd: [[0.0; 9]; 3],
    };
    // The reference triangle of the last molecule: a box of one kind of
    // molecule builds it once.
    let mut shape: Option<Shape> = None;
    let mut c = clusters.start;
    while c < clusters.end {
        let first = read(plan, table, args.inv_mass, c);
        let sh = match &mut shape {
            Some(s) if s.is(first.w, first.d2) => s,
            s => s.insert(Shape::new(first.w, first.d2)),
        };
        if c + LANES <= clusters.end {
            let mut batch = [first; LANES];
            let mut same = true;
            for (l, b) in batch.iter_mut().enumerate().skip(1) {
                *b = read(plan, table, args.inv_mass, c + l);
                same &= sh.is(b.w, b.d2);
            }
            if same {
                let (st, tb) = (stencil, table);
                shake_batch::<S, Lanes>(w, &mut f, sh, &batch, st, tb, plan, args, fuse, q, p)?;
                c += LANES;
                continue;
            }
        }
        let (st, tb) = (stencil, table);
        shake_batch::<S, f64>(w, &mut f, sh, &[first], st, tb, plan, args, fuse, q, p)?;
        c += 1;
    }
    Ok(())
}

/// The velocity stage on the triangles of one block (`project_block`'s
/// contract): the largest hidden residual left.
pub(super) fn project_triangles(
    plan: &FamilyClusters,
    inv_mass: &[f64],
    q: &[f64],
    block: Block,
    p: &mut [f64],
) -> Result<f64, ClusterFailure> {
    let base = block.particles.0;
    let mut max_hidden = 0.0f64;
    for c in block.clusters.0..block.clusters.1 {
        let parts = &plan.particles[3 * c..3 * c + 3];
        let (mut x, mut pl, mut w) = ([[0.0; 3]; 3], [[0.0; 3]; 3], [0.0; 3]);
        for (s, &i) in parts.iter().enumerate() {
            let (i, j) = (i as usize, i as usize - base);
            x[s] = q[3 * i..3 * i + 3].try_into().unwrap();
            pl[s] = p[3 * j..3 * j + 3].try_into().unwrap();
            w[s] = inv_mass[i];
        }
        let out = project(&x, w, &pl);
        match out.judge(0, &w, &pl) {
            Some((h, _)) if h <= HIDDEN_LIMIT => max_hidden = max_hidden.max(h),
            h => {
                return Err(ClusterFailure {
                    member: pair_members(plan, c)[h.map_or(0, |h| h.1)],
                    residual: h.map_or(f64::NAN, |h| h.0),
                    iterations: 0,
                    kind: FailureKind::SingularN,
                })
            }
        }
        for (s, &i) in parts.iter().enumerate() {
            let j = i as usize - base;
            p[3 * j..3 * j + 3].copy_from_slice(&out.p[s]);
        }
    }
    Ok(max_hidden)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift*), uniform in [−1, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
            (r >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        }
        fn v3(&mut self, s: f64) -> V3 {
            [s * self.next(), s * self.next(), s * self.next()]
        }
    }

    /// One triangle's inputs in local order.
    #[derive(Clone, Copy, Debug)]
    struct Triangle {
        w: V3,
        d2: V3,
        x0: [V3; 3],
        xt: [V3; 3],
    }

    /// x1 and ν of one triangle solved alone.
    struct Solved {
        x1: [V3; 3],
        nu: V3,
    }

    impl Triangle {
        fn solve(&self) -> Option<Solved> {
            let shape = Shape::new(self.w, self.d2);
            let s = solve(&shape, &self.x0, &self.xt);
            (shape.ok && s.valid(0)).then_some(Solved { x1: s.x1, nu: s.nu })
        }
    }

    /// One triangle's projection, in place: its judgement.
    fn project1(x: &[V3; 3], w: V3, p: &mut [V3; 3]) -> Option<(f64, usize)> {
        let out = project(x, w, p);
        let judged = out.judge(0, &w, p);
        *p = out.p;
        judged
    }

    /// A triangle of the given lengths (pairs (0,1), (0,2), (1,2)) placed
    /// at random about `at`, and x̃ = x0 + `kick` · random.
    fn triangle(rng: &mut Rng, w: V3, d: V3, at: V3, kick: f64) -> Triangle {
        let px = (d[0] * d[0] + d[1] * d[1] - d[2] * d[2]) / (2.0 * d[0]);
        let py = (d[1] * d[1] - px * px).sqrt();
        let body = [[0.0, 0.0, 0.0], [d[0], 0.0, 0.0], [px, py, 0.0]];
        // A random rotation: Gram–Schmidt of two random vectors.
        let u = rng.v3(1.0);
        let u = scale(1.0 / dot(u, u).sqrt(), u);
        let v = rng.v3(1.0);
        let v = sub(v, scale(dot(u, v), u));
        let v = scale(1.0 / dot(v, v).sqrt(), v);
        let z = cross(u, v);
        let x0 = body.map(|b| {
            let mut x = at;
            for k in 0..3 {
                x[k] += b[0] * u[k] + b[1] * v[k] + b[2] * z[k];
            }
            x
        });
        let xt = x0.map(|x| {
            let r = rng.v3(kick);
            [x[0] + r[0], x[1] + r[1], x[2] + r[2]]
        });
        Triangle {
            w,
            d2: d.map(|d| d * d),
            x0,
            xt,
        }
    }

    /// The SHAKE equations themselves: x1 = x̃ − W G(x0)ᵀ ν (each
    /// coordinate to a few ulps of the positions, times the condition of
    /// recovering ν from Δ, here O(1)) and g(x1) = 0 (to a few ε, relative).
    fn check_shake_equations(t: &Triangle, s: &Solved) {
        let size = t.xt.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
        let mut back = t.xt;
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            let e = sub(t.x0[i], t.x0[j]);
            for c in 0..3 {
                back[i][c] -= t.w[i] * 2.0 * s.nu[k] * e[c];
                back[j][c] += t.w[j] * 2.0 * s.nu[k] * e[c];
            }
        }
        for a in 0..3 {
            for c in 0..3 {
                let err = (back[a][c] - s.x1[a][c]).abs();
                assert!(err <= 64.0 * f64::EPSILON * size, "{err:e} at {a},{c}");
            }
        }
        let worst = residuals(&s.x1, t.d2).into_iter().fold(0.0, f64::max);
        assert!(worst <= 16.0 * f64::EPSILON * size, "residual {worst:e}");
    }

    #[test]
    fn the_closed_form_solves_the_shake_equations() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        // Water (O, H, H: 1.0, 1.0, 1.633) and a scalene triangle with
        // masses 40 to 1, near the origin and far from it.
        let cases = [
            ([1.0 / 15.9994, 1.0 / 1.008, 1.0 / 1.008], [1.0, 1.0, 1.633]),
            ([1.0 / 7.0, 1.0 / 0.3, 1.0 / 12.0], [1.0, 1.3, 0.8]),
            ([1.0, 1.0 / 40.0, 1.0], [2.0, 1.1, 1.5]),
        ];
        for (w, d) in cases {
            for at in [[0.0; 3], [1e3, -2e3, 5e2]] {
                for kick in [1e-4, 1e-2, 0.1] {
                    for _ in 0..20 {
                        let t = triangle(&mut rng, w, d, at, kick);
                        let s = t.solve().expect("a small step has a closed form");
                        check_shake_equations(&t, &s);
                    }
                }
            }
        }
    }

    #[test]
    fn the_closed_form_refuses_what_it_cannot_solve() {
        let mut rng = Rng(7);
        let (w, d) = ([1.0, 0.5, 0.25], [1.0, 1.2, 0.9]);
        // A collinear old triangle (the pair forces span too little).
        let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
        t.x0[2] = [2.0 * t.x0[1][0], 2.0 * t.x0[1][1], 2.0 * t.x0[1][2]];
        t.x0[0] = [0.0; 3];
        assert!(t.solve().is_none());
        // A reference that is no strict triangle.
        let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
        t.d2 = [1.0, 4.0, 1.0];
        assert!(t.solve().is_none());
        // A step far too large to meet the lengths on this branch.
        let t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
        let mut far = t;
        far.xt[0][0] += 50.0 * (t.x0[1][1] - t.x0[0][1]);
        far.xt[0][1] += 50.0 * (t.x0[2][2] - t.x0[0][2]);
        far.xt[2] = [far.xt[2][0], far.xt[2][1], far.xt[2][2] + 40.0];
        if let Some(s) = far.solve() {
            // (If a branch exists it must be a solution.)
            check_shake_equations(&far, &s);
        }
        // NaN anywhere.
        let mut t = triangle(&mut rng, w, d, [0.0; 3], 1e-2);
        t.xt[1][2] = f64::NAN;
        assert!(t.solve().is_none());
    }

    #[test]
    fn the_projection_leaves_every_bond_rigid() {
        let mut rng = Rng(11);
        for (w, d) in [
            ([1.0 / 16.0, 1.0, 1.0], [1.0, 1.0, 1.633]),
            ([0.1, 3.0, 0.7], [1.0, 1.3, 0.8]),
        ] {
            for _ in 0..50 {
                let t = triangle(&mut rng, w, d, [0.0; 3], 0.0);
                let mut p = [rng.v3(3.0), rng.v3(3.0), rng.v3(3.0)];
                let p_in = p;
                let (h, _) = project1(&t.x0, w, &mut p).unwrap();
                assert!(h <= 16.0 * f64::EPSILON, "hidden {h:e}");
                // The change is G(x)ᵀ μ: no net force.
                for c in 0..3 {
                    let f: f64 = (0..3).map(|a| p[a][c] - p_in[a][c]).sum();
                    assert!(f.abs() <= 64.0 * f64::EPSILON * 9.0, "net force {f:e}");
                }
            }
        }
        // Collapsed positions: N singular.
        let x = [[0.0; 3], [0.0; 3], [0.0; 3]];
        let mut p = [[1.0; 3]; 3];
        assert!(project1(&x, [1.0; 3], &mut p).is_none());
    }

    /// A triangle solved in a batch is solved bit for bit as alone: the
    /// threads' blocks may cut the batches anywhere.
    #[test]
    fn a_batch_solves_each_triangle_as_alone() {
        let mut rng = Rng(5);
        let (w, d) = ([1.0 / 15.9994, 1.0 / 1.008, 1.0 / 1.008], [1.0, 1.0, 1.633]);
        let shape = Shape::new(w, d.map(|d| d * d));
        let ts: Vec<Triangle> = (0..LANES)
            .map(|_| triangle(&mut rng, w, d, [3.0, 1.0, 2.0], 0.05))
            .collect();
        let z = Lanes::splat(0.0);
        let (mut x0, mut xt, mut p) = ([[z; 3]; 3], [[z; 3]; 3], [[z; 3]; 3]);
        let ps: Vec<[V3; 3]> = (0..LANES)
            .map(|_| [rng.v3(1.0), rng.v3(1.0), rng.v3(1.0)])
            .collect();
        for (l, t) in ts.iter().enumerate() {
            for s in 0..3 {
                for c in 0..3 {
                    x0[s][c].set(l, t.x0[s][c]);
                    xt[s][c].set(l, t.xt[s][c]);
                    p[s][c].set(l, ps[l][s][c]);
                }
            }
        }
        let many = solve(&shape, &x0, &xt);
        let wl = w.map(Lanes::splat);
        let many_p = project(&many.x1, wl, &p);
        for (l, t) in ts.iter().enumerate() {
            let one = solve(&shape, &t.x0, &t.xt);
            assert!(one.valid(0) && many.valid(l));
            let one_p = project(&one.x1, w, &ps[l]);
            for s in 0..3 {
                assert_eq!(one.nu[s].to_bits(), many.nu[s].lane(l).to_bits());
                for c in 0..3 {
                    assert_eq!(one.x1[s][c].to_bits(), many.x1[s][c].lane(l).to_bits());
                    assert_eq!(one_p.p[s][c].to_bits(), many_p.p[s][c].lane(l).to_bits());
                }
            }
            assert_eq!(one_p.judge(0, &w, &ps[l]), many_p.judge(l, &wl, &p));
        }
    }

    #[test]
    fn triangles_are_the_three_pairs_of_three_particles() {
        let plan = |slots: Vec<u8>| FamilyClusters {
            fixed: Some((3, 3)),
            slots,
            ..Default::default()
        };
        assert!(all_triangles(&plan(vec![0, 1, 0, 2, 1, 2]), 2));
        assert!(all_triangles(
            &plan(vec![2, 1, 1, 0, 0, 2, 0, 1, 2, 0, 2, 1]),
            2
        ));
        // A pair twice, a particle with itself, the wrong arity or shape.
        assert!(!all_triangles(&plan(vec![0, 1, 1, 0, 1, 2]), 2));
        assert!(!all_triangles(&plan(vec![0, 0, 0, 2, 1, 2]), 2));
        assert!(!all_triangles(&plan(vec![0, 1, 0, 2, 1, 2]), 3));
        let mut p = plan(vec![0, 1, 0, 2, 1, 2]);
        p.fixed = Some((2, 3));
        assert!(!all_triangles(&p, 2));
    }
}
