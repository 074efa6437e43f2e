//! Hand-written stencils for the common molecular terms: what
//! `constrained_system!` would generate from a template, written out so the
//! large-system path can be used (and measured) on its own.

use super::Stencil;

/// The distance constraint g = |x_a − x_b|² − l² between two particles in
/// R^D, l from the table (`DATA = 1`). Written on the difference x_a − x_b,
/// never on the expanded squares, so a system translated far from the
/// origin keeps its constraints to round-off of |x_a − x_b|.
///
/// ```
/// use geoshake_runtime::particles::{stencils::Distance, Stencil};
/// let mut grad = [0.0; 6];
/// let g = Distance::<3>.gradient(&[1e3, 0.0, 0.0, 1e3 + 1.0, 0.0, 0.0], &[1.0], &mut grad);
/// assert_eq!(g, 0.0);
/// assert_eq!(grad, [-2.0, 0.0, 0.0, 2.0, 0.0, 0.0]);
/// ```
#[derive(Copy, Clone, Debug, Default)]
pub struct Distance<const D: usize>;

impl<const D: usize> Stencil for Distance<D> {
    const ARITY: usize = 2;
    const DIM: usize = D;
    const DATA: usize = 1;
    const DISTANCE: bool = true;
    #[inline(always)]
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..D {
            let r = x[k] - x[D + k];
            s += r * r;
        }
        s - c[0] * c[0]
    }
    #[inline(always)]
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..D {
            let r = x[k] - x[D + k];
            s += r * r;
            grad[k] = 2.0 * r;
            grad[D + k] = -2.0 * r;
        }
        s - c[0] * c[0]
    }
}

/// A particle held at distance l from the origin: g = |x_a|² − l²
/// (`ARITY = 1`, `DATA = 1`), the pivot of a pendulum.
///
/// ```
/// use geoshake_runtime::particles::{stencils::Anchor, Stencil};
/// assert_eq!(Anchor::<2>.value(&[0.6, -0.8], &[1.0]), 0.0);
/// ```
#[derive(Copy, Clone, Debug, Default)]
pub struct Anchor<const D: usize>;

impl<const D: usize> Stencil for Anchor<D> {
    const ARITY: usize = 1;
    const DIM: usize = D;
    const DATA: usize = 1;
    #[inline(always)]
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..D {
            s += x[k] * x[k];
        }
        s - c[0] * c[0]
    }
    #[inline(always)]
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        for k in 0..D {
            grad[k] = 2.0 * x[k];
        }
        self.value(x, c)
    }
}

/// A harmonic spring V = (k/2)(|x_a − x_b| − r₀)², `DATA = 2` (k, r₀).
///
/// ```
/// use geoshake_runtime::particles::{stencils::Spring, Stencil};
/// let mut grad = [0.0; 6];
/// let v = Spring::<3>.gradient(&[0.0, 0.0, 0.0, 2.0, 0.0, 0.0], &[3.0, 1.0], &mut grad);
/// assert_eq!((v, grad[3]), (1.5, 3.0));
/// ```
#[derive(Copy, Clone, Debug, Default)]
pub struct Spring<const D: usize>;

impl<const D: usize> Stencil for Spring<D> {
    const ARITY: usize = 2;
    const DIM: usize = D;
    const DATA: usize = 2;
    #[inline(always)]
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..D {
            let r = x[k] - x[D + k];
            s += r * r;
        }
        let e = s.sqrt() - c[1];
        0.5 * c[0] * e * e
    }
    #[inline(always)]
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        let mut s = 0.0;
        for k in 0..D {
            let r = x[k] - x[D + k];
            s += r * r;
        }
        let len = s.sqrt();
        let e = len - c[1];
        // dV/dx_a = k (|r| − r₀) r/|r|; a coincident pair has no direction:
        // the force is taken as zero there (V is not differentiable).
        let f = if len > 0.0 { c[0] * e / len } else { 0.0 };
        for k in 0..D {
            let r = x[k] - x[D + k];
            grad[k] = f * r;
            grad[D + k] = -f * r;
        }
        0.5 * c[0] * e * e
    }
}

/// A uniform field on one particle: V = c · x_a (`ARITY = 1`, `DATA = D`),
/// e.g. gravity c = (0, m γ).
///
/// ```
/// use geoshake_runtime::particles::{stencils::LinearField, Stencil};
/// assert_eq!(LinearField::<2>.value(&[3.0, 2.0], &[0.0, 9.81]), 2.0 * 9.81);
/// ```
#[derive(Copy, Clone, Debug, Default)]
pub struct LinearField<const D: usize>;

impl<const D: usize> Stencil for LinearField<D> {
    const ARITY: usize = 1;
    const DIM: usize = D;
    const DATA: usize = D;
    #[inline(always)]
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        (0..D).map(|k| c[k] * x[k]).sum()
    }
    #[inline(always)]
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
        grad[..D].copy_from_slice(&c[..D]);
        self.value(x, c)
    }
}
