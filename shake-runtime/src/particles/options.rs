//! What a particle RATTLE is asked to do and what a step reports: the
//! method, the solver for the multipliers' linear systems, the tolerances
//! ([`Options`]) and the per-step [`StepReport`].

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
/// use shake_runtime::particles::{Method, Options};
/// let o = Options { method: Method::Shake, ..Options::default() };
/// assert_eq!(o.tol, 1e-10);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Options {
    /// Every constraint's relative residual |g_k(q1)| / (|∇g_k(q0)| ·
    /// extent_k(q0)) must end ≤ tol (extent_k² = Σ_a |x_a − x̄|² over the
    /// member's particles; for a distance constraint this is
    /// ≈ | |r| − l | / l).
    pub tol: f64,
    /// Newton iterations allowed per step (per cluster on the cluster path).
    pub max_iter: usize,
    /// SHAKE or RATTLE.
    pub method: Method,
    /// The linear solver.
    pub solver: SolverChoice,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            tol: 1e-10,
            max_iter: 50,
            method: Method::Rattle,
            solver: SolverChoice::Auto,
        }
    }
}
