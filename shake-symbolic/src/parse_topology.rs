//! The typed view of a `particles` system: families over run-time tables.
//!
//! ```text
//! system   := doc* vis? "struct" Name "{" item* "}"
//! item     := "parameters" "{" (name ("=" number)?),* "}"
//!           | "particles" x "[" DIM "]" ("," p "[" DIM "]")? ";"
//!           | "potential" "{" family,* "}"
//!           | "constraints" "{" family,* "}"
//! family   := name "[" k "in" table "(" a,+ (";" c,*)? ")" "]" ":" template
//! ```
//!
//! Templates are expressions of the dense grammar (`parse::parse_expr`), read
//! with vector meaning by `topology`.

use crate::parse::{parse_expr, Expr};
use proc_macro2::{Span, TokenStream, TokenTree};
use syn::parse::{Parse, ParseStream};
use syn::{braced, bracketed, parenthesized, token, Attribute, Ident, LitInt, Token, Visibility};

/// True when the declaration's body has a top-level `particles x` item: the
/// run-time topology form, expanded by `topology` instead of the dense path.
pub fn is_particle_system(input: &TokenStream) -> bool {
    let mut after_struct = false;
    for tt in input.clone() {
        match tt {
            TokenTree::Ident(i) if i == "struct" => after_struct = true,
            TokenTree::Group(g)
                if after_struct && g.delimiter() == proc_macro2::Delimiter::Brace =>
            {
                let body: Vec<TokenTree> = g.stream().into_iter().collect();
                return body.windows(2).any(|w| {
                    matches!((&w[0], &w[1]), (TokenTree::Ident(a), TokenTree::Ident(_)) if a == "particles")
                });
            }
            _ => {}
        }
    }
    false
}

/// Whether a family is a constraint or a term of the potential energy.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum FamilyKind {
    Constraint,
    Potential,
}

/// `name[k in table(a, b; c)]: template`.
pub struct FamilyDecl {
    pub kind: FamilyKind,
    pub name: Ident,
    /// The member index `k` (it numbers rows; a template may not use it).
    pub index: Ident,
    pub table: Ident,
    /// The particle variables `a, b`: `x[a]` is a vector of R^DIM.
    pub particles: Vec<Ident>,
    /// The data variables `c`: one number per row each.
    pub data: Vec<Ident>,
    pub template: Expr,
}

/// A `particles` system.
pub struct ParticleDef {
    pub attrs: Vec<Attribute>,
    pub vis: Visibility,
    pub name: Ident,
    pub params: Vec<Ident>,
    /// The parameters' defaults, when every one has one (as in
    /// [`SystemDef`](crate::parse::SystemDef)).
    pub defaults: Option<Vec<f64>>,
    /// The position array `x`.
    pub x: Ident,
    /// The momentum array, `p` unless declared otherwise.
    pub p: Ident,
    pub dim: usize,
    pub dim_span: Span,
    /// Every family, in declaration order (potential and constraints
    /// interleaved as written).
    pub families: Vec<FamilyDecl>,
}

fn kw(input: ParseStream, word: &str) -> bool {
    input.fork().parse::<Ident>().is_ok_and(|i| i == word)
}

fn dim(input: ParseStream) -> syn::Result<(usize, Span)> {
    let c;
    bracketed!(c in input);
    let l: LitInt = c.parse().map_err(|e| {
        syn::Error::new(
            e.span(),
            "the dimension of a particle is an integer literal, as in `particles x[3];`",
        )
    })?;
    if !c.is_empty() {
        return Err(c.error("expected `]` after the dimension"));
    }
    Ok((l.base10_parse()?, l.span()))
}

impl Parse for ParticleDef {
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
        let mut params: Option<Vec<Ident>> = None;
        let mut defaults = None;
        let mut particles: Option<(Ident, Ident, usize, Span)> = None;
        let mut families = Vec::new();
        let mut seen_blocks: Vec<Ident> = Vec::new();
        while !body.is_empty() {
            if kw(&body, "parameters") {
                let k: Ident = body.parse()?;
                if params.is_some() {
                    return Err(syn::Error::new(k.span(), "`parameters` is declared twice"));
                }
                let c;
                braced!(c in body);
                let (names, given) = crate::parse::parse_parameters(&c)?;
                params = Some(names);
                defaults = given;
                let _ = body.parse::<Option<Token![;]>>()?;
            } else if kw(&body, "particles") {
                let k: Ident = body.parse()?;
                if particles.is_some() {
                    return Err(syn::Error::new(k.span(), "`particles` is declared twice"));
                }
                let x: Ident = body.parse()?;
                let (d, span) = dim(&body)?;
                let p = if body.peek(Token![,]) {
                    body.parse::<Token![,]>()?;
                    let p: Ident = body.parse()?;
                    let (dp, sp) = dim(&body)?;
                    if dp != d {
                        return Err(syn::Error::new(
                            sp,
                            format!("`{p}` must have the dimension of `{x}`: {dp} ≠ {d}"),
                        ));
                    }
                    p
                } else {
                    Ident::new("p", Span::call_site())
                };
                body.parse::<Token![;]>()?;
                particles = Some((x, p, d, span));
            } else if kw(&body, "constraints") || kw(&body, "potential") {
                let k: Ident = body.parse()?;
                if let Some(prev) = seen_blocks.iter().find(|b| **b == k) {
                    let mut e = syn::Error::new(k.span(), format!("`{k}` is declared twice"));
                    e.combine(syn::Error::new(prev.span(), "first declared here"));
                    return Err(e);
                }
                let kind = if k == "constraints" {
                    FamilyKind::Constraint
                } else {
                    FamilyKind::Potential
                };
                seen_blocks.push(k);
                let c;
                braced!(c in body);
                parse_families(&c, kind, &mut families)?;
                let _ = body.parse::<Option<Token![;]>>()?;
            } else if kw(&body, "dof") || kw(&body, "coordinates") || kw(&body, "momenta") {
                let k: Ident = body.parse()?;
                return Err(syn::Error::new(
                    k.span(),
                    "a `particles` system has its state from `particles x[D];` (n particles, n given \
                     at run time): `dof`, `coordinates` and `momenta` belong to the compile-time form",
                ));
            } else if kw(&body, "hamiltonian") {
                let k: Ident = body.parse()?;
                return Err(syn::Error::new(
                    k.span(),
                    "a `particles` system has H = Σ_a |p_a|²/(2 m_a) + (the `potential` families): \
                     write the potential energy as `potential { name[k in table(a, b; c)]: .. }`",
                ));
            } else {
                return Err(body.error(
                    "expected one of `parameters { .. }`, `particles x[D];`, `potential { .. }`, \
                     `constraints { .. }`",
                ));
            }
        }
        let Some((x, p, dim, dim_span)) = particles else {
            return Err(syn::Error::new(name.span(), "missing `particles x[D];`"));
        };
        Ok(ParticleDef {
            attrs,
            vis,
            name,
            params: params.unwrap_or_default(),
            defaults,
            x,
            p,
            dim,
            dim_span,
            families,
        })
    }
}

fn idents(input: ParseStream, out: &mut Vec<Ident>) -> syn::Result<()> {
    while input.peek(syn::Ident) {
        out.push(input.parse()?);
        if !input.peek(Token![,]) {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    Ok(())
}

fn parse_families(
    input: ParseStream,
    kind: FamilyKind,
    out: &mut Vec<FamilyDecl>,
) -> syn::Result<()> {
    while !input.is_empty() {
        let name: Ident = input.parse()?;
        if !input.peek(token::Bracket) {
            return Err(syn::Error::new(
                name.span(),
                format!(
                    "in a `particles` system every family ranges over a run-time table: \
                     write `{name}[k in table(a, b; data)]: ..`"
                ),
            ));
        }
        let c;
        bracketed!(c in input);
        let index: Ident = c.parse()?;
        c.parse::<Token![in]>()?;
        if !(c.peek(syn::Ident) && c.peek2(token::Paren)) {
            return Err(c.error(
                "expected a table signature `table(a, b; data)`: in a `particles` system, families \
                 range over run-time tables (compile-time ranges `lo..hi` belong to the `dof` form)",
            ));
        }
        let table: Ident = c.parse()?;
        let sig;
        parenthesized!(sig in c);
        let mut particles = Vec::new();
        idents(&sig, &mut particles)?;
        let mut data = Vec::new();
        if sig.peek(Token![;]) {
            sig.parse::<Token![;]>()?;
            idents(&sig, &mut data)?;
        }
        if !sig.is_empty() {
            return Err(sig.error(
                "expected `table(a, b; c)`: particle variables, then `;` and data variables",
            ));
        }
        if particles.is_empty() {
            return Err(syn::Error::new(
                table.span(),
                format!("the table `{table}` names no particle: write `{table}(a, b; data)`"),
            ));
        }
        if !c.is_empty() {
            return Err(c.error("expected `]` after the table signature"));
        }
        input.parse::<Token![:]>()?;
        let template = parse_expr(input, 0)?;
        out.push(FamilyDecl {
            kind,
            name,
            index,
            table,
            particles,
            data,
            template,
        });
        if input.is_empty() {
            break;
        }
        input.parse::<Token![,]>()?;
    }
    Ok(())
}
