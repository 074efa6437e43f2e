//! The scales against which a constraint residual is judged: what
//! rounding the state in its last bit changes g_i by (its round-off), and
//! the bounds the constraint tolerance and Newton's tolerance put on |g_i|,
//! relative to g_i's own size ‖∂g_i/∂z‖₁ and to the size of the variables
//! it reads. Pure arithmetic on numbers and patterns, used by the kernels,
//! the guard and the API checks alike.
//!
//! With them, the other limits f64 puts on a computation, shared by both
//! engines (the dense [`Integrator`](crate::Integrator) and the particle
//! [`Rattle`](crate::particles::Rattle)): the smallest relative tolerance
//! a residual can meet, the largest Newton budget, and what a run may ask
//! for ([`check_run`], [`stored_states`]).

use std::num::NonZeroU64;

use crate::linalg::norm_inf;

/// The smallest relative residual tolerance accepted: 4ε.
///
/// A relative residual such as | |r| − ℓ | / ℓ is computed in f64 at a
/// state whose every coordinate is already rounded: rounding the
/// coordinates to their nearest f64 moves |r| by up to about ε/2 relative,
/// and evaluating g (a difference of coordinates, squares, a sum, the
/// subtraction of ℓ²) adds a few more roundings of ε/2 each. The nearest
/// state to M that f64 can hold therefore shows a residual of order ε, and
/// a tolerance below that may never be met: Newton would iterate on the
/// rounding noise until its budget runs out. 4ε leaves a factor of two
/// above the ≈ 2ε that rounding alone can produce.
pub const MIN_RELATIVE_TOLERANCE: f64 = 4.0 * f64::EPSILON;

/// The largest Newton iteration budget accepted (per solve: per step, or
/// per cluster and step on the particle path). Newton from a point at
/// distance O(h) converges in a handful of iterations; one that has not
/// converged after this many will not, and a larger budget only turns a
/// failure into a hang.
pub const MAX_ITERATIONS: usize = 10_000;

/// The most steps one run may take, counted as the index of its last step:
/// 2⁵³. Up to it every step index k is exact in f64, so the times
/// t0 + k·h are computed from the exact k; beyond it k + 1 rounds to k, the
/// stored times repeat and a run cannot be told apart from a shorter one
/// (and would not end in any useful time).
pub const MAX_STEPS: u64 = 1 << 53;

/// Why a run's request was refused before any step: what is wrong and the
/// value (each engine turns it into its own `InvalidInput`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum RunLimit {
    /// The start time t0 is NaN or infinite.
    StartTime(f64),
    /// The last step index first + steps is past [`MAX_STEPS`] (or does not
    /// fit in a u64): the steps asked for.
    Steps(u64),
    /// The time of the last step, t0 + last·h, is NaN or infinite.
    EndTime(f64),
}

impl RunLimit {
    /// What is wrong, for a message.
    pub(crate) fn what(&self) -> &'static str {
        match self {
            RunLimit::StartTime(_) => "start time must be finite",
            RunLimit::Steps(_) => {
                "a run takes at most 2^53 steps (step indices beyond are not exact in f64)"
            }
            RunLimit::EndTime(_) => "the time t0 + k·h of the last step must be finite",
        }
    }

    /// The offending value.
    pub(crate) fn value(&self) -> f64 {
        match *self {
            RunLimit::StartTime(t) | RunLimit::EndTime(t) => t,
            RunLimit::Steps(n) => n as f64,
        }
    }
}

/// Checks a run of `steps` steps from step index `first` (at time
/// t0 + first·h, t0 the run's start) with step size h, as the engines
/// compute their times (t0 + k·h from the exact k, never accumulated):
/// t0 finite, the last index first + steps at most [`MAX_STEPS`], and the
/// last time finite. Since t0 + k·h lies between t0 and the last time for
/// every k in between, the two finite ends make every stored time finite.
/// Returns the last step index. h itself is the engine's check (each has
/// its own rule for its sign).
pub(crate) fn check_run(t0: f64, h: f64, first: u64, steps: u64) -> Result<u64, RunLimit> {
    if !t0.is_finite() {
        return Err(RunLimit::StartTime(t0));
    }
    let last = match first.checked_add(steps) {
        Some(last) if last <= MAX_STEPS => last,
        _ => return Err(RunLimit::Steps(steps)),
    };
    let end = t0 + last as f64 * h;
    if !end.is_finite() {
        return Err(RunLimit::EndTime(end));
    }
    Ok(last)
}

/// How many states a run from step index `first` to `last` stores: every
/// k in first ..= last that is a multiple of `stride`, and the last one
/// too when `keep_last` (the dense driver's rule: first, every stride-th,
/// last). `None` when the count does not fit in a u64 (checked, never
/// wrapped: a wrapped count would reserve nothing and the run would then
/// grow its buffer until the allocator aborts the process).
///
/// Both engines reserve their trajectory from this count before the first
/// step, and refuse the run with a typed storage error when the
/// reservation fails.
pub(crate) fn stored_states(
    first: u64,
    last: u64,
    stride: NonZeroU64,
    keep_last: bool,
) -> Option<u64> {
    if last < first {
        return Some(0);
    }
    let s = stride.get();
    (last / s - first / s)
        .checked_add(u64::from(first.is_multiple_of(s)))?
        .checked_add(u64::from(keep_last && !last.is_multiple_of(s)))
}

/// ‖∂g_i/∂z‖₁ for each i, from g_z (m × 2d, column-major) over the
/// system's pattern of structurally nonzero entries.
pub(crate) fn gradient_sizes(pattern: &[(usize, usize)], g_z: &[f64], out: &mut [f64]) {
    let m = out.len();
    out.fill(0.0);
    for &(i, k) in pattern {
        if let Some(v) = g_z.get(i + k * m).filter(|_| i < m) {
            out[i] += v.abs();
        }
    }
}

/// Which half of z each g_i reads, from the pattern: bit 1 for q, bit 2
/// for p.
pub(crate) fn reads(pattern: &[(usize, usize)], d: usize, m: usize) -> Vec<u8> {
    let mut kind = vec![0u8; m];
    for &(i, k) in pattern {
        if i < m {
            kind[i] |= if k < d { 1 } else { 2 };
        }
    }
    kind
}

/// The scale of the variables g_i reads: ‖q‖∞ for a g_i of q alone, ‖p‖∞
/// for one of p alone, ‖z‖∞ otherwise. (Positions and momenta carry
/// different units; a holonomic g is measured against the positions only,
/// so that huge momenta cannot make a state far off M look close.)
#[inline]
pub(crate) fn variable_scale(reads: u8, qmax: f64, pmax: f64) -> f64 {
    match reads {
        1 => qmax,
        2 => pmax,
        _ => {
            if qmax.is_nan() || pmax.is_nan() {
                f64::NAN
            } else {
                qmax.max(pmax)
            }
        }
    }
}

/// The bound the constraint tolerance puts on |g_i| (see
/// [`Options::constraint_tolerance`]), from s = ‖∂g_i/∂z‖₁ and the scale
/// of the variables g_i reads ([`variable_scale`]):
///
/// tolerance · (s/2)² + 64 ε · s · scale.
///
/// The first term is relative to g_i's own size, in a way that neither a
/// change of units nor a shift of the origin moves: for a distance
/// constraint |q_a − q_b|² − ℓ², (s/2)² lies between ℓ² and 2ℓ², so 1e-8
/// allows the length to be off by about 5e-9 ℓ. The second is the
/// round-off of g at z, what rounding each variable in its last bit
/// changes g_i by (with room for the roundings that computed z): a system
/// far from its origin cannot place its points closer than that.
#[inline]
pub(crate) fn constraint_bound(tolerance: f64, size: f64, scale: f64) -> f64 {
    let half = 0.5 * size;
    tolerance * half * half + 64.0 * f64::EPSILON * size * scale
}

/// Whether every |g_i| is within `multiple` · ε Σ_k |∂g_i/∂z_k| |z_k|:
/// what rounding each entry of z = (q, p) in its last bit changes g_i by.
/// The sum runs over the Jacobian's pattern; `floor` (length m) receives
/// Σ_k |∂g_i/∂z_k| |z_k|.
pub(crate) fn g_within_roundoff(
    g: &[f64],
    pattern: &[(usize, usize)],
    g_z: &[f64],
    (q, p): (&[f64], &[f64]),
    multiple: f64,
    floor: &mut [f64],
) -> bool {
    let (d, m) = (q.len(), g.len());
    floor.fill(0.0);
    for &(i, k) in pattern {
        if i < m && k < 2 * d {
            let zk = if k < d { q[k] } else { p[k - d] };
            floor[i] += (g_z[i + k * m] * zk).abs();
        }
    }
    g.iter()
        .zip(floor.iter())
        .all(|(g, f)| g.abs() <= multiple * f64::EPSILON * f)
}

/// The bound on |g_i| at the result of a step: its round-off,
/// max(64ε, `newton_tolerance`) · s · scale, s = ‖∂g_i/∂z‖₁ and the scale
/// of the variables g_i reads. A step solves g = 0 by Newton: the
/// residual it leaves is the rounding of g's terms at the new state
/// (ε·Σ_k |∂g_i/∂z_k| |z_k| ≤ ε·s·scale, with room for the rounding of
/// the state itself and of the base map's stages), or what a Newton
/// tolerance looser than round-off allows. Unlike the constraint
/// tolerance, this does not depend on how far from M the run's initial
/// data was allowed to be.
#[inline]
pub(crate) fn step_bound(newton_tolerance: f64, size: f64, scale: f64) -> f64 {
    (64.0 * f64::EPSILON).max(newton_tolerance) * size * scale
}

/// The constraint whose |g_i| exceeds its [`constraint_bound`] by the
/// largest factor, as (|g_i|, i, that bound) (NaN the largest); the state
/// is on M when |g_i| is within its bound.
pub(crate) fn worst_constraint(
    g: &[f64],
    sizes: &[f64],
    reads: &[u8],
    scales: (f64, f64),
    tolerance: f64,
) -> (f64, usize, f64) {
    worst_constraint_by(g, sizes, reads, scales, |s, scale| {
        constraint_bound(tolerance, s, scale)
    })
}

/// [`worst_constraint`] against any bound(s, scale).
pub(crate) fn worst_constraint_by(
    g: &[f64],
    sizes: &[f64],
    reads: &[u8],
    (qmax, pmax): (f64, f64),
    bound_of: impl Fn(f64, f64) -> f64,
) -> (f64, usize, f64) {
    let mut worst = (0.0, 0, 0.0);
    let mut worst_ratio = f64::NEG_INFINITY;
    for (i, gi) in g.iter().enumerate() {
        let bound = bound_of(sizes[i], variable_scale(reads[i], qmax, pmax));
        let r = gi.abs();
        let ratio = match r / bound {
            x if x.is_nan() => f64::INFINITY,
            x => x,
        };
        if ratio > worst_ratio {
            worst = (r, i, bound);
            worst_ratio = ratio;
        }
    }
    worst
}

/// ‖(q, p)‖∞, NaN-propagating.
#[inline]
pub(crate) fn max_abs(q: &[f64], p: &[f64]) -> f64 {
    let (mq, mp) = (max_abs_of(q), max_abs_of(p));
    if mq.is_nan() || mp.is_nan() {
        return f64::NAN;
    }
    mq.max(mp)
}

/// ‖v‖∞, NaN-propagating. Each slice apart: the callers pass one half of
/// the state and an empty slice, whose loop then vanishes, where a chain
/// of the two kept its state from entry to entry.
#[inline(always)]
fn max_abs_of(v: &[f64]) -> f64 {
    if v.len() <= 8 {
        // (A few entries: one pass, no lanes to set up, no early exit.)
        let (mut m, mut nan) = (0.0f64, false);
        for x in v {
            nan |= x.is_nan();
            m = m.max(x.abs());
        }
        return if nan { f64::NAN } else { m };
    }
    if v.iter().fold(false, |n, x| n | x.is_nan()) {
        return f64::NAN;
    }
    norm_inf(v)
}

/// 1 / (√a · √b): the reciprocal of a particle constraint's scale from the
/// squares of its two factors, a = |∇g|² and b = the member's extent²
/// (Σ_a |x_a − x̄|², or |x|² for one particle), or b = |M⁻¹p|² over its
/// particles for the hidden constraint. A residual r is then judged by
/// |r| · inverse_scale ≤ tol: r is never squared and the roots are taken
/// apart, so the ratio stays right where a·b would underflow (length
/// scales down to ~1e-150).
///
/// Below that, a or b is subnormal or zero: squares of the member's
/// coordinates have underflowed, and so have the terms of g itself (for a
/// distance, |r|² and ℓ² of a bond of 1e-160 are both 0, so g = 0 "holds"
/// whatever r is), or the member is degenerate (a zero gradient,
/// coincident particles: a bond of any length ℓ > 0 cannot hold there, yet
/// its g = −ℓ² underflows to 0 for ℓ of 1e-300). Such a residual cannot be
/// judged at all, and the scale is ∞: every residual then reads ∞, or NaN
/// for a zero one, and fails `<=`, which the solvers report as a
/// non-finite residual rather than return a state they cannot tell is on
/// M. So does a factor that overflowed (a bond of 1e154: |r|² = 1e308 is
/// finite, |∇g|² = 4|r|² is not, and 1/∞ = 0 made every residual read 0),
/// and a NaN one.
#[inline(always)]
pub(crate) fn inverse_scale(a: f64, b: f64) -> f64 {
    let ab = a * b;
    // The common case in four comparisons: a, b ≥ MIN_POSITIVE (so
    // neither is NaN) and a·b normal and finite, which makes a and b
    // finite too (either infinite would make a·b infinite): every test
    // below passes, and the one root is taken.
    if a >= f64::MIN_POSITIVE
        && b >= f64::MIN_POSITIVE
        && (f64::MIN_POSITIVE..f64::INFINITY).contains(&ab)
    {
        return 1.0 / ab.sqrt();
    }
    inverse_scale_apart(a, b)
}

/// [`inverse_scale`] outside its common case.
#[cold]
fn inverse_scale_apart(a: f64, b: f64) -> f64 {
    let resolved = |x: f64| (f64::MIN_POSITIVE..f64::INFINITY).contains(&x);
    if !(resolved(a) && resolved(b)) {
        return f64::INFINITY;
    }
    let ab = a * b;
    if ab.is_normal() {
        // (One root where the product is representable: the common case.)
        return 1.0 / ab.sqrt();
    }
    1.0 / (a.sqrt() * b.sqrt())
}

/// The largest relative residual |g| / (|∇g| · extent) that rounding a
/// member's coordinates x (each by up to ε|x_i|) can leave: ε ‖x‖ /
/// extent, times 4 for the rounding of g's own evaluation
/// ([`Residuals`](crate::newton::Residuals) accepts a stalled iteration
/// there), and never above [`ROUNDOFF_CAP`]. From ‖x‖² and extent².
#[inline]
pub(crate) fn roundoff_floor(x_norm2: f64, extent2: f64) -> f64 {
    (4.0 * f64::EPSILON * (x_norm2 / extent2).sqrt()).min(ROUNDOFF_CAP)
}

/// √ε ≈ 1.5e-8: the largest residual accepted as round-off. Beyond it the
/// coordinates are too large for the member to be resolved at all (a bond
/// of 1 at 10¹⁵ has a floor above 1, where any iterate would "converge"
/// and the first-order residual no longer measures the bond error): the
/// solve fails as `NotConverged` instead of passing such a step.
pub(crate) const ROUNDOFF_CAP: f64 = 1.4901161193847656e-8;

/// Whether a residual r replaces `worst` in a running maximum: r larger,
/// or r NaN, and never once `worst` is NaN. `if !(r <= worst)` alone keeps
/// a NaN only until the next member's finite residual replaces it (a bond
/// whose |r|² overflowed to ∞ read NaN, and the member after it made the
/// cluster "converge" at iteration 0); `f64::max` drops it at once.
#[inline(always)]
pub(crate) fn worse(r: f64, worst: f64) -> bool {
    !(r <= worst) && !worst.is_nan()
}

/// |a · b| / (|a| · max(|b|, |b0|)): a hidden constraint ∇g · M⁻¹p
/// relative to its scale |∇g| |M⁻¹p|, for a velocity b left by a
/// projection from b0 (with |b0|² = `b0_sq`; 0 when there was none). An exact projection
/// leaves a residual of about κ ε |a| |b0|, so the velocity it started from
/// sets the scale: the one it leaves may be all round-off (a dimer moving
/// along its bond is left at rest, |b| ≈ ε |b0|, and |a · b| / (|a| |b|)
/// is then of order 1 however good the solve). Outside the range where
/// the squares are safe, both vectors are scaled by their largest entry
/// first, with b's own scale (the stricter test), so that neither the
/// squares nor the product of the norms can underflow or overflow (masses
/// of 1e300 and 1e-300 made |M⁻¹p|² overflow and the ratio read 0 for a
/// velocity 10 % off its tangent). 0 when b = 0 (nothing moves: the
/// constraint holds); NaN when a = 0 (a degenerate gradient) or either
/// holds NaN or ∞, so that the test fails.
#[inline(always)]
pub(crate) fn relative_dot_after(a: &[f64], b: &[f64], b0_sq: f64) -> f64 {
    let (mut dot, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        dot += x * y;
        aa += x * x;
        bb += y * y;
    }
    relative_dot_from_sums(dot, aa, bb, b0_sq).unwrap_or_else(|| relative_dot_scaled(a, b))
}

/// [`relative_dot_after`] from the sums it forms (dot = a · b, aa = |a|²,
/// bb = |b|², each accumulated in index order), so that a caller that
/// forms b on the fly needs no copy of it: `None` where the squares are
/// not safe and the scaled form must see the vectors themselves.
#[inline(always)]
pub(crate) fn relative_dot_from_sums(dot: f64, aa: f64, bb: f64, b0_sq: f64) -> Option<f64> {
    let bb = bb.max(b0_sq);
    let ab = aa * bb;
    (aa > 1e-200 && bb > 1e-200 && ab < f64::INFINITY).then(|| dot.abs() / ab.sqrt())
}

/// [`relative_dot_after`] with both vectors scaled by their largest entry.
#[cold]
fn relative_dot_scaled(a: &[f64], b: &[f64]) -> f64 {
    // (`f64::max` drops NaN, so finiteness is asked first.)
    if !a.iter().chain(b).all(|x| x.is_finite()) {
        return f64::NAN;
    }
    let am = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let bm = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if bm == 0.0 {
        return 0.0;
    }
    if am == 0.0 {
        return f64::NAN;
    }
    let (ia, ib) = (1.0 / am, 1.0 / bm);
    let (mut dot, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (x * ia, y * ib);
        dot += x * y;
        aa += x * x;
        bb += y * y;
    }
    dot.abs() / (aa.sqrt() * bb.sqrt())
}

/// The largest relative hidden-constraint residual (|∇g · M⁻¹p| over
/// |∇g| |M⁻¹p|, [`relative_dot_after`]) a particle projection may leave. The
/// projection solves N μ = G M⁻¹ p exactly, so it leaves about κ(N) ε;
/// above √ε, κ(N) exceeds 1/√ε and N is singular to half the working
/// precision (a triangle forced collinear left 1.7e-6, masses of 1e300 and
/// 1e-300 left 0.1). The Newton tolerance of the positions does not enter:
/// it bounds an iteration, and this is a linear solve.
pub(crate) const HIDDEN_LIMIT: f64 = 1.4901161193847656e-8;
#[cfg(test)]
mod tests {
    use super::*;

    fn nz(s: u64) -> NonZeroU64 {
        NonZeroU64::new(s).unwrap()
    }

    #[test]
    fn stored_states_counts_first_every_stride_th_and_last() {
        // (first, last, stride, keep_last) → count
        let table = [
            ((0, 0, 1, true), 1),
            ((0, 7, 3, true), 4),     // 0, 3, 6, 7
            ((0, 6, 3, true), 3),     // 0, 3, 6
            ((0, 7, 3, false), 3),    // 0, 3, 6
            ((5, 15, 10, false), 1),  // 10
            ((10, 20, 10, false), 2), // 10, 20
            ((0, u64::MAX - 1, 1, false), u64::MAX),
        ];
        for ((first, last, s, keep), want) in table {
            assert_eq!(stored_states(first, last, nz(s), keep), Some(want));
        }
        // One more than u64::MAX states: refused, not wrapped to 0.
        assert_eq!(stored_states(0, u64::MAX, nz(1), false), None);
    }

    #[test]
    fn check_run_refuses_each_limit_with_its_value() {
        assert_eq!(check_run(0.0, 0.1, 0, 3), Ok(3));
        assert!(
            matches!(check_run(f64::NAN, 0.1, 0, 3), Err(RunLimit::StartTime(t)) if t.is_nan())
        );
        assert_eq!(
            check_run(f64::INFINITY, 0.1, 0, 3),
            Err(RunLimit::StartTime(f64::INFINITY))
        );
        assert_eq!(check_run(0.0, 0.1, 0, MAX_STEPS), Ok(MAX_STEPS));
        assert_eq!(
            check_run(0.0, 0.1, 1, MAX_STEPS),
            Err(RunLimit::Steps(MAX_STEPS))
        );
        assert_eq!(
            check_run(0.0, 0.1, 1, u64::MAX),
            Err(RunLimit::Steps(u64::MAX))
        );
        assert_eq!(
            check_run(0.0, f64::MAX, 0, 3),
            Err(RunLimit::EndTime(f64::INFINITY))
        );
        assert_eq!(
            check_run(0.0, -f64::MAX, 0, 2),
            Err(RunLimit::EndTime(f64::NEG_INFINITY))
        );
        assert_eq!(check_run(0.0, f64::MAX, 0, 1), Ok(1));
    }
}
