//! From the typed input to the symbolic system: names resolved, indices
//! evaluated, families unrolled, H and g built in the expression graph.
//!
//! Index expressions (`q[2*k-1]`, family ranges, `if` conditions, `const`s)
//! are evaluated here, at compile time, as integers; only the branch of an
//! `if` that is taken is lowered, so `if k == 0 { .. } else { q[2*k-2] }`
//! never sees the out-of-range index of the other branch.

use crate::parse::{BinOp, CmpOp, Cond, ConstraintDecl, Dof, Expr, ExprKind, Link, SystemDef};
use crate::simplify::MAX_EXPONENT;
use crate::symbolic::{Func, Graph, Names, NodeId, ParamId, VarId};
use proc_macro2::Span;
use std::collections::HashMap;
use syn::{Error, Ident};

/// One constraint g_i after unrolling families.
pub struct Constraint {
    /// `rod`, or `link[3]` for a member of a family.
    pub name: String,
    pub span: Span,
    pub node: NodeId,
}

/// The symbolic system: H and g_1..g_m over z = (q, p) ∈ R^{2d}.
pub struct System {
    pub graph: Graph,
    pub dof: usize,
    pub params: Vec<Ident>,
    pub hamiltonian: NodeId,
    pub constraints: Vec<Constraint>,
    /// The number m of constraints declared. Members of families past the
    /// (d+1)-th constraint are counted, not lowered: m > d is refused
    /// (`lib.rs`), and lowering 10⁵ members just to refuse them takes a second.
    pub declared: usize,
}

#[derive(Clone)]
enum Sym {
    Number(f64),
    Param(ParamId),
    Var(VarId),
    Let(NodeId),
    /// The q or p array: the offset of its first variable in z.
    Array(usize),
}

struct Lowerer {
    graph: Graph,
    dof: usize,
    syms: HashMap<String, (Sym, Span)>,
    /// Bound family / sum indices, innermost last (they shadow nothing:
    /// clashes with declared names are refused).
    indices: Vec<(String, i64)>,
    /// Terms the `sum`s expanded so far ([`MAX_TERMS`]).
    terms: u64,
}

/// The most terms the `sum`s of one declaration may expand to, counted
/// over every sum and every nesting (nested sums multiply): a single range
/// is held to 100 000 terms, but two nested ones of that length are 10¹⁰
/// terms, minutes of expansion and gigabytes, before any error could be
/// reported. A million terms lower in about a second.
pub const MAX_TERMS: u64 = 1_000_000;

/// The largest d accepted: the Hessian outputs are (2d)² arrays.
const MAX_DOF: usize = 1024;

const FUNCS: &str = "sqrt, sin, cos, tan, exp, ln";
const NON_DIFFERENTIABLE: &[&str] = &[
    "abs",
    "signum",
    "sign",
    "floor",
    "ceil",
    "round",
    "trunc",
    "fract",
    "min",
    "max",
    "clamp",
    "step",
    "heaviside",
];

impl Lowerer {
    fn declare(&mut self, id: &Ident, sym: Sym) -> Result<(), Error> {
        let name = id.to_string();
        if let Some((_, prev)) = self.syms.get(&name) {
            let mut e = Error::new(id.span(), format!("duplicate name `{name}`"));
            e.combine(Error::new(
                *prev,
                format!("`{name}` is first declared here"),
            ));
            return Err(e);
        }
        self.syms.insert(name, (sym, id.span()));
        Ok(())
    }

    /// ` (did you mean `x`?)` for the nearest declared name of the wanted
    /// kind, or bound index, within a few edits.
    fn did_you_mean(&self, name: &str, kind: impl Fn(&Sym) -> bool) -> String {
        let declared = self
            .syms
            .iter()
            .filter(|(_, (s, _))| kind(s))
            .map(|(n, _)| n.as_str());
        let bound = self.indices.iter().map(|(n, _)| n.as_str());
        suggestion(name, declared.chain(bound))
    }

    fn lookup_index(&self, name: &str) -> Option<i64> {
        self.indices
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, v)| *v)
    }

    fn bind_index(&mut self, id: &Ident, value: i64) -> Result<(), Error> {
        let name = id.to_string();
        if let Some((_, prev)) = self.syms.get(&name) {
            let mut e = Error::new(
                id.span(),
                format!("the index `{name}` hides a declared name: pick another letter"),
            );
            e.combine(Error::new(*prev, format!("`{name}` is declared here")));
            return Err(e);
        }
        self.indices.push((name, value));
        Ok(())
    }

    /// Evaluates an index expression (integers, `const`s, bound indices).
    fn int(&self, e: &Expr) -> Result<i64, Error> {
        let overflow = || Error::new(e.span, "integer overflow in an index expression");
        Ok(match &e.kind {
            ExprKind::Num(v, _) if v.fract() == 0.0 && v.abs() < 9e15 => *v as i64,
            ExprKind::Ident(id) => {
                let name = id.to_string();
                if let Some(v) = self.lookup_index(&name) {
                    v
                } else {
                    match self.syms.get(&name) {
                        Some((Sym::Number(v), _)) if v.fract() == 0.0 => *v as i64,
                        Some(_) => return Err(not_int(e.span)),
                        None => {
                            return Err(Error::new(
                                id.span(),
                                format!(
                                    "unknown index `{name}`: not a `const` or a bound index{}",
                                    self.did_you_mean(&name, |s| matches!(s, Sym::Number(_)))
                                ),
                            ))
                        }
                    }
                }
            }
            ExprKind::Neg(a) => self.int(a)?.checked_neg().ok_or_else(overflow)?,
            ExprKind::Binary(op, a, b) => self.int_op(*op, self.int(a)?, self.int(b)?, e.span)?,
            ExprKind::Chain(first, links) => {
                let mut acc = self.int(first)?;
                for l in links {
                    acc = self.int_op(l.op, acc, self.int(&l.rhs)?, l.span)?;
                }
                acc
            }
            ExprKind::If(c, t, f) => {
                if self.cond(c)? {
                    self.int(t)?
                } else {
                    self.int(f)?
                }
            }
            _ => return Err(not_int(e.span)),
        })
    }

    /// `a op b` in an index expression; errors at `at`, the operator.
    fn int_op(&self, op: BinOp, a: i64, b: i64, at: Span) -> Result<i64, Error> {
        let r = match op {
            BinOp::Add => a.checked_add(b),
            BinOp::Sub => a.checked_sub(b),
            BinOp::Mul => a.checked_mul(b),
            BinOp::Div | BinOp::Rem if b == 0 => {
                return Err(Error::new(at, "division by zero in an index expression"))
            }
            BinOp::Div => a.checked_div(b),
            BinOp::Rem => a.checked_rem(b),
            BinOp::Pow => match u32::try_from(b) {
                Ok(b) => a.checked_pow(b),
                Err(_) => return Err(not_int(at)),
            },
        };
        r.ok_or_else(|| Error::new(at, "integer overflow in an index expression"))
    }

    fn cond(&self, c: &Cond) -> Result<bool, Error> {
        Ok(match c {
            Cond::Cmp(op, a, b) => {
                let (a, b) = (self.int(a)?, self.int(b)?);
                match op {
                    CmpOp::Eq => a == b,
                    CmpOp::Ne => a != b,
                    CmpOp::Lt => a < b,
                    CmpOp::Le => a <= b,
                    CmpOp::Gt => a > b,
                    CmpOp::Ge => a >= b,
                }
            }
            Cond::And(all) => {
                for c in all {
                    if !self.cond(c)? {
                        return Ok(false);
                    }
                }
                true
            }
            Cond::Or(any) => {
                for c in any {
                    if self.cond(c)? {
                        return Ok(true);
                    }
                }
                false
            }
        })
    }

    fn range(&self, lo: &Expr, hi: &Expr) -> Result<std::ops::Range<i64>, Error> {
        let (a, b) = (self.int(lo)?, self.int(hi)?);
        if b.saturating_sub(a) > 100_000 {
            return Err(Error::new(
                hi.span,
                "this range is too long (more than 100000 terms)",
            ));
        }
        Ok(a..b)
    }

    /// Refuses a power x^n with |n| > [`MAX_EXPONENT`], written or made by
    /// merging (`x^a · x^b`), at the operator `at` that made it.
    fn exponent_ok(&self, node: NodeId, at: Span) -> Result<NodeId, Error> {
        let n = self.graph.max_exponent(node);
        if n > MAX_EXPONENT {
            let shown = if n == u32::MAX {
                "beyond 4·10^9".to_string()
            } else {
                n.to_string()
            };
            return Err(Error::new(
                at,
                format!(
                    "exponent too large: this makes a power with |exponent| {shown}, above the limit of \
                     {MAX_EXPONENT} (x^n over- or underflows f64 for every |x| outside [0.5, 2] there)"
                ),
            ));
        }
        Ok(node)
    }

    /// Lowers a real-valued expression into the graph.
    ///
    /// Each form is lowered by a function of its own: the recursion runs
    /// through this dispatch and the forms that nest, and without
    /// optimisation a function's frame holds the locals of all its arms.
    fn real(&mut self, e: &Expr) -> Result<NodeId, Error> {
        match &e.kind {
            ExprKind::Num(v, _) => Ok(self.graph.num(*v)),
            ExprKind::Ident(id) => self.symbol(id),
            ExprKind::Index(id, idx, bracket) => self.state(id, idx, *bracket),
            ExprKind::Neg(a) => {
                let a = self.real(a)?;
                Ok(self.graph.neg(a))
            }
            ExprKind::Binary(op, a, b) => {
                let x = self.real(a)?;
                let y = self.real(b)?;
                self.binary(*op, x, y, e.span, b)
            }
            ExprKind::Chain(first, links) => self.chain(first, links),
            ExprKind::Call(f, args) => self.call(f, args),
            ExprKind::Sum(var, lo, hi, body) => self.sum(var, lo, hi, body),
            ExprKind::Component(_, _, bracket) => Err(Error::new(
                *bracket,
                "`x[a][c]` (coordinate c of particle a) is only for the templates of a \
                 `particles x[D];` system; with `dof`, index the state directly: `q[i]`",
            )),
            ExprKind::If(c, t, f) => {
                if self.cond(c)? {
                    self.real(t)
                } else {
                    self.real(f)
                }
            }
        }
    }

    /// A name alone: a bound index, a `const`, a parameter, a coordinate
    /// or momentum, or a `let`.
    fn symbol(&mut self, id: &Ident) -> Result<NodeId, Error> {
        let name = id.to_string();
        if let Some(v) = self.lookup_index(&name) {
            return Ok(self.graph.num(v as f64));
        }
        Ok(match self.syms.get(&name).map(|s| s.0.clone()) {
            Some(Sym::Number(v)) => self.graph.num(v),
            Some(Sym::Param(p)) => self.graph.param(p),
            Some(Sym::Var(v)) => self.graph.var(v),
            Some(Sym::Let(n)) => n,
            Some(Sym::Array(_)) => {
                return Err(Error::new(
                    id.span(),
                    format!("`{name}` is an array of the state: index it, as in `{name}[0]`"),
                ))
            }
            None => {
                return Err(Error::new(
                    id.span(),
                    format!(
                        "unknown symbol `{name}`: not a parameter, coordinate, momentum, \
                         `let`, `const` or bound index{}",
                        self.did_you_mean(&name, |s| !matches!(s, Sym::Array(_)))
                    ),
                ))
            }
        })
    }

    /// `q[idx]`: an entry of a state array.
    fn state(&mut self, id: &Ident, idx: &Expr, bracket: Span) -> Result<NodeId, Error> {
        let name = id.to_string();
        let offset = match self.syms.get(&name).map(|s| s.0.clone()) {
            Some(Sym::Array(o)) => o,
            Some(_) => {
                return Err(Error::new(
                    id.span(),
                    format!("`{name}` is not an array: it cannot be indexed"),
                ))
            }
            None => {
                return Err(Error::new(
                    id.span(),
                    format!(
                        "unknown array `{name}`: the state arrays are the ones declared by `dof`{}",
                        self.did_you_mean(&name, |s| matches!(s, Sym::Array(_)))
                    ),
                ))
            }
        };
        let i = self.int(idx)?;
        if i < 0 || i as usize >= self.dof {
            return Err(Error::new(
                bracket,
                format!(
                    "index out of range: `{name}[{i}]`, but `{name}` has {} entries ({name}[0] to {name}[{}])",
                    self.dof,
                    self.dof - 1
                ),
            ));
        }
        Ok(self.graph.var(VarId((offset + i as usize) as u32)))
    }

    /// `x op y` for the lowered operands, the operator at `at` and the
    /// right operand written `rhs` (where a division by zero is reported).
    fn binary(
        &mut self,
        op: BinOp,
        x: NodeId,
        y: NodeId,
        at: Span,
        rhs: &Expr,
    ) -> Result<NodeId, Error> {
        let r = match op {
            BinOp::Add => self.graph.add2(x, y),
            BinOp::Sub => self.graph.sub(x, y),
            BinOp::Mul => self.graph.mul2(x, y),
            BinOp::Div => {
                if self.graph.is_zero(y) {
                    return Err(Error::new(rhs.span, "division by zero"));
                }
                self.graph.div(x, y)
            }
            BinOp::Rem => {
                return Err(Error::new(
                    at,
                    "`%` is only allowed in index expressions: it is not differentiable",
                ))
            }
            BinOp::Pow => match self.graph.as_const(y) {
                Some(r) if r.is_finite() => {
                    if self.graph.is_zero(x) && r < 0.0 {
                        return Err(Error::new(at, "division by zero: 0 to a negative power"));
                    }
                    self.graph.powf(x, r)
                }
                _ => {
                    return Err(Error::new(
                        rhs.span,
                        "the exponent must be a constant (a number, a `const` or an index); \
                         write `exp(y * ln(x))` for a variable exponent",
                    ))
                }
            },
        };
        self.exponent_ok(r, at)
    }

    /// A chain `a + b - c` or `a * b / c`. A sum is one n-ary sum of its
    /// terms, so like terms are collected along the whole chain, however
    /// long (summed two at a time, a sum stops being flattened into the
    /// next past `FLATTEN_LIMIT` terms). A product is folded left to right,
    /// two factors at a time, each step checked at its operator (a division
    /// by zero, an exponent grown past the limit by merging).
    fn chain(&mut self, first: &Expr, links: &[Link]) -> Result<NodeId, Error> {
        let x = self.real(first)?;
        if links
            .iter()
            .all(|l| matches!(l.op, BinOp::Add | BinOp::Sub))
        {
            let mut terms = Vec::with_capacity(links.len() + 1);
            terms.push(x);
            for l in links {
                let y = self.real(&l.rhs)?;
                terms.push(match l.op {
                    BinOp::Sub => self.graph.neg(y),
                    _ => y,
                });
            }
            return Ok(self.graph.add(terms));
        }
        let mut acc = x;
        for l in links {
            let y = self.real(&l.rhs)?;
            acc = self.binary(l.op, acc, y, l.span, &l.rhs)?;
        }
        Ok(acc)
    }

    /// `f(args)`: sqrt and the elementary functions.
    fn call(&mut self, f: &Ident, args: &[Expr]) -> Result<NodeId, Error> {
        let name = f.to_string();
        let func = function(f, &name)?;
        if args.len() != 1 {
            return Err(Error::new(
                f.span(),
                format!("`{name}` takes one argument, {} given", args.len()),
            ));
        }
        let x = self.real(&args[0])?;
        let y = match func {
            None => self.graph.sqrt(x),
            Some(func) => self.graph.call(func, x),
        };
        // A function of a constant outside its domain (sqrt(-1),
        // ln(0)) folds to NaN or ∞: every H or g holding it would
        // be NaN or ∞ at every state.
        if self.graph.as_const(y).is_some_and(|v| !v.is_finite()) {
            return Err(Error::new(
                f.span(),
                format!(
                    "`{name}` of the constant {} is not a finite real number",
                    self.graph
                        .as_const(x)
                        .map_or("here".to_string(), |v| format!("{v}"))
                ),
            ));
        }
        Ok(y)
    }

    /// `sum var in lo..hi { body }`, expanded.
    fn sum(&mut self, var: &Ident, lo: &Expr, hi: &Expr, body: &Expr) -> Result<NodeId, Error> {
        let range = self.range(lo, hi)?;
        let len = range.end.saturating_sub(range.start).max(0) as u64;
        self.terms = self.terms.saturating_add(len);
        if self.terms > MAX_TERMS {
            return Err(Error::new(
                var.span(),
                format!(
                    "the `sum`s of this declaration expand to more than {MAX_TERMS} terms in \
                     all (nested sums multiply their lengths)"
                ),
            ));
        }
        let mut terms = Vec::new();
        for i in range {
            self.bind_index(var, i)?;
            let t = self.real(body);
            self.indices.pop();
            terms.push(t?);
        }
        Ok(self.graph.add(terms))
    }

    fn constraint(
        &mut self,
        c: &ConstraintDecl,
        out: &mut Vec<Constraint>,
        declared: &mut usize,
    ) -> Result<(), Error> {
        match &c.family {
            None => {
                *declared += 1;
                let node = self.real(&c.expr)?;
                out.push(Constraint {
                    name: c.name.to_string(),
                    span: c.name.span(),
                    node,
                });
            }
            Some((k, lo, hi)) => {
                let range = self.range(lo, hi)?;
                *declared += range.clone().count();
                for i in range {
                    if out.len() > self.dof {
                        return Ok(());
                    }
                    self.bind_index(k, i)?;
                    let node = self.real(&c.expr);
                    self.indices.pop();
                    out.push(Constraint {
                        name: format!("{}[{i}]", c.name),
                        span: c.name.span(),
                        node: node?,
                    });
                }
            }
        }
        Ok(())
    }
}

/// The function `f` (named `name`) stands for: `None` for `sqrt` (a
/// power), else the elementary function; an error naming the supported
/// functions otherwise.
fn function(f: &Ident, name: &str) -> Result<Option<Func>, Error> {
    Ok(match name {
        "sqrt" => None,
        "sin" => Some(Func::Sin),
        "cos" => Some(Func::Cos),
        "tan" => Some(Func::Tan),
        "exp" => Some(Func::Exp),
        "ln" => Some(Func::Ln),
        _ if NON_DIFFERENTIABLE.contains(&name) => {
            return Err(Error::new(
                f.span(),
                format!(
                    "`{name}` is not differentiable: the methods need derivatives of H and g \
                     (the supported functions are {FUNCS})"
                ),
            ))
        }
        "log" => {
            return Err(Error::new(
                f.span(),
                "`log` is ambiguous: write `ln` for the natural logarithm",
            ))
        }
        "sinh" | "cosh" | "tanh" => {
            return Err(Error::new(
                f.span(),
                format!(
                    "unknown function `{name}`: write the hyperbolic functions with `exp` \
                     (sinh(x) = (exp(x) - exp(-x)) / 2, cosh(x) = (exp(x) + exp(-x)) / 2, \
                     tanh(x) = sinh(x) / cosh(x)); the supported functions are {FUNCS}"
                ),
            ))
        }
        _ => {
            return Err(Error::new(
                f.span(),
                format!(
                    "unknown function `{name}`: the supported functions are {FUNCS}{}",
                    suggestion(name, FUNCS.split(", "))
                ),
            ))
        }
    })
}

fn not_int(at: Span) -> Error {
    Error::new(
        at,
        "expected a compile-time integer: index expressions may use integer literals, \
         `const`s, family and sum indices, `+ - * / %` and parentheses",
    )
}

/// The edit distance between two names, in characters: insertions,
/// deletions, substitutions and transpositions of neighbours (`cso` is one
/// edit from `cos`), the optimal-string-alignment variant of Damerau's.
fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().collect(), b.chars().collect());
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for i in 0..=a.len() {
        for j in 0..=b.len() {
            d[i * w + j] = if i == 0 || j == 0 {
                i + j
            } else {
                let cost = usize::from(a[i - 1] != b[j - 1]);
                let mut v = (d[(i - 1) * w + j] + 1)
                    .min(d[i * w + j - 1] + 1)
                    .min(d[(i - 1) * w + j - 1] + cost);
                if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                    v = v.min(d[(i - 2) * w + j - 2] + 1);
                }
                v
            };
        }
    }
    d[a.len() * w + b.len()]
}

/// ` (did you mean `x`?)` for the candidate nearest to `name`, if it is
/// within a third of the name's length in edits (at least one), else "".
/// Distances are taken between lower-case spellings, so a name that
/// differs only in case (`l` for a declared `L`) is the nearest of all,
/// ahead of any one-letter edit (`l` for `G`). Ties go to the first in
/// sorted order, so the message does not depend on hash order.
fn suggestion<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> String {
    let limit = (name.chars().count() / 3).max(1);
    let lower = name.to_lowercase();
    let mut best: Option<(usize, &str)> = None;
    for c in candidates.filter(|&c| c != name) {
        let d = edit_distance(&lower, &c.to_lowercase());
        let better = match best {
            None => true,
            Some(b) => (d, c) < b,
        };
        if d <= limit && better {
            best = Some((d, c));
        }
    }
    best.map(|(_, c)| format!(" (did you mean `{c}`?)"))
        .unwrap_or_default()
}

/// The deepest expression graph a `let` may make (the longest chain of
/// operations from it down to q, p or a parameter). Only `let`s that build
/// on each other reach it: an expression alone is at most
/// [`crate::parse::MAX_NESTING`] deep, plus a level for every
/// [`crate::simplify::FLATTEN_LIMIT`] factors of a long product (a sum is
/// one node however long). Every pass is linear in the graph,
/// but the generated code grows with the depth times the number of
/// derivatives; 2000 nested `let`s already take seconds to expand.
pub const MAX_LET_DEPTH: u32 = 1000;

fn shallow(graph: &Graph, v: NodeId, name: &Ident) -> Result<NodeId, Error> {
    if graph.height(v) > MAX_LET_DEPTH {
        return Err(Error::new(
            name.span(),
            format!(
                "`{name}` is nested too deeply: its expression is a chain of {} operations through \
                 the `let`s before it, more than the limit of {MAX_LET_DEPTH}",
                graph.height(v)
            ),
        ));
    }
    Ok(v)
}

/// Builds the symbolic system; returns every error found (one per
/// offending item), not just the first.
pub fn lower(def: &SystemDef) -> Result<System, Vec<Error>> {
    lower_with(def, false)
}

/// [`lower`] into a graph that keeps products and powers of sums factored
/// (`factored = true`: the values of the emitted code).
pub fn lower_with(def: &SystemDef, factored: bool) -> Result<System, Vec<Error>> {
    let mut lw = Lowerer {
        graph: Graph::new(factored),
        dof: 0,
        syms: HashMap::new(),
        indices: Vec::new(),
        terms: 0,
    };
    let mut errors = Vec::new();
    let mut names = Names::default();
    for (i, p) in def.params.iter().enumerate() {
        if let Err(e) = lw.declare(p, Sym::Param(ParamId(i as u32))) {
            errors.push(e);
        }
        names.params.push(p.to_string());
    }
    for (n, e) in &def.consts {
        let v = match &e.kind {
            ExprKind::Num(v, false) => Ok(*v),
            _ => lw.int(e).map(|v| v as f64),
        };
        match v.and_then(|v| lw.declare(n, Sym::Number(v))) {
            Ok(()) => {}
            Err(e) => errors.push(e),
        }
    }
    // The dimension, then the state's names.
    match &def.dof {
        Dof::Arrays { q, p, dim, p_dim } => {
            match (lw.int(dim), lw.int(p_dim)) {
                (Ok(a), Ok(b)) if a != b => errors.push(Error::new(
                    p_dim.span,
                    format!("`{p}` must have the dimension of `{q}`: {b} ≠ {a}"),
                )),
                (Ok(a), Ok(_)) if !(1..=MAX_DOF as i64).contains(&a) => errors.push(Error::new(
                    dim.span,
                    format!("the dimension must be between 1 and {MAX_DOF}, not {a}"),
                )),
                (Ok(a), Ok(_)) => lw.dof = a as usize,
                (Err(e), _) | (_, Err(e)) => errors.push(e),
            }
            for (id, off) in [(q, 0), (p, lw.dof)] {
                if let Err(e) = lw.declare(id, Sym::Array(off)) {
                    errors.push(e);
                }
            }
            for k in 0..lw.dof {
                names.vars.push(format!("{q}[{k}]"));
            }
            for k in 0..lw.dof {
                names.vars.push(format!("{p}[{k}]"));
            }
        }
        Dof::Named { coords, momenta } => {
            lw.dof = coords.len();
            for (k, id) in coords.iter().chain(momenta).enumerate() {
                if let Err(e) = lw.declare(id, Sym::Var(VarId(k as u32))) {
                    errors.push(e);
                }
                names.vars.push(id.to_string());
            }
        }
    }
    lw.graph.names = names;
    if !errors.is_empty() {
        return Err(errors);
    }
    for (n, e) in &def.lets {
        let v = match lw.real(e) {
            Ok(v) => v,
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        // Too deep: the `let`s after it would only add a cascade of errors.
        if let Err(e) = shallow(&lw.graph, v, n) {
            errors.push(e);
            return Err(errors);
        }
        match lw.declare(n, Sym::Let(v)) {
            Ok(()) => {}
            Err(e) => errors.push(e),
        }
    }
    let hamiltonian = match lw.real(&def.hamiltonian) {
        Ok(h) => Some(h),
        Err(e) => {
            errors.push(e);
            None
        }
    };
    let mut constraints = Vec::new();
    let mut declared = 0;
    let mut seen: HashMap<String, Span> = HashMap::new();
    for c in &def.constraints {
        let name = c.name.to_string();
        if let Some(prev) = seen.get(&name) {
            let mut e = Error::new(c.name.span(), format!("duplicate constraint name `{name}`"));
            e.combine(Error::new(
                *prev,
                format!("`{name}` is first declared here"),
            ));
            errors.push(e);
            continue;
        }
        seen.insert(name, c.name.span());
        if let Err(e) = lw.constraint(c, &mut constraints, &mut declared) {
            errors.push(e);
        }
    }
    match hamiltonian {
        Some(h) if errors.is_empty() => Ok(System {
            graph: lw.graph,
            dof: lw.dof,
            params: def.params.clone(),
            hamiltonian: h,
            constraints,
            declared,
        }),
        _ => Err(errors),
    }
}
