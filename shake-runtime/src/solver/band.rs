//! Cholesky within a band.

/// N = L Lᵀ for a symmetric positive definite N with half-bandwidth b
/// (N_ij = 0 for |i − j| > b): L has the same band, so the factor overwrites
/// the m (b + 1) stored numbers in place. Row i stores N_{i, i−b..=i}.
///
/// ```
/// use geoshake_runtime::solver::BandCholesky;
/// let mut n = BandCholesky::new(3, &[(0, 0), (1, 0), (1, 1), (2, 1), (2, 2)]);
/// assert_eq!(n.bandwidth(), 1);
/// for i in 0..3 {
///     let k = n.position(i, i);
///     n.values_mut()[k] = 4.0;
/// }
/// n.factor().unwrap();
/// let mut b = [4.0, 8.0, 12.0];
/// n.solve(&mut b);
/// assert_eq!(b, [1.0, 2.0, 3.0]);
/// ```
#[derive(Clone, Debug)]
pub struct BandCholesky {
    n: usize,
    b: usize,
    values: Vec<f64>,
    /// 1/L_ii: the solves multiply instead of dividing.
    inv_diag: Vec<f64>,
}

impl BandCholesky {
    /// The symbolic phase: the half-bandwidth of the lower-triangle pattern.
    pub fn new(n: usize, lower: &[(usize, usize)]) -> Self {
        let b = lower.iter().map(|&(i, j)| i.abs_diff(j)).max().unwrap_or(0);
        BandCholesky {
            n,
            b,
            values: vec![0.0; n * (b + 1)],
            inv_diag: vec![0.0; n],
        }
    }

    /// The half-bandwidth b.
    pub fn bandwidth(&self) -> usize {
        self.b
    }

    /// Where N_ij (i ≥ j, i − j ≤ b) is stored.
    pub fn position(&self, i: usize, j: usize) -> usize {
        i * (self.b + 1) + (j + self.b - i)
    }

    /// The stored numbers.
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// L Lᵀ = N in place; the index of a non-positive pivot on failure.
    pub fn factor(&mut self) -> Result<(), usize> {
        let (n, b) = (self.n, self.b);
        let w = b + 1;
        let v = &mut self.values;
        for i in 0..n {
            let lo = i.saturating_sub(b);
            for j in lo..=i {
                // s = N_ij − Σ_{k<j} L_ik L_jk, k within both rows' bands.
                let mut s = v[i * w + (j + b - i)];
                for k in lo..j {
                    s -= v[i * w + (k + b - i)] * v[j * w + (k + b - j)];
                }
                if j == i {
                    if !(s > 0.0 && s.is_finite()) {
                        return Err(i);
                    }
                    v[i * w + b] = s.sqrt();
                    self.inv_diag[i] = 1.0 / v[i * w + b];
                } else {
                    v[i * w + (j + b - i)] = s / v[j * w + b];
                }
            }
        }
        Ok(())
    }

    /// x ← N⁻¹ x: L y = x, then Lᵀ x = y.
    pub fn solve(&self, x: &mut [f64]) {
        let (n, b) = (self.n, self.b);
        let x = &mut x[..n];
        let inv = &self.inv_diag[..n];
        if b == 1 {
            // Tridiagonal (a chain): row i stores (L_{i,i-1}, L_ii).
            let v = &self.values[..2 * n];
            let mut prev = 0.0;
            for i in 0..n {
                prev = (x[i] - v[2 * i] * prev) * inv[i];
                x[i] = prev;
            }
            let mut next = 0.0;
            for i in (0..n).rev() {
                let l = if i + 1 < n { v[2 * (i + 1)] } else { 0.0 };
                next = (x[i] - l * next) * inv[i];
                x[i] = next;
            }
            return;
        }
        let w = b + 1;
        let v = &self.values;
        for i in 0..n {
            let lo = i.saturating_sub(b);
            let mut s = x[i];
            for k in lo..i {
                s -= v[i * w + (k + b - i)] * x[k];
            }
            x[i] = s * inv[i];
        }
        for i in (0..n).rev() {
            let hi = (i + b).min(n - 1);
            let mut s = x[i];
            for k in i + 1..=hi {
                s -= v[k * w + (i + b - k)] * x[k];
            }
            x[i] = s * inv[i];
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        (self.values.capacity() + self.inv_diag.capacity()) * 8
    }
}
