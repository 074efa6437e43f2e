//! The cross-cutting checks, all run before anything is emitted, with every
//! failure collected (serde_derive's context style): the user sees each
//! offending constraint or pair in one compile.
//!
//! Symbolic facts come first (they are exact); where a property only has to
//! hold *on* M or M^H, the macro samples points of those sets numerically, by
//! evaluating the expression graph in `f64` (see [`Sampler`]). The sampling is
//! deterministic (fixed seed), so a given input always gives the same answer.

use crate::diff::Derived;
use crate::lower::System;
use crate::symbolic::{Graph, NodeId};
use syn::Error;

/// The error list; `finish` turns it into one `Result`.
#[derive(Default)]
pub struct Ctxt {
    errors: Vec<Error>,
}

impl Ctxt {
    fn error(&mut self, span: proc_macro2::Span, msg: String) {
        self.errors.push(Error::new(span, msg));
    }

    pub fn finish(self) -> Result<(), Vec<Error>> {
        if self.errors.is_empty() {
            Ok(())
        } else {
            Err(self.errors)
        }
    }
}

/// Shortens a printed expression for a diagnostic.
fn short(s: String) -> String {
    const MAX: usize = 240;
    if s.chars().count() <= MAX {
        s
    } else {
        let t: String = s.chars().take(MAX).collect();
        format!("{t} …")
    }
}

pub fn check(sys: &mut System, der: &Derived) -> Result<(), Vec<Error>> {
    let mut cx = Ctxt::default();
    state_dependence(&mut cx, sys);
    duplicates(&mut cx, sys);
    if !cx.errors.is_empty() {
        return cx.finish();
    }
    let mut sampler = Sampler::new(sys, der);
    dependence(&mut cx, sys, der, &mut sampler);
    // Dependent constraints make N singular too: one error, not a cascade.
    let dependent = !cx.errors.is_empty();
    coisotropy(&mut cx, sys, der, &mut sampler);
    if !dependent {
        nondegeneracy(&mut cx, sys, der, &mut sampler);
    }
    cx.finish()
}

/// **Every constraint depends on the state.** A constant g_i is either never
/// satisfied or always satisfied; either way it is not a constraint.
///
/// ```text
/// error: constraint `c` does not depend on the state: it is the constant 1
///   |         c: length - length + 1,
///   |         ^
/// ```
fn state_dependence(cx: &mut Ctxt, sys: &System) {
    for c in &sys.constraints {
        if sys.graph.support(c.node).is_empty() {
            cx.error(
                c.span,
                format!(
                    "constraint `{}` does not depend on the state: it simplifies to `{}`, which \
                     does not involve q or p, so it is either never or always satisfied",
                    c.name,
                    short(sys.graph.display(c.node))
                ),
            );
        }
    }
}

/// **No constraint is declared twice.** Equal expressions are the same node
/// (hash-consing after canonicalisation), so this is exact for anything the
/// simplifier can identify, e.g. `q[0]^2 + q[1]^2 - 1` and `q[1]*q[1] + q[0]^2 - 1`.
///
/// ```text
/// error: constraint `b` is the same function as constraint `a`: q[0]^2 + ...
/// ```
fn duplicates(cx: &mut Ctxt, sys: &mut System) {
    for j in 0..sys.constraints.len() {
        let gj = sys.constraints[j].node;
        // g_j = −g_i is as dependent as g_j = g_i.
        let minus = sys.graph.neg(gj);
        if let Some(ci) = sys.constraints[..j]
            .iter()
            .find(|c| c.node == gj || c.node == minus)
        {
            let cj = &sys.constraints[j];
            cx.error(
                cj.span,
                format!(
                    "constraint `{}` is the same function as constraint `{}` (up to sign: {}): \
                     duplicate constraints make g_z rank-deficient and the multipliers undetermined",
                    cj.name,
                    ci.name,
                    short(sys.graph.display(gj))
                ),
            );
        }
    }
}

/// **The constraints are independent.** SHAKE and RATTLE solve for one
/// multiplier per constraint, which needs g_z of full rank m on M. If g_z is
/// rank-deficient at every sampled point of M, the constraints are (locally)
/// dependent and we refuse, at the first constraint that adds no rank.
///
/// ```text
/// error: constraint `b` is linearly dependent on the others: g_z has rank 1 < 2 at every sampled point of M
/// ```
fn dependence(cx: &mut Ctxt, sys: &System, der: &Derived, s: &mut Sampler) {
    let m = sys.constraints.len();
    if m < 2 {
        return;
    }
    let n2 = 2 * sys.dof;
    let mut worst: Option<(usize, usize)> = None; // (rank, first deficient row)
    for i in 0..SAMPLES {
        let Some(z) = s.m_point(sys, der, i) else {
            break;
        };
        let vals = s.eval(&sys.graph, &z);
        let mut a = vec![0.0; m * n2];
        for &((i, k), node) in &der.g_z {
            a[i * n2 + k] = vals[node.index()];
        }
        let (rank, first) = rank_rows(&a, m, n2);
        if rank == m {
            return;
        }
        worst = Some((rank, first));
    }
    if let Some((rank, first)) = worst {
        let c = &sys.constraints[first];
        cx.error(
            c.span,
            format!(
                "constraint `{}` is linearly dependent on the constraints before it: the Jacobian g_z \
                 has rank {rank} < {m} at every sampled point of M, so the multipliers λ are not \
                 determined (remove or combine dependent constraints)",
                c.name
            ),
        );
    }
}

/// **Coisotropy** (the paper's coisotropy assumption, Sections 1 and 3.2):
/// {g_i, g_j} = 0 on M for all i, j.
///
/// Rule: compute the bracket symbolically. If it simplifies to 0 (always the
/// case for holonomic constraints, and for m = 1) the pair is accepted.
/// Otherwise the bracket only has to vanish *on M*: evaluate it at
/// [`SAMPLES`] points of M, found by Newton projection from seeded random
/// points (parameters sampled in [0.5, 1.5]), and accept the pair only if it
/// is zero to round-off at every one of them. A pair whose bracket is nonzero
/// at any point of M is refused; so is a pair that cannot be checked because
/// no point of M was found. Every failing pair is reported, at g_i.
///
/// Example: with `a: q[0]` and `b: p[1] + q[0]*p[0]`, {a, b} = q[0] = a, which
/// is not identically zero but vanishes on M: accepted. With `a: q[0]` and
/// `b: p[0]`, {a, b} = 1: refused:
///
/// ```text
/// error: constraints `a` and `b` do not Poisson-commute on M: {a, b} = 1 ...
/// ```
fn coisotropy(cx: &mut Ctxt, sys: &mut System, der: &Derived, s: &mut Sampler) {
    let m = sys.constraints.len();
    if der.kind == crate::diff::Kind::Holonomic {
        return;
    }
    let d = sys.dof;
    let mut pending = Vec::new();
    for i in 0..m {
        for j in i + 1..m {
            let (gi, gj) = (sys.constraints[i].node, sys.constraints[j].node);
            let b = sys.graph.bracket(gi, gj, d);
            if !sys.graph.is_zero(b) {
                pending.push((i, j, b));
            }
        }
    }
    if pending.is_empty() {
        return;
    }
    let points: Vec<Vec<f64>> = (0..SAMPLES).map_while(|i| s.m_point(sys, der, i)).collect();
    for (i, j, b) in pending {
        let (ni, nj) = (&sys.constraints[i].name, &sys.constraints[j].name);
        let shown = short(sys.graph.display(b));
        if points.is_empty() {
            cx.error(
                sys.constraints[i].span,
                format!(
                    "constraints `{ni}` and `{nj}` may not Poisson-commute on M: {{{ni}, {nj}}} = {shown} \
                     is not identically zero, and no point of M was found to check that it vanishes there \
                     (coisotropy assumption, the paper's Section 3.2)"
                ),
            );
            continue;
        }
        let (gi, gj) = (sys.constraints[i].node, sys.constraints[j].node);
        let scale_terms = bracket_scale(&mut sys.graph, gi, gj, d);
        for z in &points {
            let vals = s.eval(&sys.graph, z);
            let scale: f64 = scale_terms.iter().map(|t| vals[t.index()].abs()).sum();
            let value = vals[b.index()];
            // NaN counts as nonzero: a bracket undefined on M is not accepted.
            if value.is_nan() || value.abs() > 1e-8 * scale + 1e-12 {
                let at: Vec<String> = z.iter().map(|x| format!("{x:.3}")).take(8).collect();
                cx.error(
                    sys.constraints[i].span,
                    format!(
                        "constraints `{ni}` and `{nj}` do not Poisson-commute on M: {{{ni}, {nj}}} = {shown}, \
                         which is {value:.3e} at the point z = ({}{}) of M. The constraint manifold is not \
                         coisotropic (the paper's coisotropy assumption, Section 3.2), so the fibres \
                         exp(Σ λ_i X_{{g_i}}) leave M and SHAKE/RATTLE are not defined",
                        at.join(", "),
                        if z.len() > 8 { ", …" } else { "" }
                    ),
                );
                break;
            }
        }
    }
}

/// The products |∂g_i/∂q_k ∂g_j/∂p_k| and |∂g_i/∂p_k ∂g_j/∂q_k| that make
/// up {g_i, g_j}: the scale against which "zero to round-off" is judged.
fn bracket_scale(graph: &mut Graph, f: NodeId, g: NodeId, d: usize) -> Vec<NodeId> {
    let mut out = Vec::new();
    for v in graph.support(f).to_vec() {
        let k = v.index();
        let partner = crate::symbolic::VarId(if k < d { k + d } else { k - d } as u32);
        if graph.depends_on(g, partner) {
            let a = graph.diff(f, v);
            let b = graph.diff(g, partner);
            out.push(graph.mul2(a, b));
        }
    }
    out
}

/// **Nondegeneracy** (the paper's Assumption 1.1, Section 2.3; failing
/// examples in Section 5.2): N_ij = {{H,g_i},g_j} must be invertible on M^H.
///
/// Rule: refuse when N is *identically* singular. Symbolically: a row of N
/// that simplifies to zero (in particular N ≡ 0, as for g = q̄,
/// H = p²/2 + p̄q). Numerically: N rank-deficient at every one of at least
/// two sampled points of M^H. A system singular only at some points (the
/// Hopf constraint, where N = 4(|q|² − |p|²) vanishes on a subset) is accepted;
/// that is a run-time matter.
///
/// ```text
/// error: the nondegeneracy assumption fails for constraint `bar`: {{H, bar}, g_j} = 0 for every j ...
/// ```
fn nondegeneracy(cx: &mut Ctxt, sys: &mut System, der: &Derived, s: &mut Sampler) {
    let m = sys.constraints.len();
    if m == 0 {
        return;
    }
    let g = &sys.graph;
    let mut symbolic = false;
    for (i, row) in der.n.iter().enumerate() {
        if row.iter().all(|n| g.is_zero(*n)) {
            symbolic = true;
            let c = &sys.constraints[i];
            let name = &c.name;
            let msg = if g.is_zero(der.hidden[i]) {
                format!(
                    "the nondegeneracy assumption fails for constraint `{name}`: H is constant along its fibre \
                     ({{{name}, H}} ≡ 0), so the hidden constraint is empty (M^H = M) and N_ij = {{{{H,g_i}},g_j}} \
                     has a zero row: SHAKE and RATTLE have infinitely many solutions, as for H = p²/2, g = q̄ \
                     in the paper's Section 5.2"
                )
            } else {
                format!(
                    "the nondegeneracy assumption fails for constraint `{name}`: N_ij = {{{{H,g_i}},g_j}} is \
                     identically singular (its row for `{name}` is zero, with the hidden constraint \
                     {{{name}, H}} = {}). H restricted to a fibre is linear in the fibre direction, so its \
                     critical points are degenerate: the multiplier is not determined by the hidden \
                     constraint and the problem has index greater than 3 (index 5 for g = q̄, \
                     H = p²/2 + p̄q, the paper's Section 5.2)",
                    short(g.display(der.hidden[i]))
                )
            };
            cx.error(c.span, msg);
        }
    }
    if symbolic {
        return;
    }
    // An entry within 1e-8 of the size of the products that make it up is
    // zero to round-off (as for the coisotropy brackets), however small the
    // entries are in absolute terms. (With L = q0 p1 − q1 p0 − c and
    // H = |p|²/2 + V(|q|²), N ≡ 0 for every V, but V = exp(−r²) + r⁶/3 left
    // N = −7e-16, which a rank relative to N's own largest entry took for
    // full.)
    let size = NSize::new(sys);
    // Stop at the first point of M^H where N has full rank.
    let mut found = 0;
    for i in 0..SAMPLES {
        let Some(zm) = s.m_point(sys, der, i) else {
            break;
        };
        let Some(z) = s.project_mh(sys, der, zm) else {
            continue;
        };
        found += 1;
        let vals = s.eval(&sys.graph, &z);
        let mut a: Vec<f64> = der.n.iter().flatten().map(|n| vals[n.index()]).collect();
        let sizes = size.at(&vals, sys.dof);
        for (x, size) in a.iter_mut().zip(&sizes) {
            if x.abs() <= 1e-8 * size {
                *x = 0.0;
            }
        }
        if rank_rows(&a, m, m).0 == m {
            return;
        }
    }
    if found < 2 {
        return;
    }
    cx.error(
        sys.constraints[0].span,
        format!(
            "the nondegeneracy assumption fails: N_ij = {{{{H,g_i}},g_j}} is singular at every one of {} \
             sampled points of the hidden constraint manifold M^H, so the multipliers of SHAKE and RATTLE \
             are not determined (the paper's Assumption 1.1; see the failing examples of Section 5.2)",
            found
        ),
    );
}

/// The size of the products that make up N_ij = {{H,g_i},g_j} at a point.
/// With {f, g} = Σ_a ±∂f/∂a ∂g/∂ā (ā the conjugate of a: p_k for q_k and
/// q_k for p_k), N_ij = Σ_b ±∂{g_i,H}/∂b ∂g_j/∂b̄ and ∂{g_i,H}/∂b =
/// Σ_a ±(∂²g_i/∂a∂b ∂H/∂ā + ∂g_i/∂a ∂²H/∂ā∂b), so
///
/// |N_ij| ≤ Σ_b |∂g_j/∂b̄| Σ_a (|∂²g_i/∂a∂b| |∂H/∂ā| + |∂g_i/∂a| |∂²H/∂ā∂b|),
///
/// the sum of the absolute values of its terms: what the entry's rounding
/// is relative to. Gradients and Hessians are kept sparse (their nonzero
/// entries as graph nodes), so the size costs the Hessians' entries.
struct NSize {
    h_grad: Vec<(usize, NodeId)>,
    h_hess: Vec<(usize, usize, NodeId)>,
    g_grad: Vec<Vec<(usize, NodeId)>>,
    g_hess: Vec<Vec<(usize, usize, NodeId)>>,
}

impl NSize {
    fn new(sys: &mut System) -> Self {
        let graph = &mut sys.graph;
        let grad = |graph: &mut Graph, f: NodeId| -> Vec<(usize, NodeId)> {
            graph
                .grad(f)
                .into_iter()
                .map(|(v, n)| (v.index(), n))
                .collect()
        };
        let hess = |graph: &mut Graph, g: &[(usize, NodeId)]| {
            let mut out = Vec::new();
            for &(a, ga) in g {
                for (b, gab) in graph.grad(ga) {
                    out.push((a, b.index(), gab));
                }
            }
            out
        };
        let h_grad = grad(graph, sys.hamiltonian);
        let h_hess = hess(graph, &h_grad);
        let nodes: Vec<NodeId> = sys.constraints.iter().map(|c| c.node).collect();
        let g_grad: Vec<_> = nodes.iter().map(|&g| grad(graph, g)).collect();
        let g_hess = g_grad.iter().map(|g| hess(graph, g)).collect();
        NSize {
            h_grad,
            h_hess,
            g_grad,
            g_hess,
        }
    }

    /// The sizes of N's m×m entries, row-major, from the graph's values.
    fn at(&self, vals: &[f64], d: usize) -> Vec<f64> {
        let bar = |a: usize| if a < d { a + d } else { a - d };
        let dense = |g: &[(usize, NodeId)]| {
            let mut v = vec![0.0; 2 * d];
            for &(a, n) in g {
                v[a] = vals[n.index()].abs();
            }
            v
        };
        let h = dense(&self.h_grad);
        let g: Vec<Vec<f64>> = self.g_grad.iter().map(|g| dense(g)).collect();
        let m = g.len();
        let mut out = vec![0.0; m * m];
        for i in 0..m {
            // w_b = Σ_a (|∂²g_i/∂a∂b| |∂H/∂ā| + |∂g_i/∂a| |∂²H/∂ā∂b|).
            let mut w = vec![0.0; 2 * d];
            for &(a, b, n) in &self.g_hess[i] {
                w[b] += vals[n.index()].abs() * h[bar(a)];
            }
            for &(c, b, n) in &self.h_hess {
                w[b] += g[i][bar(c)] * vals[n.index()].abs();
            }
            for j in 0..m {
                out[i * m + j] = (0..2 * d).map(|b| w[b] * g[j][bar(b)]).sum();
            }
        }
        out
    }
}

/// The numerical rank of an r×c row-major matrix (rows orthogonalised in
/// order, twice-iterated Gram-Schmidt, relative tolerance 1e-9), and the
/// first row that adds no rank.
fn rank_rows(a: &[f64], r: usize, c: usize) -> (usize, usize) {
    let scale = a.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    if scale == 0.0 {
        return (0, 0);
    }
    let tol = 1e-9 * scale;
    // Row by row: orthogonalise each row against the accepted ones
    // (modified Gram-Schmidt), which also tells which row is dependent.
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut first = r;
    for i in 0..r {
        let mut v = a[i * c..(i + 1) * c].to_vec();
        for _ in 0..2 {
            for b in &basis {
                let dot: f64 = v.iter().zip(b).map(|(x, y)| x * y).sum();
                v.iter_mut().zip(b).for_each(|(x, y)| *x -= dot * y);
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > tol {
            v.iter_mut().for_each(|x| *x /= norm);
            basis.push(v);
        } else if first == r {
            first = i;
        }
    }
    (basis.len(), first.min(r.saturating_sub(1)))
}

/// Number of points of M (and of M^H) the numerical checks use.
pub const SAMPLES: usize = 6;

/// Points of M and M^H, found by Newton projection (minimum-norm steps
/// z ← z − Jᵀ(JJᵀ)⁻¹F) from seeded random starts, with the parameters fixed
/// at seeded random values in [0.5, 1.5].
pub struct Sampler {
    params: Vec<f64>,
    lambda: Vec<f64>,
    rng: u64,
    on_m: Vec<Vec<f64>>,
    attempts: usize,
    n2: usize,
}

impl Sampler {
    pub fn new(sys: &System, der: &Derived) -> Self {
        let mut s = Sampler {
            params: Vec::new(),
            lambda: vec![0.0; der.g.len()],
            rng: 0x5eed_5a4b_e000_0001,
            on_m: Vec::new(),
            attempts: 0,
            n2: 2 * sys.dof,
        };
        s.params = (0..sys.params.len()).map(|_| 0.5 + s.uniform()).collect();
        s
    }

    /// splitmix64, mapped to [0, 1).
    fn uniform(&mut self) -> f64 {
        self.rng = self.rng.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.rng;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn eval(&self, graph: &Graph, z: &[f64]) -> Vec<f64> {
        graph.eval(z, &self.params, &self.lambda)
    }

    fn random_point(&mut self) -> Vec<f64> {
        (0..self.n2).map(|_| 2.0 * self.uniform() - 1.0).collect()
    }

    /// The i-th sampled point of M (computed on first use), `None` when
    /// fewer than i + 1 points could be found.
    pub fn m_point(&mut self, sys: &System, der: &Derived, i: usize) -> Option<Vec<f64>> {
        while self.on_m.len() <= i && self.attempts < SAMPLES * 3 {
            self.attempts += 1;
            let start = self.random_point();
            if let Some(z) = self.project(&sys.graph, &der.g, &der.g_z, start) {
                self.on_m.push(z);
            }
        }
        self.on_m.get(i).cloned()
    }

    /// Projects a point of M onto M^H = {g = 0, {g_i,H} = 0}.
    pub fn project_mh(&self, sys: &System, der: &Derived, z: Vec<f64>) -> Option<Vec<f64>> {
        let m = der.g.len();
        let rows: Vec<NodeId> = der.g.iter().chain(&der.hidden).copied().collect();
        let jac: Vec<((usize, usize), NodeId)> = der
            .g_z
            .iter()
            .copied()
            .chain(der.hidden_z.iter().map(|&((i, k), n)| ((i + m, k), n)))
            .collect();
        self.project(&sys.graph, &rows, &jac, z)
    }

    /// Newton projection onto {F = 0}; `None` if it does not converge.
    fn project(
        &self,
        graph: &Graph,
        rows: &[NodeId],
        jac: &[((usize, usize), NodeId)],
        mut z: Vec<f64>,
    ) -> Option<Vec<f64>> {
        let r = rows.len();
        for _ in 0..60 {
            let vals = self.eval(graph, &z);
            let f: Vec<f64> = rows.iter().map(|x| vals[x.index()]).collect();
            let scale = 1.0 + z.iter().fold(0.0f64, |s, x| s.max(x.abs()));
            let res = f.iter().fold(0.0f64, |s, x| s.max(x.abs()));
            if !res.is_finite() {
                return None;
            }
            if res <= 1e-12 * scale {
                return Some(z);
            }
            // J as sparse rows (a chain's rows have four entries), then
            // JJᵀ y = F and z ← z − Jᵀy.
            let mut j: Vec<Vec<(usize, f64)>> = vec![Vec::new(); r];
            for &((i, k), node) in jac {
                j[i].push((k, vals[node.index()]));
            }
            for row in &mut j {
                row.sort_unstable_by_key(|e| e.0);
            }
            let mut jjt = vec![0.0; r * r];
            for a in 0..r {
                for b in a..r {
                    let s = sparse_dot(&j[a], &j[b]);
                    jjt[a * r + b] = s;
                    jjt[b * r + a] = s;
                }
            }
            let trace: f64 = (0..r).map(|a| jjt[a * r + a]).sum::<f64>() / r as f64;
            for a in 0..r {
                jjt[a * r + a] += 1e-13 * trace;
            }
            let y = solve(jjt, f, r)?;
            for (row, ya) in j.iter().zip(&y) {
                for &(k, v) in row {
                    z[k] -= v * ya;
                }
            }
        }
        None
    }
}

/// The dot product of two sparse rows sorted by column.
fn sparse_dot(a: &[(usize, f64)], b: &[(usize, f64)]) -> f64 {
    let (mut i, mut j, mut s) = (0, 0, 0.0);
    while i < a.len() && j < b.len() {
        match a[i].0.cmp(&b[j].0) {
            std::cmp::Ordering::Less => i += 1,
            std::cmp::Ordering::Greater => j += 1,
            std::cmp::Ordering::Equal => {
                s += a[i].1 * b[j].1;
                i += 1;
                j += 1;
            }
        }
    }
    s
}

/// Solves the r×r system A x = b (row-major) by Gaussian elimination with
/// partial pivoting; `None` when A is singular.
fn solve(mut a: Vec<f64>, mut b: Vec<f64>, r: usize) -> Option<Vec<f64>> {
    for col in 0..r {
        let piv = (col..r).max_by(|x, y| a[x * r + col].abs().total_cmp(&a[y * r + col].abs()))?;
        if a[piv * r + col] == 0.0 || !a[piv * r + col].is_finite() {
            return None;
        }
        if piv != col {
            for k in 0..r {
                a.swap(piv * r + k, col * r + k);
            }
            b.swap(piv, col);
        }
        for row in col + 1..r {
            let f = a[row * r + col] / a[col * r + col];
            if f != 0.0 {
                for k in col..r {
                    a[row * r + k] -= f * a[col * r + k];
                }
                b[row] -= f * b[col];
            }
        }
    }
    for col in (0..r).rev() {
        let s: f64 = (col + 1..r).map(|k| a[col * r + k] * b[k]).sum();
        b[col] = (b[col] - s) / a[col * r + col];
    }
    Some(b)
}
