//! The arithmetic the closed forms of a rigid triangle are written over:
//! [`Real`], one triangle (`f64`) or [`LANES`] triangles side by side
//! ([`Lanes`]), lane by lane in the same order, and the 3-vector operations
//! on it.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Sub};

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
    /// Lane l is f(l): a batch gathered from its triangles.
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    /// Lane l.
    fn lane(self, l: usize) -> f64;
    /// Every lane into `out`, lane l at l < N (the others untouched): a
    /// register stored once, for reading its lanes by a run-time index
    /// without going through memory per lane.
    fn store(self, out: &mut [f64; LANES]);
    /// One truth value per lane, so that a batch is judged by a few
    /// comparisons of whole registers rather than lane by lane.
    type Mask: Copy + BitAnd<Output = Self::Mask> + BitOr<Output = Self::Mask>;
    /// Lane-wise a < b, false where either is NaN.
    fn lt(self, b: Self) -> Self::Mask;
    /// Lane-wise a ≤ b, false where either is NaN.
    fn le(self, b: Self) -> Self::Mask;
    /// Whether the mask holds on every lane.
    fn all(m: Self::Mask) -> bool;
    /// Whether the mask holds on lane l.
    fn holds(m: Self::Mask, l: usize) -> bool;
    /// The lane-wise larger of two numbers (on a lane where one is NaN,
    /// either of them: such a lane's answer is not used).
    fn max(self, b: Self) -> Self;
    /// Lane-wise finite (neither infinite nor NaN), as `f64::is_finite`.
    #[inline(always)]
    fn finite(self) -> Self::Mask {
        self.abs().le(Self::splat(f64::MAX))
    }
    /// The largest lane of numbers none of which is NaN (a maximum, the
    /// same whatever the order of the lanes).
    #[inline(always)]
    fn max_lane(self) -> f64 {
        let mut m = self.lane(0);
        for l in 1..Self::N {
            m = m.max(self.lane(l));
        }
        m
    }
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
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        f(0)
    }
    #[inline(always)]
    fn lane(self, _: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn store(self, out: &mut [f64; LANES]) {
        out[0] = self;
    }
    type Mask = bool;
    #[inline(always)]
    fn lt(self, b: Self) -> bool {
        self < b
    }
    #[inline(always)]
    fn le(self, b: Self) -> bool {
        self <= b
    }
    #[inline(always)]
    fn all(m: bool) -> bool {
        m
    }
    #[inline(always)]
    fn holds(m: bool, _: usize) -> bool {
        m
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        f64::max(self, b)
    }
}

/// Triangles per batch: four lanes fill two SSE2 registers (the baseline
/// of x86-64), whose independent chains of square roots and divisions
/// overlap.
pub(super) const LANES: usize = 4;

/// [`LANES`] numbers, one per triangle of a batch, with lane-wise
/// arithmetic: on x86-64 two SSE2 registers, so that a batch's numbers
/// stay in registers between operations (an array of four lanes was
/// vectorised per operation but kept on the stack, loaded and stored
/// around each one). SSE2's add, sub, mul, div and sqrt round as the
/// scalar operations do, so every lane is still the triangle solved alone.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(super) struct Lanes([__m128d; 2]);

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// An SSE2 intrinsic, called where the instructions always exist.
#[cfg(target_arch = "x86_64")]
macro_rules! sse2 {
    ($e:expr) => {
        // SAFETY: SSE2 is part of the x86-64 baseline, enabled on every
        // x86-64 target: the CPU has the instructions the intrinsic emits
        // (the intrinsics touch no memory here).
        unsafe { $e }
    };
}

/// -0.0 in every lane: the sign bit alone, for |x| and −x.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn sign_bit() -> __m128d {
    sse2!(_mm_set1_pd(-0.0))
}

#[cfg(target_arch = "x86_64")]
macro_rules! lanewise {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for Lanes {
            type Output = Lanes;
            #[inline(always)]
            fn $f(self, b: Lanes) -> Lanes {
                let (a, b) = (self.0, b.0);
                sse2!(Lanes([$op(a[0], b[0]), $op(a[1], b[1])]))
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
lanewise!(Add, add, _mm_add_pd);
#[cfg(target_arch = "x86_64")]
lanewise!(Sub, sub, _mm_sub_pd);
#[cfg(target_arch = "x86_64")]
lanewise!(Mul, mul, _mm_mul_pd);
#[cfg(target_arch = "x86_64")]
lanewise!(Div, div, _mm_div_pd);

#[cfg(target_arch = "x86_64")]
impl Neg for Lanes {
    type Output = Lanes;
    /// The sign bit flipped, as the scalar `-x` (NaN included).
    #[inline(always)]
    fn neg(self) -> Lanes {
        let a = self.0;
        sse2!(Lanes([
            _mm_xor_pd(a[0], sign_bit()),
            _mm_xor_pd(a[1], sign_bit())
        ]))
    }
}

#[cfg(target_arch = "x86_64")]
impl Real for Lanes {
    const N: usize = LANES;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        sse2!(Lanes([_mm_set1_pd(v); 2]))
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        let (a, b, c, d) = (f(0), f(1), f(2), f(3));
        sse2!(Lanes([_mm_set_pd(b, a), _mm_set_pd(d, c)]))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        sse2!(Lanes([_mm_sqrt_pd(self.0[0]), _mm_sqrt_pd(self.0[1])]))
    }
    /// The sign bit cleared, as `f64::abs`.
    #[inline(always)]
    fn abs(self) -> Self {
        let a = self.0;
        sse2!(Lanes([
            _mm_andnot_pd(sign_bit(), a[0]),
            _mm_andnot_pd(sign_bit(), a[1]),
        ]))
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f64 {
        let v = self.0[l / 2];
        if l.is_multiple_of(2) {
            sse2!(_mm_cvtsd_f64(v))
        } else {
            sse2!(_mm_cvtsd_f64(_mm_unpackhi_pd(v, v)))
        }
    }
    #[inline(always)]
    fn store(self, out: &mut [f64; LANES]) {
        // SAFETY: SSE2 (the x86-64 baseline); each store writes two f64
        // into `out[0..2]` and `out[2..4]`, in bounds, unaligned stores.
        unsafe {
            _mm_storeu_pd(out.as_mut_ptr(), self.0[0]);
            _mm_storeu_pd(out.as_mut_ptr().add(2), self.0[1]);
        }
    }
    type Mask = LaneMask;
    #[inline(always)]
    fn lt(self, b: Self) -> LaneMask {
        let (a, b) = (self.0, b.0);
        sse2!(LaneMask([
            _mm_cmplt_pd(a[0], b[0]),
            _mm_cmplt_pd(a[1], b[1])
        ]))
    }
    #[inline(always)]
    fn le(self, b: Self) -> LaneMask {
        let (a, b) = (self.0, b.0);
        sse2!(LaneMask([
            _mm_cmple_pd(a[0], b[0]),
            _mm_cmple_pd(a[1], b[1])
        ]))
    }
    #[inline(always)]
    fn all(m: LaneMask) -> bool {
        sse2!(_mm_movemask_pd(_mm_and_pd(m.0[0], m.0[1]))) == 0b11
    }
    #[inline(always)]
    fn holds(m: LaneMask, l: usize) -> bool {
        (sse2!(_mm_movemask_pd(m.0[l / 2])) >> (l % 2)) & 1 == 1
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        let (a, b) = (self.0, b.0);
        sse2!(Lanes([_mm_max_pd(a[0], b[0]), _mm_max_pd(a[1], b[1])]))
    }
}

/// A lane-wise truth value of [`Lanes`]: all bits set where it holds.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(super) struct LaneMask([__m128d; 2]);

#[cfg(target_arch = "x86_64")]
impl BitAnd for LaneMask {
    type Output = LaneMask;
    #[inline(always)]
    fn bitand(self, b: LaneMask) -> LaneMask {
        let (a, b) = (self.0, b.0);
        sse2!(LaneMask([_mm_and_pd(a[0], b[0]), _mm_and_pd(a[1], b[1])]))
    }
}

#[cfg(target_arch = "x86_64")]
impl BitOr for LaneMask {
    type Output = LaneMask;
    #[inline(always)]
    fn bitor(self, b: LaneMask) -> LaneMask {
        let (a, b) = (self.0, b.0);
        sse2!(LaneMask([_mm_or_pd(a[0], b[0]), _mm_or_pd(a[1], b[1])]))
    }
}

/// Whether the CPU has AVX, for [`Wide`] (the check is cached).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) fn has_avx() -> bool {
    std::arch::is_x86_feature_detected!("avx")
}

/// [`LANES`] numbers in one AVX register, for the kernel compiled for
/// AVX and entered only where [`has_avx`] holds: half the registers of
/// [`Lanes`], so fewer of a batch's numbers are spilled. The same IEEE
/// operations lane by lane, so the same bits (AVX has no fused
/// multiply-add; that is FMA, never enabled here).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(super) struct Wide(__m256d);

/// An AVX intrinsic on a [`Wide`].
#[cfg(target_arch = "x86_64")]
macro_rules! avx {
    ($e:expr) => {
        // SAFETY: a `Wide` is made and used only inside the kernel
        // compiled for AVX (`triangles_avx`), which runs only where
        // `has_avx` holds, and in tests that check it first: the CPU has
        // the instructions (the intrinsics touch no memory here).
        unsafe { $e }
    };
}

#[cfg(target_arch = "x86_64")]
macro_rules! widewise {
    ($tr:ident, $f:ident, $op:ident) => {
        impl $tr for Wide {
            type Output = Wide;
            #[inline(always)]
            fn $f(self, b: Wide) -> Wide {
                avx!(Wide($op(self.0, b.0)))
            }
        }
    };
}
#[cfg(target_arch = "x86_64")]
widewise!(Add, add, _mm256_add_pd);
#[cfg(target_arch = "x86_64")]
widewise!(Sub, sub, _mm256_sub_pd);
#[cfg(target_arch = "x86_64")]
widewise!(Mul, mul, _mm256_mul_pd);
#[cfg(target_arch = "x86_64")]
widewise!(Div, div, _mm256_div_pd);

#[cfg(target_arch = "x86_64")]
impl Neg for Wide {
    type Output = Wide;
    /// The sign bit flipped, as the scalar `-x` (NaN included).
    #[inline(always)]
    fn neg(self) -> Wide {
        avx!(Wide(_mm256_xor_pd(self.0, _mm256_set1_pd(-0.0))))
    }
}

#[cfg(target_arch = "x86_64")]
impl Real for Wide {
    const N: usize = LANES;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        avx!(Wide(_mm256_set1_pd(v)))
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        let (a, b, c, d) = (f(0), f(1), f(2), f(3));
        avx!(Wide(_mm256_set_pd(d, c, b, a)))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        avx!(Wide(_mm256_sqrt_pd(self.0)))
    }
    /// The sign bit cleared, as `f64::abs`.
    #[inline(always)]
    fn abs(self) -> Self {
        avx!(Wide(_mm256_andnot_pd(_mm256_set1_pd(-0.0), self.0)))
    }
    #[inline(always)]
    fn lane(self, l: usize) -> f64 {
        let half = if l < 2 {
            avx!(_mm256_castpd256_pd128(self.0))
        } else {
            avx!(_mm256_extractf128_pd::<1>(self.0))
        };
        if l.is_multiple_of(2) {
            sse2!(_mm_cvtsd_f64(half))
        } else {
            sse2!(_mm_cvtsd_f64(_mm_unpackhi_pd(half, half)))
        }
    }
    #[inline(always)]
    fn store(self, out: &mut [f64; LANES]) {
        // SAFETY: AVX as for every `Wide` (see `avx!`); the store writes
        // the four f64 of `out`, in bounds, an unaligned store.
        unsafe { _mm256_storeu_pd(out.as_mut_ptr(), self.0) };
    }
    type Mask = WideMask;
    #[inline(always)]
    fn lt(self, b: Self) -> WideMask {
        avx!(WideMask(_mm256_cmp_pd::<_CMP_LT_OQ>(self.0, b.0)))
    }
    #[inline(always)]
    fn le(self, b: Self) -> WideMask {
        avx!(WideMask(_mm256_cmp_pd::<_CMP_LE_OQ>(self.0, b.0)))
    }
    #[inline(always)]
    fn all(m: WideMask) -> bool {
        avx!(_mm256_movemask_pd(m.0)) == 0b1111
    }
    #[inline(always)]
    fn holds(m: WideMask, l: usize) -> bool {
        (avx!(_mm256_movemask_pd(m.0)) >> l) & 1 == 1
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        avx!(Wide(_mm256_max_pd(self.0, b.0)))
    }
}

/// A lane-wise truth value of [`Wide`]: all bits set where it holds.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(super) struct WideMask(__m256d);

#[cfg(target_arch = "x86_64")]
impl BitAnd for WideMask {
    type Output = WideMask;
    #[inline(always)]
    fn bitand(self, b: WideMask) -> WideMask {
        avx!(WideMask(_mm256_and_pd(self.0, b.0)))
    }
}

#[cfg(target_arch = "x86_64")]
impl BitOr for WideMask {
    type Output = WideMask;
    #[inline(always)]
    fn bitor(self, b: WideMask) -> WideMask {
        avx!(WideMask(_mm256_or_pd(self.0, b.0)))
    }
}

/// [`LANES`] numbers, one per triangle of a batch, with lane-wise
/// arithmetic (written out lane by lane for the vectoriser).
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy, Debug)]
pub(super) struct Lanes([f64; LANES]);

#[cfg(not(target_arch = "x86_64"))]
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
#[cfg(not(target_arch = "x86_64"))]
lanewise!(Add, add, +);
#[cfg(not(target_arch = "x86_64"))]
lanewise!(Sub, sub, -);
#[cfg(not(target_arch = "x86_64"))]
lanewise!(Mul, mul, *);
#[cfg(not(target_arch = "x86_64"))]
lanewise!(Div, div, /);

#[cfg(not(target_arch = "x86_64"))]
impl Neg for Lanes {
    type Output = Lanes;
    #[inline(always)]
    fn neg(self) -> Lanes {
        Lanes(self.0.map(|a| -a))
    }
}

#[cfg(not(target_arch = "x86_64"))]
impl Real for Lanes {
    const N: usize = LANES;
    #[inline(always)]
    fn splat(v: f64) -> Self {
        Lanes([v; LANES])
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
        Lanes([f(0), f(1), f(2), f(3)])
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
    fn store(self, out: &mut [f64; LANES]) {
        *out = self.0;
    }
    type Mask = LaneMask;
    #[inline(always)]
    fn lt(self, b: Self) -> LaneMask {
        let (a, b) = (self.0, b.0);
        LaneMask([a[0] < b[0], a[1] < b[1], a[2] < b[2], a[3] < b[3]])
    }
    #[inline(always)]
    fn le(self, b: Self) -> LaneMask {
        let (a, b) = (self.0, b.0);
        LaneMask([a[0] <= b[0], a[1] <= b[1], a[2] <= b[2], a[3] <= b[3]])
    }
    #[inline(always)]
    fn all(m: LaneMask) -> bool {
        m.0[0] & m.0[1] & m.0[2] & m.0[3]
    }
    #[inline(always)]
    fn holds(m: LaneMask, l: usize) -> bool {
        m.0[l]
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        let (a, b) = (self.0, b.0);
        Lanes([
            a[0].max(b[0]),
            a[1].max(b[1]),
            a[2].max(b[2]),
            a[3].max(b[3]),
        ])
    }
}

/// A lane-wise truth value of [`Lanes`].
#[cfg(not(target_arch = "x86_64"))]
#[derive(Clone, Copy, Debug)]
pub(super) struct LaneMask([bool; LANES]);

#[cfg(not(target_arch = "x86_64"))]
impl BitAnd for LaneMask {
    type Output = LaneMask;
    #[inline(always)]
    fn bitand(self, b: LaneMask) -> LaneMask {
        let (a, b) = (self.0, b.0);
        LaneMask([a[0] & b[0], a[1] & b[1], a[2] & b[2], a[3] & b[3]])
    }
}

#[cfg(not(target_arch = "x86_64"))]
impl BitOr for LaneMask {
    type Output = LaneMask;
    #[inline(always)]
    fn bitor(self, b: LaneMask) -> LaneMask {
        let (a, b) = (self.0, b.0);
        LaneMask([a[0] | b[0], a[1] | b[1], a[2] | b[2], a[3] | b[3]])
    }
}

pub(super) type V3<T = f64> = [T; 3];

#[inline(always)]
pub(super) fn sub<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
pub(super) fn dot<T: Real>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline(always)]
pub(super) fn cross<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline(always)]
pub(super) fn scale<T: Real>(s: T, a: V3<T>) -> V3<T> {
    [s * a[0], s * a[1], s * a[2]]
}
#[inline(always)]
pub(super) fn cross2<T: Real>(p: [T; 2], q: [T; 2]) -> T {
    p[0] * q[1] - p[1] * q[0]
}
