//! A template read with vector meaning: `x[a]` a vector of R^D, `norm2`,
//! `dot` and `cross` over vectors, parameters and table data as constants;
//! lowered twice (canonical, for the checks; as written, for the values
//! and the gradient), checked and differentiated.

use super::{err, Lowered, FUNCS};
use crate::parse::{BinOp, Expr, ExprKind};
use crate::parse_topology::{FamilyDecl, FamilyKind, ParticleDef};
use crate::symbolic::{Func, Graph, Names, Node, NodeId, ParamId, VarId};
use proc_macro2::Span;
use std::collections::HashMap;
use syn::{Error, Ident};

/// A template value: a scalar or a vector of R^D.
enum Val {
    S(NodeId),
    V(Vec<NodeId>),
}

struct Template<'a> {
    def: &'a ParticleDef,
    fam: &'a FamilyDecl,
    graph: Graph,
    /// Parameters and data variables: constants for differentiation.
    scalars: HashMap<String, NodeId>,
    /// Bound `sum` indices, innermost last.
    sums: Vec<(String, i64)>,
    /// Terms the `sum`s expanded so far (`crate::lower::MAX_TERMS`).
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
                if self.terms > crate::lower::MAX_TERMS {
                    return Err(err(
                        var.span(),
                        format!(
                            "the `sum`s of this template expand to more than {} terms in all \
                             (nested sums multiply their lengths)",
                            crate::lower::MAX_TERMS
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
pub fn lower_family(def: &ParticleDef, fam: &FamilyDecl) -> Result<Lowered, Error> {
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
