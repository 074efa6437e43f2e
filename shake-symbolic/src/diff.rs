//! Symbolic differentiation, gradients and Poisson brackets.
//!
//! ∂/∂z_v is memoised per (node, v) and short-circuits to 0 when v is not in
//! the node's support, so differentiating a chain of 64 links costs what its
//! nonzero entries cost, not (2d)² times the graph.
//!
//! The bracket follows the project's convention (MISSION.md):
//! {F,G} = Σ_k ∂F/∂q_k ∂G/∂p_k − ∂F/∂p_k ∂G/∂q_k.

use crate::symbolic::{Func, Graph, Node, NodeId, VarId};

impl Graph {
    /// ∂x/∂z_v, simplified.
    ///
    /// The derivatives of the descendants are computed first, in post-order
    /// with an explicit stack, so the recursion of `Graph::diff_node`
    /// meets only memoised children: the depth of the graph (a chain of
    /// 2·10⁴ `let`s) never reaches the machine stack.
    pub fn diff(&mut self, x: NodeId, v: VarId) -> NodeId {
        if !self.depends_on(x, v) {
            return self.zero();
        }
        if let Some(&d) = self.diff_memo.get(&(x, v)) {
            return d;
        }
        let mut stack = vec![(x, false)];
        while let Some((n, children_done)) = stack.pop() {
            if self.diff_memo.contains_key(&(n, v)) {
                continue;
            }
            if children_done {
                let d = self.diff_node(n, v);
                self.diff_memo.insert((n, v), d);
                continue;
            }
            stack.push((n, true));
            let kids = self.node(n).children().to_vec();
            for c in kids {
                if self.depends_on(c, v) && !self.diff_memo.contains_key(&(c, v)) {
                    stack.push((c, false));
                }
            }
        }
        self.diff_memo[&(x, v)]
    }

    /// ∂x/∂z_v from the derivatives of x's children (each one level deep:
    /// [`Graph::diff`] has memoised them before).
    fn diff_node(&mut self, x: NodeId, v: VarId) -> NodeId {
        if !self.depends_on(x, v) {
            return self.zero();
        }
        if let Some(&d) = self.diff_memo.get(&(x, v)) {
            return d;
        }
        match self.node(x).clone() {
            Node::Const(_) | Node::Param(_) | Node::Lambda(_) => self.zero(),
            Node::Var(w) => {
                if w == v {
                    self.one()
                } else {
                    self.zero()
                }
            }
            Node::Add(ts) => {
                let ds = ts.iter().map(|t| self.diff(*t, v)).collect();
                self.add(ds)
            }
            // Product rule, over the factors that depend on v only.
            Node::Mul(fs) => {
                let mut terms = Vec::new();
                for (i, &f) in fs.iter().enumerate() {
                    if !self.depends_on(f, v) {
                        continue;
                    }
                    let df = self.diff(f, v);
                    let mut prod = vec![df];
                    prod.extend(
                        fs.iter()
                            .enumerate()
                            .filter(|(j, _)| *j != i)
                            .map(|(_, g)| *g),
                    );
                    terms.push(self.mul(prod));
                }
                self.add(terms)
            }
            // (b^n)' = n b^(n−1) b'
            Node::Pow(b, n) => {
                let k = self.num(f64::from(n));
                let p = self.pow(b, n - 1);
                let db = self.diff(b, v);
                self.mul(vec![k, p, db])
            }
            // (b^r)' = r b^(r−1) b'
            Node::PowF(b, r) => {
                let r = f64::from_bits(r);
                let k = self.num(r);
                let p = self.powf(b, r - 1.0);
                let db = self.diff(b, v);
                self.mul(vec![k, p, db])
            }
            Node::Call(f, a) => {
                let da = self.diff(a, v);
                let outer = match f {
                    Func::Sin => self.call(Func::Cos, a),
                    Func::Cos => {
                        let s = self.call(Func::Sin, a);
                        self.neg(s)
                    }
                    // tan' = 1 + tan²
                    Func::Tan => {
                        let one = self.one();
                        let t2 = self.pow(x, 2);
                        self.add2(one, t2)
                    }
                    Func::Exp => x,
                    Func::Ln => self.pow(a, -1),
                };
                self.mul2(outer, da)
            }
        }
    }

    /// The nonzero entries (v, ∂x/∂z_v) of the gradient, sorted by v.
    pub fn grad(&mut self, x: NodeId) -> Vec<(VarId, NodeId)> {
        let support = self.support(x).to_vec();
        let all: Vec<(VarId, NodeId)> = support.into_iter().map(|v| (v, self.diff(x, v))).collect();
        all.into_iter().filter(|(_, d)| !self.is_zero(*d)).collect()
    }

    /// {F,G} = F_q·G_p − F_p·G_q for d degrees of freedom; only the pairs
    /// (q_k, p_k) in both supports contribute.
    pub fn bracket(&mut self, f: NodeId, g: NodeId, d: usize) -> NodeId {
        let mut terms = Vec::new();
        let fs = self.support(f).to_vec();
        for v in fs {
            let k = v.index();
            let (partner, sign) = if k < d {
                (VarId((k + d) as u32), 1.0)
            } else {
                (VarId((k - d) as u32), -1.0)
            };
            if !self.depends_on(g, partner) {
                continue;
            }
            let df = self.diff(f, v);
            let dg = self.diff(g, partner);
            let s = self.num(sign);
            terms.push(self.mul(vec![s, df, dg]));
        }
        self.add(terms)
    }
}

/// How the constraints depend on z (mirrors `geoshake_runtime::ConstraintKind`).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Kind {
    None,
    Holonomic,
    Quadratic,
    General,
}

/// Everything the emitted impl returns, as graph nodes, with only the
/// structurally nonzero entries. Index pairs are (row, column) of the
/// runtime's matrices; symmetric matrices keep their upper triangle a ≤ b.
pub struct Derived {
    pub h_z: Vec<(usize, NodeId)>,
    pub h_zz: Vec<((usize, usize), NodeId)>,
    pub g: Vec<NodeId>,
    pub g_z: Vec<((usize, usize), NodeId)>,
    /// Σ λ_i ∇²g_i, upper triangle.
    pub g_hess: Vec<((usize, usize), NodeId)>,
    /// {g_i, H}.
    pub hidden: Vec<NodeId>,
    pub hidden_z: Vec<((usize, usize), NodeId)>,
    /// N_ij = {{H,g_i},g_j}, all m×m entries (zeros included, for checks).
    pub n: Vec<Vec<NodeId>>,
    /// For holonomic g: (k, Σ_i λ_i ∂g_i/∂q_k), the fibre flow's momentum kick.
    pub kick: Vec<(usize, NodeId)>,
    pub kind: Kind,
    pub separable: bool,
    pub quadratic_kinetic: bool,
    /// Every g_i is a polynomial of degree at most 2 in z (a distance
    /// constraint): its Hessian is constant.
    pub quadratic_constraints: bool,
}

impl Derived {
    pub fn compute(graph: &mut Graph, dof: usize, h: NodeId, g: &[NodeId]) -> Derived {
        let is_q = |v: &VarId| v.index() < dof;
        let h_grad = graph.grad(h);
        let mut h_zz = Vec::new();
        for &(a, ha) in &h_grad {
            for (b, hab) in graph.grad(ha) {
                if b >= a {
                    h_zz.push(((a.index(), b.index()), hab));
                }
            }
        }
        h_zz.sort_unstable_by_key(|e| e.0);
        // Separable: no ∂H/∂q_k depends on p (then H_qp ≡ 0).
        let separable = h_grad
            .iter()
            .filter(|(v, _)| is_q(v))
            .all(|(_, hq)| graph.support(*hq).iter().all(is_q));
        // Quadratic kinetic energy: T = ½pᵀAp, so each ∂H/∂p_k is linear,
        // homogeneous and q-free (H_pp = A constant).
        let quadratic_kinetic = separable
            && h_grad.iter().filter(|(v, _)| !is_q(v)).all(|(_, hp)| {
                graph.degree(*hp) == Some(1)
                    && match graph.node(*hp) {
                        Node::Add(ts) => ts.iter().all(|t| graph.as_const(*t).is_none()),
                        _ => true,
                    }
            });

        let mut g_z = Vec::new();
        let mut g_hess_terms: std::collections::BTreeMap<(usize, usize), Vec<NodeId>> =
            Default::default();
        for (i, &gi) in g.iter().enumerate() {
            let lam = graph.lambda(i);
            for (a, ga) in graph.grad(gi) {
                g_z.push(((i, a.index()), ga));
                for (b, gab) in graph.grad(ga) {
                    if b >= a {
                        let t = graph.mul2(lam, gab);
                        g_hess_terms
                            .entry((a.index(), b.index()))
                            .or_default()
                            .push(t);
                    }
                }
            }
        }
        let g_hess: Vec<_> = g_hess_terms
            .into_iter()
            .map(|(k, ts)| (k, graph.add(ts)))
            .collect();
        let g_hess = g_hess
            .into_iter()
            .filter(|(_, n)| !graph.is_zero(*n))
            .collect();

        let kind = if g.is_empty() {
            Kind::None
        } else if g.iter().all(|gi| graph.support(*gi).iter().all(is_q)) {
            Kind::Holonomic
        } else if g.iter().all(|gi| graph.degree(*gi).is_some_and(|d| d <= 2)) {
            Kind::Quadratic
        } else {
            Kind::General
        };

        let hidden: Vec<NodeId> = g.iter().map(|gi| graph.bracket(*gi, h, dof)).collect();
        let mut hidden_z = Vec::new();
        for (i, &hi) in hidden.iter().enumerate() {
            for (a, d) in graph.grad(hi) {
                hidden_z.push(((i, a.index()), d));
            }
        }
        // N_ij = {{H,g_i},g_j} = −{{g_i,H},g_j}.
        let mut n = Vec::with_capacity(g.len());
        for &hi in &hidden {
            let row = g
                .iter()
                .map(|gj| {
                    let b = graph.bracket(hi, *gj, dof);
                    graph.neg(b)
                })
                .collect();
            n.push(row);
        }

        let mut kick = Vec::new();
        if kind == Kind::Holonomic {
            let mut terms: std::collections::BTreeMap<usize, Vec<NodeId>> = Default::default();
            for &((i, k), gik) in &g_z {
                let lam = graph.lambda(i);
                let t = graph.mul2(lam, gik);
                terms.entry(k).or_default().push(t);
            }
            let all: Vec<_> = terms
                .into_iter()
                .map(|(k, ts)| (k, graph.add(ts)))
                .collect();
            kick = all
                .into_iter()
                .filter(|(_, n)| !graph.is_zero(*n))
                .collect();
        }

        Derived {
            h_z: h_grad.into_iter().map(|(v, n)| (v.index(), n)).collect(),
            h_zz,
            g: g.to_vec(),
            g_z,
            g_hess,
            hidden,
            hidden_z,
            n,
            kick,
            kind,
            separable,
            quadratic_kinetic,
            quadratic_constraints: g.iter().all(|gi| graph.degree(*gi).is_some_and(|d| d <= 2)),
        }
    }
}

/// The derivatives to emit: the structure (which entries are nonzero, the
/// kind and flags) of `canon`, computed on the expanded canonical graph
/// where identities are decided, with the values of `values`, computed on
/// the factored graph of the same system (accurate to evaluate). An entry
/// that is zero in `canon` is dropped (it is the zero function; its factored
/// form would only add round-off). `None` if an entry of `canon` has no
/// factored value (then the canonical values are emitted).
pub fn aligned(
    canon: &Derived,
    canon_graph: &Graph,
    values: Derived,
    graph: &mut Graph,
) -> Option<Derived> {
    use std::collections::HashMap;
    fn keyed<K: std::hash::Hash + Eq + Copy>(
        canon: &[(K, NodeId)],
        values: &[(K, NodeId)],
    ) -> Option<Vec<(K, NodeId)>> {
        let map: HashMap<K, NodeId> = values.iter().copied().collect();
        canon
            .iter()
            .map(|(k, _)| map.get(k).map(|v| (*k, *v)))
            .collect()
    }
    let zero = graph.zero();
    let positional = |c: &[NodeId], v: &[NodeId]| -> Option<Vec<NodeId>> {
        (c.len() == v.len()).then(|| {
            c.iter()
                .zip(v)
                .map(|(c, v)| if canon_graph.is_zero(*c) { zero } else { *v })
                .collect()
        })
    };
    let n = (canon.n.len() == values.n.len())
        .then(|| {
            canon
                .n
                .iter()
                .zip(&values.n)
                .map(|(c, v)| positional(c, v))
                .collect::<Option<Vec<_>>>()
        })
        .flatten()?;
    Some(Derived {
        h_z: keyed(&canon.h_z, &values.h_z)?,
        h_zz: keyed(&canon.h_zz, &values.h_zz)?,
        g: positional(&canon.g, &values.g)?,
        g_z: keyed(&canon.g_z, &values.g_z)?,
        g_hess: keyed(&canon.g_hess, &values.g_hess)?,
        hidden: positional(&canon.hidden, &values.hidden)?,
        hidden_z: keyed(&canon.hidden_z, &values.hidden_z)?,
        n,
        kick: keyed(&canon.kick, &values.kick)?,
        kind: canon.kind,
        separable: canon.separable,
        quadratic_kinetic: canon.quadratic_kinetic,
        quadratic_constraints: canon.quadratic_constraints,
    })
}
