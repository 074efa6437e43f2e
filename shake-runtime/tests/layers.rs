//! The layering check of docs/engine.md, section 5.
//!
//! Every file of `shake-runtime/src` sits in one layer (section 2: L0 linear
//! algebra and plain data, up to L7 the facades). A file may import only from
//! its own layer or below, and inside a layer the modules (at the granularity
//! of the `LAYERS` keys) form no cycle. Today's exceptions are listed in
//! `ALLOW` and `ALLOW_CYCLES`; the steps of section 4.5 delete them, and the
//! test fails on an entry that no longer occurs, so the lists only shrink.
//!
//! Imports are read with `syn`, as the compiler sees them: every `use` tree
//! (groups, nested groups, renames, globs), every path in code that starts
//! with `crate::`, `super::` or `self::` (in signatures, types, expressions,
//! patterns and macro arguments), and every path in code that starts with a
//! child module or a module imported by name (`use super::graph::{self}`,
//! then `graph::f`). Each is resolved to the file that *defines* the item:
//! down the child modules, then through `use` re-exports (lib.rs's too, and
//! globs) to the definition. Items under `#[cfg(test)]`, files named
//! `tests.rs`, `mod x;` declarations, visibilities (`pub(super)`) and doc
//! comments are not imports.
//!
//! `cargo test --release -p geoshake-runtime --test layers -- --nocapture`
//! prints the files, the edges and the violations by layer pair.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::Path;

use proc_macro2::{Span, TokenStream, TokenTree};
use syn::visit::Visit;

/// Module path (a file's path under src/ without `.rs` and `/mod`) → layer.
/// The longest entry that is a prefix in whole segments wins
/// (`particles/stencil` does not match `particles/stencils`).
#[rustfmt::skip]
const LAYERS: &[(&str, u8)] = &[
    ("linalg", 0), ("solver", 0), ("state", 0), ("error", 0), ("report", 0), ("tolerance", 0),
    ("compensated", 0), ("composition", 0), ("diagnostics", 0), ("particles/cluster/dense", 0),
    ("particles/error", 0), ("particles/state", 0),
    ("system", 1), ("unconstrained", 1), ("examples", 1), ("particles/table", 1),
    ("particles/stencil", 1), ("particles/stencils", 1), ("particles/system", 1),
    ("particles/forces", 1),
    ("particles/graph", 1), ("particles/plan", 1),
    ("newton", 2), ("base_map", 2), ("fibre", 2),
    ("shake", 3), ("shake/workspace", 3), ("rattle", 3), ("particles/cluster", 3),
    ("particles/global", 3),
    ("guard", 4), ("particles/options", 4), ("particles/thermostat", 4),
    ("step", 5), ("particles/rattle", 5), ("particles/langevin", 5),
    ("particles/virial", 5), ("particles/adjust", 5),
    ("run", 6), ("trajectory", 6), ("particles/run", 6),
    ("integrator", 7), ("initial_data", 7), ("keep_positions", 7), ("validate", 7),
    ("particles", 7), ("particles/generate", 7), ("particles/io", 7), ("ensemble", 7), ("ensemble_store", 7),
    ("ensemble_mpi", 7), ("io", 7), ("io_arrow", 7), ("progress", 7), ("sampler", 7),
    ("lib", 7),
];

/// Today's upward imports, (importing file, defining file) under src/, with
/// the lines they were found at (`SHAKE_LAYERS_EDGES=1` and
/// `--nocapture` print today's). Each step of docs/engine.md 4.5 deletes its
/// entries; an entry that no longer occurs fails the test.
const ALLOW: &[(&str, &str)] = &[];

/// Today's module cycles inside a layer (sorted LAYERS keys): none since
/// step 5 of docs/engine.md 4.5; the list stays so that a cycle is a
/// visible, reviewed exception.
const ALLOW_CYCLES: &[&[&str]] = &[];

/// Re-export chains longer than this are taken as a loop (the item is then
/// attributed to the deepest module reached).
const DEPTH: usize = 16;

// ---------------------------------------------------------------------------
// The crate's modules

/// One `use` leaf: `use a::b::{c as d, e::*}` has two.
#[derive(Clone, Debug)]
struct UseLeaf {
    /// As written (relative to the module holding the `use`).
    path: Vec<String>,
    /// The name it binds (`None` for a glob or `as _`).
    name: Option<String>,
    glob: bool,
    line: usize,
}

#[derive(Debug, Default)]
struct Module {
    /// The file under src/ that holds the module.
    file: String,
    /// Child modules declared here (`mod x;` or `mod x { … }`), not under
    /// `#[cfg(test)]`.
    children: BTreeSet<String>,
    /// Items defined here (fn, struct, enum, trait, const, macro, …).
    defs: BTreeSet<String>,
    /// The module-level `use`s (public or not: a child may import through a
    /// private `use` of its parent, and the compiler has checked that what
    /// is written is visible).
    uses: Vec<UseLeaf>,
}

/// What a path names.
#[derive(Clone, Debug, PartialEq)]
enum Res {
    /// A module (its key: `a::b`, `""` for the crate root).
    Module(String),
    /// An item defined in (or, unresolved, last reached in) this module.
    Item(String),
    /// Outside the crate (std, nalgebra, …).
    External,
}

#[derive(Default)]
struct Crate {
    modules: BTreeMap<String, Module>,
    /// Per module, the names its `use`s bind to modules.
    scope_modules: BTreeMap<String, BTreeSet<String>>,
}

fn join(m: &str, name: &str) -> String {
    if m.is_empty() {
        name.to_string()
    } else {
        format!("{m}::{name}")
    }
}

fn parent(m: &str) -> Option<&str> {
    if m.is_empty() {
        None
    } else {
        Some(m.rsplit_once("::").map_or("", |(p, _)| p))
    }
}

fn line_of(span: Span) -> usize {
    span.start().line
}

fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && matches!(&a.meta, syn::Meta::List(l) if l.tokens.to_string().trim() == "test")
    })
}

/// The leaves of a `use` tree, paths as written.
fn flatten(tree: &syn::UseTree, prefix: &mut Vec<String>, out: &mut Vec<UseLeaf>) {
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

fn use_leaves(u: &syn::ItemUse) -> Vec<UseLeaf> {
    let mut out = Vec::new();
    if u.leading_colon.is_none() {
        flatten(&u.tree, &mut Vec::new(), &mut out);
    }
    out
}

fn item_name(item: &syn::Item) -> Option<String> {
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
    fn index(
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
    fn resolve(&self, cur: &str, segs: &[String]) -> Res {
        self.resolve_in(cur, segs, &mut Vec::new()).0
    }

    /// `stack` holds the (module, name) lookups under way: a re-export or
    /// glob loop ends there, as does a chain longer than `DEPTH`.
    fn resolve_in(
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
    fn walk(&self, m: &str, rest: &[String], stack: &mut Vec<(String, String)>) -> (Res, bool) {
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
    fn through_uses(
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

    fn file_of(&self, r: &Res) -> Option<&str> {
        match r {
            Res::Module(m) | Res::Item(m) => self.modules.get(m).map(|x| x.file.as_str()),
            Res::External => None,
        }
    }

    /// Fills `scope_modules`: the names a module's `use`s bind to modules.
    fn find_scope_modules(&mut self) {
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
    fn module_name_in_scope(&self, cur: &str, name: &str) -> bool {
        self.modules
            .get(cur)
            .is_some_and(|m| m.children.contains(name))
            || self
                .scope_modules
                .get(cur)
                .is_some_and(|s| s.contains(name))
    }
}

fn item_attrs(item: &syn::Item) -> &[syn::Attribute] {
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

// ---------------------------------------------------------------------------
// The imports of a file

/// One import as written: the module it is written in, the path, the line.
struct Written {
    module: String,
    path: Vec<String>,
    line: usize,
}

struct Collector<'a> {
    krate: &'a Crate,
    module: String,
    out: Vec<Written>,
}

impl Collector<'_> {
    fn push(&mut self, path: Vec<String>, line: usize) {
        self.out.push(Written {
            module: self.module.clone(),
            path,
            line,
        });
    }

    /// Whether a path in code is an import: `crate::…`, `super::…`,
    /// `self::…`, or through a module in scope (`child::f`, `graph::f`).
    fn is_import(&self, path: &[String]) -> bool {
        path.len() >= 2
            && match path[0].as_str() {
                "crate" | "$crate" | "super" | "self" => true,
                name => self.krate.module_name_in_scope(&self.module, name),
            }
    }

    /// Paths inside a macro's tokens (`assert!(crate::a::f())`,
    /// `$crate::x` in a `macro_rules!`): syn leaves them unparsed.
    fn scan_tokens(&mut self, tokens: TokenStream) {
        let trees: Vec<TokenTree> = tokens.into_iter().collect();
        let mut i = 0;
        while i < trees.len() {
            let prev = i.checked_sub(1).map(|j| &trees[j]);
            match &trees[i] {
                TokenTree::Group(g) => self.scan_tokens(g.stream()),
                // The start of a path (not `a::b` in the middle of one).
                TokenTree::Ident(id) if !is_punct(prev, ':') => {
                    let dollar = is_punct(prev, '$');
                    let first = if dollar && id == "crate" {
                        "$crate".to_string()
                    } else {
                        id.to_string()
                    };
                    let mut path = vec![first];
                    let mut k = i + 1;
                    while is_punct(trees.get(k), ':') && is_punct(trees.get(k + 1), ':') {
                        match trees.get(k + 2) {
                            Some(TokenTree::Ident(next)) => {
                                path.push(next.to_string());
                                k += 3;
                            }
                            _ => break,
                        }
                    }
                    if self.is_import(&path) {
                        self.push(path, line_of(id.span()));
                        i = k;
                        continue;
                    }
                }
                _ => {}
            }
            i += 1;
        }
    }
}

fn is_punct(t: Option<&TokenTree>, c: char) -> bool {
    matches!(t, Some(TokenTree::Punct(p)) if p.as_char() == c)
}

impl<'ast> Visit<'ast> for Collector<'_> {
    fn visit_item(&mut self, item: &'ast syn::Item) {
        if is_cfg_test(item_attrs(item)) {
            return;
        }
        match item {
            syn::Item::Mod(m) => {
                // `mod x;` declares, it does not import.
                if let Some((_, items)) = &m.content {
                    let inner = join(&self.module, &m.ident.to_string());
                    let outer = std::mem::replace(&mut self.module, inner);
                    for i in items {
                        self.visit_item(i);
                    }
                    self.module = outer;
                }
            }
            syn::Item::Use(u) => {
                for leaf in use_leaves(u) {
                    self.push(leaf.path, leaf.line);
                }
            }
            _ => syn::visit::visit_item(self, item),
        }
    }

    fn visit_impl_item(&mut self, item: &'ast syn::ImplItem) {
        let attrs = match item {
            syn::ImplItem::Const(i) => &i.attrs,
            syn::ImplItem::Fn(i) => &i.attrs,
            syn::ImplItem::Type(i) => &i.attrs,
            syn::ImplItem::Macro(i) => &i.attrs,
            _ => return syn::visit::visit_impl_item(self, item),
        };
        if !is_cfg_test(attrs) {
            syn::visit::visit_impl_item(self, item);
        }
    }

    fn visit_path(&mut self, path: &'ast syn::Path) {
        if path.leading_colon.is_none() {
            let segs: Vec<String> = path.segments.iter().map(|s| s.ident.to_string()).collect();
            if self.is_import(&segs) {
                let line = line_of(path.segments[0].ident.span());
                self.push(segs, line);
            }
        }
        syn::visit::visit_path(self, path);
    }

    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        self.scan_tokens(mac.tokens.clone());
        syn::visit::visit_macro(self, mac);
    }

    // `pub(super)`, `pub(in crate::a)`: who may see, not what is used.
    fn visit_visibility(&mut self, _: &'ast syn::Visibility) {}
    // Doc comments and other attributes.
    fn visit_attribute(&mut self, _: &'ast syn::Attribute) {}
}

// ---------------------------------------------------------------------------
// The graph and the rules

/// A file's module path: its path under src/ without `.rs` and `/mod`.
fn module_path(file: &str) -> String {
    let p = file.strip_suffix(".rs").unwrap_or(file);
    p.strip_suffix("/mod").unwrap_or(p).to_string()
}

/// The module key of a file's module path under src/ (`a::b`, `""` for lib.rs).
fn module_key(file: &str) -> String {
    let p = module_path(file);
    if p == "lib" {
        String::new()
    } else {
        p.replace('/', "::")
    }
}

/// The `LAYERS` entry of a file: the longest prefix in whole segments.
fn layer_entry<'l>(layers: &[(&'l str, u8)], file: &str) -> Option<(&'l str, u8)> {
    let p = module_path(file);
    layers
        .iter()
        .filter(|(k, _)| p == *k || p.starts_with(&format!("{k}/")))
        .max_by_key(|(k, _)| k.len())
        .copied()
}

struct Analysis {
    files: Vec<String>,
    /// (importing file, defining file) → lines, self-imports left out.
    edges: BTreeMap<(String, String), BTreeSet<usize>>,
    /// Files whose module is declared under `#[cfg(test)]`.
    test_files: Vec<String>,
    imports: usize,
    external: usize,
    /// Imports whose item was not found, attributed to the deepest module
    /// reached: (file, line, path).
    unresolved: Vec<(String, usize, String)>,
}

/// Parses the files (paths under src/, sources) and resolves every import.
fn analyse(sources: &[(String, String)]) -> Result<Analysis, String> {
    let mut krate = Crate::default();
    let mut parsed = Vec::new();
    let mut test_mods = BTreeSet::new();
    for (file, src) in sources {
        if file == "tests.rs" || file.ends_with("/tests.rs") {
            continue;
        }
        let ast = syn::parse_file(src).map_err(|e| {
            let at = e.span().start();
            format!(
                "shake-runtime/src/{file}:{}:{}: does not parse: {e}",
                at.line,
                at.column + 1
            )
        })?;
        parsed.push((file.clone(), ast));
    }
    for (file, ast) in &parsed {
        krate.index(&module_key(file), file, &ast.items, &mut test_mods);
    }
    krate.find_scope_modules();
    let mut a = Analysis {
        files: Vec::new(),
        edges: BTreeMap::new(),
        test_files: Vec::new(),
        imports: 0,
        external: 0,
        unresolved: Vec::new(),
    };
    for (file, ast) in &parsed {
        let key = module_key(file);
        if test_mods
            .iter()
            .any(|t| key == *t || key.starts_with(&format!("{t}::")))
        {
            a.test_files.push(file.clone());
            continue;
        }
        a.files.push(file.clone());
        let mut c = Collector {
            krate: &krate,
            module: key,
            out: Vec::new(),
        };
        for item in &ast.items {
            c.visit_item(item);
        }
        for w in c.out {
            a.imports += 1;
            let (r, found) = krate.resolve_in(&w.module, &w.path, &mut Vec::new());
            if !found {
                a.unresolved.push((file.clone(), w.line, w.path.join("::")));
            }
            match krate.file_of(&r) {
                Some(target) if target != file => {
                    a.edges
                        .entry((file.clone(), target.to_string()))
                        .or_default()
                        .insert(w.line);
                }
                Some(_) => {}
                None => a.external += 1,
            }
        }
    }
    Ok(a)
}

fn lines(ls: &BTreeSet<usize>) -> String {
    ls.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Strongly connected components with more than one node (Tarjan).
fn cycles(
    nodes: &BTreeSet<String>,
    edges: &BTreeMap<String, BTreeSet<String>>,
) -> Vec<Vec<String>> {
    struct T<'a> {
        edges: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn connect<'a>(t: &mut T<'a>, v: &'a str) {
        let i = t.index.len();
        t.index.insert(v, i);
        t.low.insert(v, i);
        t.stack.push(v);
        t.on.insert(v);
        if let Some(ws) = t.edges.get(v) {
            for w in ws {
                if !t.index.contains_key(w.as_str()) {
                    connect(t, w);
                    let lw = t.low[w.as_str()];
                    let lv = t.low.get_mut(v).unwrap();
                    *lv = (*lv).min(lw);
                } else if t.on.contains(w.as_str()) {
                    let iw = t.index[w.as_str()];
                    let lv = t.low.get_mut(v).unwrap();
                    *lv = (*lv).min(iw);
                }
            }
        }
        if t.low[v] == t.index[v] {
            let mut scc = Vec::new();
            loop {
                let w = t.stack.pop().unwrap();
                t.on.remove(w);
                scc.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if scc.len() > 1 {
                scc.sort();
                t.out.push(scc);
            }
        }
    }
    let mut t = T {
        edges,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in nodes {
        if !t.index.contains_key(v.as_str()) {
            connect(&mut t, v);
        }
    }
    t.out.sort();
    t.out
}

struct Rules<'r> {
    layers: &'r [(&'r str, u8)],
    allow: &'r [(&'r str, &'r str)],
    allow_cycles: &'r [&'r [&'r str]],
}

/// The failures, and a summary of the graph.
fn check(a: &Analysis, rules: &Rules) -> (Vec<String>, String) {
    let src = "shake-runtime/src";
    let mut fail = Vec::new();
    let mut summary = String::new();
    let mut entry = BTreeMap::new();
    for f in &a.files {
        match layer_entry(rules.layers, f) {
            Some(e) => {
                entry.insert(f.as_str(), e);
            }
            None => fail.push(format!(
                "{src}/{f} is in no LAYERS entry: place it in a layer of docs/engine.md section 2 \
                 and add its module path ({}) to LAYERS in shake-runtime/tests/layers.rs",
                module_path(f)
            )),
        }
    }
    // Upward imports.
    let mut by_pair: BTreeMap<(u8, u8), (usize, usize)> = BTreeMap::new();
    let mut seen_allowed = BTreeSet::new();
    for ((from, to), ls) in &a.edges {
        let (Some(&(_, la)), Some(&(_, lb))) = (entry.get(from.as_str()), entry.get(to.as_str()))
        else {
            continue;
        };
        if lb <= la {
            continue;
        }
        let allowed = rules.allow.contains(&(from.as_str(), to.as_str()));
        let count = by_pair.entry((la, lb)).or_default();
        if allowed {
            count.1 += 1;
            seen_allowed.insert((from.as_str(), to.as_str()));
            continue;
        }
        count.0 += 1;
        let first = ls.iter().next().unwrap();
        let mut msg = format!(
            "{src}/{from}:{first} imports {to} (layer {lb}) from layer {la}: move the item down or \
             invert the dependency (docs/engine.md section 2)"
        );
        if ls.len() > 1 {
            let _ = write!(
                msg,
                " [also at lines {}]",
                lines(&ls.iter().skip(1).copied().collect())
            );
        }
        fail.push(msg);
    }
    for &(from, to) in rules.allow {
        if !seen_allowed.contains(&(from, to)) {
            fail.push(format!(
                "ALLOW entry (\"{from}\", \"{to}\") no longer occurs (no upward import from \
                 {src}/{from} to {to}): delete it from ALLOW in shake-runtime/tests/layers.rs, the \
                 list only shrinks"
            ));
        }
    }
    // Cycles inside a layer, over the LAYERS keys.
    let mut nodes = BTreeSet::new();
    let mut key_edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut witness: BTreeMap<(String, String), Vec<String>> = BTreeMap::new();
    for &(k, _) in entry.values() {
        nodes.insert(k.to_string());
    }
    for ((from, to), ls) in &a.edges {
        let (Some(&(ka, la)), Some(&(kb, lb))) = (entry.get(from.as_str()), entry.get(to.as_str()))
        else {
            continue;
        };
        if la == lb && ka != kb {
            key_edges
                .entry(ka.to_string())
                .or_default()
                .insert(kb.to_string());
            witness
                .entry((ka.to_string(), kb.to_string()))
                .or_default()
                .push(format!("{from}:{} → {to}", lines(ls)));
        }
    }
    let found = cycles(&nodes, &key_edges);
    let allowed_cycles: Vec<Vec<String>> = rules
        .allow_cycles
        .iter()
        .map(|c| {
            let mut v: Vec<String> = c.iter().map(|s| s.to_string()).collect();
            v.sort();
            v
        })
        .collect();
    for scc in &found {
        if allowed_cycles.contains(scc) {
            continue;
        }
        let layer = rules
            .layers
            .iter()
            .find(|(k, _)| *k == scc[0])
            .map_or(0, |e| e.1);
        let members: BTreeSet<&String> = scc.iter().collect();
        let mut how = Vec::new();
        for ((ka, kb), w) in &witness {
            if members.contains(ka) && members.contains(kb) {
                how.extend(w.iter().map(|s| format!("{src}/{s}")));
            }
        }
        fail.push(format!(
            "module cycle in layer {layer}: {{{}}} import each other ({}): break it by moving the \
             shared item into one of them or a lower layer (docs/engine.md section 2: inside a \
             layer the module graph is acyclic)",
            scc.join(", "),
            how.join("; ")
        ));
    }
    for c in &allowed_cycles {
        if !found.contains(c) {
            fail.push(format!(
                "ALLOW_CYCLES entry {{{}}} no longer occurs as a cycle: delete it (or replace it \
                 by what remains) in shake-runtime/tests/layers.rs, the list only shrinks",
                c.join(", ")
            ));
        }
    }
    // Summary.
    let _ = writeln!(
        summary,
        "layers: {} files ({} test-only skipped), {} imports in crate paths ({} outside the \
         crate, {} not found and given to the deepest module reached), {} file edges, {} module \
         edges inside a layer",
        a.files.len(),
        a.test_files.len(),
        a.imports,
        a.external,
        a.unresolved.len(),
        a.edges.len(),
        key_edges.values().map(BTreeSet::len).sum::<usize>()
    );
    let _ = writeln!(
        summary,
        "upward imports by layer pair (from -> to: new, allowed):"
    );
    for ((la, lb), (new, allowed)) in &by_pair {
        let _ = writeln!(summary, "  L{la} -> L{lb}: {new} new, {allowed} allowed");
    }
    let _ = writeln!(summary, "cycles inside a layer: {found:?}");
    (fail, summary)
}

// ---------------------------------------------------------------------------
// The check

fn read_src(dir: &Path, root: &Path, out: &mut Vec<(String, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            read_src(&p, root, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            let rel = p
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            out.push((rel, std::fs::read_to_string(&p).unwrap()));
        }
    }
}

#[test]
fn layers() {
    let start = std::time::Instant::now();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut sources = Vec::new();
    read_src(&root, &root, &mut sources);
    let a = analyse(&sources).unwrap_or_else(|e| panic!("{e}"));
    let rules = Rules {
        layers: LAYERS,
        allow: ALLOW,
        allow_cycles: ALLOW_CYCLES,
    };
    let (fail, summary) = check(&a, &rules);
    print!("{summary}");
    if std::env::var_os("SHAKE_LAYERS_EDGES").is_some() {
        for ((from, to), ls) in &a.edges {
            let la = layer_entry(LAYERS, from).map_or(99, |e| e.1);
            let lb = layer_entry(LAYERS, to).map_or(99, |e| e.1);
            println!("  {from} (L{la}) -> {to} (L{lb}): {}", lines(ls));
        }
        for (file, line, path) in &a.unresolved {
            println!("  unresolved: {file}:{line} {path}");
        }
    }
    println!("layers: {:.3} s", start.elapsed().as_secs_f64());
    assert!(
        fail.is_empty(),
        "the layering of docs/engine.md is broken:\n{}\n(SHAKE_LAYERS_EDGES=1 cargo test --release \
         -p geoshake-runtime --test layers -- --nocapture lists every import)",
        fail.join("\n")
    );
}

// ---------------------------------------------------------------------------
// The check's own tests, on small crates

fn crate_of(files: &[(&str, &str)]) -> Analysis {
    let sources: Vec<(String, String)> = files
        .iter()
        .map(|(f, s)| (f.to_string(), s.to_string()))
        .collect();
    analyse(&sources).unwrap()
}

fn edges_of(a: &Analysis) -> Vec<(String, String, Vec<usize>)> {
    a.edges
        .iter()
        .map(|((f, t), ls)| (f.clone(), t.clone(), ls.iter().copied().collect()))
        .collect()
}

fn e(from: &str, to: &str, ls: &[usize]) -> (String, String, Vec<usize>) {
    (from.to_string(), to.to_string(), ls.to_vec())
}

#[test]
fn a_group_resolves_each_leaf() {
    let a = crate_of(&[
        ("lib.rs", "mod a;\nmod b;\nmod x;\n"),
        ("a.rs", "pub fn f() {}\n"),
        ("b/mod.rs", "pub mod c;\n"),
        ("b/c.rs", "pub struct C;\n"),
        (
            "x.rs",
            "use crate::{a, b::c};\nuse crate::{\n    a::f,\n    b::{c::C as D},\n};\n",
        ),
    ]);
    // `mod a;` declares, it does not import: lib.rs has no edge.
    assert_eq!(
        edges_of(&a),
        vec![e("x.rs", "a.rs", &[1, 3]), e("x.rs", "b/c.rs", &[1, 4])]
    );
}

#[test]
fn a_reexport_chain_leads_to_the_definition() {
    let a = crate_of(&[
        ("lib.rs", "mod m;\nmod user;\npub use m::Thing;\n"),
        (
            "m/mod.rs",
            "mod inner;\npub(crate) use self::inner::Thing;\n",
        ),
        ("m/inner.rs", "mod deep;\npub use deep::*;\n"),
        ("m/inner/deep.rs", "pub struct Thing;\n"),
        (
            "user.rs",
            "use crate::Thing;\nfn g() -> crate::m::Thing { crate::Thing }\n",
        ),
    ]);
    let to_deep: Vec<_> = edges_of(&a)
        .into_iter()
        .filter(|x| x.0 == "user.rs")
        .collect();
    assert_eq!(to_deep, vec![e("user.rs", "m/inner/deep.rs", &[1, 2])]);
    // The re-exports themselves are imports of what they re-export.
    assert!(a
        .edges
        .contains_key(&("lib.rs".into(), "m/inner/deep.rs".into())));
}

#[test]
fn super_super_and_self_are_made_absolute() {
    let files = |c: &'static str| {
        crate_of(&[
            ("lib.rs", "mod x;\nmod a;\n"),
            ("x.rs", "pub fn f() {}\n"),
            ("a/mod.rs", "mod b;\npub(crate) fn h() {}\n"),
            ("a/b/mod.rs", "mod c;\n"),
            ("a/b/c.rs", c),
        ])
    };
    let from_c = |a: &Analysis| {
        edges_of(a)
            .into_iter()
            .filter(|x| x.0 == "a/b/c.rs")
            .collect::<Vec<_>>()
    };
    // From a::b::c, `super` is a::b, `super::super` is a, three are the root.
    let a = files(
        "use super::super::super::x::f;\n\
         fn g() {\n\
         \x20   self::k();\n\
         \x20   super::super::h();\n\
         }\n\
         fn k() {}\n",
    );
    assert_eq!(
        from_c(&a),
        vec![e("a/b/c.rs", "a/mod.rs", &[4]), e("a/b/c.rs", "x.rs", &[1])]
    );
    // a::x does not exist: the item is attributed to the deepest module
    // reached, a/mod.rs.
    let a = files("fn g() {\n    super::super::x::f()\n}\n");
    assert_eq!(from_c(&a), vec![e("a/b/c.rs", "a/mod.rs", &[2])]);
}

#[test]
fn paths_in_expressions_types_and_macros_count_tests_and_docs_do_not() {
    let a = crate_of(&[
        (
            "lib.rs",
            "mod a;\nmod b;\nmod c;\nmod d;\nmod e;\nmod user;\n#[cfg(test)]\nmod helpers;\n",
        ),
        ("a.rs", "pub fn f() -> u8 { 1 }\n"),
        ("b.rs", "pub struct B;\n"),
        ("c.rs", "pub const C: u8 = 0;\n"),
        ("d.rs", "pub fn d() {}\n"),
        ("e.rs", "pub fn e() {}\n"),
        ("helpers.rs", "use crate::e::e;\n"),
        (
            "user.rs",
            "//! See [`crate::d::d`].\n\
             pub(crate) fn g(_: crate::b::B) {\n\
             \x20   let _v = 2 + crate::a::f();\n\
             \x20   assert_eq!(crate::c::C, 0);\n\
             }\n\
             /// [`crate::d::d`]\n\
             #[cfg(test)]\n\
             mod tests {\n\
             \x20   use crate::d::d;\n\
             }\n\
             #[cfg(test)]\n\
             fn t() { crate::e::e() }\n\
             pub(in crate::e) fn v() {}\n",
        ),
    ]);
    let from_user: Vec<_> = edges_of(&a)
        .into_iter()
        .filter(|x| x.0 == "user.rs")
        .collect();
    assert_eq!(
        from_user,
        vec![
            e("user.rs", "a.rs", &[3]),
            e("user.rs", "b.rs", &[2]),
            e("user.rs", "c.rs", &[4])
        ]
    );
    assert_eq!(a.test_files, vec!["helpers.rs".to_string()]);
}

#[test]
fn children_and_modules_imported_by_name_are_followed() {
    let a = crate_of(&[
        ("lib.rs", "mod p;\n"),
        (
            "p/mod.rs",
            "mod g;\nmod h;\nmod user;\nfn f() { g::one(); }\n",
        ),
        ("p/g.rs", "pub use super::h::two;\npub fn one() {}\n"),
        ("p/h.rs", "pub fn two() {}\n"),
        (
            "p/user.rs",
            "use super::g::{self};\nfn f() {\n    g::two();\n    let graph = 1;\n}\n",
        ),
    ]);
    let from: Vec<_> = edges_of(&a)
        .into_iter()
        .filter(|x| x.0.starts_with("p/"))
        .collect();
    assert_eq!(
        from,
        vec![
            e("p/g.rs", "p/h.rs", &[1]),
            e("p/mod.rs", "p/g.rs", &[4]),
            e("p/user.rs", "p/g.rs", &[1]),
            e("p/user.rs", "p/h.rs", &[3]),
        ]
    );
}

#[test]
fn external_paths_and_self_references_are_not_edges() {
    let a = crate_of(&[
        ("lib.rs", "mod a;\npub use nalgebra;\npub use std::fmt;\n"),
        (
            "a.rs",
            "use std::fmt;\n\
             use crate::nalgebra::DMatrix;\n\
             fn f() { self::g(); let _ = crate::nalgebra::zero(); }\n\
             fn g() {}\n",
        ),
    ]);
    assert!(a.edges.is_empty(), "{:?}", a.edges);
    assert!(a.external >= 2);
}

#[test]
fn the_longest_whole_segment_prefix_places_a_file() {
    let layers = [
        ("p", 7),
        ("p/stencil", 1),
        ("p/stencils", 2),
        ("p/c", 3),
        ("p/c/dense", 0),
        ("lib", 7),
    ];
    assert_eq!(layer_entry(&layers, "p/stencil.rs"), Some(("p/stencil", 1)));
    assert_eq!(
        layer_entry(&layers, "p/stencils.rs"),
        Some(("p/stencils", 2))
    );
    assert_eq!(layer_entry(&layers, "p/c/mod.rs"), Some(("p/c", 3)));
    assert_eq!(layer_entry(&layers, "p/c/dense.rs"), Some(("p/c/dense", 0)));
    assert_eq!(layer_entry(&layers, "p/c/fixed.rs"), Some(("p/c", 3)));
    assert_eq!(layer_entry(&layers, "p/mod.rs"), Some(("p", 7)));
    assert_eq!(layer_entry(&layers, "lib.rs"), Some(("lib", 7)));
    assert_eq!(layer_entry(&layers, "pq.rs"), None);
}

/// A small crate with an upward import (low → high), a cycle inside layer
/// 1 (m ↔ n) and a file in no layer.
fn broken() -> Analysis {
    crate_of(&[
        (
            "lib.rs",
            "mod low;\nmod high;\nmod m;\nmod n;\nmod stray;\n",
        ),
        (
            "low.rs",
            "pub struct L;\nfn f() {\n    let _ = crate::high::H;\n}\n",
        ),
        ("high.rs", "pub struct H;\nuse crate::low::L;\n"),
        ("m.rs", "use crate::n::N;\npub struct M;\n"),
        ("n.rs", "use crate::m::M;\npub struct N;\n"),
        ("stray.rs", "\n"),
    ])
}

const SMALL_LAYERS: &[(&str, u8)] = &[("low", 0), ("m", 1), ("n", 1), ("high", 2), ("lib", 2)];

#[test]
fn the_rules_fail_with_actionable_messages() {
    let a = broken();
    let rules = Rules {
        layers: SMALL_LAYERS,
        allow: &[],
        allow_cycles: &[],
    };
    let (fail, summary) = check(&a, &rules);
    assert_eq!(fail.len(), 3, "{fail:#?}");
    assert!(
        fail[0].starts_with("shake-runtime/src/stray.rs is in no LAYERS entry: place it"),
        "{}",
        fail[0]
    );
    assert_eq!(
        fail[1],
        "shake-runtime/src/low.rs:3 imports high.rs (layer 2) from layer 0: move the item down or \
         invert the dependency (docs/engine.md section 2)"
    );
    assert!(
        fail[2].starts_with("module cycle in layer 1: {m, n} import each other"),
        "{}",
        fail[2]
    );
    assert!(
        fail[2].contains("shake-runtime/src/m.rs:1 → n.rs"),
        "{}",
        fail[2]
    );
    assert!(summary.contains("L0 -> L2: 1 new, 0 allowed"), "{summary}");

    // Allowed: passes; an allowance that is not used fails.
    let layers: Vec<(&str, u8)> = SMALL_LAYERS.iter().copied().chain([("stray", 0)]).collect();
    let rules = Rules {
        layers: &layers,
        allow: &[("low.rs", "high.rs")],
        allow_cycles: &[&["n", "m"]],
    };
    let (fail, _) = check(&a, &rules);
    assert!(fail.is_empty(), "{fail:#?}");
    let rules = Rules {
        layers: &layers,
        allow: &[("low.rs", "high.rs"), ("m.rs", "high.rs")],
        allow_cycles: &[&["m", "n"], &["high", "low"]],
    };
    let (fail, _) = check(&a, &rules);
    assert_eq!(fail.len(), 2, "{fail:#?}");
    assert!(
        fail[0].starts_with("ALLOW entry (\"m.rs\", \"high.rs\") no longer occurs"),
        "{}",
        fail[0]
    );
    assert!(
        fail[1].starts_with("ALLOW_CYCLES entry {high, low} no longer occurs"),
        "{}",
        fail[1]
    );
}

#[test]
fn tarjan_finds_each_component() {
    let nodes: BTreeSet<String> = ["a", "b", "c", "d", "e"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (x, y) in [
        ("a", "b"),
        ("b", "c"),
        ("c", "a"),
        ("c", "d"),
        ("d", "e"),
        ("e", "d"),
    ] {
        edges
            .entry(x.to_string())
            .or_default()
            .insert(y.to_string());
    }
    assert_eq!(
        cycles(&nodes, &edges),
        vec![vec!["a", "b", "c"], vec!["d", "e"]]
    );
}
