//! General sparse Cholesky through faer.
//!
//! Why faer: it is pure Rust (no BLAS/SuiteSparse to install), well kept,
//! and splits exactly the phases we need: `factorize_symbolic_cholesky`
//! (AMD fill-reducing ordering, elimination tree, simplicial or supernodal
//! structure) once, `factorize_numeric_llt` into a caller-owned value buffer
//! with caller-owned scratch (so a step does not allocate), and in-place
//! solves.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, MatMut, Par, Side};
use std::sync::Arc;

/// N = L Lᵀ for a symmetric positive definite N with an arbitrary pattern.
/// The lower triangle of N is stored by columns (CSC).
///
/// ```
/// use geoshake_runtime::solver::SparseCholesky;
/// // An arrow: every row couples to the last one.
/// let n = 4;
/// let mut lower = vec![];
/// for i in 0..n { lower.push((i, i)); }
/// for i in 0..n - 1 { lower.push((n - 1, i)); }
/// let mut s = SparseCholesky::new(n, &lower).unwrap();
/// for &(i, j) in &lower {
///     let k = s.position(i, j);
///     s.values_mut()[k] = if i == j { 4.0 } else { 1.0 };
/// }
/// s.factor().unwrap();
/// let mut b = [5.0, 5.0, 5.0, 7.0];
/// s.solve(&mut b);
/// for v in b { assert!((v - 1.0).abs() < 1e-14); }
/// ```
pub struct SparseCholesky {
    n: usize,
    /// The symbolic phase, which no numeric call changes: clones share it.
    analysis: Arc<Analysis>,
    values: Vec<f64>,
    factor: Vec<f64>,
    stack: MemBuffer,
}

/// N's pattern and its symbolic factorisation (ordering, elimination tree)
/// with the scratch the numeric calls need.
struct Analysis {
    pattern: SymbolicSparseColMat<usize>,
    symbolic: SymbolicCholesky<usize>,
    scratch: StackReq,
}

/// Shares the symbolic phase; copies the values and the factor, and gives
/// the copy scratch of its own.
impl Clone for SparseCholesky {
    fn clone(&self) -> Self {
        SparseCholesky {
            n: self.n,
            analysis: Arc::clone(&self.analysis),
            values: self.values.clone(),
            factor: self.factor.clone(),
            stack: MemBuffer::new(self.analysis.scratch),
        }
    }
}

impl std::fmt::Debug for SparseCholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseCholesky")
            .field("n", &self.n)
            .field("nnz", &self.values.len())
            .field("factor_nnz", &self.factor.len())
            .finish()
    }
}

impl SparseCholesky {
    /// The symbolic phase: CSC pattern of the lower triangle, AMD ordering,
    /// symbolic factorisation, and scratch for factor and solve.
    pub fn new(n: usize, lower: &[(usize, usize)]) -> Result<Self, String> {
        let mut entries: Vec<(usize, usize)> = lower
            .iter()
            .map(|&(i, j)| if i >= j { (j, i) } else { (i, j) })
            .collect();
        entries.sort_unstable();
        entries.dedup();
        let mut col_ptr = vec![0usize; n + 1];
        for &(j, _) in &entries {
            col_ptr[j + 1] += 1;
        }
        for j in 0..n {
            col_ptr[j + 1] += col_ptr[j];
        }
        let row_idx: Vec<usize> = entries.iter().map(|&(_, i)| i).collect();
        let pattern = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        let symbolic = factorize_symbolic_cholesky(
            pattern.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .map_err(|e| format!("{e:?}"))?;
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
        ]);
        let stack = MemBuffer::try_new(req).map_err(|e| format!("{e:?}"))?;
        let factor = vec![0.0; symbolic.len_val()];
        let analysis = Analysis {
            pattern,
            symbolic,
            scratch: req,
        };
        Ok(SparseCholesky {
            n,
            values: vec![0.0; entries.len()],
            analysis: Arc::new(analysis),
            factor,
            stack,
        })
    }

    /// Where N_ij (i ≥ j, in the pattern) is stored: column j, row i.
    pub fn position(&self, i: usize, j: usize) -> usize {
        let p = self.analysis.pattern.as_ref();
        let start = p.col_ptr()[j];
        let rows = &p.row_idx()[start..p.col_ptr()[j + 1]];
        start
            + rows
                .binary_search(&i)
                .expect("entry outside the symbolic pattern")
    }

    /// The values of N's lower triangle (CSC order).
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// The numeric factorisation.
    pub fn factor(&mut self) -> Result<(), usize> {
        let a = SparseColMatRef::new(self.analysis.pattern.as_ref(), &self.values);
        let stack = MemStack::new(&mut self.stack);
        self.analysis
            .symbolic
            .factorize_numeric_llt(
                &mut self.factor,
                a,
                Side::Lower,
                LltRegularization::default(),
                Par::Seq,
                stack,
                Default::default(),
            )
            .map(|_| ())
            .map_err(|e| match e {
                faer::linalg::cholesky::llt::factor::LltError::NonPositivePivot { index } => {
                    index.saturating_sub(1)
                }
            })
    }

    /// b ← N⁻¹ b.
    pub fn solve(&mut self, b: &mut [f64]) {
        let llt = LltRef::new(&self.analysis.symbolic, &self.factor);
        let rhs = MatMut::from_column_major_slice_mut(b, self.n, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(&mut self.stack));
    }

    /// Bytes held: pattern, values, factor (an estimate of faer's symbolic
    /// structure as 2 indices per row and per factor entry), scratch.
    pub fn bytes(&self) -> usize {
        let p = self.analysis.pattern.as_ref();
        (p.col_ptr().len() + p.row_idx().len()) * 8
            + self.values.capacity() * 8
            + self.factor.capacity() * 8
            + self.factor.len() * 8
            + self.n * 16
    }
}
