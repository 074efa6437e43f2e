//! Families over run-time tables: one template per family, lowered to a
//! small local system, differentiated once and checked, for the proc macro
//! to emit as a `geoshake::runtime::particles::Stencil` and for run-time
//! declarations to evaluate.
//!
//! A family `bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2`
//! in a system of particles in R^D is the function
//! f(x_a, x_b; length) of the ARITY·D local coordinates (particle by
//! particle: coordinate c of the i-th particle of the signature is local
//! variable i·D + c) and of the DATA numbers of a row. Nothing here depends on
//! the number of members (the rows are given at run time), so the work and
//! the size of the result do not either.
//!
//! Checks run once per template: every name is known, particles are reached
//! only through the table's particle variables, the template depends on the
//! positions only (holonomic; then {g_i, g_j} = 0 for every pair of members
//! of every family, so coisotropy holds without a check), its gradient is not
//! identically zero, and it uses every particle it declares. What only the
//! table decides (dangling or repeated indices, duplicate members, clusters
//! with more constraints than coordinates) is the runtime's job, with a
//! `TopologyError` naming the family and the member.
//!
//! ```
//! use geoshake_symbolic::parse_topology::ParticleDef;
//! let def: ParticleDef = syn::parse_str(
//!     "struct Water {
//!         particles x[3];
//!         constraints { bond[k in bonds(a, b; length)]: norm2(x[a] - x[b]) - length^2 }
//!     }",
//! )
//! .unwrap();
//! let families = geoshake_symbolic::topology::analyse(&def).unwrap();
//! // f of 2·3 local coordinates: a value and six gradient entries.
//! assert_eq!(families[0].gradient.len(), 6);
//! ```

mod check;
mod template;

pub use check::check_declaration;
pub use template::lower_family;

use crate::parse_topology::ParticleDef;
use crate::symbolic::{Graph, NodeId};
use proc_macro2::Span;
use syn::Error;

/// The runtime's `MAX_LOCAL`: the most local coordinates (ARITY·DIM) a
/// stencil may have (they live on the stack).
pub const MAX_LOCAL: usize = 64;

/// The functions a template may call.
const FUNCS: &str = "sqrt, sin, cos, tan, exp, ln (scalars); dot(u, v), norm2(u), norm(u), \
                     cross(u, v) (vectors; cross in R^3 only)";

/// One lowered template: the value and every entry of its gradient, in one
/// graph whose variables are the member's local coordinates
/// (`VarId(i·D + c)`) and whose parameters are the system's parameters
/// followed by the table's data (`ParamId`, in declaration order).
pub struct Lowered {
    /// The graph of both forms.
    pub graph: Graph,
    /// The canonical value: the checks and the documented formula.
    pub value: NodeId,
    /// The value as written: the one to evaluate (see the lowering's
    /// `Template::add` for why it is not the canonical one).
    pub written: NodeId,
    /// ∂f/∂x_l of the written form, for l in 0..ARITY·DIM (zeros included).
    pub gradient: Vec<NodeId>,
}

/// Every check of a particle declaration and the lowering of each of its
/// families, in declaration order. Declaration-level errors stop before any
/// template is lowered; then every family's first error is reported, so a
/// user sees all broken templates in one go.
pub fn analyse(def: &ParticleDef) -> Result<Vec<Lowered>, Vec<Error>> {
    let errors = check_declaration(def);
    if !errors.is_empty() {
        return Err(errors);
    }
    let mut errors = Vec::new();
    let mut lowered = Vec::new();
    for f in &def.families {
        match lower_family(def, f) {
            Ok(l) => lowered.push(l),
            Err(e) => errors.push(e),
        }
    }
    if errors.is_empty() {
        Ok(lowered)
    } else {
        Err(errors)
    }
}

fn err(span: Span, msg: impl std::fmt::Display) -> Error {
    Error::new(span, msg.to_string())
}
