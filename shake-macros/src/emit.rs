//! The generated items: the struct, its constructor, and the impls of
//! `geoshake::runtime::{Hamiltonian, ConstrainedSystem}`.
//!
//! Layout follows the runtime's contract (`shake-runtime/src/system.rs`):
//! flat column-major outputs, q-columns before p-columns, and only
//! structurally nonzero entries are written, with literal indices into
//! fixed-size arrays (so there are no bounds checks in the hot code).

use crate::cse::{Block, Coder};
use crate::diff::{Derived, Kind};
use crate::lower::System;
use crate::parse::SystemDef;
use crate::symbolic::NodeId;
use proc_macro2::{Literal, TokenStream};
use quote::quote;

fn idx(k: usize) -> Literal {
    Literal::usize_unsuffixed(k)
}

/// The struct with one `pub f64` field per parameter, and `new`.
pub fn struct_items(def: &SystemDef, extra_doc: &str) -> TokenStream {
    let attrs = &def.attrs;
    let vis = &def.vis;
    let name = &def.name;
    let params = &def.params;
    let field_docs = field_docs(params, def.defaults.as_deref());
    let new = constructor(params);
    let default = default_impl(name, def.defaults.as_deref());
    quote! {
        #(#attrs)*
        #[doc = #extra_doc]
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[allow(non_snake_case)]
        #vis struct #name {
            #( #[doc = #field_docs] pub #params: f64, )*
        }

        impl #name {
            #new
        }

        #default
    }
}

/// `pub const fn new(..) -> Self`, the parameters in declaration order.
///
/// Parameters are named as in the mathematics (`L`, `G`), but a function's
/// arguments are patterns: `new(L: f64)` would match a constant `L` in the
/// user's scope instead of binding it (E0005), and draws `non_snake_case`.
/// So each argument is the parameter's name behind `__` (`__L`), a name no
/// user item has, and the doc line names the parameters; the fields keep
/// the user's names.
pub fn constructor(params: &[syn::Ident]) -> TokenStream {
    let args: Vec<syn::Ident> = params
        .iter()
        .map(|p| quote::format_ident!("__{}", p, span = p.span()))
        .collect();
    let names: Vec<String> = params.iter().map(|p| format!("`{p}`")).collect();
    let doc = if names.is_empty() {
        " Creates the system (it has no parameters).".to_string()
    } else {
        format!(
            " Creates the system from its parameters, in declaration order: {}.",
            names.join(", ")
        )
    };
    quote! {
        #[doc = #doc]
        #[allow(non_snake_case, clippy::too_many_arguments, clippy::used_underscore_binding)]
        #[must_use]
        pub const fn new(#(#args: f64),*) -> Self {
            Self { #(#params: #args),* }
        }
    }
}

/// One doc line per parameter field, with its default when declared.
pub fn field_docs(params: &[syn::Ident], defaults: Option<&[f64]>) -> Vec<String> {
    params
        .iter()
        .enumerate()
        .map(|(k, p)| match defaults {
            Some(d) => format!(
                " The parameter `{p}` (a constant for differentiation; default {:?}).",
                d[k]
            ),
            None => format!(" The parameter `{p}` (a constant for differentiation)."),
        })
        .collect()
}

/// `impl Default` from the declared defaults (all parameters have one),
/// through `new` so that the order is the declaration's.
pub fn default_impl(name: &syn::Ident, defaults: Option<&[f64]>) -> TokenStream {
    let Some(d) = defaults else {
        return TokenStream::new();
    };
    let values = d.iter().map(|&v| {
        let lit = Literal::f64_suffixed(v.abs());
        if v.is_sign_negative() {
            quote!(-#lit)
        } else {
            quote!(#lit)
        }
    });
    quote! {
        /// The parameters' declared defaults.
        impl ::core::default::Default for #name {
            fn default() -> Self {
                Self::new(#(#values),*)
            }
        }
    }
}

/// Input conversions to fixed-size arrays, only for inputs the block uses.
fn inputs(b: &Block, d: usize, m: usize) -> TokenStream {
    let mut t = TokenStream::new();
    if b.uses_q {
        t.extend(quote!(let q: &[f64; #d] = ::core::convert::TryInto::try_into(&q[..]).expect("q must have length DOF");));
    }
    if b.uses_p {
        t.extend(quote!(let p: &[f64; #d] = ::core::convert::TryInto::try_into(&p[..]).expect("p must have length DOF");));
    }
    if b.uses_lambda {
        t.extend(quote!(let lambda: &[f64; #m] = ::core::convert::TryInto::try_into(&lambda[..]).expect("lambda must have length CONSTRAINTS");));
    }
    t
}

fn out_array(name: &proc_macro2::Ident, len: usize) -> TokenStream {
    let msg = format!("{name} must have length {len}");
    quote!(let #name: &mut [f64; #len] = ::core::convert::TryInto::try_into(&mut #name[..]).expect(#msg);)
}

/// A method body writing `out[index] = value` for each (index, node).
fn writes(
    coder: &Coder,
    out: &str,
    len: usize,
    entries: &[(usize, NodeId)],
    m: usize,
) -> TokenStream {
    let roots: Vec<NodeId> = entries.iter().map(|e| e.1).collect();
    let b = coder.block(&roots);
    let ins = inputs(&b, coder.dof, m);
    let out = proc_macro2::Ident::new(out, proc_macro2::Span::call_site());
    let arr = out_array(&out, len);
    let lets = &b.lets;
    let assigns = entries.iter().zip(&b.values).map(|((i, _), v)| {
        let i = idx(*i);
        quote!(#out[#i] = #v;)
    });
    quote!(#ins #arr #lets #(#assigns)*)
}

/// Upper-triangle entries (a, b) of an n×n symmetric matrix, written to
/// both (a, b) and (b, a) in column-major order.
fn symmetric(entries: &[((usize, usize), NodeId)], n: usize) -> Vec<(usize, NodeId)> {
    let mut out = Vec::new();
    for &((a, b), node) in entries {
        out.push((a + b * n, node));
        if a != b {
            out.push((b + a * n, node));
        }
    }
    out
}

pub fn impls(def: &SystemDef, sys: &System, der: &Derived) -> TokenStream {
    let name = &def.name;
    let d = sys.dof;
    let n2 = 2 * d;
    let m = der.g.len();
    let coder = Coder {
        graph: &sys.graph,
        dof: d,
        params: &sys.params,
    };
    let separable = der.separable;
    let quadratic_kinetic = der.quadratic_kinetic;
    let quadratic_constraints = der.quadratic_constraints;

    // H
    let hb = coder.block(&[sys.hamiltonian]);
    let h_ins = inputs(&hb, d, m);
    let h_lets = &hb.lets;
    let h_val = &hb.values[0];

    let h_q: Vec<(usize, NodeId)> = der.h_z.iter().filter(|e| e.0 < d).copied().collect();
    let h_p: Vec<(usize, NodeId)> = der
        .h_z
        .iter()
        .filter(|e| e.0 >= d)
        .map(|e| (e.0 - d, e.1))
        .collect();
    let grad_q = writes(&coder, "h_q", d, &h_q, m);
    let grad_p = writes(&coder, "h_p", d, &h_p, m);
    // Both halves in one block so their common subexpressions are shared.
    let gradient = {
        let roots: Vec<NodeId> = h_q.iter().chain(&h_p).map(|e| e.1).collect();
        let b = coder.block(&roots);
        let ins = inputs(&b, d, m);
        let lets = &b.lets;
        let hq = proc_macro2::Ident::new("h_q", proc_macro2::Span::call_site());
        let hp = proc_macro2::Ident::new("h_p", proc_macro2::Span::call_site());
        let aq = out_array(&hq, d);
        let ap = out_array(&hp, d);
        let assigns = h_q
            .iter()
            .map(|e| (&hq, e.0))
            .chain(h_p.iter().map(|e| (&hp, e.0)))
            .zip(&b.values)
            .map(|((o, i), v)| {
                let i = idx(i);
                quote!(#o[#i] = #v;)
            });
        quote!(#ins #aq #ap #lets #(#assigns)*)
    };
    let hessian = writes(&coder, "h_zz", n2 * n2, &symmetric(&der.h_zz, n2), m);

    let kind = match der.kind {
        Kind::None => quote!(None),
        Kind::Holonomic => quote!(Holonomic),
        Kind::Quadratic => quote!(Quadratic),
        Kind::General => quote!(General),
    };
    let pattern = der.g_z.iter().map(|((i, k), _)| quote!((#i, #k)));
    let names = sys.constraints.iter().map(|c| c.name.as_str());
    let var_names = sys.graph.names.vars.iter().map(String::as_str);
    let g_entries: Vec<(usize, NodeId)> = der.g.iter().copied().enumerate().collect();
    let constraints = writes(&coder, "g", m, &g_entries, m);
    let jac: Vec<(usize, NodeId)> = der.g_z.iter().map(|((i, k), n)| (i + k * m, *n)).collect();
    let jacobian = writes(&coder, "g_z", m * n2, &jac, m);
    // The same entries packed in the pattern's order (the same roots in
    // the same order: the same block of lets, the same bits).
    let packed: Vec<(usize, NodeId)> = der
        .g_z
        .iter()
        .enumerate()
        .map(|(e, (_, n))| (e, *n))
        .collect();
    let jacobian_values = writes(&coder, "values", packed.len(), &packed, m);
    let nnz = packed.len();
    let g_hess = writes(&coder, "out", n2 * n2, &symmetric(&der.g_hess, n2), m);
    let hidden_entries: Vec<(usize, NodeId)> = der
        .hidden
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, n)| !sys.graph.is_zero(*n))
        .collect();
    let hidden = writes(&coder, "out", m, &hidden_entries, m);
    let hz: Vec<(usize, NodeId)> = der
        .hidden_z
        .iter()
        .map(|((i, k), n)| (i + k * m, *n))
        .collect();
    let hidden_jac = writes(&coder, "out", m * n2, &hz, m);
    let mut n_entries = Vec::new();
    for (i, row) in der.n.iter().enumerate() {
        for (j, &nij) in row.iter().enumerate() {
            if !sys.graph.is_zero(nij) {
                n_entries.push((i + j * m, nij));
            }
        }
    }
    let nondeg = writes(&coder, "n", m * m, &n_entries, m);

    let fibre = match der.kind {
        Kind::None => quote! {
            #[inline]
            fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ::geoshake::runtime::ClosedForm {
                ::geoshake::runtime::ClosedForm::Applied
            }
        },
        // exp(Σλ_i X_{g_i}) for g = g(q): q fixed, p ← p − g_q(q)ᵀλ (Section 5.1).
        Kind::Holonomic => {
            let roots: Vec<NodeId> = der.kick.iter().map(|e| e.1).collect();
            let b = coder.block(&roots);
            let lets = &b.lets;
            let q_in = if b.uses_q {
                quote!(let q: &[f64; #d] = ::core::convert::TryInto::try_into(&q[..]).expect("q must have length DOF");)
            } else {
                quote!()
            };
            let l_in = if b.uses_lambda {
                quote!(let lambda: &[f64; #m] = ::core::convert::TryInto::try_into(&lambda[..]).expect("lambda must have length CONSTRAINTS");)
            } else {
                quote!()
            };
            let pid = proc_macro2::Ident::new("p", proc_macro2::Span::call_site());
            let p_arr = out_array(&pid, d);
            let kicks = der.kick.iter().zip(&b.values).map(|((k, _), v)| {
                let k = idx(*k);
                quote!(p[#k] -= #v;)
            });
            quote! {
                #[inline]
                fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ::geoshake::runtime::ClosedForm {
                    #q_in #l_in #lets #p_arr
                    #(#kicks)*
                    ::geoshake::runtime::ClosedForm::Applied
                }
            }
        }
        Kind::Quadratic | Kind::General => quote!(),
    };

    // d and m as constants for the runtime's fixed-size classical step
    // (stack arrays of the system's size), offered where the runtime has
    // one: holonomic g, separable H with quadratic T, one to eight
    // constraints. Elsewhere the default (`dynamic`) stands, and no
    // fixed-size code is instantiated for the system.
    let classical = der.kind == Kind::Holonomic && separable && quadratic_kinetic;
    let fixed = if classical && (1..=8).contains(&m) {
        quote! {
            #[inline]
            fn with_sizes<V: ::geoshake::runtime::SizeVisitor<Self>>(&self, v: V) -> V::Output {
                v.fixed::<#d, #m>(self)
            }
        }
    } else {
        quote!()
    };

    quote! {
        impl #name {
            /// The number d of degrees of freedom (also `Hamiltonian::dof`),
            /// as a constant for array lengths.
            pub const DOF: usize = #d;
            /// The number m of constraints (also
            /// `ConstrainedSystem::constraint_count`), as a constant.
            pub const CONSTRAINTS: usize = #m;
            /// The structurally nonzero entries of g_z (also
            /// `ConstrainedSystem::jacobian_pattern`), as a constant.
            pub const JACOBIAN_PATTERN: &'static [(usize, usize)] = &[#(#pattern),*];
        }

        #[automatically_derived]
        #[allow(unused_variables, unused_mut, clippy::all, clippy::pedantic, clippy::nursery)]
        impl ::geoshake::runtime::Hamiltonian for #name {
            #[inline]
            fn dof(&self) -> usize { #d }
            #[inline]
            fn separable(&self) -> bool { #separable }
            #[inline]
            fn quadratic_kinetic(&self) -> bool { #quadratic_kinetic }
            fn variable_name(&self, k: usize) -> ::std::borrow::Cow<'_, str> {
                const NAMES: &[&str] = &[#(#var_names),*];
                ::std::borrow::Cow::Borrowed(NAMES[k])
            }

            #[inline]
            fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
                #h_ins #h_lets #h_val
            }
            #[inline]
            fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) { #grad_q }
            #[inline]
            fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) { #grad_p }
            #[inline]
            fn gradient(&self, q: &[f64], p: &[f64], h_q: &mut [f64], h_p: &mut [f64]) { #gradient }
            fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) { #hessian }
        }

        #[automatically_derived]
        #[allow(unused_variables, unused_mut, clippy::all, clippy::pedantic, clippy::nursery)]
        impl ::geoshake::runtime::ConstrainedSystem for #name {
            #[inline]
            fn constraint_count(&self) -> usize { #m }
            #[inline]
            fn kind(&self) -> ::geoshake::runtime::ConstraintKind { ::geoshake::runtime::ConstraintKind::#kind }
            #[inline]
            fn quadratic_constraints(&self) -> bool { #quadratic_constraints }
            fn jacobian_pattern(&self) -> &[(usize, usize)] {
                Self::JACOBIAN_PATTERN
            }
            fn constraint_name(&self, i: usize) -> &str {
                const NAMES: &[&str] = &[#(#names),*];
                NAMES[i]
            }

            #[inline]
            fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) { #constraints }
            #[inline]
            fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) { #jacobian }
            #[inline]
            fn constraint_jacobian_values(&self, q: &[f64], p: &[f64], values: &mut [f64]) -> bool {
                if values.len() != #nnz {
                    return false;
                }
                #jacobian_values
                true
            }
            fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) { #g_hess }
            #[inline]
            fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) { #hidden }
            fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) { #hidden_jac }
            #[inline]
            fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) { #nondeg }
            #fibre
            #fixed
        }
    }
}

/// What the user sees besides the errors: the struct and impls whose bodies
/// are unreachable, so uses of the type do not add a cascade of errors.
pub fn fallback(def: &SystemDef) -> TokenStream {
    let name = &def.name;
    let s = struct_items(def, "");
    quote! {
        #s
        impl #name {
            /// Unreachable: the declaration has errors.
            pub const DOF: usize = 0;
            /// Unreachable: the declaration has errors.
            pub const CONSTRAINTS: usize = 0;
            /// Unreachable: the declaration has errors.
            pub const JACOBIAN_PATTERN: &'static [(usize, usize)] = &[];
        }
        #[allow(unused_variables)]
        impl ::geoshake::runtime::Hamiltonian for #name {
            fn dof(&self) -> usize { unreachable!() }
            fn separable(&self) -> bool { unreachable!() }
            fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 { unreachable!() }
            fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) { unreachable!() }
            fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) { unreachable!() }
            fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) { unreachable!() }
        }
        #[allow(unused_variables)]
        impl ::geoshake::runtime::ConstrainedSystem for #name {
            fn constraint_count(&self) -> usize { unreachable!() }
            fn kind(&self) -> ::geoshake::runtime::ConstraintKind { unreachable!() }
            fn jacobian_pattern(&self) -> &[(usize, usize)] { unreachable!() }
            fn constraint_name(&self, i: usize) -> &str { unreachable!() }
            fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) { unreachable!() }
            fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) { unreachable!() }
            fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) { unreachable!() }
            fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) { unreachable!() }
            fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) { unreachable!() }
            fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) { unreachable!() }
        }
    }
}
