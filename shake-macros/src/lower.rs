//! From the typed input to the symbolic system: names resolved, indices
//! evaluated, families unrolled, H and g built in the expression graph.
//!
//! Index expressions (`q[2*k-1]`, family ranges, `if` conditions, `const`s)
//! are evaluated here, at compile time, as integers; only the branch of an
//! `if` that is taken is lowered, so `if k == 0 { .. } else { q[2*k-2] }`
//! never sees the out-of-range index of the other branch.

use crate::parse::{BinOp, CmpOp, Cond, ConstraintDecl, Dof, Expr, ExprKind, SystemDef};
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
}

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
        let not_int = || {
            Error::new(
                e.span,
                "expected a compile-time integer: index expressions may use integer literals, \
                 `const`s, family and sum indices, `+ - * / %` and parentheses",
            )
        };
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
                        Some(_) => return Err(not_int()),
                        None => {
                            return Err(Error::new(
                                id.span(),
                                format!("unknown index `{name}`: not a `const` or a bound index"),
                            ))
                        }
                    }
                }
            }
            ExprKind::Neg(a) => self.int(a)?.checked_neg().ok_or_else(overflow)?,
            ExprKind::Binary(op, a, b) => {
                let (a, b) = (self.int(a)?, self.int(b)?);
                let r = match op {
                    BinOp::Add => a.checked_add(b),
                    BinOp::Sub => a.checked_sub(b),
                    BinOp::Mul => a.checked_mul(b),
                    BinOp::Div | BinOp::Rem if b == 0 => {
                        return Err(Error::new(
                            e.span,
                            "division by zero in an index expression",
                        ))
                    }
                    BinOp::Div => a.checked_div(b),
                    BinOp::Rem => a.checked_rem(b),
                    BinOp::Pow => match u32::try_from(b) {
                        Ok(b) => a.checked_pow(b),
                        Err(_) => return Err(not_int()),
                    },
                };
                r.ok_or_else(overflow)?
            }
            ExprKind::If(c, t, f) => {
                if self.cond(c)? {
                    self.int(t)?
                } else {
                    self.int(f)?
                }
            }
            _ => return Err(not_int()),
        })
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
            Cond::And(a, b) => self.cond(a)? && self.cond(b)?,
            Cond::Or(a, b) => self.cond(a)? || self.cond(b)?,
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

    /// Lowers a real-valued expression into the graph.
    fn real(&mut self, e: &Expr) -> Result<NodeId, Error> {
        Ok(match &e.kind {
            ExprKind::Num(v, _) => self.graph.num(*v),
            ExprKind::Ident(id) => {
                let name = id.to_string();
                if let Some(v) = self.lookup_index(&name) {
                    return Ok(self.graph.num(v as f64));
                }
                match self.syms.get(&name).map(|s| s.0.clone()) {
                    Some(Sym::Number(v)) => self.graph.num(v),
                    Some(Sym::Param(p)) => self.graph.param(p),
                    Some(Sym::Var(v)) => self.graph.var(v),
                    Some(Sym::Let(n)) => n,
                    Some(Sym::Array(_)) => {
                        return Err(Error::new(
                            id.span(),
                            format!(
                                "`{name}` is an array of the state: index it, as in `{name}[0]`"
                            ),
                        ))
                    }
                    None => {
                        return Err(Error::new(
                            id.span(),
                            format!(
                                "unknown symbol `{name}`: not a parameter, coordinate, momentum, \
                                 `let`, `const` or bound index"
                            ),
                        ))
                    }
                }
            }
            ExprKind::Index(id, idx, bracket) => {
                let name = id.to_string();
                let offset = match self.syms.get(&name).map(|s| s.0.clone()) {
                    Some(Sym::Array(o)) => o,
                    Some(_) => {
                        return Err(Error::new(id.span(), format!("`{name}` is not an array: it cannot be indexed")))
                    }
                    None => {
                        return Err(Error::new(
                            id.span(),
                            format!("unknown array `{name}`: the state arrays are the ones declared by `dof`"),
                        ))
                    }
                };
                let i = self.int(idx)?;
                if i < 0 || i as usize >= self.dof {
                    return Err(Error::new(
                        *bracket,
                        format!(
                            "index out of range: `{name}[{i}]`, but `{name}` has {} entries ({name}[0] to {name}[{}])",
                            self.dof,
                            self.dof - 1
                        ),
                    ));
                }
                self.graph.var(VarId((offset + i as usize) as u32))
            }
            ExprKind::Neg(a) => {
                let a = self.real(a)?;
                self.graph.neg(a)
            }
            ExprKind::Binary(op, a, b) => {
                let x = self.real(a)?;
                let y = self.real(b)?;
                match op {
                    BinOp::Add => self.graph.add2(x, y),
                    BinOp::Sub => self.graph.sub(x, y),
                    BinOp::Mul => self.graph.mul2(x, y),
                    BinOp::Div => {
                        if self.graph.is_zero(y) {
                            return Err(Error::new(b.span, "division by zero"));
                        }
                        self.graph.div(x, y)
                    }
                    BinOp::Rem => {
                        return Err(Error::new(
                            e.span,
                            "`%` is only allowed in index expressions: it is not differentiable",
                        ))
                    }
                    BinOp::Pow => match self.graph.as_const(y) {
                        Some(r) if r.is_finite() => {
                            if self.graph.is_zero(x) && r < 0.0 {
                                return Err(Error::new(
                                    e.span,
                                    "division by zero: 0 to a negative power",
                                ));
                            }
                            self.graph.powf(x, r)
                        }
                        _ => return Err(Error::new(
                            b.span,
                            "the exponent must be a constant (a number, a `const` or an index); \
                                 write `exp(y * ln(x))` for a variable exponent",
                        )),
                    },
                }
            }
            ExprKind::Call(f, args) => {
                let name = f.to_string();
                let func = match name.as_str() {
                    "sqrt" => None,
                    "sin" => Some(Func::Sin),
                    "cos" => Some(Func::Cos),
                    "tan" => Some(Func::Tan),
                    "exp" => Some(Func::Exp),
                    "ln" => Some(Func::Ln),
                    _ if NON_DIFFERENTIABLE.contains(&name.as_str()) => {
                        return Err(Error::new(
                            f.span(),
                            format!(
                                "`{name}` is not differentiable: the methods need derivatives of H and g \
                                 (the supported functions are {FUNCS})"
                            ),
                        ))
                    }
                    "log" => {
                        return Err(Error::new(f.span(), "`log` is ambiguous: write `ln` for the natural logarithm"))
                    }
                    _ => {
                        return Err(Error::new(
                            f.span(),
                            format!("unknown function `{name}`: the supported functions are {FUNCS}"),
                        ))
                    }
                };
                if args.len() != 1 {
                    return Err(Error::new(
                        f.span(),
                        format!("`{name}` takes one argument, {} given", args.len()),
                    ));
                }
                let x = self.real(&args[0])?;
                match func {
                    None => self.graph.sqrt(x),
                    Some(func) => self.graph.call(func, x),
                }
            }
            ExprKind::Sum(var, lo, hi, body) => {
                let mut terms = Vec::new();
                for i in self.range(lo, hi)? {
                    self.bind_index(var, i)?;
                    let t = self.real(body);
                    self.indices.pop();
                    terms.push(t?);
                }
                self.graph.add(terms)
            }
            ExprKind::Component(_, _, bracket) => {
                return Err(Error::new(
                    *bracket,
                    "`x[a][c]` (coordinate c of particle a) is only for the templates of a \
                     `particles x[D];` system; with `dof`, index the state directly: `q[i]`",
                ))
            }
            ExprKind::If(c, t, f) => {
                if self.cond(c)? {
                    self.real(t)?
                } else {
                    self.real(f)?
                }
            }
        })
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

/// Builds the symbolic system; returns every error found (one per
/// offending item), not just the first.
pub fn lower(def: &SystemDef) -> Result<System, Vec<Error>> {
    let mut lw = Lowerer {
        graph: Graph::default(),
        dof: 0,
        syms: HashMap::new(),
        indices: Vec::new(),
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
        match lw.real(e).and_then(|v| lw.declare(n, Sym::Let(v))) {
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
