//! The expression graph: hash-consed nodes, newtype ids, per-node facts.
//!
//! # Invariant
//!
//! Nodes live in one `Vec`; a node's children always have *smaller* ids than
//! the node itself. Hence the vector is a topological order: evaluating or
//! emitting nodes by increasing id never meets a child that is not ready.
//!
//! Every node is interned through a hash-cons memo: two structurally equal
//! nodes get the same [`NodeId`]. Because the smart constructors of
//! `simplify` bring sums and products into a canonical form (sorted,
//! flattened, like terms collected) before interning, "equal up to
//! reordering" also means "same id", and common-subexpression elimination in
//! the emitted code comes for free: each id is computed once.
//!
//! Alongside each node the graph keeps two facts computed from its children:
//! the sorted set of state variables it depends on (its *support*: derivatives
//! with respect to anything else are zero without looking), and its polynomial
//! degree in the state z = (q, p) (`None` when it is not a polynomial in z;
//! parameters count as constants).

use std::collections::HashMap;
use std::fmt::Write as _;

/// A node of the graph. Children have smaller ids (see the module doc).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub(crate) u32);

/// A state variable: z_k, with k < d for q_k and k ≥ d for p_{k−d}.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VarId(pub(crate) u32);

/// A runtime parameter (an `f64` field of the declared struct).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamId(pub(crate) u32);

impl NodeId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

impl VarId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// The elementary functions the grammar accepts (all differentiable where
/// defined).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    Sin,
    Cos,
    Tan,
    Exp,
    Ln,
}

impl Func {
    pub fn name(self) -> &'static str {
        match self {
            Func::Sin => "sin",
            Func::Cos => "cos",
            Func::Tan => "tan",
            Func::Exp => "exp",
            Func::Ln => "ln",
        }
    }

    pub fn apply(self, x: f64) -> f64 {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
        }
    }
}

/// One node. `sqrt` is `PowF(x, 0.5)`, `a − b` is `a + (−1)·b`, `a / b` is
/// `a · b^(−1)`: fewer shapes, fewer rules.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Node {
    /// An `f64` constant, stored by its bits (−0 is normalised to +0).
    Const(u64),
    Var(VarId),
    Param(ParamId),
    /// The multiplier λ_i, an input of `constraint_hessian` and `fibre_flow`.
    Lambda(u32),
    /// A sum of at least two terms, sorted by id, at most one constant.
    Add(Box<[NodeId]>),
    /// A product of at least two factors: an optional constant coefficient
    /// first, then non-constant factors sorted by id with distinct bases.
    Mul(Box<[NodeId]>),
    /// An integer power, exponent ∉ {0, 1}.
    Pow(NodeId, i32),
    /// A constant non-integer real power (bits of the exponent).
    PowF(NodeId, u64),
    Call(Func, NodeId),
}

impl Node {
    pub fn children(&self) -> &[NodeId] {
        match self {
            Node::Add(c) | Node::Mul(c) => c,
            Node::Pow(x, _) | Node::PowF(x, _) | Node::Call(_, x) => std::slice::from_ref(x),
            _ => &[],
        }
    }
}

/// Names used to print expressions in diagnostics and docs.
#[derive(Clone, Debug, Default)]
pub struct Names {
    pub vars: Vec<String>,
    pub params: Vec<String>,
}

/// The hash-consed expression graph.
#[derive(Debug, Default)]
pub struct Graph {
    nodes: Vec<Node>,
    support: Vec<Box<[VarId]>>,
    degree: Vec<Option<u32>>,
    memo: HashMap<Node, NodeId>,
    pub(crate) diff_memo: HashMap<(NodeId, VarId), NodeId>,
    pub names: Names,
}

pub(crate) fn bits(x: f64) -> u64 {
    if x == 0.0 {
        0
    } else {
        x.to_bits()
    }
}

impl Graph {
    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id.index()]
    }

    /// The sorted state variables `id` depends on.
    pub fn support(&self, id: NodeId) -> &[VarId] {
        &self.support[id.index()]
    }

    pub fn depends_on(&self, id: NodeId, v: VarId) -> bool {
        self.support(id).binary_search(&v).is_ok()
    }

    /// Polynomial degree in z, `None` if not polynomial in z.
    pub fn degree(&self, id: NodeId) -> Option<u32> {
        self.degree[id.index()]
    }

    pub fn as_const(&self, id: NodeId) -> Option<f64> {
        match self.nodes[id.index()] {
            Node::Const(b) => Some(f64::from_bits(b)),
            _ => None,
        }
    }

    pub fn is_zero(&self, id: NodeId) -> bool {
        self.as_const(id) == Some(0.0)
    }

    /// Interns a node that is already in canonical form (the constructors in
    /// `simplify` are the only callers outside this module).
    pub(crate) fn intern(&mut self, node: Node) -> NodeId {
        if let Some(&id) = self.memo.get(&node) {
            return id;
        }
        let (support, degree) = self.facts(&node);
        let id = NodeId(u32::try_from(self.nodes.len()).expect("graph too large"));
        debug_assert!(node.children().iter().all(|c| c.0 < id.0));
        self.nodes.push(node.clone());
        self.support.push(support);
        self.degree.push(degree);
        self.memo.insert(node, id);
        id
    }

    fn facts(&self, node: &Node) -> (Box<[VarId]>, Option<u32>) {
        let support: Box<[VarId]> = match node {
            Node::Var(v) => Box::new([*v]),
            _ => {
                let mut s: Vec<VarId> = node
                    .children()
                    .iter()
                    .flat_map(|c| self.support(*c).iter().copied())
                    .collect();
                s.sort_unstable();
                s.dedup();
                s.into()
            }
        };
        let constant = support.is_empty();
        let deg = |c: &NodeId| self.degree(*c);
        let degree = match node {
            _ if constant => Some(0),
            Node::Var(_) => Some(1),
            Node::Add(c) => c.iter().map(deg).try_fold(0, |a, d| d.map(|d| a.max(d))),
            Node::Mul(c) => c
                .iter()
                .map(deg)
                .try_fold(0u32, |a, d| d.map(|d| a.saturating_add(d))),
            Node::Pow(x, n) if *n > 0 => self.degree(*x).map(|d| d.saturating_mul(*n as u32)),
            _ => None,
        };
        (support, degree)
    }

    /// Evaluates every node in order (the invariant makes one pass enough).
    pub fn eval(&self, z: &[f64], params: &[f64], lambda: &[f64]) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.nodes.len());
        for node in &self.nodes {
            let x = match node {
                Node::Const(b) => f64::from_bits(*b),
                Node::Var(k) => z[k.index()],
                Node::Param(k) => params[k.0 as usize],
                Node::Lambda(k) => lambda[*k as usize],
                Node::Add(c) => c.iter().map(|c| v[c.index()]).sum(),
                Node::Mul(c) => c.iter().map(|c| v[c.index()]).product(),
                Node::Pow(x, n) => f64::powi(v[x.index()], *n),
                Node::PowF(x, r) => f64::powf(v[x.index()], f64::from_bits(*r)),
                Node::Call(f, x) => f.apply(v[x.index()]),
            };
            v.push(x);
        }
        v
    }

    /// A readable rendering, for diagnostics and generated docs.
    pub fn display(&self, id: NodeId) -> String {
        let mut s = String::new();
        self.write(id, 0, &mut s);
        s
    }

    // Precedences: 1 sum, 2 product, 3 power/unary, 4 atom.
    fn write(&self, id: NodeId, outer: u8, s: &mut String) {
        let (text, prec) = match self.node(id) {
            Node::Const(b) => {
                let x = f64::from_bits(*b);
                (fmt_num(x), if x < 0.0 { 1 } else { 4 })
            }
            Node::Var(k) => (self.names.vars[k.index()].clone(), 4),
            Node::Param(k) => (self.names.params[k.0 as usize].clone(), 4),
            Node::Lambda(k) => (format!("λ[{k}]"), 4),
            Node::Add(c) => {
                let mut t = String::new();
                for (i, term) in c.iter().enumerate() {
                    let (neg, body) = self.split_sign(*term);
                    match (i, neg) {
                        (0, true) => t.push('-'),
                        (_, true) => t.push_str(" - "),
                        (0, false) => {}
                        (_, false) => t.push_str(" + "),
                    }
                    t.push_str(&body);
                }
                (t, 1)
            }
            Node::Mul(_) => {
                let (neg, body) = self.split_sign(id);
                if neg {
                    (format!("-{body}"), 1)
                } else {
                    (body, 2)
                }
            }
            Node::Pow(x, n) if *n < 0 => {
                let mut t = String::from("1/");
                self.write(*x, 4, &mut t);
                if *n != -1 {
                    let _ = write!(t, "^{}", -n);
                }
                (t, 2)
            }
            Node::Pow(x, n) => {
                let mut t = String::new();
                self.write(*x, 4, &mut t);
                let _ = write!(t, "^{n}");
                (t, 3)
            }
            Node::PowF(x, r) if f64::from_bits(*r) == 0.5 => {
                let mut t = String::from("sqrt(");
                self.write(*x, 0, &mut t);
                t.push(')');
                (t, 4)
            }
            Node::PowF(x, r) => {
                let mut t = String::new();
                self.write(*x, 4, &mut t);
                let _ = write!(t, "^{}", fmt_num(f64::from_bits(*r)));
                (t, 3)
            }
            Node::Call(f, x) => {
                let mut t = format!("{}(", f.name());
                self.write(*x, 0, &mut t);
                t.push(')');
                (t, 4)
            }
        };
        if prec < outer {
            s.push('(');
            s.push_str(&text);
            s.push(')');
        } else {
            s.push_str(&text);
        }
    }

    /// A product or constant as (is negative, rendering of its magnitude).
    fn split_sign(&self, id: NodeId) -> (bool, String) {
        match self.node(id) {
            Node::Const(b) if f64::from_bits(*b) < 0.0 => (true, fmt_num(-f64::from_bits(*b))),
            Node::Mul(c) => {
                let mut coef = 1.0;
                let mut num = Vec::new();
                let mut den = Vec::new();
                for f in c.iter() {
                    match self.node(*f) {
                        Node::Const(b) => coef = f64::from_bits(*b),
                        Node::Pow(x, n) if *n < 0 => {
                            let mut t = String::new();
                            self.write(*x, 4, &mut t);
                            if *n != -1 {
                                let _ = write!(t, "^{}", -n);
                            }
                            den.push(t);
                        }
                        _ => {
                            let mut t = String::new();
                            self.write(*f, 2, &mut t);
                            num.push(t);
                        }
                    }
                }
                if coef.abs() != 1.0 || num.is_empty() {
                    num.insert(0, fmt_num(coef.abs()));
                }
                let mut t = num.join("*");
                match den.len() {
                    0 => {}
                    1 => {
                        t.push('/');
                        t.push_str(&den[0]);
                    }
                    _ => {
                        let _ = write!(t, "/({})", den.join("*"));
                    }
                }
                (coef < 0.0, t)
            }
            _ => {
                let mut t = String::new();
                self.write(id, 2, &mut t);
                (false, t)
            }
        }
    }
}

fn fmt_num(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{}", x as i64)
    } else {
        format!("{x}")
    }
}
