//! The sparse linear-solver layer of the large-system path: solves with the
//! symmetric positive definite N = G M⁻¹ Gᵀ of holonomic constraints.
//!
//! Every solver has a *symbolic phase*, done once from the sparsity pattern
//! of N (which entries can be nonzero: constraints sharing a particle), and
//! a *numeric phase*, done whenever N is re-evaluated: the values are
//! written at positions fixed by the symbolic phase ([`SpdSolver::position`]),
//! then factorised, then used for any number of solves.
//!
//! - [`BandCholesky`]: N is banded in the constraints' own order (a chain:
//!   tridiagonal). Cholesky within the band, O(m b²) work and m (b + 1)
//!   numbers, no fill outside the band.
//! - [`SparseCholesky`]: anything else, through faer's sparse Cholesky
//!   (approximate-minimum-degree ordering and symbolic factorisation once,
//!   numeric LLᵀ per use; simplicial or supernodal as faer decides).
//!
//! Independent small clusters (rigid waters) never reach this layer: each is
//! solved densely on its own (see `particles::cluster`).
//!
//! ```
//! use geoshake_runtime::solver::SpdSolver;
//! // N = [[2, -1], [-1, 2]] (lower triangle given).
//! let mut n = SpdSolver::band(2, &[(0, 0), (1, 0), (1, 1)]);
//! for (i, j, v) in [(0, 0, 2.0), (1, 0, -1.0), (1, 1, 2.0)] {
//!     let k = n.position(i, j);
//!     n.values_mut()[k] = v;
//! }
//! n.factor().unwrap();
//! let mut b = [1.0, 1.0];
//! n.solve(&mut b);
//! assert!((b[0] - 1.0).abs() < 1e-15 && (b[1] - 1.0).abs() < 1e-15);
//! ```

mod band;
mod sparse;

pub use band::BandCholesky;
pub use sparse::SparseCholesky;

/// A symmetric positive definite solver chosen from the pattern.
#[derive(Clone, Debug)]
pub enum SpdSolver {
    /// Cholesky within a band.
    Band(BandCholesky),
    /// faer's sparse Cholesky.
    Sparse(Box<SparseCholesky>),
}

impl SpdSolver {
    /// The band solver for an n×n matrix whose lower-triangle pattern is
    /// `lower` ((i, j) with i ≥ j).
    pub fn band(n: usize, lower: &[(usize, usize)]) -> Self {
        SpdSolver::Band(BandCholesky::new(n, lower))
    }

    /// The general sparse solver (symbolic analysis and ordering now).
    pub fn sparse(n: usize, lower: &[(usize, usize)]) -> Result<Self, String> {
        SparseCholesky::new(n, lower).map(|s| SpdSolver::Sparse(Box::new(s)))
    }

    /// The solver's name: "band" or "sparse".
    pub fn name(&self) -> &'static str {
        match self {
            SpdSolver::Band(_) => "band",
            SpdSolver::Sparse(_) => "sparse",
        }
    }

    /// Where entry (i, j), i ≥ j, of N lives in [`values_mut`](Self::values_mut).
    /// (i, j) must be in the pattern given at construction.
    pub fn position(&self, i: usize, j: usize) -> usize {
        match self {
            SpdSolver::Band(s) => s.position(i, j),
            SpdSolver::Sparse(s) => s.position(i, j),
        }
    }

    /// The values of N's lower triangle, to be filled before [`factor`](Self::factor).
    pub fn values_mut(&mut self) -> &mut [f64] {
        match self {
            SpdSolver::Band(s) => s.values_mut(),
            SpdSolver::Sparse(s) => s.values_mut(),
        }
    }

    /// Sets every value to zero (before an assembly that adds into them).
    pub fn clear(&mut self) {
        self.values_mut().fill(0.0);
    }

    /// The numeric factorisation N = L Lᵀ. On failure, the index of the
    /// first pivot that was not positive (in the solver's own order).
    pub fn factor(&mut self) -> Result<(), usize> {
        match self {
            SpdSolver::Band(s) => s.factor(),
            SpdSolver::Sparse(s) => s.factor(),
        }
    }

    /// b ← N⁻¹ b with the last factorisation.
    pub fn solve(&mut self, b: &mut [f64]) {
        match self {
            SpdSolver::Band(s) => s.solve(b),
            SpdSolver::Sparse(s) => s.solve(b),
        }
    }

    /// Bytes held (pattern, values, factor, scratch).
    pub fn bytes(&self) -> usize {
        match self {
            SpdSolver::Band(s) => s.bytes(),
            SpdSolver::Sparse(s) => s.bytes(),
        }
    }
}
