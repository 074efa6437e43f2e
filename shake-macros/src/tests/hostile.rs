//! Sources of hostile declarations: each once crashed or hung the macro.
//! And how they are expanded: on a thread with rustc's stack, whole or
//! phase by phase.

use crate::lower::lower;
use crate::parse::SystemDef;

fn wrap(lets: &str, h: &str) -> String {
    format!(
        "struct S {{ dof q[2], p[2]; {lets} hamiltonian = p[0]^2 + p[1]^2 + {h}; \
         constraints {{ c: q[0]^2 + q[1]^2 - 1 }} }}"
    )
}
pub fn parens(n: usize) -> String {
    wrap("", &format!("{}q[0]{}", "(".repeat(n), ")".repeat(n)))
}
pub fn minus(n: usize) -> String {
    wrap("", &format!("{}q[0]", "- ".repeat(n)))
}
pub fn power_chain(n: usize) -> String {
    wrap("", &format!("q[0]{}", "^1".repeat(n)))
}
/// `let a_k = sin(a_{k−1})`: a graph n nodes deep.
pub fn nested_lets(n: usize) -> String {
    let mut lets = String::from("let a0 = q[0];");
    for k in 1..=n {
        lets.push_str(&format!("let a{k} = sin(a{});", k - 1));
    }
    wrap(&lets, &format!("a{n}"))
}
/// `let a_k = sin(a_{k−1}) * cos(a_{k−1})`: a DAG of n nodes, a tree of 2^n.
pub fn dag(n: usize) -> String {
    let mut lets = String::from("let a0 = q[0] + q[1];");
    for k in 1..=n {
        lets.push_str(&format!("let a{k} = sin(a{0}) + cos(a{0});", k - 1));
    }
    wrap(&lets, &format!("a{n}"))
}
/// A polynomial DAG: `let a_k = a_{k−1} * a_{k−1} + q[1]`.
pub fn poly_dag(n: usize) -> String {
    let mut lets = String::from("let a0 = q[0] + q[1];");
    for k in 1..=n {
        lets.push_str(&format!("let a{k} = a{0} * a{0} + q[1];", k - 1));
    }
    wrap(&lets, &format!("a{n}"))
}
/// A planar arm of n links with joint angles q[k] (q[0] from the
/// x axis), the absolute direction (C_k, S_k) of link k by the rotation
/// recurrence, the joints by x_k = x_{k−1} + l C_k, and the tip held
/// on the line x = ax.
pub fn arm(n: usize) -> String {
    let mut lets = String::from(
        "let c0 = cos(q[0]); let s0 = sin(q[0]); let C0 = c0; let S0 = s0; \
         let x0 = l * C0; let y0 = l * S0;",
    );
    for k in 1..n {
        let j = k - 1;
        lets.push_str(&format!(
            "let c{k} = cos(q[{k}]); let s{k} = sin(q[{k}]); \
             let C{k} = C{j} * c{k} - S{j} * s{k}; let S{k} = S{j} * c{k} + C{j} * s{k}; \
             let x{k} = x{j} + l * C{k}; let y{k} = y{j} + l * S{k};"
        ));
    }
    let ys: Vec<String> = (0..n).map(|k| format!("y{k}")).collect();
    format!(
        "struct Arm {{ parameters {{ l, gravity, ax }} dof q[{n}], p[{n}]; {lets} \
         hamiltonian = sum i in 0..{n} {{ p[i]^2 / 2 }} + gravity * ({}); \
         constraints {{ tip: x{} - ax }} }}",
        ys.join(" + "),
        n - 1
    )
}
/// The same arm with absolute angles φ_k = φ_{k−1} + θ_k.
pub fn arm_angles(n: usize) -> String {
    let mut lets = String::from("let f0 = q[0]; let x0 = l * cos(f0); let y0 = l * sin(f0);");
    for k in 1..n {
        let j = k - 1;
        lets.push_str(&format!(
            "let f{k} = f{j} + q[{k}]; let x{k} = x{j} + l * cos(f{k}); let y{k} = y{j} + l * sin(f{k});"
        ));
    }
    let ys: Vec<String> = (0..n).map(|k| format!("y{k}")).collect();
    format!(
        "struct Arm {{ parameters {{ l, gravity, ax }} dof q[{n}], p[{n}]; {lets} \
         hamiltonian = sum i in 0..{n} {{ p[i]^2 / 2 }} + gravity * ({}); \
         constraints {{ tip: x{} - ax }} }}",
        ys.join(" + "),
        n - 1
    )
}

/// Expands `src` on a thread with rustc's 8 MiB stack; (seconds, refused,
/// first 300 characters of the output).
pub(crate) fn expand_like_rustc(src: &str) -> (f64, bool, String) {
    let src = src.to_string();
    std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            let tokens: proc_macro2::TokenStream = src.parse().expect("tokens");
            let t = std::time::Instant::now();
            let out = crate::expand(tokens).to_string();
            let dt = t.elapsed().as_secs_f64();
            let refused = out.contains("compile_error");
            let head = match out.find("compile_error") {
                Some(i) => out[i..].chars().take(300).collect(),
                None => out.chars().take(120).collect(),
            };
            (dt, refused, head)
        })
        .expect("thread")
        .join()
        .expect("the expansion panicked")
}

/// Time per phase of the expansion of `src`, with the graph's size.
pub(crate) fn phases(src: &str) -> String {
    let t = std::time::Instant::now();
    let def: SystemDef = syn::parse_str(src).expect("parse");
    let t_parse = t.elapsed().as_secs_f64();
    let mut sys = match lower(&def) {
        Ok(s) => s,
        Err(e) => return format!("refused: {}", e[0]),
    };
    let t_lower = t.elapsed().as_secs_f64();
    let n_lower = sys.graph.len();
    let g: Vec<_> = sys.constraints.iter().map(|c| c.node).collect();
    let der = crate::diff::Derived::compute(&mut sys.graph, sys.dof, sys.hamiltonian, &g);
    let t_diff = t.elapsed().as_secs_f64();
    let n_diff = sys.graph.len();
    let checked = crate::check::check(&mut sys, &der).is_ok();
    let t_check = t.elapsed().as_secs_f64();
    let doc = crate::system_doc(&sys, &der);
    let t_doc = t.elapsed().as_secs_f64();
    let out = crate::emit::impls(&def, &sys, &der).to_string();
    let t_emit = t.elapsed().as_secs_f64();
    format!(
        "parse {t_parse:.3} lower {:.3} ({n_lower} nodes) diff {:.3} ({n_diff} nodes) check {:.3} ({checked}) \
         doc {:.3} ({} B) emit {:.3} ({} B)",
        t_lower - t_parse,
        t_diff - t_lower,
        t_check - t_diff,
        t_doc - t_check,
        doc.len(),
        t_emit - t_doc,
        out.len()
    )
}
