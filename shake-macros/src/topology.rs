//! The emission of a `particles` system: one
//! `geoshake::runtime::particles::Stencil` per family, from the templates
//! `geoshake_symbolic::topology` lowered, differentiated and checked, and
//! the user's struct with its tables and `system(..)`.
//!
//! Nothing emitted depends on the number of members (the rows are given at
//! run time), so expansion time and code size do not either.

use crate::cse::Coder;
use crate::parse_topology::{FamilyDecl, FamilyKind, ParticleDef};
use geoshake_symbolic::topology::{self, Lowered};
use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use syn::{Error, Ident};

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
    let lowered = match topology::analyse(&def) {
        Ok(l) => l,
        Err(errors) => return fail(errors),
    };
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
