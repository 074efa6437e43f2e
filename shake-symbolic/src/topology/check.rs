//! The checks of a particle declaration as a whole, before any template
//! is lowered: names (duplicates, clashes with the system's), the
//! dimension, and the runtime's limit on a member's local coordinates.

use super::{err, MAX_LOCAL};
use crate::parse_topology::ParticleDef;
use proc_macro2::Span;
use std::collections::HashMap;
use syn::Error;

/// Declaration-level checks: names, limits.
pub fn check_declaration(def: &ParticleDef) -> Vec<Error> {
    let mut errors = Vec::new();
    if def.dim == 0 {
        errors.push(err(def.dim_span, "particles need at least one coordinate"));
    }
    if def.x == def.p {
        errors.push(err(
            def.p.span(),
            "positions and momenta need different names",
        ));
    }
    let mut global: HashMap<String, Span> = HashMap::new();
    for id in def.params.iter().chain([&def.x, &def.p]) {
        let name = id.to_string();
        if let Some(prev) = global.get(&name) {
            let mut e = err(id.span(), format!("duplicate name `{name}`"));
            e.combine(err(*prev, format!("`{name}` is first declared here")));
            errors.push(e);
        } else {
            global.insert(name, id.span());
        }
    }
    let mut families: HashMap<String, Span> = HashMap::new();
    let mut tables: HashMap<String, Span> = HashMap::new();
    for f in &def.families {
        for (id, seen, what) in [
            (&f.name, &mut families, "family"),
            (&f.table, &mut tables, "table"),
        ] {
            let name = id.to_string();
            if let Some(prev) = seen.get(&name) {
                let mut e = err(
                    id.span(),
                    format!(
                        "duplicate {what} name `{name}`{}",
                        if what == "table" {
                            ": every family has its own table (an argument of `system(..)`)"
                        } else {
                            ""
                        }
                    ),
                );
                e.combine(err(*prev, format!("`{name}` is first declared here")));
                errors.push(e);
            } else {
                seen.insert(name, id.span());
            }
        }
        if f.table == "masses" {
            errors.push(err(
                f.table.span(),
                "`masses` is the first argument of `system(..)`: name the table otherwise",
            ));
        }
        let mut local: HashMap<String, Span> = HashMap::new();
        for id in std::iter::once(&f.index).chain(&f.particles).chain(&f.data) {
            let name = id.to_string();
            if let Some(prev) = local.get(&name).or(global.get(&name)) {
                let mut e = err(
                    id.span(),
                    format!("`{name}` is declared twice (in the table signature or the system)"),
                );
                e.combine(err(*prev, format!("`{name}` is first declared here")));
                errors.push(e);
            } else {
                local.insert(name, id.span());
            }
        }
        // Checked: a DIM near usize::MAX must not wrap past the limit.
        let local_dim = f.particles.len().checked_mul(def.dim);
        if local_dim.is_none_or(|n| n > MAX_LOCAL) {
            let shown = local_dim.map_or("more than 2^64".to_string(), |n| n.to_string());
            errors.push(err(
                f.table.span(),
                format!(
                    "a member of `{}` touches {} particles in R^{}: {shown} local \
                     coordinates, more than the runtime's limit of {MAX_LOCAL} (ARITY·DIM)",
                    f.name,
                    f.particles.len(),
                    def.dim
                ),
            ));
        }
    }
    errors
}
