//! The classical path's own buffers and the structure it finds once per
//! system: the pattern of G = g_q, the diagonal mass matrix when A is one,
//! G's columns, and the terms of SHAKE's Jacobian within its band.

use crate::linalg::Band;
use crate::system::{ConstrainedSystem, ConstraintKind};

/// What the classical step (parent module) keeps between calls, allocated
/// once. Buffers that receive a system's output are written only by the
/// system, as the contract in `system` requires.
#[derive(Clone, Debug)]
pub(crate) struct Buffers {
    /// The entries (i, k) of `JACOBIAN_PATTERN` with k < d (∂g_i/∂q_k).
    pub(crate) pattern: Vec<(usize, usize)>,
    /// The column group (i mod groups) of each entry of `pattern`.
    pub(crate) group: Vec<usize>,
    /// The diagonal of the constant mass matrix A = H_pp when A is
    /// diagonal and `products` lists the Jacobian's terms (empty
    /// otherwise, or when the classical path does not apply).
    pub(crate) mass: Vec<f64>,
    /// The terms a_k G1(i, k) G0(j, k) of SHAKE's Jacobian that fall in its
    /// band (A diagonal), in the order the sum takes them: k, the entry of
    /// G1 (i + k m), of G0 (j + k m) and of the Jacobian (i + j m).
    pub(crate) products: Vec<[usize; 4]>,
    /// −a h ∇V(q0), the first kick.
    pub(crate) kick: Vec<f64>,
    /// The momentum increment before the last kick.
    pub(crate) u: Vec<f64>,
    /// Scratch vector and `grad_p` output (written only by the system).
    pub(crate) v: Vec<f64>,
    pub(crate) w: Vec<f64>,
    /// `grad_q` output (written only by the system).
    pub(crate) hq: Vec<f64>,
    /// The round-off level of each g_i at the step's start.
    pub(crate) floor: Vec<f64>,
}

impl Buffers {
    /// For `sys`, whose SHAKE Jacobian has the band `band` and is
    /// evaluated in `groups` column groups (`shake::Workspace`).
    pub(crate) fn new<S: ConstrainedSystem>(sys: &S, band: Band, groups: usize) -> Self {
        let (d, m) = (sys.dof(), sys.constraint_count());
        let pattern: Vec<(usize, usize)> = sys
            .jacobian_pattern()
            .iter()
            .copied()
            .filter(|&(i, k)| i < m && k < d)
            .collect();
        let mut mass = diagonal_mass(sys);
        // G's columns (CSC: column k's rows are
        // col_rows[col_start[k]..col_start[k + 1]]).
        let col_start = column_starts(sys, d, m);
        let col_rows = column_rows(sys, d, m);
        // The list only where the classical path can run (g holonomic, H
        // separable with quadratic T), and only while it stays a few times
        // G's own size: a column with r rows gives r² terms, so a G with
        // dense columns would make it quadratic in m (its Jacobian then
        // comes from the column groups, without the list).
        let classical =
            sys.kind() == ConstraintKind::Holonomic && sys.separable() && sys.quadratic_kinetic();
        let most = 16 * pattern.len().max(4);
        let products = if classical && !mass.is_empty() {
            jacobian_products(&mass, &col_start, &col_rows, m, band, most)
        } else {
            None
        };
        if products.is_none() {
            mass.clear();
        }
        let products = products.unwrap_or_default();
        Buffers {
            group: pattern.iter().map(|&(i, _)| i % groups).collect(),
            pattern,
            mass,
            products,
            kick: vec![0.0; d],
            u: vec![0.0; d],
            v: vec![0.0; d],
            w: vec![0.0; d],
            hq: vec![0.0; d],
            floor: vec![0.0; m],
        }
    }
}

/// The diagonal of A = H_pp when H is separable with a quadratic T and A
/// is diagonal (masses), found by applying `grad_p` (= A p) to the unit
/// vectors; empty otherwise, and for d > 2048 (d² work to find out).
fn diagonal_mass<S: ConstrainedSystem>(sys: &S) -> Vec<f64> {
    let d = sys.dof();
    if !(sys.separable() && sys.quadratic_kinetic()) || d > 2048 {
        return Vec::new();
    }
    let q = vec![0.5; d];
    let (mut e, mut w) = (vec![0.0; d], vec![0.0; d]);
    // T homogeneous: A·0 = 0 (else grad_p is not A p).
    sys.grad_p(&q, &e, &mut w);
    if w.iter().any(|&x| x != 0.0) {
        return Vec::new();
    }
    let mut mass = vec![0.0; d];
    for k in 0..d {
        e[k] = 1.0;
        w.fill(0.0);
        sys.grad_p(&q, &e, &mut w);
        e[k] = 0.0;
        if w.iter().enumerate().any(|(j, &x)| j != k && x != 0.0) || !w[k].is_finite() {
            return Vec::new();
        }
        mass[k] = w[k];
    }
    mass
}

/// `col_start`: where each column k < d of G
/// starts in `column_rows`.
fn column_starts<S: ConstrainedSystem>(sys: &S, d: usize, m: usize) -> Vec<usize> {
    let mut start = vec![0usize; d + 1];
    for &(i, k) in sys.jacobian_pattern() {
        if i < m && k < d {
            start[k + 1] += 1;
        }
    }
    for k in 0..d {
        start[k + 1] += start[k];
    }
    start
}

/// `products`: for each k with a_k ≠ 0 and each pair (i, j) of rows of
/// G's column k within the Jacobian's band, [k, i + k m, j + k m, i + j m]
/// (k, then i, then j: the order of the sum it replaces); `None` beyond
/// `most` terms.
fn jacobian_products(
    mass: &[f64],
    col_start: &[usize],
    col_rows: &[usize],
    m: usize,
    band: Band,
    most: usize,
) -> Option<Vec<[usize; 4]>> {
    let mut products = Vec::new();
    for k in 0..mass.len() {
        if mass[k] == 0.0 {
            continue;
        }
        let rows = &col_rows[col_start[k]..col_start[k + 1]];
        for &i in rows {
            for &j in rows {
                if i <= j + band.lower && j <= i + band.upper {
                    if products.len() == most {
                        return None;
                    }
                    products.push([k, i + k * m, j + k * m, i + j * m]);
                }
            }
        }
    }
    Some(products)
}

/// The rows of each column k < d of G, column after column.
fn column_rows<S: ConstrainedSystem>(sys: &S, d: usize, m: usize) -> Vec<usize> {
    let start = column_starts(sys, d, m);
    let mut next = start.clone();
    let mut rows = vec![0usize; start[d]];
    for &(i, k) in sys.jacobian_pattern() {
        if i < m && k < d {
            rows[next[k]] = i;
            next[k] += 1;
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_products_list_follows_the_band_and_stops_at_its_cap() {
        // G of 3 constraints on 2 columns: column 0 reads rows 0, 1, 2,
        // column 1 rows 1, 2 (CSC).
        let (col_start, col_rows) = (vec![0, 3, 5], vec![0, 1, 2, 1, 2]);
        let full = Band { lower: 2, upper: 2 };
        let all = jacobian_products(&[1.0, 2.0], &col_start, &col_rows, 3, full, 100).unwrap();
        assert_eq!(all.len(), 9 + 4);
        // k first, then i, then j; entries as flat indices.
        assert_eq!(all[0], [0, 0, 0, 0]);
        assert_eq!(all[1], [0, 0, 1, 3]);
        assert_eq!(all[9], [1, 1 + 3, 1 + 3, 1 + 3]);
        // A tridiagonal band drops the (0, 2) and (2, 0) terms.
        let tri = Band { lower: 1, upper: 1 };
        assert_eq!(
            jacobian_products(&[1.0, 2.0], &col_start, &col_rows, 3, tri, 100)
                .unwrap()
                .len(),
            7 + 4
        );
        // A zero mass adds no terms; past the cap there is no list.
        let one = jacobian_products(&[0.0, 2.0], &col_start, &col_rows, 3, full, 100).unwrap();
        assert_eq!(one.len(), 4);
        assert_eq!(
            jacobian_products(&[1.0, 2.0], &col_start, &col_rows, 3, full, 12),
            None
        );
    }
}
