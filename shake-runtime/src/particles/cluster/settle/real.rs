//! The arithmetic the closed forms of a rigid triangle are written over:
//! [`Real`], one triangle (`f64`) or [`LANES`] triangles side by side
//! ([`Lanes`]), lane by lane in the same order, and the 3-vector operations
//! on it.

use std::ops::{Add, Div, Mul, Neg, Sub};

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
