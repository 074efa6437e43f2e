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
    /// band (A diagonal), in the order the sum takes them, column k after
    /// column: the entry of `pattern` holding G1(i, k), the one holding
    /// G0(j, k), and the entry of the Jacobian (i + j m).
    pub(crate) products: Vec<[usize; 3]>,
    /// For each column k with terms, in increasing k: a_k, and where its
    /// terms end in `products` (they start where the previous column's
    /// end), so that h a_k is formed and tested once per column.
    pub(crate) product_columns: Vec<(f64, usize)>,
    /// G0 = G(q0) and G1 = G at the last Jacobian's q1, packed: entry e of
    /// each is ∂g_i/∂q_k for (i, k) = `pattern[e]` (`packed_jacobian`).
    pub(crate) g0: Vec<f64>,
    pub(crate) g1: Vec<f64>,
    /// Whether `pattern` is the system's whole pattern, so that the system's
    /// own packed values ([`ConstrainedSystem::constraint_jacobian_values`])
    /// are entries of `pattern` in its order.
    pub(crate) whole: bool,
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
    /// The residual at λ = 0, kept for the fitted roots of decoupled
    /// constraints (`classical::fitted_root`).
    pub(crate) r0: Vec<f64>,
    /// For one constraint of degree at most 2 (a distance), the nonzero
    /// entries (j, k, ∂²g/∂q_j∂q_k) of its constant Hessian: SHAKE's
    /// residual along its line is then the quadratic whose λ² coefficient
    /// they give (`fixed`). Empty otherwise.
    pub(crate) g_qq: Vec<(usize, usize, f64)>,
}

impl Buffers {
    /// For `sys`, whose SHAKE Jacobian has the band `band` and is
    /// evaluated in `groups` column groups (`geoshake::Workspace`).
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
        let (col_rows, col_entries) = column_rows(sys, d, m);
        // The list only where the classical path can run (g holonomic, H
        // separable with quadratic T), and only while it stays a few times
        // G's own size: a column with r rows gives r² terms, so a G with
        // dense columns would make it quadratic in m (its Jacobian then
        // comes from the column groups, without the list).
        let classical =
            sys.kind() == ConstraintKind::Holonomic && sys.separable() && sys.quadratic_kinetic();
        let most = 16 * pattern.len().max(4);
        let products = if classical && !mass.is_empty() {
            jacobian_products(&mass, &col_start, (&col_rows, &col_entries), m, band, most)
        } else {
            None
        };
        if products.is_none() {
            mass.clear();
        }
        let products = products.unwrap_or_default();
        let mut product_columns: Vec<(f64, usize)> = Vec::new();
        for (n, t) in products.iter().enumerate() {
            match product_columns.last_mut() {
                Some((_, end)) if products[n - 1][0] == t[0] => *end = n + 1,
                _ => product_columns.push((mass[t[0]], n + 1)),
            }
        }
        let products = products.iter().map(|t| [t[1], t[2], t[3]]).collect();
        Buffers {
            group: pattern.iter().map(|&(i, _)| i % groups).collect(),
            g0: vec![0.0; pattern.len()],
            g1: vec![0.0; pattern.len()],
            whole: pattern.len() == sys.jacobian_pattern().len(),
            pattern,
            mass,
            products,
            product_columns,
            kick: vec![0.0; d],
            u: vec![0.0; d],
            v: vec![0.0; d],
            w: vec![0.0; d],
            hq: vec![0.0; d],
            floor: vec![0.0; m],
            r0: vec![0.0; m],
            g_qq: if classical && m == 1 {
                constant_hessian(sys)
            } else {
                Vec::new()
            },
        }
    }
}

impl Buffers {
    /// jac ← jac − h Σ_k a_k G1[:, k] G0[:, k]ᵀ over the terms of
    /// `products` (A diagonal), in their order, each (h a_k G1(i, k))
    /// G0(j, k): the Jacobian's sum of outer products of G's sparse
    /// columns, for every classical kernel (slice and fixed-size).
    #[inline(always)]
    pub(crate) fn subtract_products(&self, h: f64, jac: &mut [f64]) {
        let (g0, g1) = (&self.g0, &self.g1);
        let mut start = 0;
        for &(mass, end) in &self.product_columns {
            let terms = &self.products[start..end];
            start = end;
            let a = h * mass;
            // (h a_k can underflow: such a column adds nothing, even
            // against an infinite entry of G.)
            if a != 0.0 {
                for &[e1, e0, at] in terms {
                    jac[at] -= (a * g1[e1]) * g0[e0];
                }
            }
        }
    }
}

/// The q-block of ∇²g of a system with one constraint that declares it of
/// degree at most 2 ([`ConstrainedSystem::quadratic_constraints`]), as its
/// nonzero entries (j, k, value), read at two unrelated points (no two
/// coordinates equal, so that differences q_a − q_b do not vanish) and
/// kept only if they agree (a constant Hessian); empty otherwise, and for
/// d > 64 (4d² numbers to read it; the fixed-size step it serves is for
/// small systems).
fn constant_hessian<S: ConstrainedSystem>(sys: &S) -> Vec<(usize, usize, f64)> {
    let d = sys.dof();
    if !sys.quadratic_constraints() || sys.constraint_count() != 1 || d > 64 {
        return Vec::new();
    }
    let n2 = 2 * d;
    let read = |x: &dyn Fn(f64) -> f64| {
        let q: Vec<f64> = (0..d).map(|k| x(k as f64)).collect();
        let mut out = vec![0.0; n2 * n2];
        sys.constraint_hessian(&q, &q, &[1.0], &mut out);
        out
    };
    let (a, b) = (read(&|k| 0.5 + 0.37 * k), read(&|k| -0.375 + 0.11 * k * k));
    let mut entries = Vec::new();
    for k in 0..d {
        for j in 0..d {
            let (x, y) = (a[j + k * n2], b[j + k * n2]);
            if x != y || !x.is_finite() {
                return Vec::new();
            }
            if x != 0.0 {
                entries.push((j, k, x));
            }
        }
    }
    entries
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
/// G's column k within the Jacobian's band, [k, e(i, k), e(j, k), i + j m]
/// with e the entry of the classical pattern (k, then i, then j: the order
/// of the sum it replaces); `None` beyond `most` terms.
fn jacobian_products(
    mass: &[f64],
    col_start: &[usize],
    (col_rows, col_entries): (&[usize], &[usize]),
    m: usize,
    band: Band,
    most: usize,
) -> Option<Vec<[usize; 4]>> {
    let mut products = Vec::new();
    for k in 0..mass.len() {
        if mass[k] == 0.0 {
            continue;
        }
        let at = col_start[k]..col_start[k + 1];
        let (rows, entries) = (&col_rows[at.clone()], &col_entries[at]);
        for (&i, &ei) in rows.iter().zip(entries) {
            for (&j, &ej) in rows.iter().zip(entries) {
                if i <= j + band.lower && j <= i + band.upper {
                    if products.len() == most {
                        return None;
                    }
                    products.push([k, ei, ej, i + j * m]);
                }
            }
        }
    }
    Some(products)
}

/// The rows of each column k < d of G, column after column, and where
/// each sits in the classical pattern (the entries (i, k) of the system's
/// pattern with i < m, k < d, in its order).
fn column_rows<S: ConstrainedSystem>(sys: &S, d: usize, m: usize) -> (Vec<usize>, Vec<usize>) {
    let start = column_starts(sys, d, m);
    let mut next = start.clone();
    let mut rows = vec![0usize; start[d]];
    let mut entries = vec![0usize; start[d]];
    let mut e = 0;
    for &(i, k) in sys.jacobian_pattern() {
        if i < m && k < d {
            rows[next[k]] = i;
            entries[next[k]] = e;
            next[k] += 1;
            e += 1;
        }
    }
    (rows, entries)
}

/// G(q) packed over `cl.pattern` into `out` (`cl.g0` or `cl.g1`): the
/// system's own packed values when it has them and the classical pattern
/// is its whole pattern, else read out of its dense g_z (written into
/// `dense`). The same numbers either way.
#[inline(always)]
pub(crate) fn packed_jacobian<S: ConstrainedSystem>(
    sys: &S,
    q: &[f64],
    p: &[f64],
    (pattern, whole): (&[(usize, usize)], bool),
    dense: &mut [f64],
    out: &mut [f64],
) {
    if whole && sys.constraint_jacobian_values(q, p, out) {
        return;
    }
    let m = sys.constraint_count();
    sys.constraint_jacobian(q, p, dense);
    for (o, &(i, k)) in out.iter_mut().zip(pattern) {
        *o = dense[i + k * m];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_products_list_follows_the_band_and_stops_at_its_cap() {
        // G of 3 constraints on 2 columns: column 0 reads rows 0, 1, 2,
        // column 1 rows 1, 2 (CSC).
        // The pattern, by rows: (0,0) (1,0) (1,1) (2,0) (2,1), so column 0
        // holds entries 0, 1, 3 and column 1 entries 2, 4.
        let (col_start, col_rows) = (vec![0, 3, 5], vec![0, 1, 2, 1, 2]);
        let col_entries = [0, 1, 3, 2, 4];
        let cols = (&col_rows[..], &col_entries[..]);
        let full = Band { lower: 2, upper: 2 };
        let all = jacobian_products(&[1.0, 2.0], &col_start, cols, 3, full, 100).unwrap();
        assert_eq!(all.len(), 9 + 4);
        // k first, then i, then j; G's entries as entries of the pattern,
        // the Jacobian's as flat indices.
        assert_eq!(all[0], [0, 0, 0, 0]);
        assert_eq!(all[1], [0, 0, 1, 3]);
        assert_eq!(all[2], [0, 0, 3, 6]);
        assert_eq!(all[9], [1, 2, 2, 1 + 3]);
        assert_eq!(all[12], [1, 4, 4, 2 + 2 * 3]);
        // A tridiagonal band drops the (0, 2) and (2, 0) terms.
        let tri = Band { lower: 1, upper: 1 };
        assert_eq!(
            jacobian_products(&[1.0, 2.0], &col_start, cols, 3, tri, 100)
                .unwrap()
                .len(),
            7 + 4
        );
        // A zero mass adds no terms; past the cap there is no list.
        let one = jacobian_products(&[0.0, 2.0], &col_start, cols, 3, full, 100).unwrap();
        assert_eq!(one.len(), 4);
        assert_eq!(
            jacobian_products(&[1.0, 2.0], &col_start, cols, 3, full, 12),
            None
        );
    }

    /// Two coordinates, g = (q₀ − q₁)² or (q₀ − q₁)³ (`cubic`), claiming
    /// degree ≤ 2 either way: only `constant_hessian`'s reads are
    /// implemented.
    struct Claims {
        cubic: bool,
    }

    impl crate::system::Hamiltonian for Claims {
        fn dof(&self) -> usize {
            2
        }
        fn separable(&self) -> bool {
            true
        }
        fn hamiltonian(&self, _: &[f64], _: &[f64]) -> f64 {
            0.0
        }
        fn grad_q(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn grad_p(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn hessian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    }

    impl ConstrainedSystem for Claims {
        fn constraint_count(&self) -> usize {
            1
        }
        fn kind(&self) -> ConstraintKind {
            ConstraintKind::Holonomic
        }
        fn quadratic_constraints(&self) -> bool {
            true
        }
        fn jacobian_pattern(&self) -> &[(usize, usize)] {
            &[(0, 0), (0, 1)]
        }
        fn constraint_name(&self, _: usize) -> &str {
            "g"
        }
        fn constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn constraint_hessian(&self, q: &[f64], _: &[f64], l: &[f64], out: &mut [f64]) {
            // ∇²g = c [[1, −1], [−1, 1]] in the q-block of the 4 × 4.
            let c = l[0] * if self.cubic { 6.0 * (q[0] - q[1]) } else { 2.0 };
            (out[0], out[1], out[4], out[5]) = (c, -c, -c, c);
        }
        fn hidden_constraints(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn hidden_constraint_jacobian(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
        fn nondegeneracy_matrix(&self, _: &[f64], _: &[f64], _: &mut [f64]) {}
    }

    #[test]
    fn the_constant_hessian_is_read_only_where_it_is_constant() {
        assert_eq!(
            constant_hessian(&Claims { cubic: false }),
            [(0, 0, 2.0), (1, 0, -2.0), (0, 1, -2.0), (1, 1, 2.0)]
        );
        // A claim the Hessian contradicts (6(q₀ − q₁), which two points
        // with equal coordinates would not see) is not taken.
        assert!(constant_hessian(&Claims { cubic: true }).is_empty());
        // The hand-written pendulum claims it (|q|² − ℓ²); the Hopf
        // constraint does not.
        let pendulum = crate::examples::Pendulum::default();
        assert_eq!(constant_hessian(&pendulum), [(0, 0, 2.0), (1, 1, 2.0)]);
        assert!(constant_hessian(&crate::examples::HopfHarmonic::unit()).is_empty());
    }
}
