//! The rules: each file's layer (the longest `LAYERS` prefix), no import
//! from a layer above, no module cycle inside a layer (Tarjan), and the
//! allowlists that may only shrink; with the summary the check prints.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use crate::imports::{module_path, Analysis};

/// The `LAYERS` entry of a file: the longest prefix in whole segments.
pub(crate) fn layer_entry<'l>(layers: &[(&'l str, u8)], file: &str) -> Option<(&'l str, u8)> {
    let p = module_path(file);
    layers
        .iter()
        .filter(|(k, _)| p == *k || p.starts_with(&format!("{k}/")))
        .max_by_key(|(k, _)| k.len())
        .copied()
}

pub(crate) fn lines(ls: &BTreeSet<usize>) -> String {
    ls.iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Strongly connected components with more than one node (Tarjan).
pub(crate) fn cycles(
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

pub(crate) struct Rules<'r> {
    pub(crate) layers: &'r [(&'r str, u8)],
    pub(crate) allow: &'r [(&'r str, &'r str)],
    pub(crate) allow_cycles: &'r [&'r [&'r str]],
}

/// The failures, and a summary of the graph.
pub(crate) fn check(a: &Analysis, rules: &Rules) -> (Vec<String>, String) {
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
                 and add its module path ({}) to LAYERS in shake-runtime/tests/layers/main.rs",
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
                 {src}/{from} to {to}): delete it from ALLOW in shake-runtime/tests/layers/main.rs, the \
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
                 by what remains) in shake-runtime/tests/layers/main.rs, the list only shrinks",
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
