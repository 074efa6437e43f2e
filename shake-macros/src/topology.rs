//! Families over run-time tables: one template per family, lowered to a
//! small local system, differentiated once, emitted as a
//! `geoshake::runtime::particles::Stencil`.
//!
//! A family `bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2`
//! in a system of particles in R^D is the function
//! f(x_a, x_b; length) of the ARITY·D local coordinates (particle by
//! particle: coordinate c of the i-th particle of the signature is local
//! variable i·D + c) and of the DATA numbers of a row. Nothing here depends on
//! the number of members (the rows are given at run time), so expansion time
//! and code size do not either.
//!
//! Checks run once per template: every name is known, particles are reached
//! only through the table's particle variables, the template depends on the
//! positions only (holonomic; then {g_i, g_j} = 0 for every pair of members
//! of every family, so coisotropy holds without a check), its gradient is not
//! identically zero, and it uses every particle it declares. What only the
//! table decides (dangling or repeated indices, duplicate members, clusters
//! with more constraints than coordinates) is the runtime's job, with a
//! `TopologyError` naming the family and the member.

use crate::cse::Coder;
use crate::parse::{BinOp, Expr, ExprKind};
use crate::parse_topology::{FamilyDecl, FamilyKind, ParticleDef};
use crate::symbolic::{Func, Graph, Names, Node, NodeId, ParamId, VarId};
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use std::collections::HashMap;
use syn::{Error, Ident};

/// The runtime's `MAX_LOCAL`: the most local coordinates (ARITY·DIM) a
/// stencil may have (they live on the stack).
const MAX_LOCAL: usize = 64;

/// The functions a template may call.
const FUNCS: &str = "sqrt, sin, cos, tan, exp, ln (scalars); dot(u, v), norm2(u), norm(u), \
                     cross(u, v) (vectors; cross in R^3 only)";

/// A template value: a scalar or a vector of R^D.
enum Val {
    S(NodeId),
    V(Vec<NodeId>),
}

/// One lowered template: the value and every entry of its gradient.
struct Lowered {
    graph: Graph,
    /// The canonical value (checks, docs).
    value: NodeId,
    /// The value as written, for emission (see `Template::add`).
    written: NodeId,
    /// ∂f/∂x_l for l in 0..ARITY·DIM (zeros included).
    gradient: Vec<NodeId>,
}

struct Template<'a> {
    def: &'a ParticleDef,
    fam: &'a FamilyDecl,
    graph: Graph,
    /// Parameters and data variables: constants for differentiation.
    scalars: HashMap<String, NodeId>,
    /// Bound `sum` indices, innermost last.
    sums: Vec<(String, i64)>,
    /// Terms the `sum`s expanded so far (`geoshake_symbolic::lower::MAX_TERMS`).
    terms: u64,
    /// Build nodes as written (no canonical form): for the emitted value.
    raw: bool,
}

/// `a op b` in an index expression, with the operator at `at`.
fn int_op(op: BinOp, a: i64, b: i64, at: Span) -> Result<i64, Error> {
    let r = match op {
        BinOp::Add => a.checked_add(b),
        BinOp::Sub => a.checked_sub(b),
        BinOp::Mul => a.checked_mul(b),
        BinOp::Div | BinOp::Rem if b == 0 => {
            return Err(err(at, "division by zero in an index expression"))
        }
        BinOp::Div => a.checked_div(b),
        BinOp::Rem => a.checked_rem(b),
        BinOp::Pow => None,
    };
    r.ok_or_else(|| err(at, NOT_INT))
}

const NOT_INT: &str =
    "expected a compile-time integer (literals and `sum` indices, with `+ - * / %`)";

fn err(span: Span, msg: impl std::fmt::Display) -> Error {
    Error::new(span, msg.to_string())
}

/// The arithmetic of a template, in one of two forms. Canonical (`raw ==
/// false`): the smart constructors of `simplify`, whose canonical form makes
/// the checks exact and the derivatives small. Raw: nodes as the user wrote
/// them (constants folded, nothing expanded or reordered), for the emitted
/// *value* only. The canonical form expands |x_a − x_b|² into
/// x_a² − 2x_a x_b + x_b², which cancels catastrophically far from the
/// origin (at |x| ~ 10³ it leaves ~10⁻¹⁰ of a unit bond's g, the tolerance
/// SHAKE is asked to meet); the written form rounds only the difference.
/// Raw nodes are never differentiated: the gradient comes from the
/// canonical form, where expansion is harmless (2x_a − 2x_b is one rounding).
impl Template<'_> {
    fn add(&mut self, terms: Vec<NodeId>) -> NodeId {
        if !self.raw {
            return self.graph.add(terms);
        }
        match terms.len() {
            0 => self.graph.zero(),
            1 => terms[0],
            _ => self.graph.intern(Node::Add(terms.into())),
        }
    }

    fn add2(&mut self, a: NodeId, b: NodeId) -> NodeId {
        self.add(vec![a, b])
    }

    fn mul2(&mut self, a: NodeId, b: NodeId) -> NodeId {
        if !self.raw {
            return self.graph.mul2(a, b);
        }
        match (self.graph.as_const(a), self.graph.as_const(b)) {
            (Some(x), Some(y)) => self.graph.num(x * y),
            (Some(c), None) | (None, Some(c)) if c == 1.0 => {
                if self.graph.as_const(a).is_some() {
                    b
                } else {
                    a
                }
            }
            // At most one constant per product (`Coder` emits one coefficient).
            (None, Some(_)) => self.graph.intern(Node::Mul(Box::new([b, a]))),
            _ => self.graph.intern(Node::Mul(Box::new([a, b]))),
        }
    }

    fn neg(&mut self, x: NodeId) -> NodeId {
        let m1 = self.graph.num(-1.0);
        self.mul2(m1, x)
    }

    fn sub(&mut self, a: NodeId, b: NodeId) -> NodeId {
        let nb = self.neg(b);
        self.add2(a, nb)
    }

    fn div(&mut self, a: NodeId, b: NodeId) -> NodeId {
        if !self.raw {
            return self.graph.div(a, b);
        }
        let inv = self.powf(b, -1.0);
        self.mul2(a, inv)
    }

    fn powf(&mut self, x: NodeId, r: f64) -> NodeId {
        if !self.raw {
            return self.graph.powf(x, r);
        }
        if let Some(c) = self.graph.as_const(x) {
            return self.graph.num(c.powf(r));
        }
        if r == 1.0 {
            x
        } else if r == 0.0 {
            self.graph.one()
        } else if r.fract() == 0.0 && r.abs() < 64.0 {
            self.graph.intern(Node::Pow(x, r as i32))
        } else {
            self.graph.intern(Node::PowF(x, crate::symbolic::bits(r)))
        }
    }

    fn sqrt(&mut self, x: NodeId) -> NodeId {
        self.powf(x, 0.5)
    }

    fn call(&mut self, f: Func, x: NodeId) -> NodeId {
        self.graph.call(f, x)
    }

    fn particle(&self, name: &str) -> Option<usize> {
        self.fam.particles.iter().position(|p| p == name)
    }

    fn sig(&self) -> String {
        let f = self.fam;
        let ps: Vec<String> = f.particles.iter().map(|p| p.to_string()).collect();
        let ds: Vec<String> = f.data.iter().map(|p| p.to_string()).collect();
        if ds.is_empty() {
            format!("{}({})", f.table, ps.join(", "))
        } else {
            format!("{}({}; {})", f.table, ps.join(", "), ds.join(", "))
        }
    }

    fn momentum_error(&self, span: Span) -> Error {
        err(
            span,
            format!(
                "`{}` is a momentum: the template of `{}` depends on momenta, but a family over a \
                 run-time table must be holonomic (positions only). Momentum-dependent families \
                 need the compile-time (dense) form: `dof q[d], p[d];` with `{}[k in 0..N]: ..`",
                self.def.p, self.fam.name, self.fam.name
            ),
        )
    }

    /// A compile-time integer: literals and bound `sum` indices.
    fn int(&self, e: &Expr) -> Result<i64, Error> {
        let not_int = || err(e.span, NOT_INT);
        match &e.kind {
            ExprKind::Num(v, true) => Ok(*v as i64),
            ExprKind::Ident(id) => self
                .sums
                .iter()
                .rev()
                .find(|(n, _)| id == n)
                .map(|(_, v)| *v)
                .ok_or_else(not_int),
            ExprKind::Neg(a) => Ok(-self.int(a)?),
            ExprKind::Binary(op, a, b) => {
                let (a, b) = (self.int(a)?, self.int(b)?);
                int_op(*op, a, b, e.span)
            }
            ExprKind::Chain(first, links) => {
                let mut acc = self.int(first)?;
                for l in links {
                    acc = int_op(l.op, acc, self.int(&l.rhs)?, l.span)?;
                }
                Ok(acc)
            }
            _ => Err(not_int()),
        }
    }

    fn scalar(&mut self, e: &Expr) -> Result<NodeId, Error> {
        match self.val(e)? {
            Val::S(s) => Ok(s),
            Val::V(_) => Err(err(
                e.span,
                format!(
                    "this is a vector of R^{}, a scalar is needed here: take `norm2(..)`, \
                     `norm(..)`, `dot(.., ..)` or a component `x[a][c]`",
                    self.def.dim
                ),
            )),
        }
    }

    fn vector(&mut self, e: &Expr) -> Result<Vec<NodeId>, Error> {
        match self.val(e)? {
            Val::V(v) => Ok(v),
            Val::S(_) => Err(err(
                e.span,
                "this is a scalar, a vector is needed here (a position `x[a]`, or sums, \
                 differences and multiples of positions)",
            )),
        }
    }

    fn val(&mut self, e: &Expr) -> Result<Val, Error> {
        Ok(match &e.kind {
            ExprKind::Num(v, _) => Val::S(self.graph.num(*v)),
            ExprKind::Ident(id) => {
                let name = id.to_string();
                if let Some((_, v)) = self.sums.iter().rev().find(|(n, _)| *n == name) {
                    return Ok(Val::S(self.graph.num(*v as f64)));
                }
                if let Some(&n) = self.scalars.get(&name) {
                    return Ok(Val::S(n));
                }
                let f = self.fam;
                let msg =
                    if self.particle(&name).is_some() {
                        format!(
                            "`{name}` is a particle of the table: its position is `{}[{name}]`",
                            self.def.x
                        )
                    } else if f.index == name {
                        format!(
                        "`{name}` numbers the members of `{}`: a template is the same formula for \
                         every member and cannot depend on it; put per-member numbers in the \
                         table's data, as in `{}(..; value)`",
                        f.name, f.table
                    )
                    } else if self.def.x == name {
                        format!("`{name}` holds every position: take one, `{name}[a]`")
                    } else if self.def.p == name {
                        return Err(self.momentum_error(id.span()));
                    } else {
                        let params: Vec<String> =
                            self.def.params.iter().map(|p| p.to_string()).collect();
                        format!(
                        "unknown name `{name}` in the template of `{}`: it may use the parameters \
                         ({}), the data of its table `{}` and the positions `{}[..]` of the \
                         table's particles",
                        f.name,
                        if params.is_empty() { "none".to_string() } else { params.join(", ") },
                        self.sig(),
                        self.def.x
                    )
                    };
                return Err(err(id.span(), msg));
            }
            ExprKind::Index(id, idx, bracket) => {
                if *id == self.def.p {
                    return Err(self.momentum_error(id.span()));
                }
                if *id != self.def.x {
                    return Err(err(
                        id.span(),
                        format!(
                            "unknown array `{id}`: the positions are `{}[a]`, `a` a particle of \
                             the table",
                            self.def.x
                        ),
                    ));
                }
                let ExprKind::Ident(a) = &idx.kind else {
                    return Err(err(
                        *bracket,
                        format!(
                            "a template reaches particles only through its table: write `{}[a]` \
                             with `a` one of the particles of `{}`",
                            self.def.x,
                            self.sig()
                        ),
                    ));
                };
                let Some(i) = self.particle(&a.to_string()) else {
                    return Err(err(
                        a.span(),
                        format!(
                            "`{a}` is not a particle of the table `{}`: index variables used as \
                             particles must be declared in the table signature",
                            self.sig()
                        ),
                    ));
                };
                let d = self.def.dim;
                Val::V(
                    (0..d)
                        .map(|c| self.graph.var(VarId((i * d + c) as u32)))
                        .collect(),
                )
            }
            ExprKind::Component(v, c, bracket) => {
                let v = self.vector(v)?;
                let c = self.int(c)?;
                if c < 0 || c as usize >= v.len() {
                    return Err(err(
                        *bracket,
                        format!(
                            "component {c} out of range: positions are in R^{}, components 0 to {}",
                            v.len(),
                            v.len() - 1
                        ),
                    ));
                }
                Val::S(v[c as usize])
            }
            ExprKind::Neg(a) => match self.val(a)? {
                Val::S(s) => Val::S(self.neg(s)),
                Val::V(v) => Val::V(v.into_iter().map(|x| self.neg(x)).collect()),
            },
            ExprKind::Binary(op, a, b) => {
                let (x, y) = (self.val(a)?, self.val(b)?);
                self.binary(*op, x, y, e.span, b)?
            }
            ExprKind::Chain(first, links) => {
                let mut acc = self.val(first)?;
                for l in links {
                    let y = self.val(&l.rhs)?;
                    acc = self.binary(l.op, acc, y, l.span, &l.rhs)?;
                }
                acc
            }
            ExprKind::Call(f, args) => self.function(f, args)?,
            ExprKind::Sum(var, lo, hi, body) => {
                let (lo, hi) = (self.int(lo)?, self.int(hi)?);
                if hi.saturating_sub(lo) > 1024 {
                    return Err(err(
                        var.span(),
                        "this `sum` is too long (more than 1024 terms)",
                    ));
                }
                self.terms = self
                    .terms
                    .saturating_add(hi.saturating_sub(lo).max(0) as u64);
                if self.terms > geoshake_symbolic::lower::MAX_TERMS {
                    return Err(err(
                        var.span(),
                        format!(
                            "the `sum`s of this template expand to more than {} terms in all \
                             (nested sums multiply their lengths)",
                            geoshake_symbolic::lower::MAX_TERMS
                        ),
                    ));
                }
                let name = var.to_string();
                if self.scalars.contains_key(&name) || self.particle(&name).is_some() {
                    return Err(err(
                        var.span(),
                        format!("the index `{name}` hides a declared name: pick another letter"),
                    ));
                }
                let mut terms = Vec::new();
                for i in lo..hi {
                    self.sums.push((name.clone(), i));
                    let t = self.scalar(body);
                    self.sums.pop();
                    terms.push(t?);
                }
                Val::S(self.add(terms))
            }
            ExprKind::If(..) => {
                return Err(err(
                    e.span,
                    format!(
                        "`if` in a template: a template is one formula for every member; declare \
                         another family (another table) for the members of `{}` that differ",
                        self.fam.name
                    ),
                ))
            }
        })
    }

    /// `x op y` for the values of the operands, the operator at `at` and the
    /// right operand written `rhs`.
    fn binary(&mut self, op: BinOp, x: Val, y: Val, at: Span, rhs: &Expr) -> Result<Val, Error> {
        Ok(match (op, x, y) {
            (BinOp::Add, Val::S(x), Val::S(y)) => Val::S(self.add2(x, y)),
            (BinOp::Sub, Val::S(x), Val::S(y)) => Val::S(self.sub(x, y)),
            (BinOp::Add | BinOp::Sub, Val::V(x), Val::V(y)) => Val::V(
                x.into_iter()
                    .zip(y)
                    .map(|(x, y)| match op {
                        BinOp::Add => self.add2(x, y),
                        _ => self.sub(x, y),
                    })
                    .collect(),
            ),
            (BinOp::Add | BinOp::Sub, _, _) => {
                return Err(err(at, "cannot add a scalar and a vector"))
            }
            (BinOp::Mul, Val::S(x), Val::S(y)) => Val::S(self.mul2(x, y)),
            (BinOp::Mul, Val::S(s), Val::V(v)) | (BinOp::Mul, Val::V(v), Val::S(s)) => {
                Val::V(v.into_iter().map(|x| self.mul2(s, x)).collect())
            }
            (BinOp::Mul, Val::V(_), Val::V(_)) => {
                return Err(err(
                    at,
                    "`*` between two vectors is ambiguous: write `dot(u, v)` (or \
                     `cross(u, v)` in R^3)",
                ))
            }
            (BinOp::Div, x, Val::S(y)) => {
                if self.graph.is_zero(y) {
                    return Err(err(rhs.span, "division by zero"));
                }
                match x {
                    Val::S(x) => Val::S(self.div(x, y)),
                    Val::V(v) => Val::V(v.into_iter().map(|x| self.div(x, y)).collect()),
                }
            }
            (BinOp::Div, _, Val::V(_)) => return Err(err(rhs.span, "cannot divide by a vector")),
            (BinOp::Rem, _, _) => {
                return Err(err(
                    at,
                    "`%` is only allowed in index expressions: it is not differentiable",
                ))
            }
            (BinOp::Pow, Val::S(x), Val::S(y)) => match self.graph.as_const(y) {
                Some(r) if r.is_finite() => {
                    if r.abs() > crate::simplify::MAX_EXPONENT as f64 {
                        return Err(err(
                            rhs.span,
                            format!(
                                "exponent too large: |{r}| is above the limit of {} \
                                 (x^n over- or underflows f64 for every |x| outside \
                                 [0.5, 2] there)",
                                crate::simplify::MAX_EXPONENT
                            ),
                        ));
                    }
                    if self.graph.is_zero(x) && r < 0.0 {
                        return Err(err(at, "division by zero: 0 to a negative power"));
                    }
                    Val::S(self.powf(x, r))
                }
                _ => {
                    return Err(err(
                        rhs.span,
                        "the exponent must be a constant; write `exp(y * ln(x))` for a \
                         variable exponent",
                    ))
                }
            },
            (BinOp::Pow, _, _) => {
                return Err(err(at, "powers are of scalars: for |u|² write `norm2(u)`"))
            }
        })
    }

    fn function(&mut self, f: &Ident, args: &[Expr]) -> Result<Val, Error> {
        let name = f.to_string();
        let arity = match name.as_str() {
            "sqrt" | "sin" | "cos" | "tan" | "exp" | "ln" | "norm2" | "norm" => 1,
            "dot" | "cross" => 2,
            "log" => {
                return Err(err(
                    f.span(),
                    "`log` is ambiguous: write `ln` for the natural logarithm",
                ))
            }
            _ => {
                return Err(err(
                    f.span(),
                    format!("unknown function `{name}`: a template may call {FUNCS}"),
                ))
            }
        };
        if args.len() != arity {
            return Err(err(
                f.span(),
                format!("`{name}` takes {arity} argument(s), {} given", args.len()),
            ));
        }
        Ok(match name.as_str() {
            "norm2" | "norm" => {
                let v = self.vector(&args[0])?;
                let sq: Vec<NodeId> = v.iter().map(|x| self.mul2(*x, *x)).collect();
                let n2 = self.add(sq);
                Val::S(if name == "norm" { self.sqrt(n2) } else { n2 })
            }
            "dot" => {
                let (u, v) = (self.vector(&args[0])?, self.vector(&args[1])?);
                let t: Vec<NodeId> = u.into_iter().zip(v).map(|(a, b)| self.mul2(a, b)).collect();
                Val::S(self.add(t))
            }
            "cross" => {
                if self.def.dim != 3 {
                    return Err(err(
                        f.span(),
                        format!(
                            "`cross` is the cross product of R^3; the particles are in R^{}",
                            self.def.dim
                        ),
                    ));
                }
                let (u, v) = (self.vector(&args[0])?, self.vector(&args[1])?);
                let mut w = Vec::with_capacity(3);
                for (i, j) in [(1, 2), (2, 0), (0, 1)] {
                    let a = self.mul2(u[i], v[j]);
                    let b = self.mul2(u[j], v[i]);
                    w.push(self.sub(a, b));
                }
                Val::V(w)
            }
            _ => {
                let x = self.scalar(&args[0])?;
                Val::S(match name.as_str() {
                    "sqrt" => self.sqrt(x),
                    "sin" => self.call(Func::Sin, x),
                    "cos" => self.call(Func::Cos, x),
                    "tan" => self.call(Func::Tan, x),
                    "exp" => self.call(Func::Exp, x),
                    _ => self.call(Func::Ln, x),
                })
            }
        })
    }
}

/// Lowers, checks and differentiates one template.
fn lower_family(def: &ParticleDef, fam: &FamilyDecl) -> Result<Lowered, Error> {
    let d = def.dim;
    let mut names = Names::default();
    for p in &fam.particles {
        for c in 0..d {
            names.vars.push(format!("{}[{p}][{c}]", def.x));
        }
    }
    let mut graph = Graph::default();
    let mut scalars = HashMap::new();
    for (i, p) in def.params.iter().chain(&fam.data).enumerate() {
        names.params.push(p.to_string());
        let n = graph.param(ParamId(i as u32));
        scalars.insert(p.to_string(), n);
    }
    graph.names = names;
    let mut t = Template {
        def,
        fam,
        graph,
        scalars,
        sums: Vec::new(),
        terms: 0,
        raw: false,
    };
    let value = match t.val(&fam.template)? {
        Val::S(s) => s,
        Val::V(_) => {
            return Err(err(
                fam.name.span(),
                format!(
                    "the template of `{}` is a vector of R^{d}: a {} is a scalar (take \
                     `norm2(..)`, `norm(..)` or `dot(.., ..)`)",
                    fam.name,
                    match fam.kind {
                        FamilyKind::Constraint => "constraint",
                        FamilyKind::Potential => "term of the potential energy",
                    }
                ),
            ))
        }
    };
    let graph = t.graph;
    let what = match fam.kind {
        FamilyKind::Constraint => "constraint",
        FamilyKind::Potential => "potential",
    };
    if graph.support(value).is_empty() {
        return Err(err(
            fam.name.span(),
            format!(
                "the {what} template `{}` does not depend on the positions: it simplifies to `{}`, \
                 so its gradient is identically zero{}",
                fam.name,
                graph.display(value),
                match fam.kind {
                    FamilyKind::Constraint => " and it is either never or always satisfied",
                    FamilyKind::Potential => " and it exerts no force",
                }
            ),
        ));
    }
    for (i, p) in fam.particles.iter().enumerate() {
        let moves = graph.support(value).iter().any(|v| v.index() / d == i);
        if !moves {
            return Err(err(
                p.span(),
                format!(
                    "the {what} template `{}` does not depend on particle `{p}` of its table: it \
                     simplifies to `{}`, which has no `{}[{p}]`; drop `{p}` from `{}` or use it",
                    fam.name,
                    graph.display(value),
                    def.x,
                    fam.table
                ),
            ));
        }
    }
    // The emitted value, as written (see `Template::add`); lowering it again
    // cannot fail, the canonical pass accepted the same tokens.
    let mut r = Template {
        def,
        fam,
        graph,
        scalars: t.scalars,
        sums: Vec::new(),
        terms: 0,
        raw: true,
    };
    let written = match r.val(&fam.template)? {
        Val::S(s) => s,
        Val::V(_) => value,
    };
    let mut graph = r.graph;
    // The gradient of the written form: sums the user did not expand stay
    // factors (|x_a − x_b| in a spring's force is not rebuilt from
    // x_a² − 2x_a x_b + x_b²), which is both more accurate and cheaper.
    let gradient: Vec<NodeId> = (0..fam.particles.len() * d)
        .map(|l| graph.diff(written, VarId(l as u32)))
        .collect();
    Ok(Lowered {
        graph,
        value,
        written,
        gradient,
    })
}

/// Declaration-level checks: names, limits.
fn check_declaration(def: &ParticleDef) -> Vec<Error> {
    let mut errors = Vec::new();
    if def.dim == 0 {
        errors.push(err(def.dim_span, "particles need at least one coordinate"));
    }
    if def.x == def.p {
        errors.push(err(
            def.p.span(),
            "positions and momenta need different names",
        ));
    }
    let mut global: HashMap<String, Span> = HashMap::new();
    for id in def.params.iter().chain([&def.x, &def.p]) {
        let name = id.to_string();
        if let Some(prev) = global.get(&name) {
            let mut e = err(id.span(), format!("duplicate name `{name}`"));
            e.combine(err(*prev, format!("`{name}` is first declared here")));
            errors.push(e);
        } else {
            global.insert(name, id.span());
        }
    }
    let mut families: HashMap<String, Span> = HashMap::new();
    let mut tables: HashMap<String, Span> = HashMap::new();
    for f in &def.families {
        for (id, seen, what) in [
            (&f.name, &mut families, "family"),
            (&f.table, &mut tables, "table"),
        ] {
            let name = id.to_string();
            if let Some(prev) = seen.get(&name) {
                let mut e = err(
                    id.span(),
                    format!(
                        "duplicate {what} name `{name}`{}",
                        if what == "table" {
                            ": every family has its own table (an argument of `system(..)`)"
                        } else {
                            ""
                        }
                    ),
                );
                e.combine(err(*prev, format!("`{name}` is first declared here")));
                errors.push(e);
            } else {
                seen.insert(name, id.span());
            }
        }
        if f.table == "masses" {
            errors.push(err(
                f.table.span(),
                "`masses` is the first argument of `system(..)`: name the table otherwise",
            ));
        }
        let mut local: HashMap<String, Span> = HashMap::new();
        for id in std::iter::once(&f.index).chain(&f.particles).chain(&f.data) {
            let name = id.to_string();
            if let Some(prev) = local.get(&name).or(global.get(&name)) {
                let mut e = err(
                    id.span(),
                    format!("`{name}` is declared twice (in the table signature or the system)"),
                );
                e.combine(err(*prev, format!("`{name}` is first declared here")));
                errors.push(e);
            } else {
                local.insert(name, id.span());
            }
        }
        // Checked: a DIM near usize::MAX must not wrap past the limit.
        let local_dim = f.particles.len().checked_mul(def.dim);
        if local_dim.is_none_or(|n| n > MAX_LOCAL) {
            let shown = local_dim.map_or("more than 2^64".to_string(), |n| n.to_string());
            errors.push(err(
                f.table.span(),
                format!(
                    "a member of `{}` touches {} particles in R^{}: {shown} local \
                     coordinates, more than the runtime's limit of {MAX_LOCAL} (ARITY·DIM)",
                    f.name,
                    f.particles.len(),
                    def.dim
                ),
            ));
        }
    }
    errors
}

fn camel(s: &str) -> String {
    s.split('_')
        .filter(|w| !w.is_empty())
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_uppercase().chain(c).collect::<String>())
                .unwrap_or_default()
        })
        .collect()
}

/// The name of a family's stencil struct: `Water` + `bond` → `WaterBond`.
fn stencil_name(def: &ParticleDef, fam: &FamilyDecl) -> Ident {
    format_ident!(
        "{}{}",
        def.name,
        camel(&fam.name.to_string()),
        span = fam.name.span()
    )
}

/// The stencil struct of one family and its `Stencil` impl.
fn emit_stencil(def: &ParticleDef, fam: &FamilyDecl, low: &Lowered) -> TokenStream {
    let vis = &def.vis;
    let sname = stencil_name(def, fam);
    let params = &def.params;
    let data = &fam.data;
    let arity = fam.particles.len();
    let dim = def.dim;
    let ndata = data.len();
    let w = arity * dim;
    let all: Vec<Ident> = params.iter().chain(data).cloned().collect();
    let coder = Coder {
        graph: &low.graph,
        dof: w,
        params: &all,
    };
    let vb = coder.block(&[low.written]);
    let v_lets = &vb.lets;
    let v_val = &vb.values[0];
    let mut roots = vec![low.written];
    roots.extend(&low.gradient);
    let gb = coder.block(&roots);
    let g_lets = &gb.lets;
    let g_val = &gb.values[0];
    let g_assigns = gb.values[1..].iter().enumerate().map(|(l, v)| {
        let l = proc_macro2::Literal::usize_unsuffixed(l);
        quote!(grad[#l] = #v;)
    });
    let data_idx = (0..ndata).map(proc_macro2::Literal::usize_unsuffixed);
    let data_idx2 = data_idx.clone();
    let c_in = if ndata > 0 {
        quote!(let c: &[f64; #ndata] = ::core::convert::TryInto::try_into(c).expect("a row's data has DATA entries");)
    } else {
        quote!()
    };
    let x_in = quote!(let q: &[f64; #w] = ::core::convert::TryInto::try_into(x).expect("a member has ARITY * DIM coordinates"););
    let kind = match fam.kind {
        FamilyKind::Constraint => "constraint",
        FamilyKind::Potential => "potential",
    };
    let sig = {
        let ps: Vec<String> = fam.particles.iter().map(|p| p.to_string()).collect();
        let ds: Vec<String> = fam.data.iter().map(|p| p.to_string()).collect();
        if ds.is_empty() {
            format!("{}({})", fam.table, ps.join(", "))
        } else {
            format!("{}({}; {})", fam.table, ps.join(", "), ds.join(", "))
        }
    };
    let formula = {
        let s = low.graph.display(low.value);
        if s.chars().count() > 300 {
            format!("{} …", s.chars().take(300).collect::<String>())
        } else {
            s
        }
    };
    let doc = format!(
        " The {kind} family `{}` of [`{}`] over the table `{sig}`, as a \
         [`Stencil`](::geoshake::runtime::particles::Stencil) (ARITY = {arity}, DIM = {dim}, DATA = \
         {ndata}): f = `{formula}`, with its gradient in straight-line code. Its fields are the \
         system's parameters.",
        fam.name, def.name
    );
    let field_docs = params.iter().map(|p| format!(" The parameter `{p}`."));
    quote! {
        #[doc = #doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[allow(non_snake_case)]
        #vis struct #sname {
            #( #[doc = #field_docs] pub #params: f64, )*
        }

        #[automatically_derived]
        #[allow(unused_variables, unused_mut, clippy::all, clippy::pedantic, clippy::nursery)]
        impl ::geoshake::runtime::particles::Stencil for #sname {
            const ARITY: usize = #arity;
            const DIM: usize = #dim;
            const DATA: usize = #ndata;

            #[inline]
            fn value(&self, x: &[f64], c: &[f64]) -> f64 {
                #[allow(dead_code, non_snake_case)]
                struct Env { #(#all: f64,)* }
                #[allow(unused_variables, clippy::all, clippy::pedantic, clippy::nursery)]
                impl Env {
                    #[inline(always)]
                    fn run(&self, q: &[f64; #w]) -> f64 { #v_lets #v_val }
                }
                #x_in #c_in
                Env { #(#params: self.#params,)* #(#data: c[#data_idx],)* }.run(q)
            }

            #[inline]
            fn gradient(&self, x: &[f64], c: &[f64], grad: &mut [f64]) -> f64 {
                #[allow(dead_code, non_snake_case)]
                struct Env { #(#all: f64,)* }
                #[allow(unused_variables, clippy::all, clippy::pedantic, clippy::nursery)]
                impl Env {
                    #[inline(always)]
                    fn run(&self, q: &[f64; #w], grad: &mut [f64; #w]) -> f64 {
                        #g_lets
                        #(#g_assigns)*
                        #g_val
                    }
                }
                #x_in #c_in
                let grad: &mut [f64; #w] = ::core::convert::TryInto::try_into(grad).expect("the gradient has ARITY * DIM entries");
                Env { #(#params: self.#params,)* #(#data: c[#data_idx2],)* }.run(q, grad)
            }
        }
    }
}

/// The user's struct: parameters, `new`, the stencils, empty tables and
/// `system(..)`. With `stencils == false` (after an error) the stencil
/// accessors are left out and `system` is unreachable.
fn emit_struct(def: &ParticleDef, formulas: Option<&[String]>) -> TokenStream {
    let attrs = &def.attrs;
    let vis = &def.vis;
    let name = &def.name;
    let params = &def.params;
    let dim = def.dim;
    let field_docs = crate::emit::field_docs(params, def.defaults.as_deref());
    let default = crate::emit::default_impl(name, def.defaults.as_deref());
    let new = crate::emit::constructor(params);
    let mut doc = format!(
        "\n\n# Declared system\n\nn particles in R^{dim} (n and the masses are given at run time, \
         to [`{name}::system`]), H = Σ_a |p_a|²/(2 m_a) + the potential families; holonomic \
         constraint families.\n"
    );
    let mut table_fns = Vec::new();
    let mut stencil_fns = Vec::new();
    let mut args = Vec::new();
    let mut adds = Vec::new();
    for (i, f) in def.families.iter().enumerate() {
        let sname = stencil_name(def, f);
        let table = &f.table;
        let arity = f.particles.len();
        let ndata = f.data.len();
        let fname = f.name.to_string();
        let sig = {
            let ps: Vec<String> = f.particles.iter().map(|p| p.to_string()).collect();
            let ds: Vec<String> = f.data.iter().map(|p| p.to_string()).collect();
            format!("({}; {})", ps.join(", "), ds.join(", "))
        };
        let kind = match f.kind {
            FamilyKind::Constraint => "constraint",
            FamilyKind::Potential => "potential",
        };
        let formula = formulas.map(|fs| fs[i].as_str()).unwrap_or("");
        doc.push_str(&format!(
            "\n- {kind} family `{fname}` over the table `{table}{sig}`: `{formula}`"
        ));
        let tdoc = format!(
            " An empty table for the {kind} family `{fname}`: rows of {arity} particle indices \
             and {ndata} data numbers, `{table}{sig}`."
        );
        let tfn = format_ident!("{}_table", table.to_string());
        table_fns.push(quote! {
            #[doc = #tdoc]
            #[must_use]
            pub fn #tfn() -> ::geoshake::runtime::particles::Table {
                ::geoshake::runtime::particles::Table::new(#arity, #ndata)
            }
        });
        if formulas.is_some() {
            let sfn = format_ident!("{}_stencil", fname);
            let sdoc =
                format!(" The stencil of the {kind} family `{fname}`, with these parameters.");
            stencil_fns.push(quote! {
                #[doc = #sdoc]
                #[must_use]
                pub fn #sfn(&self) -> #sname {
                    #sname { #(#params: self.#params,)* }
                }
            });
            let with = match f.kind {
                FamilyKind::Constraint => quote!(with_constraints),
                FamilyKind::Potential => quote!(with_potential),
            };
            adds.push(quote! {
                let system = system.#with(#fname, #sname { #(#params: self.#params,)* }, #table)?;
            });
        }
        args.push(quote!(#table: ::geoshake::runtime::particles::Table));
    }
    let arg_list: Vec<String> = def
        .families
        .iter()
        .map(|f| format!("`{}` (family `{}`)", f.table, f.name))
        .collect();
    let sys_doc = format!(
        " The particle system: n = `masses.len()` particles in R^{dim}, and one table per family, \
         in declaration order: {}.\n\n Each table holds one row per member (see the `*_table()` \
         helpers for empty tables of the right shape). The runtime checks the topology: a \
         particle index beyond n, a particle named twice in a row, a member repeated, or a \
         wrongly shaped row is a \
         [`TopologyError`](::geoshake::runtime::particles::TopologyError) naming the family and \
         the member. Nondegeneracy (N = G M⁻¹ Gᵀ invertible, G the constraint gradient) \
         depends on the actual topology, so it is the runtime's to check, not the macro's: a \
         cluster of constraints with more constraints than the coordinates it moves can never \
         have an invertible N, and the runtime's solvers refuse it when they are set up on \
         this system (`TopologyError::TooManyConstraints`). Coisotropy needs no check: \
         holonomic constraints Poisson-commute.",
        if arg_list.is_empty() {
            "none".to_string()
        } else {
            arg_list.join(", ")
        }
    );
    let body = if formulas.is_some() {
        quote! {
            let system = ::geoshake::runtime::particles::ParticleSystem::new(#dim, masses)?;
            #(#adds)*
            Ok(system)
        }
    } else {
        quote!(unreachable!())
    };
    quote! {
        #(#attrs)*
        #[doc = #doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[allow(non_snake_case)]
        #vis struct #name {
            #( #[doc = #field_docs] pub #params: f64, )*
        }

        #[allow(unused_variables, clippy::all, clippy::pedantic, clippy::nursery)]
        impl #name {
            /// The dimension D of each particle's position.
            pub const DIM: usize = #dim;

            #new

            #(#table_fns)*
            #(#stencil_fns)*

            #[doc = #sys_doc]
            pub fn system(
                &self,
                masses: ::std::vec::Vec<f64>,
                #(#args),*
            ) -> ::core::result::Result<
                ::geoshake::runtime::particles::ParticleSystem,
                ::geoshake::runtime::particles::TopologyError,
            > {
                #body
            }
        }

        #default
    }
}

/// The whole expansion of a `particles` system.
pub fn expand(input: TokenStream) -> TokenStream {
    let def: ParticleDef = match syn::parse2(input) {
        Ok(d) => d,
        Err(e) => return e.to_compile_error(),
    };
    let fail = |es: Vec<Error>| {
        let errs = es.iter().map(Error::to_compile_error);
        let fallback = emit_struct(&def, None);
        quote!(#(#errs)* #fallback)
    };
    let errors = check_declaration(&def);
    if !errors.is_empty() {
        return fail(errors);
    }
    let mut errors = Vec::new();
    let mut lowered = Vec::new();
    for f in &def.families {
        match lower_family(&def, f) {
            Ok(l) => lowered.push(l),
            Err(e) => errors.push(e),
        }
    }
    if !errors.is_empty() {
        return fail(errors);
    }
    let formulas: Vec<String> = lowered
        .iter()
        .map(|l| {
            let s = l.graph.display(l.value);
            if s.chars().count() > 200 {
                format!("{} …", s.chars().take(200).collect::<String>())
            } else {
                s
            }
        })
        .collect();
    let st = emit_struct(&def, Some(&formulas));
    let stencils = def
        .families
        .iter()
        .zip(&lowered)
        .map(|(f, l)| emit_stencil(&def, f, l));
    quote!(#st #(#stencils)*)
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    const WATER: &str = "pub struct Water {
        particles x[3];
        constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
    }";

    const SPRING_CHAIN: &str = "pub struct SpringChain {
        parameters { stiffness }
        particles x[3];
        potential { spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2 }
        constraints { link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
    }";

    fn expand(src: &str) -> String {
        crate::expand(src.parse().expect("tokens")).to_string()
    }

    #[test]
    fn declarations_expand_without_errors() {
        for src in [WATER, SPRING_CHAIN] {
            let out = expand(src);
            assert!(!out.contains("compile_error"), "{out:.400}");
            assert!(out.contains("Stencil for"), "{out:.400}");
        }
    }

    #[test]
    fn templates_are_checked_once_each() {
        let cases = [
            ("x[a][3]", "component 3 out of range"),
            ("x[a] - x[b]", "is a vector of R^3"),
            ("norm2(x[a] - x[b]) - k", "numbers the members"),
            ("norm2(x[a] - x[b]) - foo", "unknown name `foo`"),
            ("x[a] * x[b]", "ambiguous"),
            (
                "if 1 > 0 { x[a][0] } else { x[b][0] }",
                "`if` in a template",
            ),
            ("norm2(x[0] - x[b])", "only through its table"),
            ("norm2(x[a] - x[b]) - p[a][0]", "is a momentum"),
            // 10⁹ terms: refused at once, not expanded for minutes.
            (
                "sum i in 0..1000 { sum j in 0..1000 { sum k in 0..1000 { x[a][0] } } }",
                "more than 1000000 terms in all",
            ),
        ];
        for (template, msg) in cases {
            let src = format!(
                "struct S {{ particles x[3]; constraints {{ c[k in t(a, b; l)]: {template} }} }}"
            );
            let out = expand(&src);
            assert!(
                out.contains("compile_error") && out.contains(msg),
                "{template}: {out:.600}"
            );
        }
    }

    #[test]
    fn declarations_are_checked() {
        let many: Vec<String> = (0..22).map(|i| format!("a{i}")).collect();
        let cases = [
            (
                format!(
                    "struct S {{ particles x[3]; constraints {{ c[k in t({}; l)]: x[a0][0] - l }} }}",
                    many.join(", ")
                ),
                "more than the runtime's limit of 64",
            ),
            (
                "struct S { particles x[3]; constraints { c[k in t(a, b)]: norm2(x[a] - x[b]) - 1, \
                 d[k in t(a, b)]: norm2(x[a] - x[b]) - 2 } }"
                    .to_string(),
                "duplicate table name `t`",
            ),
            (
                "struct S { particles x[3]; constraints { c: x[0][0] } }".to_string(),
                "ranges over a run-time table",
            ),
            (
                "struct S { dof q[2], p[2]; hamiltonian = p[0]^2; \
                 constraints { c[k in t(a, b)]: q[0] } }"
                    .to_string(),
                "belongs to a `particles x[D];` system",
            ),
            (
                "struct S { dof q[2], p[2]; hamiltonian = p[0]^2 + q[0][1]; }".to_string(),
                "only for the templates of a `particles x[D];` system",
            ),
            (
                "struct S { particles x[3]; hamiltonian = 0; }".to_string(),
                "H = Σ_a |p_a|²/(2 m_a)",
            ),
            (
                "struct S { parameters { a } particles x[3]; \
                 constraints { c[k in t(a, b)]: norm2(x[a] - x[b]) - 1 } }"
                    .to_string(),
                "`a` is declared twice",
            ),
            // ARITY·DIM computed with a checked product (it wrapped to 0
            // and rustc ran out of memory on the emitted arrays).
            (
                "struct S { particles x[9223372036854775808]; \
                 constraints { c[k in t(a, b; l)]: x[a][0] - x[b][0] - l } }"
                    .to_string(),
                "more than 2^64 local coordinates",
            ),
            // The exponent limit of the compile-time form holds here too.
            (
                "struct S { particles x[3]; \
                 constraints { c[k in t(a, b; l)]: norm2(x[a] - x[b])^100000 - l } }"
                    .to_string(),
                "exponent too large",
            ),
        ];
        for (src, msg) in cases {
            let out = expand(&src);
            assert!(
                out.contains("compile_error") && out.contains(msg),
                "{src}: {out:.600}"
            );
        }
    }

    fn template() -> impl proptest::strategy::Strategy<Value = String> {
        use proptest::prelude::*;
        let leaf = prop_oneof![
            Just("x[a]".to_string()),
            Just("x[b]".to_string()),
            Just("x[c]".to_string()),
            Just("p[a]".to_string()),
            (0usize..4).prop_map(|i| format!("x[a][{i}]")),
            (0usize..4).prop_map(|i| format!("x[b][{i}]")),
            Just("l".to_string()),
            Just("s".to_string()),
            Just("k".to_string()),
            Just("0".to_string()),
            Just("2.5".to_string()),
        ];
        leaf.prop_recursive(4, 24, 3, |inner| {
            prop_oneof![
                (
                    inner.clone(),
                    prop::sample::select(vec!["+", "-", "*", "/", "^", "%"]),
                    inner.clone()
                )
                    .prop_map(|(a, op, b)| format!("({a} {op} {b})")),
                (inner.clone(), -3i64..4).prop_map(|(a, n)| format!("({a})^{n}")),
                inner.clone().prop_map(|a| format!("-{a}")),
                (
                    prop::sample::select(vec!["norm2", "norm", "sqrt", "ln", "sin", "foo"]),
                    inner.clone()
                )
                    .prop_map(|(f, a)| format!("{f}({a})")),
                (
                    prop::sample::select(vec!["dot", "cross"]),
                    inner.clone(),
                    inner.clone()
                )
                    .prop_map(|(f, a, b)| format!("{f}({a}, {b})")),
                inner
                    .clone()
                    .prop_map(|a| format!("sum i in 0..3 {{ {a} + x[a][i] }}")),
            ]
        })
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config { cases: 256, ..Default::default() })]
        /// Random templates never panic the macro: they expand to stencils
        /// or to compile errors.
        #[test]
        fn random_templates_never_panic(t in template(), v in template()) {
            let src = format!(
                "struct S {{ parameters {{ s }} particles x[3]; \
                 potential {{ e[k in es(a, b; l)]: {v} }} \
                 constraints {{ c[k in cs(a, b; l)]: {t} }} }}"
            );
            let out = std::panic::catch_unwind(|| expand(&src));
            proptest::prop_assert!(out.is_ok(), "the macro panicked on: {}", src);
            let out = out.unwrap_or_default();
            proptest::prop_assert!(out.contains("compile_error") || out.contains("Stencil for"));
        }
    }

    /// Expansion time of the run-time topology declarations, and of the
    /// refusal of a compile-time family of 2000 constraints on 8 coordinates:
    /// `cargo test -p geoshake-macros --release -- --ignored --nocapture expansion_of_topologies`.
    #[test]
    #[ignore = "a measurement, not a check"]
    fn expansion_of_topologies() {
        let crowded = "pub struct Crowded {
            const N = 2000;
            dof q[8], p[8];
            hamiltonian = sum i in 0..8 { p[i]^2 / 2 };
            constraints { link[k in 0..N]: q[k % 7]^2 + q[k % 7 + 1]^2 - 1 - k }
        }";
        let crowded_max = crowded.replace("2000", "100000");
        println!("| declaration | expansion time | generated source (bytes) |");
        println!("|---|---:|---:|");
        for (name, src) in [
            ("water (any n: n is not in the declaration)", WATER),
            ("spring chain (any n)", SPRING_CHAIN),
            ("refused: 2000 constraints on d = 8", crowded),
            ("refused: 100000 constraints on d = 8", crowded_max.as_str()),
        ] {
            let input: proc_macro2::TokenStream = src.parse().expect("tokens");
            let mut best = f64::INFINITY;
            let mut out = String::new();
            for _ in 0..5 {
                let t = Instant::now();
                out = crate::expand(input.clone()).to_string();
                best = best.min(t.elapsed().as_secs_f64());
            }
            println!("| {name} | {:.2} ms | {} |", best * 1e3, out.len());
        }
    }
}
