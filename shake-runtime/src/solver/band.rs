//! Cholesky within a band; for large matrices, one level of nested
//! dissection so that the factor and the solves run on threads.

use rayon::prelude::*;

/// N = L Lᵀ for a symmetric positive definite N with half-bandwidth b
/// (N_ij = 0 for |i − j| > b): L has the same band, so the factor overwrites
/// the m (b + 1) stored numbers in place. Row i stores N_{i, i−b..=i}.
///
/// From 2¹⁶ rows on (`PARTITION_MIN`, and b ≥ 1) the rows are partitioned,
/// once, by n and b alone: interiors I_0, I_1, …, I_K of 2¹⁴ rows (`BLOCK`)
/// (the last one the rest), each followed but the last by a separator S_j
/// of b rows. No entry of N couples two interiors (their rows are more
/// than b apart), so in the order (I_0, …, I_K, S_0, …, S_{K−1}) N is
///
/// ```text
/// [ N_II  N_IS ]   N_II = diag(N_{I_0 I_0}, …, N_{I_K I_K}),
/// [ N_SI  N_SS ]
/// ```
///
/// and the elimination in that order is: every interior factorised on its
/// own (a principal submatrix of an SPD matrix: SPD, no pivoting), with
/// Z_j = N_{I_j I_j}⁻¹ N_{I_j T_j} for the separator rows T_j next to I_j
/// (S_{j−1} and S_j); the Schur complement S = N_SS − Σ_j N_{T_j I_j} Z_j,
/// SPD again and banded (half-bandwidth 2b − 1 in separator order),
/// factorised serially. A solve is z_I = N_II⁻¹ r_I on every interior,
/// x_S = S⁻¹ (r_S − N_SI z_I), x_I = z_I − Σ_j Z_j x_{T_j}. The interiors'
/// work, nearly all of it, goes to threads; each interior's numbers are
/// computed by the same operations in the same order whichever thread
/// does it, and the partition depends on n and b only, so the factor and
/// every solve are the same bits on any number of threads. They are not
/// the bits of the serial elimination (another order of the same
/// elimination: they agree to round-off).
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
    /// The partition of a large matrix (None: the elimination in the
    /// natural order).
    split: Option<Box<Split>>,
}

/// Rows from which a band matrix is partitioned into interiors and
/// separators (below: the serial elimination in the natural order).
pub const PARTITION_MIN: usize = 1 << 16;

/// Rows of an interior of a partitioned band matrix: a few per core on
/// 10⁶ rows, and an interior's band (16 K rows × (b + 1)) stays in L2.
pub const BLOCK: usize = 1 << 14;

/// The nested dissection of [`BandCholesky`]: interior j is rows
/// j·(B + b) .. j·(B + b) + B (the last one to n), separator j the b rows
/// after it.
#[derive(Clone, Debug)]
struct Split {
    /// Separators K (interiors K + 1).
    seps: usize,
    /// Per interior j: Z_j column-major (one column per row of T_j, the
    /// separator rows S_{j−1} then S_j that exist), then N_{T_j I_j} Z_j
    /// (|T_j|², row-major).
    z: Vec<Vec<f64>>,
    /// The Schur complement's factor, rows in separator order (S_0 row 0,
    /// …, S_0 row b − 1, S_1 row 0, …).
    schur: BandCholesky,
    /// Separator right-hand sides and solutions (separator order).
    xs: Vec<f64>,
}

impl BandCholesky {
    /// The symbolic phase: the half-bandwidth of the lower-triangle pattern
    /// and, for large n, the partition.
    pub fn new(n: usize, lower: &[(usize, usize)]) -> Self {
        let b = lower.iter().map(|&(i, j)| i.abs_diff(j)).max().unwrap_or(0);
        Self::with_bandwidth(n, b)
    }

    fn with_bandwidth(n: usize, b: usize) -> Self {
        let split = (n >= PARTITION_MIN && b >= 1).then(|| {
            let p = BLOCK + b;
            let seps = (n - 1) / p;
            let z = (0..=seps)
                .map(|j| {
                    let t = b * (usize::from(j > 0) + usize::from(j < seps));
                    let rows = interior_rows(n, p, seps, j);
                    vec![0.0; t * rows + t * t]
                })
                .collect();
            Box::new(Split {
                seps,
                z,
                schur: BandCholesky::with_bandwidth(seps * b, 2 * b - 1),
                xs: vec![0.0; seps * b],
            })
        });
        BandCholesky {
            n,
            b,
            values: vec![0.0; n * (b + 1)],
            inv_diag: vec![0.0; n],
            split,
        }
    }

    /// The half-bandwidth b.
    pub fn bandwidth(&self) -> usize {
        self.b
    }

    /// Whether the matrix is partitioned (factor and solves on threads).
    pub fn partitioned(&self) -> bool {
        self.split.is_some()
    }

    /// Where N_ij (i ≥ j, i − j ≤ b) is stored.
    pub fn position(&self, i: usize, j: usize) -> usize {
        i * (self.b + 1) + (j + self.b - i)
    }

    /// The stored numbers.
    pub fn values_mut(&mut self) -> &mut [f64] {
        &mut self.values
    }

    /// L Lᵀ = N in place; the index of a non-positive pivot on failure
    /// (partitioned: the first in the elimination order, a row of N).
    pub fn factor(&mut self) -> Result<(), usize> {
        let (n, b) = (self.n, self.b);
        let Some(split) = self.split.as_deref_mut() else {
            return factor_rows(&mut self.values, &mut self.inv_diag, b);
        };
        let (w, p, seps) = (b + 1, BLOCK + b, split.seps);
        // The interiors (in place: an interior's factor writes its own
        // rows' entries within the interior only, so the couplings to the
        // separators, stored in the first b rows' left entries and in the
        // separator rows, stay N's), their Z_j and their terms of S.
        let interiors = self
            .values
            .par_chunks_mut(p * w)
            .zip(self.inv_diag.par_chunks_mut(p))
            .zip(split.z.par_iter_mut())
            .enumerate()
            .map(|(j, ((v, inv), z))| {
                let rows = interior_rows(n, p, seps, j);
                factor_rows(&mut v[..rows * w], &mut inv[..rows], b).map_err(|r| j * p + r)?;
                interior_schur(v, &inv[..rows], b, rows, j > 0, j < seps, z);
                Ok::<(), usize>(())
            })
            .reduce(|| Ok(()), Result::and);
        interiors?;
        // S = N_SS − Σ_j N_{T_j I_j} Z_j in separator order.
        let s = &mut split.schur;
        s.values.fill(0.0);
        let ws = 2 * b;
        for j in 0..seps {
            for r in 0..b {
                let row = j * p + BLOCK + r;
                for c in 0..=r {
                    s.values[(j * b + r) * ws + (c + 2 * b - 1 - r)] =
                        self.values[row * w + (c + b - r)];
                }
            }
        }
        for (j, z) in split.z.iter().enumerate() {
            let t = b * (usize::from(j > 0) + usize::from(j < seps));
            let first = if j > 0 { (j - 1) * b } else { j * b };
            let c = &z[z.len() - t * t..];
            for r in 0..t {
                for k in 0..=r {
                    let (si, sk) = (first + r, first + k);
                    s.values[si * ws + (sk + 2 * b - 1 - si)] -= c[r * t + k];
                }
            }
        }
        s.factor().map_err(|k| (k / b) * p + BLOCK + k % b)
    }

    /// x ← N⁻¹ x: L y = x, then Lᵀ x = y (partitioned: the interiors'
    /// solves, the separators', the interiors' corrections).
    pub fn solve(&mut self, x: &mut [f64]) {
        let (n, b) = (self.n, self.b);
        let x = &mut x[..n];
        let Some(split) = self.split.as_deref_mut() else {
            solve_rows(&self.values, &self.inv_diag, b, x);
            return;
        };
        let (w, p, seps) = (b + 1, BLOCK + b, split.seps);
        let (values, inv_diag) = (&self.values, &self.inv_diag);
        x.par_chunks_mut(p).enumerate().for_each(|(j, x)| {
            let rows = interior_rows(n, p, seps, j);
            let (lo, hi) = (j * p * w, (j * p + rows) * w);
            solve_rows(
                &values[lo..hi],
                &inv_diag[j * p..j * p + rows],
                b,
                &mut x[..rows],
            );
        });
        // r_S − N_SI z_I: separator row s meets I_j's last b rows (in its
        // own row) and I_{j+1}'s first b rows (in theirs).
        for j in 0..seps {
            for r in 0..b {
                let s = j * p + BLOCK + r;
                let mut acc = x[s];
                for i in s - b..j * p + BLOCK {
                    acc -= values[s * w + (i + b - s)] * x[i];
                }
                for i in (j + 1) * p..(s + b + 1).min(n) {
                    acc -= values[i * w + (s + b - i)] * x[i];
                }
                split.xs[j * b + r] = acc;
            }
        }
        split.schur.solve(&mut split.xs);
        let xs = &split.xs;
        let z = &split.z;
        x.par_chunks_mut(p).enumerate().for_each(|(j, x)| {
            let rows = interior_rows(n, p, seps, j);
            let first = if j > 0 { (j - 1) * b } else { 0 };
            let t = b * (usize::from(j > 0) + usize::from(j < seps));
            let (xi, xsep) = x.split_at_mut(rows);
            for (c, &xt) in xs[first..first + t].iter().enumerate() {
                for (xi, zi) in xi.iter_mut().zip(&z[j][c * rows..(c + 1) * rows]) {
                    *xi -= zi * xt;
                }
            }
            if j < seps {
                xsep.copy_from_slice(&xs[j * b..(j + 1) * b]);
            }
        });
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        let split = self.split.as_deref().map_or(0, |s| {
            s.z.iter().map(|z| z.capacity() * 8).sum::<usize>()
                + s.schur.bytes()
                + s.xs.capacity() * 8
        });
        (self.values.capacity() + self.inv_diag.capacity()) * 8 + split
    }
}

/// Rows of interior j of `seps` separators, period p = B + b: B, the
/// last one the rest of the n rows.
fn interior_rows(n: usize, p: usize, seps: usize, j: usize) -> usize {
    if j < seps {
        BLOCK
    } else {
        n - j * p
    }
}

/// The Cholesky factor in place of the band rows `v` (row i: N_{i,
/// i−b..=i}, entries left of row 0 ignored), 1/L_ii into `inv`; the row
/// of a non-positive pivot on failure.
fn factor_rows(v: &mut [f64], inv: &mut [f64], b: usize) -> Result<(), usize> {
    let w = b + 1;
    for i in 0..inv.len() {
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
                inv[i] = 1.0 / v[i * w + b];
            } else {
                v[i * w + (j + b - i)] = s / v[j * w + b];
            }
        }
    }
    Ok(())
}

/// x ← N⁻¹ x with the factor of [`factor_rows`] (x as long as `inv`;
/// entries left of row 0 not read).
fn solve_rows(v: &[f64], inv: &[f64], b: usize, x: &mut [f64]) {
    let n = x.len();
    if n == 0 {
        return;
    }
    // Slices of length n: the loops below index without bounds checks.
    let (v, inv) = (&v[..n * (b + 1)], &inv[..n]);
    if b == 1 {
        // Tridiagonal (a chain): row i stores (L_{i,i-1}, L_ii).
        let v = &v[..2 * n];
        let mut prev = x[0] * inv[0];
        x[0] = prev;
        for i in 1..n {
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

/// Interior j's part of the partitioned factor: `v` holds its `rows`
/// factorised rows then (unless last) the b rows of S_j; T_j is S_{j−1}
/// (`before`: its couplings in the first b rows' left entries) and S_j
/// (`after`). Writes Z_j = N_{I_j I_j}⁻¹ N_{I_j T_j} and N_{T_j I_j} Z_j
/// into `z`.
fn interior_schur(
    v: &[f64],
    inv: &[f64],
    b: usize,
    rows: usize,
    before: bool,
    after: bool,
    z: &mut [f64],
) {
    let w = b + 1;
    let t = b * (usize::from(before) + usize::from(after));
    let (zc, c) = z.split_at_mut(t * rows);
    // Column of T_j's row r (local numbering: S_{j−1} rows −b..0, S_j rows
    // rows..rows + b): N_{i, s} for the interior rows i within b of s.
    let sep = |k: usize| -> isize {
        if before && k < b {
            k as isize - b as isize
        } else {
            (rows + k - if before { b } else { 0 }) as isize
        }
    };
    // N_{i, s} (i interior, s separator, |i − s| ≤ b), from the row of the
    // larger index.
    let coupling = |i: usize, s: isize| -> f64 {
        if s < 0 {
            v[i * w + (b as isize + s - i as isize) as usize]
        } else {
            let s = s as usize;
            v[s * w + (i + b - s)]
        }
    };
    for k in 0..t {
        let s = sep(k);
        let col = &mut zc[k * rows..(k + 1) * rows];
        col.fill(0.0);
        let (lo, hi) = if s < 0 {
            (0, ((s + b as isize) as usize + 1).min(rows))
        } else {
            ((s as usize).saturating_sub(b).min(rows), rows)
        };
        for i in lo..hi {
            if i as isize - s <= b as isize && s - i as isize <= b as isize {
                col[i] = coupling(i, s);
            }
        }
        solve_rows(v, inv, b, col);
    }
    for r in 0..t {
        let s = sep(r);
        for k in 0..t {
            let zk = &zc[k * rows..(k + 1) * rows];
            let (lo, hi) = if s < 0 {
                (0, ((s + b as isize) as usize + 1).min(rows))
            } else {
                ((s as usize).saturating_sub(b).min(rows), rows)
            };
            let mut acc = 0.0;
            for i in lo..hi {
                if i as isize - s <= b as isize && s - i as isize <= b as isize {
                    acc += coupling(i, s) * zk[i];
                }
            }
            c[r * t + k] = acc;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random SPD band matrix, strictly diagonally dominant (off-diagonal
    /// entries in (−1, 1), diagonal their row's and column's absolute sum
    /// plus (0.1, 1.1)), in a solver of either kind.
    fn random(n: usize, b: usize, partition: bool, seed: u64) -> BandCholesky {
        let mut s = seed;
        let mut uniform = move || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut m = BandCholesky::with_bandwidth(n, b);
        if !partition {
            m.split = None;
        }
        assert_eq!(m.partitioned(), partition);
        let mut off = vec![0.0; n];
        for i in 0..n {
            for j in i.saturating_sub(b)..i {
                let x = 2.0 * uniform() - 1.0;
                let k = m.position(i, j);
                m.values[k] = x;
                off[i] += x.abs();
                off[j] += x.abs();
            }
        }
        for i in 0..n {
            let k = m.position(i, i);
            m.values[k] = off[i] + 0.1 + uniform();
        }
        m
    }

    /// N x (N from the lower band of `m` before factoring) and ‖N‖_∞.
    fn apply(values: &[f64], b: usize, x: &[f64]) -> (Vec<f64>, f64) {
        let (n, w) = (x.len(), b + 1);
        let (mut y, mut rows) = (vec![0.0; n], vec![0.0f64; n]);
        for i in 0..n {
            for j in i.saturating_sub(b)..=i {
                let v = values[i * w + (j + b - i)];
                y[i] += v * x[j];
                rows[i] += v.abs();
                if j != i {
                    y[j] += v * x[i];
                    rows[j] += v.abs();
                }
            }
        }
        (y, rows.into_iter().fold(0.0, f64::max))
    }

    fn norm(x: &[f64]) -> f64 {
        x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }

    /// ‖N x − r‖_∞ / (‖N‖_∞ ‖x‖_∞) after factor and solve.
    fn residual(mut m: BandCholesky, seed: u64) -> f64 {
        let n = m.n;
        let n0 = m.values.clone();
        let r: Vec<f64> = (0..n)
            .map(|i| ((i as u64 * 7919 + seed) % 1000) as f64 / 500.0 - 1.0)
            .collect();
        m.factor().unwrap();
        let mut x = r.clone();
        m.solve(&mut x);
        let (nx, nn) = apply(&n0, m.b, &x);
        let d: Vec<f64> = nx.iter().zip(&r).map(|(a, b)| a - b).collect();
        norm(&d) / (nn * norm(&x))
    }

    /// The partitioned solve meets the backward-error bound of Cholesky,
    /// O((b + 1) ε) relative residual, as the serial one does, on n not a
    /// multiple of the period (the last interior longer than the others).
    #[test]
    fn partitioned_solve_is_at_round_off_as_the_serial_one() {
        for (n, b) in [
            (70_001, 1),
            (PARTITION_MIN + 3 * (BLOCK + 2) - 1, 2),
            (80_000, 3),
        ] {
            for (seed, partition) in [(1, true), (1, false), (2, true)] {
                let m = random(n, b, partition, seed);
                let rel = residual(m, seed);
                assert!(
                    rel <= 4.0 * (b + 1) as f64 * f64::EPSILON,
                    "n {n} b {b}: {rel:e}"
                );
            }
        }
    }

    /// The partitioned and the serial solutions agree to round-off of a
    /// well-conditioned (diagonally dominant) matrix.
    #[test]
    fn partitioned_and_serial_solutions_agree() {
        let (n, b) = (PARTITION_MIN + 12_345, 2);
        let (mut a, mut s) = (random(n, b, true, 5), random(n, b, false, 5));
        a.factor().unwrap();
        s.factor().unwrap();
        let r: Vec<f64> = (0..n).map(|i| (i % 17) as f64 - 8.0).collect();
        let (mut xa, mut xs) = (r.clone(), r);
        a.solve(&mut xa);
        s.solve(&mut xs);
        let d: Vec<f64> = xa.iter().zip(&xs).map(|(a, b)| a - b).collect();
        assert!(
            norm(&d) <= 64.0 * f64::EPSILON * norm(&xs),
            "{:e}",
            norm(&d) / norm(&xs)
        );
        assert_ne!(xa, xs, "another elimination order: not the same bits");
    }

    /// A non-positive pivot is named by its row of N, in an interior and
    /// in a separator (the Schur complement's pivot mapped back).
    #[test]
    fn a_non_positive_pivot_names_its_row() {
        for b in [1, 2] {
            let n = PARTITION_MIN + 1000;
            for row in [40_000, 2 * (BLOCK + b) + BLOCK + b - 1, n - 1] {
                let mut m = random(n, b, true, 3);
                let k = m.position(row, row);
                m.values[k] = -1.0;
                assert_eq!(m.factor(), Err(row), "b {b}");
                let mut m = random(n, b, false, 3);
                m.values[k] = -1.0;
                assert_eq!(m.factor(), Err(row), "b {b}");
            }
        }
    }

    /// Any number of threads: the same bits.
    #[test]
    fn partitioned_solve_is_the_same_bits_on_one_and_two_threads() {
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut m = random(PARTITION_MIN + 777, 2, true, 9);
                m.factor().unwrap();
                let mut x: Vec<f64> = (0..m.n).map(|i| (i % 13) as f64).collect();
                m.solve(&mut x);
                x.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
            })
        };
        assert_eq!(run(1), run(2));
    }
}
