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

//!
//! The check reads in three steps, one module each: `modules` indexes the
//! crate's modules and resolves a path to the file that defines its item,
//! `imports` collects every import of a file and resolves it into the
//! file graph, `rules` places each file in its layer and judges the
//! graph. `self_tests` runs the check on small crates.

mod imports;
mod modules;
mod rules;
mod self_tests;

use std::path::Path;

use imports::analyse;
use rules::{check, layer_entry, lines, Rules};

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
    ("particles/family", 1),
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
