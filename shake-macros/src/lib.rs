//! The `constrained_system!` macro of `shake`.
//!
//! A thin shell over `geoshake-symbolic`, which holds the front end: `parse`
//! the declaration into a typed view that keeps the user's spans, `lower` it
//! into the hash-consed expression graph of `symbolic` (kept canonical by
//! `simplify`), differentiate it (`diff`), `check` the paper's assumptions;
//! for a particle system, its `topology` lowers, differentiates and checks
//! each family's template. This crate turns the result into tokens: `emit`
//! straight-line code, scheduled by `cse`; `topology` does the same for the
//! families of a particle system. See [`constrained_system!`] for the
//! grammar.

mod cse;
mod emit;
mod topology;

// The front end's modules under their old paths (`crate::diff::Derived`).
#[cfg(test)]
use geoshake_symbolic::check;
use geoshake_symbolic::{diff, lower, parse, parse_topology, symbolic};

#[cfg(test)]
mod fuzz_tests;
#[cfg(test)]
mod tests;

use proc_macro::TokenStream;
use proc_macro2::TokenStream as TokenStream2;
use quote::quote;

/// Declares a constrained Hamiltonian system: a struct whose `f64` fields are
/// the parameters, with generated impls of `geoshake::runtime::Hamiltonian` and
/// `geoshake::runtime::ConstrainedSystem` (H, g and every derivative SHAKE and
/// RATTLE need, differentiated symbolically at compile time).
///
/// ```
/// use geoshake::prelude::*;
///
/// constrained_system! {
///     /// Planar pendulum (the paper's Example 1.3).
///     pub struct Pendulum {
///         parameters { length, gravity }
///         dof q[2], p[2];
///         let r2 = q[0]^2 + q[1]^2;
///         hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
///         constraints {
///             rod: r2 - length^2,
///         }
///     }
/// }
///
/// # fn main() -> Result<(), StepError> {
/// // `new` takes the parameters in declaration order; the fields are
/// // `pub f64` named after them, so a struct literal names each one (no
/// // silent swap when there are many).
/// let pendulum = Pendulum { length: 1.0, gravity: 9.81 };
/// assert_eq!(pendulum, Pendulum::new(1.0, 9.81));
/// assert_eq!((Pendulum::DOF, Pendulum::CONSTRAINTS), (2, 1));
/// assert_eq!(pendulum.constraint_name(0), "rod");
///
/// let mut rattle = Integrator::new(pendulum, StormerVerlet, 0.01).rattle();
/// let z0 = rattle.project_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.0, 0.5]))?;
/// let z = rattle.run(z0, Stop::Steps(100)).execute().into_result().map_err(|(_, e)| e)?.last().unwrap();
/// let mut g = [0.0];
/// pendulum.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
/// assert!(g[0].abs() < 1e-14); // on the rod, to round-off
/// # Ok(())
/// # }
/// ```
///
/// With a default for every parameter the struct implements `Default`,
/// and struct update syntax changes one parameter by name. Defaults for
/// some parameters only are refused (at the first without one), as is a
/// default that is not a number literal:
///
/// ```
/// use geoshake::prelude::*;
///
/// constrained_system! {
///     pub struct Pendulum {
///         parameters { length = 1.0, gravity = 9.81 }
///         dof q[2], p[2];
///         hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
///         constraints { rod: q[0]^2 + q[1]^2 - length^2 }
///     }
/// }
///
/// # fn main() {
/// assert_eq!(Pendulum::default(), Pendulum::new(1.0, 9.81));
/// let long = Pendulum { length: 2.5, ..Pendulum::default() };
/// assert_eq!((long.length, long.gravity), (2.5, 9.81));
/// # }
/// ```
///
/// ```compile_fail
/// geoshake::constrained_system! {
///     pub struct Pendulum {
///         parameters { length = 1.0, gravity }
///         dof q[2], p[2];
///         hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
///         constraints { rod: q[0]^2 + q[1]^2 - length^2 }
///     }
/// }
/// # fn main() {}
/// ```
///
/// A chain of `N` links, anchored at the origin:
///
/// ```
/// use geoshake::prelude::*;
///
/// constrained_system! {
///     pub struct Chain {
///         parameters { length, gravity }
///         const N = 8;
///         dof q[2*N], p[2*N];
///         hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
///         constraints {
///             link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
///                 else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
///         }
///     }
/// }
///
/// # fn main() {
/// assert_eq!((Chain::DOF, Chain::CONSTRAINTS), (16, 8));
/// assert_eq!(Chain::new(1.0, 9.81).constraint_name(3), "link[3]");
/// // The chain hanging straight down satisfies every link.
/// let q: Vec<f64> = (0..16).map(|j| if j % 2 == 1 { -((j / 2 + 1) as f64) } else { 0.0 }).collect();
/// let mut g = [1.0; 8];
/// Chain::new(1.0, 9.81).constraints(&q, &[0.0; 16], &mut g);
/// assert_eq!(g, [0.0; 8]);
/// # }
/// ```
///
/// # Grammar
///
/// ```text
/// system     := doc* vis? "struct" Name "{" item* "}"
/// item       := "parameters" "{" param,* "}"          -- pub f64 fields, in `new(..)` order
/// param      := name | name "=" "-"? number           -- all with defaults: `impl Default`
///             | "const" NAME "=" expr ";"             -- compile-time number (integer for indices)
///             | "dof" q "[" index "]" "," p "[" index "]" ";"   -- z = (q, p) ∈ R^{2d}
///             | "coordinates" name,+ ";" "momenta" name,+ ";"  -- named scalars, paired in order
///             | "let" name "=" expr ";"               -- intermediate, usable below
///             | "hamiltonian" "=" expr ";"
///             | "constraints" "{" (cname ("[" k "in" index ".." index "]")? ":" expr),* "}"
/// expr       := expr ("+" | "-" | "*" | "/") expr | expr "^" expr | "-" expr | "(" expr ")"
///             | number | name | q "[" index "]" | func "(" expr ")"
///             | "sum" i "in" index ".." index "{" expr "}"
///             | "if" cond "{" expr "}" "else" "{" expr "}"      -- decided at compile time
/// func       := sqrt | sin | cos | tan | exp | ln
/// index      := integer expression of literals, consts and bound indices: + - * / % ( )
/// cond       := index ("==" | "!=" | "<" | "<=" | ">" | ">=") index, joined by && ||
/// ```
///
/// `^` binds tighter than unary minus (`-x^2 = -(x^2)`) and is
/// right-associative; its exponent must be a constant (integer exponents are
/// emitted as products or `powi`). Families `name[k in a..b]` declare one
/// constraint per k, named `name[k]`. One (`dof`) or the other
/// (`coordinates`/`momenta`) declares the state; `hamiltonian` is required,
/// `constraints` may be absent (m = 0).
///
/// # Run-time topologies
///
/// Large systems (rigid water boxes, chains of 10⁶ links) declare each
/// family once, as a *template* over a table whose rows are given at run
/// time; nothing is unrolled, so expansion time and code size do not depend
/// on the number of members, which the macro never sees. The system is then
/// `n` particles in R^D (n and the masses given at run time) with
/// H = Σ_a |p_a|²/(2 m_a) + V(x), V the sum of the `potential` families, and
/// the holonomic constraint families of `constraints`; the runtime's
/// `geoshake::runtime::particles` solves it.
///
/// ```
/// use geoshake::constrained_system;
///
/// constrained_system! {
///     /// Rigid water: three distance constraints per molecule.
///     pub struct Water {
///         particles x[3];
///         constraints {
///             bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2,
///         }
///     }
/// }
/// constrained_system! {
///     pub struct SpringChain {
///         parameters { stiffness }
///         particles x[3];
///         potential {
///             spring[k in springs(a, b; rest)]: stiffness / 2 * (norm(x[a] - x[b]) - rest)^2,
///         }
///         constraints {
///             link[k in links(a, b; length)]: norm2(x[a] - x[b]) - length^2,
///         }
///     }
/// }
///
/// # fn main() -> Result<(), Box<dyn std::error::Error>> {
/// let mut bonds = Water::bonds_table();          // Table::new(2, 1)
/// bonds.push(&[0, 1], &[0.9572])?;
/// bonds.push(&[0, 2], &[0.9572])?;
/// bonds.push(&[1, 2], &[1.5139])?;
/// let water = Water::new().system(vec![16.0, 1.0, 1.0], bonds)?;
/// assert_eq!((water.particles(), water.constraints()), (3, 3));
///
/// let (springs, mut links) = (SpringChain::springs_table(), SpringChain::links_table());
/// links.push(&[0, 1], &[1.0])?;
/// let chain = SpringChain::new(100.0).system(vec![1.0; 2], springs, links)?;
/// assert_eq!(chain.constraints(), 1);
/// # Ok(())
/// # }
/// ```
///
/// ```text
/// system     := doc* vis? "struct" Name "{" pitem* "}"
/// pitem      := "parameters" "{" param,* "}"
///             | "particles" x "[" DIM "]" ("," p "[" DIM "]")? ";"   -- DIM an integer literal
///             | "potential" "{" family,* "}"
///             | "constraints" "{" family,* "}"
/// family     := fname "[" k "in" table "(" a,+ (";" c,*)? ")" "]" ":" template
/// template   := expr, read with vector values:
///               x "[" a "]"                      -- particle a's position, a vector of R^DIM
///             | x "[" a "]" "[" int "]"          -- one of its coordinates
///             | u ("+" | "-") v | s "*" u | u "*" s | u "/" s | "-" u
///             | "dot" "(" u "," v ")" | "norm2" "(" u ")" | "norm" "(" u ")"
///             | "cross" "(" u "," v ")"          -- R^3 only
///             | the scalar expressions of `expr` (no `if`, no state arrays)
/// ```
///
/// `a, b, …` are the particle variables of the table (the member's particle
/// indices, ARITY of them), `c, …` its data variables (DATA numbers per row,
/// such as a bond length); `k` numbers the rows and may not appear in the
/// template (it is one formula for every member). `p` names the momenta
/// (`p` by default) only so that using them can be refused: run-time
/// families are holonomic. A template may use the parameters, its data
/// variables, `x[a]` of its own particles, numbers and `sum i in 0..n { .. }`
/// over compile-time ranges (for coordinates: `x[a][i]`).
///
/// Generated for `Water` (names from the declaration): the struct with one
/// `pub f64` per parameter and `new(..)`; `Water::DIM`; per family a struct
/// `WaterBond` (system name + family name in CamelCase, the parameters as
/// fields) implementing `geoshake::runtime::particles::Stencil` (`ARITY`, `DIM`,
/// `DATA`, `value` and `gradient` as straight-line code, differentiated once,
/// simplified and CSE'd), `water.bond_stencil()`, and `Water::bonds_table()`
/// (an empty `Table::new(ARITY, DATA)`); and
/// `water.system(masses, bonds, …) -> Result<ParticleSystem, TopologyError>`,
/// one `Table` per family in declaration order.
///
/// Refused at compile time, once per template (with spans): unknown names,
/// particle indices not declared in the table signature, momenta in a
/// template (momentum-dependent families need the compile-time form above),
/// a template that does not depend on the positions (identically zero
/// gradient) or does not depend on one of its declared particles, vector
/// values where a scalar is needed, and ARITY·DIM > 64 (the runtime's stack
/// buffer). Coisotropy needs no check: holonomic constraints Poisson-commute,
/// {g_i, g_j} = 0 for every pair of members. What depends on the table is the
/// runtime's (`TopologyError`, naming the family and member): dangling and
/// repeated particle indices and duplicate members when `system(..)` builds
/// the system, and nondegeneracy on the actual topology (a cluster with more
/// constraints than coordinates) when a solver is set up on it.
///
/// # Limits
///
/// Past each limit the declaration is refused with an error at the
/// offending token (never a crash of the compiler):
///
/// - one expression nests at most 256 levels (parentheses, unary minus
///   signs, `^` chains, calls, `sum` and `if` bodies): the parser is
///   recursive and rustc runs it on an 8 MiB stack; sums and products of
///   any length are flat lists and add no level;
/// - a `let` built on earlier `let`s is at most 1000 operations deep (the
///   longest chain down to q, p or a parameter); the expansion of such a
///   chain, with its derivatives, takes about a second;
/// - integer and real exponents satisfy |n| ≤ 1024, also after merging
///   (`x^a * x^b = x^(a+b)`): beyond, x^n over- or underflows `f64` for every
///   |x| outside [0.5, 2];
/// - ranges of families and sums have at most 10⁵ members (a particle
///   template's sums 1024), and the sums of one declaration expand to at
///   most 10⁶ terms in all, nested sums multiplying their lengths (two
///   nested sums of 10⁵ were 10¹⁰ terms, minutes and gigabytes before any
///   error); d ≤ 1024.
///
/// A `let` used many times costs one node however it is used: work and
/// memory are linear in the size of the expression DAG (40 `let`s each
/// using the one before twice expand in milliseconds, a 24-link arm written
/// with rotation recurrences in about two seconds).
///
/// # Accuracy of the generated code
///
/// Identities are decided on an expanded canonical form (products and
/// powers of sums multiplied out), but values are emitted in the form the
/// user wrote: `(q[2] - q[0])^2` is computed as a difference squared, not as
/// `q[2]^2 - 2 q[2] q[0] + q[0]^2`, which would cancel catastrophically when
/// the coordinates are large compared with their differences (a chain
/// translated by 10³ would meet its constraints 10⁶ times less accurately).
///
/// # What is generated
///
/// The struct (the user's doc and visibility, one `pub f64` field per
/// parameter, `new`, the constants `DOF` and `CONSTRAINTS`), and impls of
/// `Hamiltonian` (`dof`, `separable`, `quadratic_kinetic`, H, H_q, H_p,
/// H_zz) and `ConstrainedSystem` (`constraint_count`, `kind`,
/// `jacobian_pattern`, `constraint_name`, g, g_z, Σλ_i∇²g_i, {g_i,H}, its
/// Jacobian, N_ij = {{H,g_i},g_j}, and for holonomic constraints the
/// closed-form fibre flow p ← p − g_q(q)ᵀλ). Only structurally nonzero
/// entries are computed and written.
///
/// Parameters may be named as in the mathematics, `parameters { L, G }`:
/// the fields are `L` and `G` (with `non_snake_case` allowed on the
/// struct), and `new`'s arguments are `__L` and `__G`, so a constant `L` in
/// the caller's scope cannot turn an argument into a pattern.
///
/// # Refusals (compile errors at the user's tokens)
///
/// Unknown symbols and functions (with the nearest declared name),
/// non-differentiable functions, indices out of range, non-constant
/// exponents, `**` for a power, declarations past the limits above,
/// duplicate names, constraints that do not depend on the state, duplicate
/// or dependent constraints, pairs {g_i,g_j} that do not vanish on M
/// (coisotropy), and an identically singular N
/// (nondegeneracy, the paper's Section 5.2). More constraints than
/// coordinates (m > d, e.g. a family `link[k in 0..2000]` on `dof q[8]`) is
/// refused right after lowering, before anything is differentiated: such a
/// system can never be coisotropic with an invertible N.
///
/// (Each refusal's exact message is pinned by a trybuild case in
/// `shake-ui/tests/ui/`; the examples below only show that it is refused.)
/// A misspelt name, "did you mean `theta`?":
///
/// ```compile_fail
/// geoshake::constrained_system! {
///     pub struct Cone {
///         parameters { length, gravity }
///         coordinates theta, phi;
///         momenta p_theta, p_phi;
///         hamiltonian = (p_theta^2 + p_phi^2) / 2 - gravity * cos(thetta);
///         constraints { cone: phi - length * theta }
///     }
/// }
/// # fn main() {}
/// ```
///
/// `**` for a power, "the power operator is `^`":
///
/// ```compile_fail
/// geoshake::constrained_system! {
///     pub struct Oscillator {
///         dof q[1], p[1];
///         hamiltonian = (p[0]**2 + q[0]**2) / 2;
///     }
/// }
/// # fn main() {}
/// ```
///
/// Constraints whose bracket {a, b} = 2q₀ does not vanish on M (not
/// coisotropic, Section 3.2):
///
/// ```compile_fail
/// geoshake::constrained_system! {
///     pub struct Bad {
///         dof q[2], p[2];
///         hamiltonian = (p[0]^2 + p[1]^2) / 2;
///         constraints { a: q[0]^2 - 1, b: p[0] + q[1] }
///     }
/// }
/// # fn main() {}
/// ```
///
/// The same declarations with the mistake fixed compile (a `compile_fail`
/// example that failed for another reason would prove nothing):
///
/// ```
/// geoshake::constrained_system! {
///     pub struct Cone {
///         parameters { length, gravity }
///         coordinates theta, phi;
///         momenta p_theta, p_phi;
///         hamiltonian = (p_theta^2 + p_phi^2) / 2 - gravity * cos(theta);
///         constraints { cone: phi - length * theta }
///     }
/// }
/// geoshake::constrained_system! {
///     pub struct Oscillator {
///         dof q[1], p[1];
///         hamiltonian = (p[0]^2 + q[0]^2) / 2;
///     }
/// }
/// geoshake::constrained_system! {
///     pub struct Good {
///         dof q[2], p[2];
///         hamiltonian = (p[0]^2 + p[1]^2) / 2;
///         constraints { a: q[0]^2 - 1, b: q[1] }
///     }
/// }
/// # fn main() {}
/// ```
#[proc_macro]
pub fn constrained_system(input: TokenStream) -> TokenStream {
    expand(input.into()).into()
}

/// The whole pipeline on `proc_macro2` tokens (testable outside a compiler).
fn expand(input: TokenStream2) -> TokenStream2 {
    if parse_topology::is_particle_system(&input) {
        return topology::expand(input);
    }
    let def: parse::SystemDef = match syn::parse2(input) {
        Ok(d) => d,
        Err(e) => return e.to_compile_error(),
    };
    let errors = |es: Vec<syn::Error>| {
        let errs = es.iter().map(syn::Error::to_compile_error);
        let fallback = emit::fallback(&def);
        quote!(#(#errs)* #fallback)
    };
    let analysis = match geoshake_symbolic::analyse(&def) {
        Ok(a) => a,
        Err(es) => return errors(es),
    };
    let (sys, der) = &analysis.checked;
    let doc = system_doc(sys, der);
    let items = emit::struct_items(&def, &doc);
    let (vs, vd) = analysis.values();
    let impls = emit::impls(&def, vs, vd);
    quote!(#items #impls)
}

/// A generated doc section stating the declared system.
fn system_doc(sys: &lower::System, der: &diff::Derived) -> String {
    let cut = |s: String| {
        if s.chars().count() > 200 {
            format!("{} …", s.chars().take(200).collect::<String>())
        } else {
            s
        }
    };
    let mut doc = format!(
        "\n\n# Declared system\n\nd = {}, m = {}, constraint kind: {:?}, separable: {}.\n\n- H = `{}`",
        sys.dof,
        sys.constraints.len(),
        der.kind,
        der.separable,
        cut(sys.graph.display(sys.hamiltonian))
    );
    for c in sys.constraints.iter().take(8) {
        doc.push_str(&format!(
            "\n- {} = `{}`",
            c.name,
            cut(sys.graph.display(c.node))
        ));
    }
    if sys.constraints.len() > 8 {
        doc.push_str(&format!(
            "\n- … ({} constraints in all)",
            sys.constraints.len()
        ));
    }
    doc
}
