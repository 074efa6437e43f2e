//! The check's own tests, on small crates: the resolver's tricky cases (a
//! group, a re-export chain through a glob, `super::super::x`, paths in
//! expressions and macros, modules imported by name), the placing of a
//! file, and the rules' messages.

use std::collections::{BTreeMap, BTreeSet};

use crate::imports::{analyse, Analysis};
use crate::rules::{check, cycles, layer_entry, Rules};

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
