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
pub struct NodeId(pub u32);

/// A state variable: z_k, with k < d for q_k and k ≥ d for p_{k−d}.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct VarId(pub u32);

/// A runtime parameter (an `f64` field of the declared struct).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ParamId(pub u32);

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
    /// The largest |exponent| of a power in the node's subgraph (saturating).
    max_exp: Vec<u32>,
    /// The length of the longest path from the node down to a leaf.
    height: Vec<u32>,
    memo: HashMap<Node, NodeId>,
    pub diff_memo: HashMap<(NodeId, VarId), NodeId>,
    pub names: Names,
    /// The graph of the emitted values: products and powers of sums stay as
    /// written (see `simplify`), for accuracy; `false` in the graph the
    /// checks decide identities on.
    pub factored: bool,
}

pub fn bits(x: f64) -> u64 {
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

    /// The nodes the evaluation of `id` reads, as emitted code (the
    /// macro's Rust, the tape) evaluates it: a product writes its negative
    /// powers as a denominator, so it reads their bases.
    pub fn emitted_deps(&self, id: NodeId) -> Vec<NodeId> {
        match self.node(id) {
            Node::Mul(fs) => fs
                .iter()
                .map(|f| match self.node(*f) {
                    Node::Pow(b, n) if *n < 0 => *b,
                    _ => *f,
                })
                .collect(),
            n => n.children().to_vec(),
        }
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

    /// An empty graph; `factored` as in [`Graph::factored`].
    pub fn new(factored: bool) -> Graph {
        Graph {
            factored,
            ..Graph::default()
        }
    }

    /// The number of nodes.
    #[allow(clippy::len_without_is_empty)]
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// The longest path from `id` down to a leaf of the graph.
    pub fn height(&self, id: NodeId) -> u32 {
        self.height[id.index()]
    }

    /// The largest |n| of a power x^n anywhere in `id` (saturating).
    pub fn max_exponent(&self, id: NodeId) -> u32 {
        self.max_exp[id.index()]
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
    pub fn intern(&mut self, node: Node) -> NodeId {
        if let Some(&id) = self.memo.get(&node) {
            return id;
        }
        let (support, degree) = self.facts(&node);
        let id = NodeId(u32::try_from(self.nodes.len()).expect("graph too large"));
        debug_assert!(node.children().iter().all(|c| c.0 < id.0));
        self.nodes.push(node.clone());
        self.support.push(support);
        self.degree.push(degree);
        let own = match &node {
            Node::Pow(_, n) => n.unsigned_abs(),
            // `as` saturates (NaN becomes 0: a NaN exponent is folded away).
            Node::PowF(_, r) => f64::from_bits(*r).abs().ceil() as u32,
            _ => 0,
        };
        let max_exp = node
            .children()
            .iter()
            .map(|c| self.max_exp[c.index()])
            .fold(own, u32::max);
        self.max_exp.push(max_exp);
        let height = node
            .children()
            .iter()
            .map(|c| self.height[c.index()] + 1)
            .max()
            .unwrap_or(0);
        self.height.push(height);
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

    /// A readable rendering, for diagnostics and generated docs, cut with
    /// `…` after about [`DISPLAY_BUDGET`] characters or [`DISPLAY_DEPTH`]
    /// levels. The graph is a DAG and the rendering a tree (a `let` used
    /// twice is printed twice), so an uncut rendering can be exponentially
    /// longer than the graph (40 `let`s each using the one before twice
    /// print 2^40 subtrees): the budget keeps the work linear in what is
    /// shown, and the recursion shallow.
    pub fn display(&self, id: NodeId) -> String {
        let mut s = String::new();
        self.write(id, 0, &mut s, 0);
        s
    }

    /// True when the budget is spent (and `…` has been written once).
    fn spent(s: &mut String, depth: usize) -> bool {
        if s.len() < DISPLAY_BUDGET && depth <= DISPLAY_DEPTH {
            return false;
        }
        if !s.ends_with('…') {
            s.push('…');
        }
        true
    }

    /// The precedence of the rendering of `id`: 1 sum, 2 product,
    /// 3 power/unary, 4 atom.
    fn prec(&self, id: NodeId) -> u8 {
        match self.node(id) {
            Node::Const(b) if f64::from_bits(*b) < 0.0 => 1,
            Node::Const(_) | Node::Var(_) | Node::Param(_) | Node::Lambda(_) | Node::Call(..) => 4,
            Node::Add(_) => 1,
            Node::Mul(_) if self.negative(id) => 1,
            Node::Mul(_) => 2,
            Node::Pow(_, n) if *n < 0 => 2,
            Node::PowF(_, r) if f64::from_bits(*r) == 0.5 => 4,
            Node::Pow(..) | Node::PowF(..) => 3,
        }
    }

    /// A negative constant, or a product with a negative coefficient.
    fn negative(&self, id: NodeId) -> bool {
        match self.node(id) {
            Node::Const(b) => f64::from_bits(*b) < 0.0,
            Node::Mul(c) => self.as_const(c[0]).is_some_and(|k| k < 0.0),
            _ => false,
        }
    }

    fn write(&self, id: NodeId, outer: u8, s: &mut String, depth: usize) {
        if Self::spent(s, depth) {
            return;
        }
        let paren = self.prec(id) < outer;
        if paren {
            s.push('(');
        }
        match self.node(id) {
            Node::Const(b) => s.push_str(&fmt_num(f64::from_bits(*b))),
            Node::Var(k) => s.push_str(&self.names.vars[k.index()]),
            Node::Param(k) => s.push_str(&self.names.params[k.0 as usize]),
            Node::Lambda(k) => {
                let _ = write!(s, "λ[{k}]");
            }
            Node::Add(c) => {
                for (i, term) in c.iter().enumerate() {
                    if Self::spent(s, depth) {
                        break;
                    }
                    match (i, self.negative(*term)) {
                        (0, true) => s.push('-'),
                        (_, true) => s.push_str(" - "),
                        (0, false) => {}
                        (_, false) => s.push_str(" + "),
                    }
                    self.write_magnitude(*term, s, depth + 1);
                }
            }
            Node::Mul(_) => {
                if self.negative(id) {
                    s.push('-');
                }
                self.write_magnitude(id, s, depth + 1);
            }
            Node::Pow(x, n) if *n < 0 => {
                s.push_str("1/");
                self.write(*x, 4, s, depth + 1);
                if *n != -1 {
                    let _ = write!(s, "^{}", -i64::from(*n));
                }
            }
            Node::Pow(x, n) => {
                self.write(*x, 4, s, depth + 1);
                let _ = write!(s, "^{n}");
            }
            Node::PowF(x, r) if f64::from_bits(*r) == 0.5 => {
                s.push_str("sqrt(");
                self.write(*x, 0, s, depth + 1);
                s.push(')');
            }
            Node::PowF(x, r) => {
                self.write(*x, 4, s, depth + 1);
                let _ = write!(s, "^{}", fmt_num(f64::from_bits(*r)));
            }
            Node::Call(f, x) => {
                s.push_str(f.name());
                s.push('(');
                self.write(*x, 0, s, depth + 1);
                s.push(')');
            }
        }
        if paren {
            s.push(')');
        }
    }

    /// The magnitude of a product or constant (its sign is written by the
    /// caller); anything else as a factor.
    fn write_magnitude(&self, id: NodeId, s: &mut String, depth: usize) {
        if Self::spent(s, depth) {
            return;
        }
        match self.node(id) {
            Node::Const(b) => s.push_str(&fmt_num(f64::from_bits(*b).abs())),
            Node::Mul(c) => {
                let coef = self.as_const(c[0]).unwrap_or(1.0);
                let is_den = |f: &NodeId| matches!(self.node(*f), Node::Pow(_, n) if *n < 0);
                let num: Vec<NodeId> = c
                    .iter()
                    .filter(|f| self.as_const(**f).is_none() && !is_den(f))
                    .copied()
                    .collect();
                let den: Vec<NodeId> = c.iter().filter(|f| is_den(f)).copied().collect();
                let mut first = true;
                if coef.abs() != 1.0 || num.is_empty() {
                    s.push_str(&fmt_num(coef.abs()));
                    first = false;
                }
                for f in num {
                    if !first {
                        s.push('*');
                    }
                    first = false;
                    self.write(f, 2, s, depth + 1);
                }
                if !den.is_empty() {
                    s.push('/');
                    if den.len() > 1 {
                        s.push('(');
                    }
                    for (i, f) in den.iter().enumerate() {
                        if i > 0 {
                            s.push('*');
                        }
                        let Node::Pow(x, n) = self.node(*f) else {
                            unreachable!()
                        };
                        self.write(*x, 4, s, depth + 1);
                        if *n != -1 {
                            let _ = write!(s, "^{}", -i64::from(*n));
                        }
                    }
                    if den.len() > 1 {
                        s.push(')');
                    }
                }
            }
            _ => self.write(id, 2, s, depth),
        }
    }
}

/// The rendering of [`Graph::display`] stops after this many bytes.
pub const DISPLAY_BUDGET: usize = 400;
/// ... or this deep in the expression.
pub const DISPLAY_DEPTH: usize = 64;

fn fmt_num(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        format!("{}", x as i64)
    } else {
        format!("{x}")
    }
}
