//! The typed view of the macro's input. Every node keeps the span of the
//! user's tokens, so later stages can point at them.
//!
//! The grammar is stated in the doc comment of `constrained_system!`
//! (`lib.rs`); this module follows it item by item.

use proc_macro2::{Span, TokenStream, TokenTree};
use syn::parse::{Parse, ParseStream};
use syn::{
    braced, bracketed, parenthesized, token, Attribute, Ident, LitFloat, LitInt, Token, Visibility,
};

/// The whole declaration.
pub struct SystemDef {
    pub attrs: Vec<Attribute>,
    pub vis: Visibility,
    pub name: Ident,
    pub params: Vec<Ident>,
    /// The parameters' defaults (`parameters { length = 1.0, .. }`), in
    /// order; `Some` only when every parameter has one (then the struct
    /// implements `Default`).
    pub defaults: Option<Vec<f64>>,
    pub consts: Vec<(Ident, Expr)>,
    pub dof: Dof,
    pub lets: Vec<(Ident, Expr)>,
    pub hamiltonian: Expr,
    pub constraints: Vec<ConstraintDecl>,
}

/// The degrees of freedom.
pub enum Dof {
    /// `dof q[d], p[d];`
    Arrays {
        q: Ident,
        p: Ident,
        dim: Expr,
        p_dim: Expr,
    },
    /// `coordinates x, y; momenta px, py;`
    Named {
        coords: Vec<Ident>,
        momenta: Vec<Ident>,
    },
}

/// `name: expr` or `name[k in lo..hi]: expr`.
pub struct ConstraintDecl {
    pub name: Ident,
    pub family: Option<(Ident, Expr, Expr)>,
    pub expr: Expr,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    Rem,
    Pow,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum CmpOp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

/// A compile-time condition on indices, in `if cond { .. } else { .. }`.
/// `&&` and `||` chains are flat lists, so a long chain is not a deep tree.
pub enum Cond {
    Cmp(CmpOp, Box<Expr>, Box<Expr>),
    /// `a && b && ..`: at least two comparisons.
    And(Vec<Cond>),
    /// `a || b || ..`: at least two operands, each a comparison or an `And`.
    Or(Vec<Cond>),
}

/// An expression; `span` is the span of its first token (or of its operator).
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

pub enum ExprKind {
    /// A literal, with `true` when it was written as an integer.
    Num(f64, bool),
    Ident(Ident),
    /// `q[index]`; the span is the bracket's.
    Index(Ident, Box<Expr>, Span),
    /// `x[a][c]`: coordinate c of particle a, in the templates of a
    /// `particles` system (see `topology`); the span is the second bracket's.
    Component(Box<Expr>, Box<Expr>, Span),
    Neg(Box<Expr>),
    /// `a ^ b`. `^` is right-associative, so `a^b^c` nests, one level of
    /// [`MAX_NESTING`] per `^`.
    Binary(BinOp, Box<Expr>, Box<Expr>),
    /// `a + b - c` or `a * b / c % d`: the left-associative operators of one
    /// precedence, applied left to right to the first operand and each
    /// link's. The tree `((a + b) - c)` they stand for would be as deep as
    /// the sum is long, and so would every recursive pass over it (a sum of
    /// 10⁵ terms overflows the stack); a flat list is one level. The span of
    /// the chain is its last operator's, the root of that tree.
    Chain(Box<Expr>, Vec<Link>),
    Call(Ident, Vec<Expr>),
    /// `sum i in lo..hi { body }`
    Sum(Ident, Box<Expr>, Box<Expr>, Box<Expr>),
    If(Cond, Box<Expr>, Box<Expr>),
}

/// One step of a [`ExprKind::Chain`]: `op rhs`, the operator at `span`.
pub struct Link {
    pub op: BinOp,
    pub span: Span,
    pub rhs: Expr,
}

/// `name, ..` or `name = default, ..`: the parameters and, when every one
/// has a default, the defaults. A default is a number literal with an
/// optional sign; some with and some without is refused at the first
/// without (a `Default` impl needs them all, and silently not generating
/// it would surface far away, where `Default` is used).
pub(crate) fn parse_parameters(input: ParseStream) -> syn::Result<(Vec<Ident>, Option<Vec<f64>>)> {
    let mut params = Vec::new();
    let mut defaults: Vec<Option<f64>> = Vec::new();
    while !input.is_empty() {
        let name: Ident = input.parse()?;
        let default = if input.peek(Token![=]) {
            input.parse::<Token![=]>()?;
            Some(parse_default(input, &name)?)
        } else {
            None
        };
        params.push(name);
        defaults.push(default);
        if input.is_empty() {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    let with = defaults.iter().filter(|d| d.is_some()).count();
    if with == 0 {
        return Ok((params, None));
    }
    if let Some(k) = defaults.iter().position(Option::is_none) {
        let given = &params[defaults.iter().position(Option::is_some).unwrap_or(0)];
        return Err(syn::Error::new(
            params[k].span(),
            format!(
                "parameter `{}` has no default, but `{given}` has one: give every parameter a \
                 default (`{} = 1.0`) to get `impl Default`, or none",
                params[k], params[k]
            ),
        ));
    }
    Ok((params, Some(defaults.into_iter().flatten().collect())))
}

/// The default after `name =`: `-`? then a float or integer literal,
/// finite as an f64.
fn parse_default(input: ParseStream, name: &Ident) -> syn::Result<f64> {
    let neg = input.parse::<Option<Token![-]>>()?.is_some();
    let bad = |span: Span| {
        syn::Error::new(
            span,
            format!(
                "the default of parameter `{name}` must be a number literal, e.g. `{name} = 1.0` \
                 (expressions, constants and other parameters are not evaluated here)"
            ),
        )
    };
    let (value, span) = if input.peek(LitFloat) {
        let l: LitFloat = input.parse()?;
        (l.base10_parse::<f64>()?, l.span())
    } else if input.peek(LitInt) {
        let l: LitInt = input.parse()?;
        (l.base10_parse::<f64>()?, l.span())
    } else {
        return Err(bad(input.span()));
    };
    // Anything after the literal but before the next `,` (an operator, a
    // call) would be an expression: refused at it.
    if !input.is_empty() && !input.peek(Token![,]) {
        return Err(bad(input.span()));
    }
    if !value.is_finite() {
        return Err(syn::Error::new(
            span,
            format!("the default of parameter `{name}` is not a finite f64"),
        ));
    }
    Ok(if neg { -value } else { value })
}

fn kw(input: ParseStream, word: &str) -> bool {
    input.fork().parse::<Ident>().is_ok_and(|i| i == word)
}

impl Parse for SystemDef {
    fn parse(input: ParseStream) -> syn::Result<Self> {
        let attrs = input.call(Attribute::parse_outer)?;
        let vis: Visibility = input.parse()?;
        input.parse::<Token![struct]>()?;
        let name: Ident = input.parse()?;
        let body;
        braced!(body in input);
        if !input.is_empty() {
            return Err(input.error("unexpected tokens after the system's `{ ... }`"));
        }
        let mut params = Vec::new();
        let mut defaults = None;
        let mut consts = Vec::new();
        let mut dof: Option<Dof> = None;
        let mut coords: Option<(Span, Vec<Ident>)> = None;
        let mut momenta: Option<(Span, Vec<Ident>)> = None;
        let mut lets = Vec::new();
        let mut hamiltonian: Option<Expr> = None;
        let mut constraints: Option<Vec<ConstraintDecl>> = None;
        while !body.is_empty() {
            if body.peek(Token![const]) {
                body.parse::<Token![const]>()?;
                let n: Ident = body.parse()?;
                body.parse::<Token![=]>()?;
                let e = parse_expr(&body, 0)?;
                body.parse::<Token![;]>()?;
                consts.push((n, e));
            } else if body.peek(Token![let]) {
                body.parse::<Token![let]>()?;
                let n: Ident = body.parse()?;
                body.parse::<Token![=]>()?;
                let e = parse_expr(&body, 0)?;
                body.parse::<Token![;]>()?;
                lets.push((n, e));
            } else if kw(&body, "parameters") {
                let k: Ident = body.parse()?;
                if !params.is_empty() {
                    return Err(syn::Error::new(k.span(), "`parameters` is declared twice"));
                }
                let c;
                braced!(c in body);
                (params, defaults) = parse_parameters(&c)?;
                let _ = body.parse::<Option<Token![;]>>()?;
            } else if kw(&body, "dof") {
                let k: Ident = body.parse()?;
                if dof.is_some() || coords.is_some() {
                    return Err(syn::Error::new(
                        k.span(),
                        "the degrees of freedom are declared twice",
                    ));
                }
                let q: Ident = body.parse()?;
                let c;
                bracketed!(c in body);
                let dim = parse_expr(&c, 0)?;
                body.parse::<Token![,]>()?;
                let p: Ident = body.parse()?;
                let c2;
                bracketed!(c2 in body);
                let p_dim = parse_expr(&c2, 0)?;
                body.parse::<Token![;]>()?;
                dof = Some(Dof::Arrays { q, p, dim, p_dim });
            } else if kw(&body, "coordinates") || kw(&body, "momenta") {
                let k: Ident = body.parse()?;
                let mut names = vec![body.parse::<Ident>()?];
                while body.peek(Token![,]) {
                    body.parse::<Token![,]>()?;
                    if body.peek(Token![;]) {
                        break;
                    }
                    names.push(body.parse()?);
                }
                body.parse::<Token![;]>()?;
                let slot = if k == "coordinates" {
                    &mut coords
                } else {
                    &mut momenta
                };
                if slot.is_some() || dof.is_some() {
                    return Err(syn::Error::new(
                        k.span(),
                        "the degrees of freedom are declared twice",
                    ));
                }
                *slot = Some((k.span(), names));
            } else if kw(&body, "hamiltonian") {
                let k: Ident = body.parse()?;
                if hamiltonian.is_some() {
                    return Err(syn::Error::new(
                        k.span(),
                        "the hamiltonian is declared twice",
                    ));
                }
                body.parse::<Token![=]>()?;
                hamiltonian = Some(parse_expr(&body, 0)?);
                body.parse::<Token![;]>()?;
            } else if kw(&body, "constraints") {
                let k: Ident = body.parse()?;
                if constraints.is_some() {
                    return Err(syn::Error::new(k.span(), "`constraints` is declared twice"));
                }
                let c;
                braced!(c in body);
                constraints = Some(parse_constraints(&c)?);
                let _ = body.parse::<Option<Token![;]>>()?;
            } else {
                return Err(body.error(
                    "expected one of `parameters { .. }`, `const N = ..;`, `dof q[..], p[..];`, \
                     `coordinates ..;`, `momenta ..;`, `let name = ..;`, `hamiltonian = ..;`, \
                     `constraints { .. }`",
                ));
            }
        }
        let dof = match (dof, coords, momenta) {
            (Some(d), _, _) => d,
            (None, Some((_, coords)), Some((span, momenta))) => {
                if coords.len() != momenta.len() {
                    return Err(syn::Error::new(
                        span,
                        format!(
                            "{} coordinates but {} momenta: each coordinate needs its conjugate momentum",
                            coords.len(),
                            momenta.len()
                        ),
                    ));
                }
                Dof::Named { coords, momenta }
            }
            (None, Some((span, _)), None) => {
                return Err(syn::Error::new(span, "`coordinates` needs a matching `momenta ..;` line"))
            }
            (None, None, Some((span, _))) => {
                return Err(syn::Error::new(span, "`momenta` needs a matching `coordinates ..;` line"))
            }
            (None, None, None) => {
                return Err(syn::Error::new(
                    name.span(),
                    "missing degrees of freedom: add `dof q[d], p[d];` or `coordinates ..; momenta ..;`",
                ))
            }
        };
        let hamiltonian = hamiltonian
            .ok_or_else(|| syn::Error::new(name.span(), "missing `hamiltonian = ...;`"))?;
        Ok(SystemDef {
            attrs,
            vis,
            name,
            params,
            defaults,
            consts,
            dof,
            lets,
            hamiltonian,
            constraints: constraints.unwrap_or_default(),
        })
    }
}

fn parse_constraints(input: ParseStream) -> syn::Result<Vec<ConstraintDecl>> {
    let mut out = Vec::new();
    while !input.is_empty() {
        let name: Ident = input.parse()?;
        let family = if input.peek(token::Bracket) {
            let c;
            bracketed!(c in input);
            let k: Ident = c.parse()?;
            c.parse::<Token![in]>()?;
            if c.peek(syn::Ident) && c.peek2(token::Paren) {
                return Err(c.error(
                    "a family over a run-time table, `name[k in table(a, b; data)]`, belongs to \
                     a `particles x[D];` system (see \"Run-time topologies\" in the macro's docs); \
                     with `dof`, families range over compile-time `lo..hi`",
                ));
            }
            let lo = parse_expr(&c, 0)?;
            c.parse::<Token![..]>()?;
            let hi = parse_expr(&c, 0)?;
            if !c.is_empty() {
                return Err(c.error("expected `]` after the family's range `lo..hi`"));
            }
            Some((k, lo, hi))
        } else {
            None
        };
        input.parse::<Token![:]>()?;
        let expr = parse_expr(input, 0)?;
        out.push(ConstraintDecl { name, family, expr });
        if input.is_empty() {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    Ok(out)
}

const PREC_SUM: u8 = 1;
const PREC_PRODUCT: u8 = 2;
const PREC_POWER: u8 = 3;

fn peek_binop(input: ParseStream) -> Option<BinOp> {
    if input.peek(Token![+]) {
        Some(BinOp::Add)
    } else if input.peek(Token![-]) {
        Some(BinOp::Sub)
    } else if input.peek(Token![*]) {
        Some(BinOp::Mul)
    } else if input.peek(Token![/]) {
        Some(BinOp::Div)
    } else if input.peek(Token![%]) {
        Some(BinOp::Rem)
    } else if input.peek(Token![^]) {
        Some(BinOp::Pow)
    } else {
        None
    }
}

fn precedence(op: BinOp) -> u8 {
    match op {
        BinOp::Add | BinOp::Sub => PREC_SUM,
        BinOp::Mul | BinOp::Div | BinOp::Rem => PREC_PRODUCT,
        BinOp::Pow => PREC_POWER,
    }
}

/// The deepest nesting of one expression the parser accepts: parentheses,
/// unary minus signs, `^` chains (right-associative), calls, `sum` and `if`
/// bodies each add a level (a level is one call of [`parse_expr`], so a
/// bracket inside a sum of products can cost up to three). Chains of `+ -`
/// and `* / %` add none, however long: they are flat ([`ExprKind::Chain`]).
///
/// The parser is recursive, and so are the lowering and the drop of the
/// syntax tree after it; every pass on the expression graph after that is
/// iterative or bounded (`diff` keeps an explicit stack, the tape is
/// emitted in id order, renderings stop at `DISPLAY_DEPTH`). At this limit
/// the deepest of these recursions (nested `if`s) takes at most about
/// 0.4 MiB of stack in an optimised build, 1 MiB without optimisation:
/// within the 2 MiB Rust gives a spawned thread (a test's) with room to
/// spare (rustc runs the macro, and Python its main thread, on 8 MiB).
pub const MAX_NESTING: usize = 256;

/// The deepest nesting of brackets `()`, `[]` and `{}` in a declaration:
/// an expression's own (each bracket in an expression opens at least one
/// level of [`MAX_NESTING`]) inside at most three of the declaration's
/// (the struct's braces, `constraints { }`, a family's `[ ]`). Anything
/// deeper is refused by [`check_bracket_depth`].
pub const MAX_BRACKET_DEPTH: usize = MAX_NESTING + 3;

/// Refuses tokens whose brackets nest deeper than [`MAX_BRACKET_DEPTH`], at
/// the first bracket past it. Run on a declaration read from a string
/// before `syn` sees it: `syn` copies the tokens into its buffer with one
/// recursive call per bracket level, which overflows an 8 MiB stack at
/// some 40 000 levels, before the parser's [`MAX_NESTING`] can refuse
/// anything. This walk keeps its own stack.
pub fn check_bracket_depth(tokens: &TokenStream) -> syn::Result<()> {
    let mut open = vec![tokens.clone().into_iter()];
    while let Some(level) = open.last_mut() {
        match level.next() {
            Some(TokenTree::Group(g)) => {
                // `g` is at depth `open.len()` (a top-level group is at 1).
                if open.len() > MAX_BRACKET_DEPTH {
                    return Err(syn::Error::new(
                        g.span_open(),
                        format!(
                            "expression nested too deeply: brackets `()`, `[]`, `{{}}` nest more \
                             than {MAX_BRACKET_DEPTH} deep here, and an expression may nest at \
                             most {MAX_NESTING} levels of parentheses, unary minus signs, `^` or \
                             calls (split it with `let`s)"
                        ),
                    ));
                }
                open.push(g.stream().into_iter());
            }
            Some(_) => {}
            None => {
                open.pop();
            }
        }
    }
    Ok(())
}

thread_local! {
    /// The current nesting of [`parse_expr`] calls on this thread.
    static NESTING: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// One level of nesting, given back when dropped (also on `?` returns).
struct Nested;

impl Nested {
    fn enter(input: ParseStream) -> syn::Result<Nested> {
        let depth = NESTING.with(|n| {
            n.set(n.get() + 1);
            n.get()
        });
        let guard = Nested;
        if depth > MAX_NESTING {
            return Err(input.error(format!(
                "expression nested too deeply: more than {MAX_NESTING} levels of parentheses, \
                 unary minus signs, `^` or calls (split it with `let`s)"
            )));
        }
        Ok(guard)
    }
}

impl Drop for Nested {
    fn drop(&mut self) {
        NESTING.with(|n| n.set(n.get() - 1));
    }
}

/// Precedence climbing: `+ -` < `* / %` < unary `-` < `^` (right-assoc).
/// Operators of one precedence in a row make one [`ExprKind::Chain`].
pub fn parse_expr(input: ParseStream, min_prec: u8) -> syn::Result<Expr> {
    let _nested = Nested::enter(input)?;
    let mut lhs = parse_unary(input)?;
    // Links applied to `lhs`, not yet folded into it.
    let mut links: Vec<Link> = Vec::new();
    while let Some(op) = peek_binop(input) {
        let prec = precedence(op);
        if prec < min_prec {
            break;
        }
        let span = parse_operator(input, op)?;
        let rhs = parse_expr(input, if op == BinOp::Pow { prec } else { prec + 1 })?;
        apply(&mut lhs, &mut links, Link { op, span, rhs });
    }
    fold(&mut lhs, &mut links);
    Ok(lhs)
}

// `apply` and `fold` build the tree in place, outside `parse_expr`: the
// temporaries they need stay off the stack of the recursion.

/// Applies `link` to `lhs` followed by `links`: a `^` at once, the others
/// appended to `links`, after folding them into `lhs` if their precedence
/// differs.
fn apply(lhs: &mut Expr, links: &mut Vec<Link>, link: Link) {
    let prec = precedence(link.op);
    if link.op == BinOp::Pow || links.last().is_some_and(|l| precedence(l.op) != prec) {
        fold(lhs, links);
    }
    if link.op == BinOp::Pow {
        let base = take(lhs);
        *lhs = Expr {
            kind: ExprKind::Binary(link.op, Box::new(base), Box::new(link.rhs)),
            span: link.span,
        };
    } else {
        links.push(link);
    }
}

/// Makes `lhs` the chain of `lhs` and `links`, and empties `links`.
fn fold(lhs: &mut Expr, links: &mut Vec<Link>) {
    if let Some(last) = links.last() {
        let span = last.span;
        let first = take(lhs);
        *lhs = Expr {
            span,
            kind: ExprKind::Chain(Box::new(first), std::mem::take(links)),
        };
    }
}

/// Moves `e` out, leaving a placeholder.
fn take(e: &mut Expr) -> Expr {
    let placeholder = Expr {
        kind: ExprKind::Num(0.0, true),
        span: e.span,
    };
    std::mem::replace(e, placeholder)
}

/// Reads the operator `op` that [`peek_binop`] saw; its span.
fn parse_operator(input: ParseStream, op: BinOp) -> syn::Result<Span> {
    let span = input.span();
    let tt: TokenTree = input.parse()?;
    if let TokenTree::Punct(star) = &tt {
        // `x ** 2` lexes as `*` joined to `*`.
        if op == BinOp::Mul
            && star.spacing() == proc_macro2::Spacing::Joint
            && input.peek(Token![*])
        {
            return Err(syn::Error::new(
                span,
                "`**` is not an operator of the grammar: write `^` for a power, as in `x^2`",
            ));
        }
    }
    Ok(span)
}

// `parse_unary` and `parse_primary` only dispatch: each form has its own
// function, so the recursion through one form does not carry the stack
// frames of the others (without optimisation every local of a function has
// its own slot).
fn parse_unary(input: ParseStream) -> syn::Result<Expr> {
    if input.peek(Token![-]) {
        parse_neg(input)
    } else {
        parse_primary(input)
    }
}

/// `- expr`: the operand binds tighter than `* /`, looser than `^`.
fn parse_neg(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    input.parse::<Token![-]>()?;
    let e = parse_expr(input, PREC_POWER)?;
    Ok(Expr {
        kind: ExprKind::Neg(Box::new(e)),
        span,
    })
}

fn parse_primary(input: ParseStream) -> syn::Result<Expr> {
    if input.peek(token::Paren) {
        parse_parenthesized(input)
    } else if input.peek(LitInt) || input.peek(LitFloat) {
        parse_number(input)
    } else if input.peek(Token![if]) {
        parse_if(input)
    } else if kw(input, "sum") && input.peek2(syn::Ident) && input.peek3(Token![in]) {
        parse_sum(input)
    } else if input.peek(syn::Ident) && input.peek2(token::Bracket) {
        parse_index(input)
    } else if input.peek(syn::Ident) && input.peek2(token::Paren) {
        parse_call(input)
    } else if input.peek(syn::Ident) {
        parse_ident(input)
    } else {
        Err(input.error("expected an expression: a number, a name, `q[i]`, `f(x)`, `(..)`, `sum i in a..b { .. }` or `if .. { .. } else { .. }`"))
    }
}

/// A name alone.
fn parse_ident(input: ParseStream) -> syn::Result<Expr> {
    let id: Ident = input.parse()?;
    Ok(Expr {
        span: id.span(),
        kind: ExprKind::Ident(id),
    })
}

/// `( expr )`.
fn parse_parenthesized(input: ParseStream) -> syn::Result<Expr> {
    let c;
    parenthesized!(c in input);
    let e = parse_expr(&c, 0)?;
    if !c.is_empty() {
        return Err(c.error("expected `)`"));
    }
    Ok(e)
}

/// `{ expr }`: the body of a `sum` or a branch of an `if`.
fn parse_braced(input: ParseStream) -> syn::Result<Expr> {
    let c;
    braced!(c in input);
    let e = parse_expr(&c, 0)?;
    if !c.is_empty() {
        return Err(c.error("expected `}`"));
    }
    Ok(e)
}

/// `[ expr ]`, and the span of the brackets.
fn parse_bracketed(input: ParseStream) -> syn::Result<(Expr, Span)> {
    let c;
    let b = bracketed!(c in input);
    let e = parse_expr(&c, 0)?;
    if !c.is_empty() {
        return Err(c.error("expected `]`"));
    }
    Ok((e, b.span.join()))
}

/// An integer or float literal.
fn parse_number(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    if input.peek(LitInt) {
        let l: LitInt = input.parse()?;
        let v: i64 = l.base10_parse()?;
        return Ok(Expr {
            kind: ExprKind::Num(v as f64, true),
            span,
        });
    }
    let l: LitFloat = input.parse()?;
    let v: f64 = l.base10_parse()?;
    Ok(Expr {
        kind: ExprKind::Num(v, false),
        span,
    })
}

/// `if cond { expr } else { expr }`, or `else if ..`.
fn parse_if(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    input.parse::<Token![if]>()?;
    let cond = parse_cond(input)?;
    let then = Box::new(parse_braced(input)?);
    let otherwise = Box::new(parse_else(input)?);
    Ok(Expr {
        kind: ExprKind::If(cond, then, otherwise),
        span,
    })
}

/// `else { expr }` or `else if ..`.
fn parse_else(input: ParseStream) -> syn::Result<Expr> {
    input.parse::<Token![else]>()?;
    if input.peek(Token![if]) {
        // `else if` chains recurse here, not through `parse_expr`.
        let _nested = Nested::enter(input)?;
        parse_if(input)
    } else {
        parse_braced(input)
    }
}

/// `sum i in lo..hi { body }`.
fn parse_sum(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    let (var, lo, hi) = parse_range(input)?;
    let body = Box::new(parse_braced(input)?);
    Ok(Expr {
        kind: ExprKind::Sum(var, lo, hi, body),
        span,
    })
}

/// `sum i in lo..hi`: the index and the bounds.
fn parse_range(input: ParseStream) -> syn::Result<(Ident, Box<Expr>, Box<Expr>)> {
    input.parse::<Ident>()?;
    let var: Ident = input.parse()?;
    input.parse::<Token![in]>()?;
    let lo = parse_expr(input, 0)?;
    input.parse::<Token![..]>()?;
    let hi = parse_expr(input, 0)?;
    Ok((var, Box::new(lo), Box::new(hi)))
}

/// `q[i]`, or `x[a][c]`.
fn parse_index(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    let id: Ident = input.parse()?;
    let (idx, bracket) = parse_bracketed(input)?;
    let mut e = Expr {
        kind: ExprKind::Index(id, Box::new(idx), bracket),
        span,
    };
    // `x[a][c]`: a coordinate of a particle (topology templates).
    if input.peek(token::Bracket) {
        let (comp, bracket) = parse_bracketed(input)?;
        e = Expr {
            kind: ExprKind::Component(Box::new(e), Box::new(comp), bracket),
            span,
        };
    }
    Ok(e)
}

/// `f(args)`.
fn parse_call(input: ParseStream) -> syn::Result<Expr> {
    let span = input.span();
    let id: Ident = input.parse()?;
    let c;
    parenthesized!(c in input);
    let mut args = Vec::new();
    while !c.is_empty() {
        args.push(parse_expr(&c, 0)?);
        if c.is_empty() {
            break;
        }
        c.parse::<Token![,]>()?;
    }
    Ok(Expr {
        kind: ExprKind::Call(id, args),
        span,
    })
}

/// `a || b || ..` of [`parse_and`]s.
fn parse_cond(input: ParseStream) -> syn::Result<Cond> {
    let mut any = vec![parse_and(input)?];
    while input.peek(Token![||]) {
        input.parse::<Token![||]>()?;
        any.push(parse_and(input)?);
    }
    Ok(if any.len() == 1 {
        any.swap_remove(0)
    } else {
        Cond::Or(any)
    })
}

/// `a && b && ..` of comparisons.
fn parse_and(input: ParseStream) -> syn::Result<Cond> {
    let mut all = vec![parse_cmp(input)?];
    while input.peek(Token![&&]) {
        input.parse::<Token![&&]>()?;
        all.push(parse_cmp(input)?);
    }
    Ok(if all.len() == 1 {
        all.swap_remove(0)
    } else {
        Cond::And(all)
    })
}
fn parse_cmp(input: ParseStream) -> syn::Result<Cond> {
    let a = parse_expr(input, 0)?;
    let op = if input.peek(Token![==]) {
        input.parse::<Token![==]>()?;
        CmpOp::Eq
    } else if input.peek(Token![!=]) {
        input.parse::<Token![!=]>()?;
        CmpOp::Ne
    } else if input.peek(Token![<=]) {
        input.parse::<Token![<=]>()?;
        CmpOp::Le
    } else if input.peek(Token![>=]) {
        input.parse::<Token![>=]>()?;
        CmpOp::Ge
    } else if input.peek(Token![<]) {
        input.parse::<Token![<]>()?;
        CmpOp::Lt
    } else if input.peek(Token![>]) {
        input.parse::<Token![>]>()?;
        CmpOp::Gt
    } else {
        return Err(
            input.error("expected a comparison (`==`, `!=`, `<`, `<=`, `>`, `>=`) of indices")
        );
    };
    let b = parse_expr(input, 0)?;
    Ok(Cond::Cmp(op, Box::new(a), Box::new(b)))
}
