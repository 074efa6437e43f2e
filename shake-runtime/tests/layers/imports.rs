//! The imports of a file, read with `syn` as the compiler sees them (`use`
//! trees, paths in code, in macro arguments, through modules imported by
//! name), and the analysis that resolves each into an edge of the file
//! graph.

use std::collections::{BTreeMap, BTreeSet};

use proc_macro2::{TokenStream, TokenTree};
use syn::visit::Visit;

use crate::modules::{is_cfg_test, item_attrs, join, line_of, use_leaves, Crate};

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

/// A file's module path: its path under src/ without `.rs` and `/mod`.
pub(crate) fn module_path(file: &str) -> String {
    let p = file.strip_suffix(".rs").unwrap_or(file);
    p.strip_suffix("/mod").unwrap_or(p).to_string()
}

/// The module key of a file's module path under src/ (`a::b`, `""` for lib.rs).
pub(crate) fn module_key(file: &str) -> String {
    let p = module_path(file);
    if p == "lib" {
        String::new()
    } else {
        p.replace('/', "::")
    }
}

pub(crate) struct Analysis {
    pub(crate) files: Vec<String>,
    /// (importing file, defining file) → lines, self-imports left out.
    pub(crate) edges: BTreeMap<(String, String), BTreeSet<usize>>,
    /// Files whose module is declared under `#[cfg(test)]`.
    pub(crate) test_files: Vec<String>,
    pub(crate) imports: usize,
    pub(crate) external: usize,
    /// Imports whose item was not found, attributed to the deepest module
    /// reached: (file, line, path).
    pub(crate) unresolved: Vec<(String, usize, String)>,
}

/// Parses the files (paths under src/, sources) and resolves every import.
pub(crate) fn analyse(sources: &[(String, String)]) -> Result<Analysis, String> {
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
