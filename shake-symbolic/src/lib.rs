//! The front end of `shake`'s `constrained_system!`, as a plain library.
//!
//! A declaration goes top-down through `parse` (a typed view that keeps the
//! user's spans), `lower` (the hash-consed expression graph of `symbolic`,
//! kept canonical by `simplify`), `diff` (every derivative SHAKE and RATTLE
//! need), and `check` (the paper's assumptions: coisotropy and
//! nondegeneracy, Sections 3.2 and 5.2). The proc macro (`geoshake-macros`)
//! turns the result into Rust code; a run-time path ([`declare`]) reads the
//! same grammar from a string and evaluates the same graph. Particle systems
//! (families over run-time tables) go through `parse_topology` and
//! `topology` (lowering, differentiation and the checks of each template),
//! for the macro and for [`declare_particles`] alike.
//!
//! ```
//! let src = "pub struct Pendulum {
//!     parameters { length, gravity }
//!     dof q[2], p[2];
//!     hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
//!     constraints { rod: q[0]^2 + q[1]^2 - length^2 }
//! }";
//! let sys = geoshake_symbolic::declare(src).unwrap();
//! assert_eq!((sys.dof(), sys.constraint_count()), (2, 1));
//! let typo = src.replace("gravity * q[1]", "gravty * q[1]");
//! let Err(bad) = geoshake_symbolic::declare(&typo) else { panic!("accepted") };
//! assert_eq!((bad.line, bad.column), (4, 43));
//! assert!(bad.message.contains("gravity"), "{}", bad.message);
//! ```

pub mod check;
pub mod diff;
pub mod lower;
pub mod parse;
pub mod parse_topology;
pub mod simplify;
pub mod symbolic;
pub mod tape;
pub mod topology;

mod declare;

pub use declare::{
    declare, declare_particles, DeclError, Declared, DeclaredParticles, FamilyShape,
};

use diff::Derived;
use lower::System;
use parse::SystemDef;

/// A declaration that passed every check: the graph the checks ran on and,
/// when it exists, the graph values are best computed from.
pub struct Analysis {
    /// The canonical (expanded) graph: identities, sparsity and the checks.
    pub checked: (System, Derived),
    /// The same functions in the form the user wrote (`(a - b)^2` kept as a
    /// difference squared, no cancellation), aligned entry by entry with
    /// `checked`; `None` when the two graphs do not align, and then values
    /// come from `checked`.
    pub factored: Option<(System, Derived)>,
}

impl Analysis {
    /// The graph and derivatives to evaluate: values from the factored graph
    /// (accurate), structure from the checked canonical one.
    pub fn values(&self) -> (&System, &Derived) {
        match &self.factored {
            Some((s, d)) => (s, d),
            None => (&self.checked.0, &self.checked.1),
        }
    }
}

/// Lowers, differentiates and checks a parsed declaration (not a particle
/// system): the whole front end after parsing. Errors carry the spans of
/// the user's tokens.
pub fn analyse(def: &SystemDef) -> Result<Analysis, Vec<syn::Error>> {
    let mut sys = lower::lower(def)?;
    if let Some(e) = too_many_constraints(&sys) {
        return Err(vec![e]);
    }
    let g: Vec<_> = sys.constraints.iter().map(|c| c.node).collect();
    let der = Derived::compute(&mut sys.graph, sys.dof, sys.hamiltonian, &g);
    check::check(&mut sys, &der)?;
    let factored = lower::lower_with(def, true).ok().and_then(|mut fs| {
        let g: Vec<_> = fs.constraints.iter().map(|c| c.node).collect();
        let values = Derived::compute(&mut fs.graph, fs.dof, fs.hamiltonian, &g);
        diff::aligned(&der, &sys.graph, values, &mut fs.graph).map(|d| (fs, d))
    });
    Ok(Analysis {
        checked: (sys, der),
        factored,
    })
}

/// Refuses m > d before anything is differentiated (checking such a system
/// pair by pair is O(m²) work for nothing): on M the gradients of
/// constraints whose brackets vanish span an isotropic subspace of R^{2d},
/// of dimension at most d, so with m > d either the constraints are not
/// coisotropic or g_z has rank < m, and N = ({{H,g_i},g_j}) is singular.
pub fn too_many_constraints(sys: &System) -> Option<syn::Error> {
    let (m, d) = (sys.declared, sys.dof);
    (m > d).then(|| {
        let c = &sys.constraints[d];
        syn::Error::new(
            c.span,
            format!(
                "{m} constraints on {d} coordinates: more constraints than coordinates (m > d), \
                 from `{}` on. Constraints that Poisson-commute on M have gradients spanning an \
                 isotropic subspace, of dimension at most d, so N = {{{{H,g_i}},g_j}} (m×m) can \
                 never be invertible: the system violates the paper's coisotropy or \
                 nondegeneracy assumption (Sections 3.2 and 5.2) whatever the constraints are",
                c.name
            ),
        )
    })
}
