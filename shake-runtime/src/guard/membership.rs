//! Whether a state lies on M = {g = 0} to the constraint tolerance,
//! relative to g's own scale there ([`Options::constraint_tolerance`]):
//! the check of initial data and of a step's result.

use crate::error::StepError;
use crate::shake::Workspace;
use crate::system::ConstrainedSystem;
use crate::tolerance::{gradient_sizes, max_abs, worst_constraint};
#[allow(unused_imports)] // (doc links)
use crate::Options;
use crate::SolveError;

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
    // A residual or bound that overflowed says nothing about M: ∞ ≤ ∞
    // would let g = ∞ pass at a state of 10²⁰⁰.
    let overflowed = !residual.is_finite() || !bound.is_finite();
    (overflowed || !(residual <= bound)).then(|| StepError::NotOnConstraint {
        step: 0,
        t: 0.0,
        residual,
        tolerance: bound,
        constraint: system.constraint_name(i).to_string(),
        cause: overflowed.then_some(SolveError::NonFinite { iterations: 0 }),
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
    let scales = (max_abs(q, &[]), max_abs(&[], p));
    worst_constraint(&ws.g, &ws.g_size, &ws.g_reads, scales, tolerance)
}
