//! One member of a family as a function of the particles it touches.

/// A scalar function f(x; c) of the coordinates x of the `ARITY` particles
/// one member touches (each in R^`DIM`) and of the `DATA` numbers c in the
/// member's row of its [`Table`](super::Table): a constraint g_k (say
/// |x_a − x_b|² − l_k²) or a term of the potential energy.
///
/// The local coordinates are laid out particle by particle: coordinate `c`
/// of the member's `a`-th particle is `x[a * DIM + c]`, and the gradient
/// uses the same layout. `constrained_system!` generates implementations
/// from a template; a hand-written one is a few lines:
///
/// ```
/// use geoshake_runtime::particles::Stencil;
///
/// /// g = |x_a − x_b|² − l², l from the table.
/// struct Distance;
///
/// impl Stencil for Distance {
///     const ARITY: usize = 2;
///     const DIM: usize = 3;
///     const DATA: usize = 1;
///     fn value(&self, x: &[f64], c: &[f64]) -> f64 {
///         (0..3).map(|k| (x[k] - x[3 + k]).powi(2)).sum::<f64>() - c[0] * c[0]
///     }
///     fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
///         for k in 0..3 {
///             let r = x[k] - x[3 + k];
///             grad[k] = 2.0 * r;
///             grad[3 + k] = -2.0 * r;
///         }
///         self.value(x, c)
///     }
/// }
///
/// let mut grad = [0.0; 6];
/// let g = Distance.gradient(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], &[1.0], &mut grad);
/// assert_eq!((g, grad[0]), (0.0, 2.0));
/// ```
///
/// Implementations are called in the innermost loops with slices of exactly
/// `ARITY * DIM` and `DATA` entries; they should be `#[inline]` straight-line
/// code and must not allocate.
pub trait Stencil: Send + Sync {
    /// Particles per member.
    const ARITY: usize;
    /// Coordinates per particle.
    const DIM: usize;
    /// Numbers per row of the table.
    const DATA: usize;
    /// True when f is the distance constraint f(x; c) = |x_0 − x_1|² −
    /// c_0² (ARITY 2, DATA ≥ 1), exactly: a declaration, not checked. A
    /// family of such members whose clusters are triangles (three
    /// particles, their three pairs) in R³, rigid water for one, then has
    /// its SHAKE and RATTLE steps solved in closed form (SETTLE) instead
    /// of by Newton. False by default.
    const DISTANCE: bool = false;

    /// f(x; c).
    fn value(&self, x: &[f64], c: &[f64]) -> f64;

    /// f(x; c), with ∂f/∂x written into `grad` (`ARITY * DIM` entries, the
    /// layout of `x`).
    fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64;
}

/// 1 / (|∇g| · extent) of a member from its gradient block and local
/// coordinates (`tolerance::inverse_scale`), and its extent².
#[inline(always)]
pub(crate) fn member_scale<S: Stencil>(grad: &[f64], xm: &[f64]) -> (f64, f64) {
    let n2: f64 = grad.iter().map(|v| v * v).sum();
    let e2 = extent2::<S>(xm);
    (crate::tolerance::inverse_scale(n2, e2), e2)
}

/// A member's relative residual at its own coordinates `xm` (gradient
/// into `grad`), and whether it is within `tol` or the round-off floor of
/// those coordinates (`tolerance::roundoff_floor`): the per-member test of
/// a stalled Newton iteration (`newton::Rate::RoundOff`).
#[inline]
pub(crate) fn member_at_roundoff<S: Stencil>(
    stencil: &S,
    xm: &[f64],
    data: &[f64],
    grad: &mut [f64],
    tol: f64,
) -> (bool, f64) {
    let g = stencil.gradient(xm, data, grad);
    let (inv, e2) = member_scale::<S>(grad, xm);
    let n2: f64 = xm.iter().map(|v| v * v).sum();
    let r = g.abs() * inv;
    (r <= tol.max(crate::tolerance::roundoff_floor(n2, e2)), r)
}

/// Squared extent of a member: Σ_a |x_a − x̄|² over its particles (|x_a|²
/// for a single-particle member, whose constraint refers to the origin).
#[inline(always)]
pub(crate) fn extent2<S: Stencil>(xm: &[f64]) -> f64 {
    let (d, ar) = (S::DIM, S::ARITY);
    if ar == 1 {
        return xm[..d].iter().map(|v| v * v).sum();
    }
    let mut e = 0.0;
    for c in 0..d {
        let mut mean = 0.0;
        for a in 0..ar {
            mean += xm[a * d + c];
        }
        mean /= ar as f64;
        for a in 0..ar {
            let r = xm[a * d + c] - mean;
            e += r * r;
        }
    }
    e
}
