//! Common-subexpression elimination and straight-line code for one method.
//!
//! Hash-consing already made every shared subexpression one node, so CSE is
//! a schedule: starting from the outputs a method needs, collect the nodes
//! they reach and emit each once, by increasing id (a topological order, by
//! the graph's invariant), as `let tN = ...;`. Leaves (state entries,
//! parameters, λ, constants) are written inline. Nodes no output reaches are
//! never emitted, so a method pays only for what it returns.

use crate::symbolic::{Graph, Node, NodeId};
use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};
use std::collections::BTreeSet;

/// The most `let`s emitted one after the other in one scope.
///
/// Every `let` opens a scope nested in the one before, and rustc's debug
/// info walks those scopes recursively: a few thousand nested `let`s (a
/// chain of 256 links has about ten thousand temporaries in one method)
/// overflow the stack of LLVM's DWARF writer (rustc dies with SIGSEGV
/// whenever debug info is on, as in the dev profile). Longer blocks are
/// emitted in chunks, `let (t1, t2, …) = { let t1 = …; …; (t1, t2, …) };`,
/// so scopes nest at most `LET_CHUNK` + (number of chunks) deep; the values
/// stay SSA values (no arrays in memory), so the optimised code is the same.
const LET_CHUNK: usize = 128;

/// `defs` as chunks of at most [`LET_CHUNK`] `let`s, each a block whose
/// value is the tuple of its temporaries.
fn chunked_lets(defs: Vec<(TokenStream, TokenStream)>) -> TokenStream {
    let mut out = TokenStream::new();
    for chunk in defs.chunks(LET_CHUNK) {
        let ts: Vec<&TokenStream> = chunk.iter().map(|(t, _)| t).collect();
        let es = chunk.iter().map(|(_, e)| e);
        out.extend(quote! {
            let (#(#ts,)*) = { #(let #ts: f64 = #es;)* (#(#ts,)*) };
        });
    }
    out
}

/// Straight-line code for a set of roots.
pub struct Block {
    /// The `let` statements, in order.
    pub lets: TokenStream,
    /// The value of each root, as an expression over the lets.
    pub values: Vec<TokenStream>,
    pub uses_q: bool,
    pub uses_p: bool,
    pub uses_lambda: bool,
}

pub struct Coder<'a> {
    pub graph: &'a Graph,
    pub dof: usize,
    pub params: &'a [Ident],
}

fn lit(x: f64) -> TokenStream {
    if x.is_nan() {
        quote!(::core::f64::NAN)
    } else if x.is_infinite() {
        if x > 0.0 {
            quote!(::core::f64::INFINITY)
        } else {
            quote!(::core::f64::NEG_INFINITY)
        }
    } else if x < 0.0 {
        let l = Literal::f64_suffixed(-x);
        quote!((-#l))
    } else {
        let l = Literal::f64_suffixed(x);
        quote!(#l)
    }
}

/// `a * b * c` (quote's repetition cannot use `*` as a separator).
fn product(factors: Vec<TokenStream>) -> TokenStream {
    let mut it = factors.into_iter();
    let mut e = it.next().unwrap_or_else(|| quote!(1.0f64));
    for f in it {
        e = quote!(#e * #f);
    }
    e
}

fn idx(k: usize) -> Literal {
    Literal::usize_unsuffixed(k)
}

impl Coder<'_> {
    fn is_leaf(&self, id: NodeId) -> bool {
        matches!(
            self.graph.node(id),
            Node::Const(_) | Node::Var(_) | Node::Param(_) | Node::Lambda(_)
        )
    }

    /// A reference to the value of `id`: a leaf inline, else its `let`.
    pub fn atom(&self, id: NodeId) -> TokenStream {
        match self.graph.node(id) {
            Node::Const(b) => lit(f64::from_bits(*b)),
            Node::Var(v) => {
                let k = v.index();
                if k < self.dof {
                    let i = idx(k);
                    quote!(q[#i])
                } else {
                    let i = idx(k - self.dof);
                    quote!(p[#i])
                }
            }
            Node::Param(p) => {
                let name = &self.params[p.0 as usize];
                quote!(self.#name)
            }
            Node::Lambda(i) => {
                let i = idx(*i as usize);
                quote!(lambda[#i])
            }
            _ => {
                let t = format_ident!("t{}", id.index(), span = Span::call_site());
                quote!(#t)
            }
        }
    }

    fn power(&self, base: NodeId, n: i32) -> TokenStream {
        let b = self.atom(base);
        match n {
            1 => b,
            2 => quote!(#b * #b),
            3 => quote!(#b * #b * #b),
            n if n < 0 => {
                let d = self.power(base, -n);
                quote!(1.0f64 / (#d))
            }
            n => quote!(#b.powi(#n)),
        }
    }

    /// The defining expression of a non-leaf node.
    fn expr(&self, id: NodeId) -> TokenStream {
        match self.graph.node(id) {
            Node::Add(ts) => {
                let ts = ts.iter().map(|t| self.atom(*t));
                quote!(#(#ts)+*)
            }
            Node::Mul(fs) => {
                let mut coef = 1.0;
                let mut num = Vec::new();
                let mut den = Vec::new();
                for f in fs.iter() {
                    match self.graph.node(*f) {
                        Node::Const(b) => coef = f64::from_bits(*b),
                        Node::Pow(b, n) if *n < 0 => den.push(self.power(*b, -n)),
                        _ => num.push(self.atom(*f)),
                    }
                }
                if coef.abs() != 1.0 || num.is_empty() {
                    num.insert(0, lit(coef.abs()));
                }
                let mut e = product(num);
                if !den.is_empty() {
                    let d = product(den);
                    e = quote!(#e / (#d));
                }
                if coef < 0.0 {
                    quote!(-(#e))
                } else {
                    e
                }
            }
            Node::Pow(b, n) => self.power(*b, *n),
            Node::PowF(b, r) => {
                let r = f64::from_bits(*r);
                let b = self.atom(*b);
                if r == 0.5 {
                    quote!(#b.sqrt())
                } else if r == -0.5 {
                    quote!(1.0f64 / #b.sqrt())
                } else {
                    let r = lit(r);
                    quote!(#b.powf(#r))
                }
            }
            Node::Call(f, x) => {
                let x = self.atom(*x);
                let m = Ident::new(f.name(), Span::call_site());
                quote!(#x.#m())
            }
            _ => self.atom(id),
        }
    }

    /// Schedules and emits the code computing `roots`.
    pub fn block(&self, roots: &[NodeId]) -> Block {
        let mut needed = BTreeSet::new();
        let mut stack: Vec<NodeId> = roots.to_vec();
        let (mut uses_q, mut uses_p, mut uses_lambda) = (false, false, false);
        while let Some(id) = stack.pop() {
            if !needed.insert(id) {
                continue;
            }
            match self.graph.node(id) {
                Node::Var(v) if v.index() < self.dof => uses_q = true,
                Node::Var(_) => uses_p = true,
                Node::Lambda(_) => uses_lambda = true,
                _ => stack.extend(self.graph.emitted_deps(id)),
            }
        }
        let defs: Vec<(TokenStream, TokenStream)> = needed
            .iter()
            .filter(|id| !self.is_leaf(**id))
            .map(|&id| (self.atom(id), self.expr(id)))
            .collect();
        let lets = if defs.len() <= LET_CHUNK {
            let (ts, es): (Vec<_>, Vec<_>) = defs.into_iter().unzip();
            quote!(#(let #ts: f64 = #es;)*)
        } else {
            chunked_lets(defs)
        };
        Block {
            lets,
            values: roots.iter().map(|r| self.atom(*r)).collect(),
            uses_q,
            uses_p,
            uses_lambda,
        }
    }
}

#[cfg(test)]
mod expansion_cost {
    use std::time::Instant;

    /// Expansion time and size of the generated code of chains of N links
    /// (BENCHMARKS.md): `cargo test -p geoshake-macros --release -- --ignored
    /// --nocapture expansion_of_chains`.
    #[test]
    #[ignore = "a measurement, not a check"]
    fn expansion_of_chains() {
        println!("| N | expansion time | generated tokens | generated source (bytes) |");
        println!("|---:|---:|---:|---:|");
        for n in [4usize, 16, 64, 256] {
            let src = format!(
                "pub struct Chain {{
                    parameters {{ length, gravity }}
                    const N = {n};
                    dof q[2*N], p[2*N];
                    hamiltonian = sum i in 0..N {{ (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] }};
                    constraints {{
                        link[k in 0..N]: if k == 0 {{ q[0]^2 + q[1]^2 - length^2 }}
                            else {{ (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 }},
                    }}
                }}"
            );
            let input: proc_macro2::TokenStream = src.parse().unwrap();
            let mut best = f64::INFINITY;
            let mut out = proc_macro2::TokenStream::new();
            for _ in 0..3 {
                let t = Instant::now();
                out = crate::expand(input.clone());
                best = best.min(t.elapsed().as_secs_f64());
            }
            let text = out.to_string();
            assert!(!text.contains("compile_error"), "{n}: {text:.300}");
            let tokens = out.into_iter().map(count).sum::<usize>();
            println!("| {n} | {:.1} ms | {tokens} | {} |", best * 1e3, text.len());
        }

        fn count(t: proc_macro2::TokenTree) -> usize {
            match t {
                proc_macro2::TokenTree::Group(g) => {
                    1 + g.stream().into_iter().map(count).sum::<usize>()
                }
                _ => 1,
            }
        }
    }
}
