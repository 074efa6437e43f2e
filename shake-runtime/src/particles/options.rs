//! What a particle RATTLE is asked to do: the method, the solver for the
//! multipliers' linear systems and the tolerances ([`Options`]).

use crate::error::StepError;
use crate::tolerance::{MAX_ITERATIONS, MIN_RELATIVE_TOLERANCE};

/// SHAKE (positions constrained, momenta as Störmer–Verlet leaves them) or
/// RATTLE (momenta projected onto M^H as well).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// RATTLE: p1 also satisfies the hidden constraints G(q1) M⁻¹ p1 = 0.
    #[default]
    Rattle,
    /// SHAKE: no velocity stage.
    Shake,
}

/// Which linear solver handles the constraint graph.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Default)]
pub enum SolverChoice {
    /// From the pattern: independent clusters if every cluster is small
    /// (≤ 12 constraints) and within one family, a band solver if N is
    /// banded (half-bandwidth ≤ 16) in the constraints' order, faer's sparse
    /// Cholesky otherwise.
    #[default]
    Auto,
    /// Independent per-cluster Newton (refused if a cluster is too big).
    Clusters,
    /// Cholesky within the band of N (refused if the band is wider than 64).
    Band,
    /// faer's sparse Cholesky.
    Sparse,
}

/// Tolerances and choices of a [`Rattle`](super::Rattle).
///
/// ```
/// use geoshake_runtime::particles::{Method, Options};
/// let o = Options { method: Method::Shake, ..Options::default() };
/// assert_eq!(o.tol, 1e-12);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Options {
    /// Every constraint's relative residual |g_k(q1)| / (|∇g_k(q0)| ·
    /// extent_k(q0)) must end ≤ tol (extent_k² = Σ_a |x_a − x̄|² over the
    /// member's particles; for a distance constraint this is the relative
    /// bond-length error | |r| − l | / l to first order). Default 1e-12:
    /// the bond error LAMMPS `fix rattle` delivers at its `tol 1e-10`
    /// (it over-converges), so that a comparison of cost per constraint
    /// compares equal accuracy. Far from the origin the coordinates may
    /// not resolve it (a member's residual cannot go below about
    /// 4ε ‖x‖ / extent, ≈ 3e-9 for a bond of 1 at 10⁶): there an
    /// iteration whose residual no longer halves (it stalls, wanders or
    /// creeps down by rounding) with every member within `tol` or that
    /// floor is accepted, and the step reports the residual reached.
    /// In [4ε, 1): below
    /// [`MIN_RELATIVE_TOLERANCE`](crate::validate::MIN_RELATIVE_TOLERANCE)
    /// = 4ε rounding alone can keep the residual above the tolerance, and
    /// Newton would spend its whole budget on rounding noise.
    pub tol: f64,
    /// Newton iterations allowed per step (per cluster on the cluster
    /// path), in 1 ..= [`MAX_ITERATIONS`](crate::validate::MAX_ITERATIONS)
    /// = 10 000: Newton converges in a few iterations or not at all, and a
    /// larger budget only makes a failing step hang.
    pub max_iter: usize,
    /// SHAKE or RATTLE.
    pub method: Method,
    /// The linear solver.
    pub solver: SolverChoice,
}

impl Options {
    /// `Ok` when every option is in its documented range, else
    /// [`StepError::InvalidInput`] naming it, its range and its value.
    /// [`Rattle::new`](super::Rattle::new) calls it.
    ///
    /// ```
    /// use geoshake_runtime::{particles::Options, StepError};
    /// assert!(Options::default().validate().is_ok());
    /// let tiny = Options { tol: 1e-20, ..Options::default() };
    /// assert!(matches!(
    ///     tiny.validate(),
    ///     Err(StepError::InvalidInput { what, value }) if what.starts_with("tol") && value == 1e-20
    /// ));
    /// ```
    pub fn validate(&self) -> Result<(), StepError> {
        if !(self.tol >= MIN_RELATIVE_TOLERANCE && self.tol < 1.0) {
            return Err(StepError::InvalidInput {
                what: "tol, the relative residual tolerance, must lie in [4ε, 1) (4ε ≈ 8.9e-16: below it f64 rounding alone can keep the residual above the tolerance)",
                value: self.tol,
            });
        }
        if self.max_iter == 0 || self.max_iter > MAX_ITERATIONS {
            return Err(StepError::InvalidInput {
                what: "max_iter, the Newton iteration budget, must lie in 1 ..= 10000",
                value: self.max_iter as f64,
            });
        }
        Ok(())
    }
}

impl Default for Options {
    fn default() -> Self {
        Options {
            tol: 1e-12,
            max_iter: 50,
            method: Method::Rattle,
            solver: SolverChoice::Auto,
        }
    }
}
