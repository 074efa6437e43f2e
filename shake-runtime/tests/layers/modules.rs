//! The crate's modules: each file's child modules, definitions and `use`
//! leaves, indexed from its syntax tree, and the resolution of a path
//! written in a module to the module or item it names, down the children
//! and through `use` re-exports (globs too) to the file that defines it.

use std::collections::{BTreeMap, BTreeSet};

use proc_macro2::Span;

/// Re-export chains longer than this are taken as a loop (the item is then
/// attributed to the deepest module reached).
pub(crate) const DEPTH: usize = 16;

/// One `use` leaf: `use a::b::{c as d, e::*}` has two.
#[derive(Clone, Debug)]
pub(crate) struct UseLeaf {
    /// As written (relative to the module holding the `use`).
    pub(crate) path: Vec<String>,
    /// The name it binds (`None` for a glob or `as _`).
    pub(crate) name: Option<String>,
    pub(crate) glob: bool,
    pub(crate) line: usize,
}

#[derive(Debug, Default)]
pub(crate) struct Module {
    /// The file under src/ that holds the module.
    pub(crate) file: String,
    /// Child modules declared here (`mod x;` or `mod x { … }`), not under
    /// `#[cfg(test)]`.
    pub(crate) children: BTreeSet<String>,
    /// Items defined here (fn, struct, enum, trait, const, macro, …).
    pub(crate) defs: BTreeSet<String>,
    /// The module-level `use`s (public or not: a child may import through a
    /// private `use` of its parent, and the compiler has checked that what
    /// is written is visible).
    pub(crate) uses: Vec<UseLeaf>,
}

/// What a path names.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Res {
    /// A module (its key: `a::b`, `""` for the crate root).
    Module(String),
    /// An item defined in (or, unresolved, last reached in) this module.
    Item(String),
    /// Outside the crate (std, nalgebra, …).
    External,
}

#[derive(Default)]
pub(crate) struct Crate {
    pub(crate) modules: BTreeMap<String, Module>,
    /// Per module, the names its `use`s bind to modules.
    pub(crate) scope_modules: BTreeMap<String, BTreeSet<String>>,
}

pub(crate) fn join(m: &str, name: &str) -> String {
    if m.is_empty() {
        name.to_string()
    } else {
        format!("{m}::{name}")
    }
}

pub(crate) fn parent(m: &str) -> Option<&str> {
    if m.is_empty() {
        None
    } else {
        Some(m.rsplit_once("::").map_or("", |(p, _)| p))
    }
}

pub(crate) fn line_of(span: Span) -> usize {
    span.start().line
}

pub(crate) fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && matches!(&a.meta, syn::Meta::List(l) if l.tokens.to_string().trim() == "test")
    })
}

/// The leaves of a `use` tree, paths as written.
pub(crate) fn flatten(tree: &syn::UseTree, prefix: &mut Vec<String>, out: &mut Vec<UseLeaf>) {
    match tree {
        syn::UseTree::Path(p) => {
            prefix.push(p.ident.to_string());
            flatten(&p.tree, prefix, out);
            prefix.pop();
        }
        syn::UseTree::Name(n) => {
            let name = n.ident.to_string();
            let line = line_of(n.ident.span());
            if name == "self" {
                out.push(UseLeaf {
                    path: prefix.clone(),
                    name: prefix.last().cloned(),
                    glob: false,
                    line,
                });
            } else {
                let mut path = prefix.clone();
                path.push(name.clone());
                out.push(UseLeaf {
                    path,
                    name: Some(name),
                    glob: false,
                    line,
                });
            }
        }
        syn::UseTree::Rename(r) => {
            let mut path = prefix.clone();
            if r.ident != "self" {
                path.push(r.ident.to_string());
            }
            let rename = r.rename.to_string();
            let name = (rename != "_").then_some(rename);
            out.push(UseLeaf {
                path,
                name,
                glob: false,
                line: line_of(r.ident.span()),
            });
        }
        syn::UseTree::Glob(g) => {
            out.push(UseLeaf {
                path: prefix.clone(),
                name: None,
                glob: true,
                line: line_of(g.star_token.span),
            });
        }
        syn::UseTree::Group(g) => {
            for t in &g.items {
                flatten(t, prefix, out);
            }
        }
    }
}

pub(crate) fn use_leaves(u: &syn::ItemUse) -> Vec<UseLeaf> {
    let mut out = Vec::new();
    if u.leading_colon.is_none() {
        flatten(&u.tree, &mut Vec::new(), &mut out);
    }
    out
}

pub(crate) fn item_name(item: &syn::Item) -> Option<String> {
    use syn::Item::*;
    let ident = match item {
        Fn(i) => &i.sig.ident,
        Struct(i) => &i.ident,
        Enum(i) => &i.ident,
        Union(i) => &i.ident,
        Trait(i) => &i.ident,
        TraitAlias(i) => &i.ident,
        Type(i) => &i.ident,
        Const(i) => &i.ident,
        Static(i) => &i.ident,
        Macro(i) => i.ident.as_ref()?,
        ExternCrate(i) => i.rename.as_ref().map_or(&i.ident, |(_, r)| r),
        _ => return None,
    };
    Some(ident.to_string())
}

impl Crate {
    /// Indexes a module's items: children, definitions, `use`s. Children
    /// declared under `#[cfg(test)]` go to `test_mods` (their files are test
    /// code).
    pub(crate) fn index(
        &mut self,
        key: &str,
        file: &str,
        items: &[syn::Item],
        test_mods: &mut BTreeSet<String>,
    ) {
        self.modules.entry(key.to_string()).or_default().file = file.to_string();
        for item in items {
            let attrs = item_attrs(item);
            if let syn::Item::Mod(m) = item {
                let child = join(key, &m.ident.to_string());
                if is_cfg_test(attrs) {
                    test_mods.insert(child);
                    continue;
                }
                self.modules
                    .get_mut(key)
                    .unwrap()
                    .children
                    .insert(m.ident.to_string());
                if let Some((_, inner)) = &m.content {
                    self.index(&child, file, inner, test_mods);
                }
                continue;
            }
            if is_cfg_test(attrs) {
                continue;
            }
            let module = self.modules.get_mut(key).unwrap();
            if let syn::Item::Use(u) = item {
                module.uses.extend(use_leaves(u));
            } else if let Some(name) = item_name(item) {
                module.defs.insert(name);
            }
        }
    }

    /// Resolves a path written in module `cur` (a `use` path or a path in
    /// code).
    pub(crate) fn resolve(&self, cur: &str, segs: &[String]) -> Res {
        self.resolve_in(cur, segs, &mut Vec::new()).0
    }

    /// `stack` holds the (module, name) lookups under way: a re-export or
    /// glob loop ends there, as does a chain longer than `DEPTH`.
    pub(crate) fn resolve_in(
        &self,
        cur: &str,
        segs: &[String],
        stack: &mut Vec<(String, String)>,
    ) -> (Res, bool) {
        let Some(first) = segs.first() else {
            return (Res::Module(cur.to_string()), true);
        };
        match first.as_str() {
            "crate" | "$crate" => self.walk("", &segs[1..], stack),
            "super" | "self" => {
                let mut m = cur;
                let mut i = 0;
                while i < segs.len() && (segs[i] == "super" || segs[i] == "self") {
                    if segs[i] == "super" {
                        match parent(m) {
                            Some(p) => m = p,
                            None => return (Res::External, true),
                        }
                    }
                    i += 1;
                }
                self.walk(m, &segs[i..], stack)
            }
            name => {
                // A relative path: a child module, an item defined here, or
                // a name that another `use` of this module binds (not
                // `use nalgebra;` itself); else another crate.
                let Some(module) = self.modules.get(cur) else {
                    return (Res::External, true);
                };
                let bound = module.uses.iter().any(|u| {
                    u.name.as_deref() == Some(name)
                        && u.path.first().map(String::as_str) != Some(name)
                });
                if module.children.contains(name) || module.defs.contains(name) || bound {
                    self.walk(cur, segs, stack)
                } else {
                    (Res::External, true)
                }
            }
        }
    }

    /// Follows `rest` down from module `m`. The flag says whether the item
    /// was found (not merely attributed to the deepest module reached).
    pub(crate) fn walk(
        &self,
        m: &str,
        rest: &[String],
        stack: &mut Vec<(String, String)>,
    ) -> (Res, bool) {
        let Some(name) = rest.first() else {
            return (Res::Module(m.to_string()), true);
        };
        let Some(module) = self.modules.get(m) else {
            return (Res::Item(m.to_string()), false);
        };
        let child = join(m, name);
        if module.children.contains(name) && self.modules.contains_key(&child) {
            return self.walk(&child, &rest[1..], stack);
        }
        if module.defs.contains(name) {
            return (Res::Item(m.to_string()), true);
        }
        let key = (m.to_string(), name.clone());
        if stack.len() >= DEPTH || stack.contains(&key) {
            return (Res::Item(m.to_string()), false);
        }
        stack.push(key);
        let found = self.through_uses(m, module, rest, stack);
        stack.pop();
        found.unwrap_or((Res::Item(m.to_string()), false))
    }

    /// `rest[0]` through the `use`s of module `m`: an explicit one binding
    /// the name, else a glob that brings it.
    pub(crate) fn through_uses(
        &self,
        m: &str,
        module: &Module,
        rest: &[String],
        stack: &mut Vec<(String, String)>,
    ) -> Option<(Res, bool)> {
        let name = rest[0].as_str();
        if let Some(u) = module.uses.iter().find(|u| u.name.as_deref() == Some(name)) {
            return Some(match self.resolve_in(m, &u.path, stack) {
                (Res::Module(t), true) => self.walk(&t, &rest[1..], stack),
                found => found,
            });
        }
        for u in module.uses.iter().filter(|u| u.glob) {
            if let (Res::Module(g), true) = self.resolve_in(m, &u.path, stack)
                && g != m
            {
                let (r, found) = self.walk(&g, rest, stack);
                if found {
                    return Some((r, true));
                }
            }
        }
        None
    }

    pub(crate) fn file_of(&self, r: &Res) -> Option<&str> {
        match r {
            Res::Module(m) | Res::Item(m) => self.modules.get(m).map(|x| x.file.as_str()),
            Res::External => None,
        }
    }

    /// Fills `scope_modules`: the names a module's `use`s bind to modules.
    pub(crate) fn find_scope_modules(&mut self) {
        let mut found = BTreeMap::new();
        for (key, module) in &self.modules {
            let names: BTreeSet<String> = module
                .uses
                .iter()
                .filter(|u| matches!(self.resolve(key, &u.path), Res::Module(_)))
                .filter_map(|u| u.name.clone())
                .collect();
            found.insert(key.clone(), names);
        }
        self.scope_modules = found;
    }

    /// Whether a path in code that starts with `name` (not `crate`, `super`
    /// or `self`) goes through a module: a child module, or a module that a
    /// `use` of this module binds (`use super::graph::{self}`).
    pub(crate) fn module_name_in_scope(&self, cur: &str, name: &str) -> bool {
        self.modules
            .get(cur)
            .is_some_and(|m| m.children.contains(name))
            || self
                .scope_modules
                .get(cur)
                .is_some_and(|s| s.contains(name))
    }
}

pub(crate) fn item_attrs(item: &syn::Item) -> &[syn::Attribute] {
    use syn::Item::*;
    match item {
        Const(i) => &i.attrs,
        Enum(i) => &i.attrs,
        ExternCrate(i) => &i.attrs,
        Fn(i) => &i.attrs,
        ForeignMod(i) => &i.attrs,
        Impl(i) => &i.attrs,
        Macro(i) => &i.attrs,
        Mod(i) => &i.attrs,
        Static(i) => &i.attrs,
        Struct(i) => &i.attrs,
        Trait(i) => &i.attrs,
        TraitAlias(i) => &i.attrs,
        Type(i) => &i.attrs,
        Union(i) => &i.attrs,
        Use(i) => &i.attrs,
        _ => &[],
    }
}
