//! Input validation at the API boundary (issue 13): every number a user
//! hands to an [`Integrator`](crate::Integrator) is checked once, before any
//! work, and a bad one is refused with [`StepError::InvalidInput`] naming it
//! and carrying its value.
//!
//! What is checked and why:
//! - the step size h: finite and nonzero (a step of 0 or ∞ has no meaning);
//! - the start time t0 and a stop time: finite (the times t0 + k·h stored
//!   with the trajectory would be NaN);
//! - [`Options`]: every tolerance finite where a finite value is meant and of
//!   the right sign, and the Newton iteration bounded. The stopping rule of
//!   every Newton iteration (see [`newton`](crate::newton)) guarantees a
//!   result at round-off only for a relative step tolerance far below 1, so
//!   `step_tolerance` is capped at [`MAX_STEP_TOLERANCE`]; `max_iterations`
//!   lies in 1 ..= [`MAX_ITERATIONS`] so that no call can spin, whatever the
//!   stagnation threshold;
//! - states: the dimension and finiteness checks live with the integrator
//!   (`check_dims`); `finite` is the check of a step's *result*: NaN or ∞
//!   anywhere in it is an error at that step, never an `Ok`.
//!
//! ```
//! use shake_runtime::{Integrator, Options, StormerVerlet, State, StepError, examples::Pendulum};
//! let bad = Options { constraint_tolerance: f64::NAN, ..Options::default() };
//! let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_options(bad);
//! let z0 = State::from_slices(&[0.0, -1.0], &[1.0, 0.0]);
//! assert!(matches!(integ.step(&z0), Err(StepError::InvalidInput { .. })));
//! ```

use crate::shake::Workspace;
use crate::{ConstrainedSystem, Options, StepError};

/// The largest accepted `NewtonOptions::step_tolerance` (relative): above it a
/// Newton iteration may stop on a point visibly off M.
pub const MAX_STEP_TOLERANCE: f64 = 1e-8;

/// The largest accepted `NewtonOptions::max_iterations`: a Newton iteration
/// that has not converged after this many steps will not.
pub const MAX_ITERATIONS: usize = 10_000;

fn invalid(what: &'static str, value: f64) -> StepError {
    StepError::InvalidInput { what, value }
}

/// h finite and nonzero.
pub(crate) fn step_size(h: f64) -> Result<(), StepError> {
    if h == 0.0 || !h.is_finite() {
        return Err(invalid("step size h must be finite and nonzero", h));
    }
    Ok(())
}

/// A time (start or stop) must be finite.
pub(crate) fn time(what: &'static str, t: f64) -> Result<(), StepError> {
    if !t.is_finite() {
        return Err(invalid(what, t));
    }
    Ok(())
}

/// Every field of [`Options`] in its documented range.
pub(crate) fn options(o: &Options) -> Result<(), StepError> {
    let n = &o.newton;
    if !(n.step_tolerance >= 0.0 && n.step_tolerance <= MAX_STEP_TOLERANCE) {
        return Err(invalid(
            "newton.step_tolerance must lie in [0, 1e-8]",
            n.step_tolerance,
        ));
    }
    if !(n.stagnation_threshold >= 0.0 && n.stagnation_threshold <= 1.0) {
        return Err(invalid(
            "newton.stagnation_threshold must lie in [0, 1]",
            n.stagnation_threshold,
        ));
    }
    if n.max_iterations == 0 || n.max_iterations > MAX_ITERATIONS {
        return Err(invalid(
            "newton.max_iterations must lie in 1 ..= 10000",
            n.max_iterations as f64,
        ));
    }
    // Relative to g's own size: above 1 a state would pass with |g| larger
    // than g itself, which no longer says "near M".
    if !(o.constraint_tolerance > 0.0 && o.constraint_tolerance <= 1.0) {
        return Err(invalid(
            "constraint_tolerance must be in (0, 1] (it is relative to the constraint's own size)",
            o.constraint_tolerance,
        ));
    }
    // ∞ is allowed: it turns the check off, as documented.
    if !(o.max_condition >= 1.0) {
        return Err(invalid("max_condition must be at least 1", o.max_condition));
    }
    if !(o.jump_ratio >= 0.0) {
        return Err(invalid("jump_ratio must be non-negative", o.jump_ratio));
    }
    if !(o.reverse_tolerance >= 0.0) {
        return Err(invalid(
            "reverse_tolerance must be non-negative (infinity turns the check off)",
            o.reverse_tolerance,
        ));
    }
    Ok(())
}

/// NaN or ∞ anywhere in a computed state is an error at that step (the
/// caller stamps step and time).
pub(crate) fn finite(what: &'static str, q: &[f64], p: &[f64]) -> Result<(), StepError> {
    crate::guard::Guard::finite(q, p, what, 0, 0.0)
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

/// (q, p) lies on M to `tolerance`, relative to g's scale there
/// ([`Options::constraint_tolerance`]), else [`StepError::NotOnConstraint`]
/// for the constraint furthest off (step 0, t = 0: the caller stamps
/// them). `ws.g`, `ws.g_z_1` and `ws.g_size` are scratch.
pub(crate) fn on_constraint<S: ConstrainedSystem>(
    system: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
    tolerance: f64,
) -> Result<(), StepError> {
    if system.constraint_count() == 0 {
        return Ok(());
    }
    match off_constraint(system, q, p, ws, tolerance) {
        None => Ok(()),
        Some(e) => Err(e),
    }
}

/// [`on_constraint`]'s error, or `None`.
pub(crate) fn off_constraint<S: ConstrainedSystem>(
    system: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
    tolerance: f64,
) -> Option<StepError> {
    let (residual, i, bound) = furthest_off(system, q, p, ws, tolerance);
    (!(residual <= bound)).then(|| StepError::NotOnConstraint {
        step: 0,
        t: 0.0,
        residual,
        tolerance: bound,
        constraint: system.constraint_name(i).to_string(),
        cause: None,
    })
}

/// The constraint furthest off M against its tolerance at (q, p)
/// ([`worst_constraint`]). Leaves g in `ws.g` and the gradient sizes in
/// `ws.g_size`; m ≥ 1.
pub(crate) fn furthest_off<S: ConstrainedSystem>(
    system: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
    tolerance: f64,
) -> (f64, usize, f64) {
    system.constraints(q, p, &mut ws.g);
    ws.g_z_1.fill(0.0);
    system.constraint_jacobian(q, p, &mut ws.g_z_1);
    gradient_sizes(&ws.pattern, &ws.g_z_1, &mut ws.g_size);
    let scales = (crate::guard::max_abs(q, &[]), crate::guard::max_abs(&[], p));
    worst_constraint(&ws.g, &ws.g_size, &ws.g_reads, scales, tolerance)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::NewtonOptions;

    #[test]
    fn default_options_pass_and_each_bad_field_is_named() {
        assert!(options(&Options::default()).is_ok());
        let d = Options::default();
        let bad = [
            Options {
                constraint_tolerance: -1.0,
                ..d
            },
            Options {
                constraint_tolerance: 1e300,
                ..d
            },
            Options {
                max_condition: f64::NAN,
                ..d
            },
            Options {
                jump_ratio: -0.5,
                ..d
            },
            Options {
                reverse_tolerance: f64::NAN,
                ..d
            },
            Options {
                reverse_tolerance: -1e-6,
                ..d
            },
            Options {
                newton: NewtonOptions {
                    max_iterations: usize::MAX,
                    ..d.newton
                },
                ..d
            },
            Options {
                newton: NewtonOptions {
                    step_tolerance: 1e181,
                    ..d.newton
                },
                ..d
            },
            Options {
                newton: NewtonOptions {
                    stagnation_threshold: -1e-6,
                    ..d.newton
                },
                ..d
            },
        ];
        for o in bad {
            assert!(
                matches!(options(&o), Err(StepError::InvalidInput { .. })),
                "{o:?}"
            );
        }
        // ∞ turns the reverse check off, as documented.
        let off = Options {
            reverse_tolerance: f64::INFINITY,
            ..d
        };
        assert!(options(&off).is_ok());
    }
}
