//! Input validation at the API boundary: every number a user
//! hands to an [`Integrator`](crate::Integrator) is checked once, before any
//! work, and a bad one is refused with [`StepError::InvalidInput`] naming it
//! and carrying its value.
//!
//! What is checked and why:
//! - the step size h: finite and nonzero (a step of 0 or ∞ has no meaning);
//! - a run's start time t0, its number of steps and the time of its last
//!   step, together (`tolerance::check_run`, shared with the particle
//!   path): t0 finite, at most [`MAX_STEPS`] steps, t0 + n·h finite (the
//!   times stored with the trajectory would be NaN or ∞), and the states it
//!   stores counted without wrapping and reserved before the first step
//!   ([`StepError::Storage`] when they do not fit);
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
//! use geoshake_runtime::{Integrator, Options, StormerVerlet, State, StepError, examples::Pendulum};
//! let bad = Options { constraint_tolerance: f64::NAN, ..Options::default() };
//! let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_options(bad);
//! let z0 = State::from_slices(&[0.0, -1.0], &[1.0, 0.0]);
//! assert!(matches!(integ.step(&z0), Err(StepError::InvalidInput { .. })));
//! ```

use crate::{Options, StepError};

/// The largest accepted `NewtonOptions::step_tolerance` (relative): above it a
/// Newton iteration may stop on a point visibly off M.
pub const MAX_STEP_TOLERANCE: f64 = 1e-8;

/// The largest accepted `NewtonOptions::max_iterations` (and particle
/// `Options::max_iter`), the most steps of one run, and the smallest
/// relative tolerance of the particle path: limits both engines share.
pub use crate::tolerance::{MAX_ITERATIONS, MAX_STEPS, MIN_RELATIVE_TOLERANCE};

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
