//! Unit tables for the symbolic engine: simplification and differentiation.
//!
//! Each case is lowered into one graph together with its expected result;
//! because the graph is hash-consed and canonical, "simplifies to" means
//! "is the same node".

use crate::lower::{lower, System};
use crate::parse::SystemDef;
use crate::symbolic::VarId;

/// Lowers `lhs` as H and each of `rhs` as a constraint, in one graph, over
/// the coordinates x, y, w (momenta px, py, pw) and parameters a, b.
fn system(lhs: &str, rhs: &[&str]) -> System {
    let cons: Vec<String> = rhs
        .iter()
        .enumerate()
        .map(|(i, r)| format!("c{i}: {r}"))
        .collect();
    let src = format!(
        "struct T {{ parameters {{ a, b }} coordinates x, y, w; momenta px, py, pw; \
         hamiltonian = {lhs}; constraints {{ {} }} }}",
        cons.join(", ")
    );
    let def: SystemDef = syn::parse_str(&src).unwrap_or_else(|e| panic!("{src}: {e}"));
    lower(&def).unwrap_or_else(|e| panic!("{src}: {}", e[0]))
}

#[test]
fn simplification_table() {
    let cases: &[(&str, &str)] = &[
        ("x*1+0", "x"),
        ("x*0 + y", "y"),
        ("x - x", "0"),
        ("x / x", "1"),
        ("-(-x)", "x"),
        ("2*3 + x", "x + 6"),
        ("x + x + x", "3*x"),
        ("x*x*x", "x^3"),
        ("(x^2)^3", "x^6"),
        ("x^0", "1"),
        ("x^1", "x"),
        ("2*(x + y)", "2*x + 2*y"),
        ("(x + y)^2", "x^2 + 2*x*y + y^2"),
        ("(x + y)*(x - y)", "x^2 - y^2"),
        ("(x + y)^2 - x^2 - 2*x*y - y^2", "0"),
        ("a*(x + b) - a*x", "a*b"),
        ("sqrt(x)^2", "x"),
        ("sqrt(4)", "2"),
        ("ln(exp(x))", "x"),
        ("sin(0) + cos(0)", "1"),
        ("x * y / y", "x"),
        ("(x*y)^2 / x", "x*y^2"),
        ("1/(1/x)", "x"),
        ("x - 2*x + x", "0"),
        ("sum i in 0..3 { x }", "3*x"),
        ("sum i in 0..4 { i }", "6"),
        ("if 2 > 1 { x } else { y }", "x"),
        ("x^0.5", "sqrt(x)"),
        ("2^10", "1024"),
        ("(a + b)*x", "a*x + b*x"),
    ];
    for (lhs, rhs) in cases {
        let s = system(lhs, &[rhs]);
        assert_eq!(
            s.hamiltonian,
            s.constraints[0].node,
            "{lhs} should simplify to {rhs}, got {} vs {}",
            s.graph.display(s.hamiltonian),
            s.graph.display(s.constraints[0].node)
        );
    }
}

#[test]
fn differentiation_table() {
    // (f, variable index in z = (x, y, w, px, py, pw), ∂f/∂z_v)
    let cases: &[(&str, u32, &str)] = &[
        ("x^3", 0, "3*x^2"),
        ("x*y", 0, "y"),
        ("x*y", 3, "0"),
        ("a*x^2 + b", 0, "2*a*x"),
        ("sin(x)", 0, "cos(x)"),
        ("cos(x)", 0, "-sin(x)"),
        ("tan(x)", 0, "1 + tan(x)^2"),
        ("exp(2*x)", 0, "2*exp(2*x)"),
        ("ln(x)", 0, "1/x"),
        ("sqrt(x)", 0, "0.5/sqrt(x)"),
        ("x^2.5", 0, "2.5*x^1.5"),
        ("1/x", 0, "-1/x^2"),
        ("(x + y)^2", 1, "2*x + 2*y"),
        ("sin(x*y)", 1, "x*cos(x*y)"),
        ("px^2/2 + x*py", 4, "x"),
        ("exp(x)*sin(x)", 0, "exp(x)*sin(x) + exp(x)*cos(x)"),
    ];
    for (f, v, df) in cases {
        let mut s = system(f, &[df]);
        let d = s.graph.diff(s.hamiltonian, VarId(*v));
        assert_eq!(
            d,
            s.constraints[0].node,
            "d({f})/dz{v} should be {df}, got {}",
            s.graph.display(d)
        );
    }
}

#[test]
fn brackets_follow_the_convention() {
    // {F,G} = F_q·G_p − F_p·G_q; {x, px} = 1, {px, x} = −1, {x², px²} = 4 x px.
    let cases: &[(&str, &str, &str)] = &[
        ("x", "px", "1"),
        ("px", "x", "-1"),
        ("x^2", "px^2", "4*x*px"),
        ("x*py - y*px", "x*px + y*py", "0"),
    ];
    for (f, g, b) in cases {
        let mut s = system(f, &[g, b]);
        let br = s.graph.bracket(s.hamiltonian, s.constraints[0].node, 3);
        assert_eq!(
            br,
            s.constraints[1].node,
            "{{{f}, {g}}} should be {b}, got {}",
            s.graph.display(br)
        );
    }
}

#[test]
fn degrees_and_supports() {
    let s = system("x^2*px + a*sin(b)", &["sin(x)", "x*y*w"]);
    assert_eq!(s.graph.degree(s.hamiltonian), Some(3));
    assert_eq!(s.graph.degree(s.constraints[0].node), None);
    assert_eq!(s.graph.degree(s.constraints[1].node), Some(3));
    assert_eq!(s.graph.support(s.hamiltonian), &[VarId(0), VarId(3)]);
}

#[test]
fn display_is_readable() {
    let s = system("(px^2 + py^2)/2 - a*x + 1/y", &[]);
    assert_eq!(
        s.graph.display(s.hamiltonian),
        "0.5*px^2 + 0.5*py^2 - a*x + 1/y"
    );
}

/// The macro's expansion time for chains of N links (d = 2N, m = N).
/// Run with `cargo test -p geoshake-macros --release -- --ignored --nocapture expansion_time`.
#[test]
#[ignore]
fn expansion_time() {
    for n in [8, 32, 64] {
        let src = format!(
            "pub struct Chain {{ parameters {{ mass, length, gravity }} const N = {n}; dof q[2*N], p[2*N];
             hamiltonian = sum i in 0..N {{ (p[2*i]^2 + p[2*i+1]^2) / (2*mass) + mass * gravity * q[2*i+1] }};
             constraints {{ link[k in 0..N]: if k == 0 {{ q[0]^2 + q[1]^2 - length^2 }}
                 else {{ (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 }} }} }}"
        );
        let tokens: proc_macro2::TokenStream = src.parse().expect("tokens");
        let t = std::time::Instant::now();
        let out = crate::expand(tokens);
        let dt = t.elapsed();
        println!(
            "chain of {n:2} links: expansion {:8.2} ms, {} bytes of generated code",
            dt.as_secs_f64() * 1e3,
            out.to_string().len()
        );
        assert!(!out.to_string().contains("compile_error"));
    }
}

/// The fixed-size classical step is emitted where the runtime can use it:
/// `geoshake::classical::fixed` for one constraint, `geoshake::classical::fixed_m` with d and m
/// as constants for two to eight, nothing beyond eight or when the
/// classical path does not apply (g reads p).
#[test]
fn the_fixed_size_step_is_emitted_for_one_to_eight_constraints() {
    let chain = |n: usize| {
        format!(
            "pub struct Chain {{ parameters {{ length }} const N = {n}; dof q[2*N], p[2*N];
             hamiltonian = sum i in 0..N {{ (p[2*i]^2 + p[2*i+1]^2) / 2 + q[2*i+1] }};
             constraints {{ link[k in 0..N]: if k == 0 {{ q[0]^2 + q[1]^2 - length^2 }}
                 else {{ (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 }} }} }}"
        )
    };
    let expand = |src: &str| {
        let out = crate::expand(src.parse().expect("tokens")).to_string();
        assert!(!out.contains("compile_error"), "{out}");
        out.replace(' ', "")
    };
    assert!(expand(&chain(1)).contains("v.fixed::<2usize,1usize>(self)"));
    assert!(expand(&chain(2)).contains("v.fixed::<4usize,2usize>(self)"));
    assert!(expand(&chain(8)).contains("v.fixed::<16usize,8usize>(self)"));
    let nine = expand(&chain(9));
    assert!(!nine.contains("fnwith_sizes"), "m = 9 takes the slice path");
    let hopf = expand(
        "pub struct Hopf { dof q[2], p[2]; hamiltonian = (p[0]^2 + p[1]^2) / 2;
         constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - 1 } }",
    );
    assert!(
        !hopf.contains("fnwith_sizes"),
        "g reads p: no classical step"
    );
}

/// Prints the expansion of the pendulum (for reading the generated code).
/// Run with `cargo test -p geoshake-macros -- --ignored --nocapture print_pendulum`.
#[test]
#[ignore]
fn print_pendulum() {
    let src = "pub struct Pendulum { parameters { length, gravity } dof q[2], p[2];
        let r2 = q[0]^2 + q[1]^2;
        hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
        constraints { rod: r2 - length^2 } }";
    println!("{}", crate::expand(src.parse().expect("tokens")));
}

/// Bad input is a compile error, never a panic of the macro.
#[test]
fn bad_input_never_panics() {
    let cases = [
        "",
        "struct",
        "pub struct S {}",
        "struct S { dof q[0], p[0]; hamiltonian = 1; }",
        "struct S { dof q[99999999999999999999], p[1]; hamiltonian = 1; }",
        "struct S { const N = 9223372036854775807; dof q[N+1], p[N+1]; hamiltonian = q[0]; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[2^70]; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[-1]; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[0.5]; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[0]^1e400; }",
        "struct S { dof q[1], p[1]; hamiltonian = ln(0) * q[0]; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[0]^2147483647 * q[0]^2147483647; }",
        "struct S { dof q[1], p[1]; hamiltonian = (q[0] + p[0])^100; }",
        "struct S { dof q[1], p[1]; hamiltonian = sum i in 5..0 { q[i] }; }",
        "struct S { dof q[2], p[2]; hamiltonian = p[0]^2; constraints { c[k in 0..0]: q[k] } }",
        "struct S { dof q[2], p[2]; hamiltonian = p[0]^2 + p[1]^2; constraints { c: q[if 1 == 1 { 0 } else { 9 }] } }",
        "struct S { dof q[1], p[1]; hamiltonian = sqrt(-1) + q[0]; constraints { c: q[0] - sqrt(-1) } }",
        "struct S { coordinates x; momenta; hamiltonian = x; }",
        "struct S { dof q[1], p[1]; hamiltonian = 1 / 0; }",
        "struct S { dof q[1], p[1]; hamiltonian = q[0] % 2; }",
        "struct S { dof q[1], p[1]; hamiltonian = sin(q[0], p[0]); }",
        "struct S { dof q[1], p[1]; hamiltonian = q; }",
        "struct S { dof q[1], p[1]; hamiltonian = p[0]^2; constraints { c: exp(q[0]*1000) } }",
    ];
    for src in cases {
        let tokens: proc_macro2::TokenStream = src.parse().expect("tokens");
        let out = std::panic::catch_unwind(|| crate::expand(tokens).to_string());
        assert!(out.is_ok(), "the macro panicked on: {src}");
    }
}

/// Sources of hostile declarations: each once crashed or hung the macro.
pub(crate) mod hostile {
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

/// Expansion time of the hostile declarations (BENCHMARKS.md).
/// Run with `cargo test -p geoshake-macros --release -- --ignored --nocapture
/// hostile_timings`; `HOSTILE=<part of a name>` runs only the matching cases
/// (one at a time is kinder to a machine when checking an old version that
/// exhausts memory).
#[test]
#[ignore = "a measurement, not a check"]
fn hostile_timings() {
    let which = std::env::var("HOSTILE").unwrap_or_default();
    let cases: Vec<(&str, String)> = vec![
        ("parens 1000", hostile::parens(1000)),
        ("minus 10^4", hostile::minus(10_000)),
        ("power chain 10^4", hostile::power_chain(10_000)),
        ("nested lets 2*10^4", hostile::nested_lets(20_000)),
        ("dag 20", hostile::dag(20)),
        ("dag 40", hostile::dag(40)),
        ("poly dag 40", hostile::poly_dag(40)),
        ("arm 8", hostile::arm(8)),
        ("arm 12", hostile::arm(12)),
        ("arm 24", hostile::arm(24)),
        ("arm angles 24", hostile::arm_angles(24)),
    ];
    for (name, src) in cases {
        if !which.is_empty() && !name.contains(&which) {
            continue;
        }
        let (dt, refused, head) = expand_like_rustc(&src);
        println!("{name:22} {dt:9.3} s refused={refused} {head}");
    }
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

/// Time per phase for one hostile family at size `N`:
/// `HOSTILE=arm N=24 cargo test -p geoshake-macros --release -- --ignored --nocapture hostile_phases`.
#[test]
#[ignore = "a measurement, not a check"]
fn hostile_phases() {
    let n: usize = std::env::var("N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    let src = match std::env::var("HOSTILE").unwrap_or_default().as_str() {
        "nested lets" => hostile::nested_lets(n),
        "dag" => hostile::dag(n),
        "poly dag" => hostile::poly_dag(n),
        "arm angles" => hostile::arm_angles(n),
        _ => hostile::arm(n),
    };
    let s = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || phases(&src))
        .expect("thread")
        .join()
        .expect("panicked");
    println!("{s}");
}

/// The hostile declarations are compile errors with a message, on a
/// stack the size of rustc's.
#[test]
fn hostile_depths_are_refused_with_a_message() {
    let cases = [
        (hostile::parens(1000), "nested too deeply"),
        (hostile::minus(10_000), "nested too deeply"),
        (hostile::power_chain(10_000), "nested too deeply"),
        (hostile::nested_lets(20_000), "`a1001` is nested too deeply"),
        (
            hostile::parens(0).replacen(
                "q[0]",
                &format!("{} q[0] {}", "if 1 > 2 { q[1] } else ".repeat(10_000), ""),
                1,
            ),
            "nested too deeply",
        ),
        (
            hostile::parens(0).replacen("q[0]", "q[0]^2000000000 * q[0]^2000000000", 1),
            "exponent too large",
        ),
        (
            hostile::parens(0).replacen("q[0]", "q[0]^1000 * q[0]^1000", 1),
            "|exponent| 2000",
        ),
        // One range past its limit, and 10¹⁰ terms from two within it
        // (this ran for minutes and gigabytes before the total was held).
        (
            hostile::parens(0).replacen("q[0]", "sum i in 0..2000000000 { q[0] }", 1),
            "range is too long",
        ),
        (
            hostile::parens(0).replacen(
                "q[0]",
                "sum i in 0..100000 { sum j in 0..100000 { q[0] } }",
                1,
            ),
            "more than 1000000 terms in all",
        ),
    ];
    for (src, msg) in cases {
        let (_, refused, head) = expand_like_rustc(&src);
        assert!(refused && head.contains(msg), "{msg}: {head}");
        // One error, not a cascade.
        assert_eq!(head.matches("compile_error").count(), 1, "{head}");
    }
    // Within the limits: accepted.
    for src in [
        hostile::parens(200),
        hostile::minus(200),
        hostile::nested_lets(900),
    ] {
        let (_, refused, head) = expand_like_rustc(&src);
        assert!(!refused, "{head}");
    }
}

/// A DAG of n `let`s, each using the one before twice, is a tree of 2^n:
/// the graph (with all derivatives) and the generated code must grow
/// linearly in n.
#[test]
fn shared_lets_cost_linear_work() {
    let size = |n: usize| {
        let src = hostile::dag(n);
        let def: SystemDef = syn::parse_str(&src).expect("parse");
        let mut sys = lower(&def).expect("lower");
        let g: Vec<_> = sys.constraints.iter().map(|c| c.node).collect();
        let _ = crate::diff::Derived::compute(&mut sys.graph, sys.dof, sys.hamiltonian, &g);
        let out = crate::expand(src.parse().expect("tokens")).to_string();
        assert!(!out.contains("compile_error"), "{out:.300}");
        (sys.graph.len(), out.len())
    };
    let (n20, o20) = size(20);
    let (n40, o40) = size(40);
    println!("nodes {n20} -> {n40}, code {o20} -> {o40} bytes");
    // Linear: doubling n at most doubles the sizes, up to the fixed part.
    assert!(n40 <= 2 * n20 + 64, "nodes {n20} -> {n40}");
    assert!(o40 <= 2 * o20 + 4096, "code {o20} -> {o40}");
}

/// The emitted values keep a difference squared factored, while the
/// checks see its expansion (so identities are still decided).
#[test]
fn emission_keeps_products_of_sums_factored() {
    let src = "struct C { dof q[4], p[4]; hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2; \
               constraints { link: (q[2] - q[0])^2 + (q[3] - q[1])^2 - 1 } }";
    let def: SystemDef = syn::parse_str(src).expect("parse");
    let canon = lower(&def).expect("lower");
    let fact = crate::lower::lower_with(&def, true).expect("lower");
    let shown = |s: &System| s.graph.display(s.constraints[0].node);
    assert_eq!(
        shown(&fact),
        "-1 + (q[2] - q[0])^2 + (q[3] - q[1])^2",
        "{}",
        shown(&fact)
    );
    assert!(!shown(&canon).contains('('), "{}", shown(&canon));
}

/// Friendly errors: did-you-mean, `**`.
#[test]
fn friendly_errors() {
    let base = |h: &str| {
        format!(
            "struct S {{ parameters {{ length, gravity }} coordinates x, y; momenta px, py; \
             hamiltonian = {h}; constraints {{ rod: x^2 + y^2 - length^2 }} }}"
        )
    };
    let cases = [
        (base("px^2 + gravty * y"), "did you mean `gravity`?"),
        (base("pxx^2 + gravity * y"), "did you mean `px`?"),
        (base("px^2 + Gravity * y"), "did you mean `gravity`?"),
        // Case counts, and a case-only difference is the nearest name.
        (
            "struct S { parameters { L, G } dof q[1], p[1]; hamiltonian = p[0]^2 + l * q[0]; }"
                .to_string(),
            "unknown symbol `l`: not a parameter, coordinate, momentum, `let`, `const` or bound \
             index (did you mean `L`?)",
        ),
        (base("px^2 - cso(x)"), "did you mean `cos`?"),
        (base("px**2"), "write `^` for a power"),
    ];
    for (src, msg) in cases {
        let out = crate::expand(src.parse().expect("tokens")).to_string();
        assert!(out.contains(msg), "{msg}: {out:.400}");
    }
    // Nothing near: no suggestion.
    let out = crate::expand(base("px^2 + zzzzzz").parse().expect("tokens")).to_string();
    assert!(
        out.contains("unknown symbol") && !out.contains("did you mean"),
        "{out:.300}"
    );
}

/// Parameters named as in the mathematics are accepted, in the scalar and
/// the particle form: the fields keep the names, `new`'s arguments do not
/// (an argument `L` would be a pattern if a constant `L` is in scope).
/// `tests/suite/capitalised_parameters.rs` compiles and runs such systems.
#[test]
fn capitalised_parameters_are_fields_not_arguments() {
    let cases = [
        "struct P { parameters { L, G } dof q[2], p[2]; \
         hamiltonian = (p[0]^2 + p[1]^2) / 2 + G * q[1]; constraints { rod: q[0]^2 + q[1]^2 - L^2 } }",
        "struct C { parameters { L, G } particles x[2]; \
         potential { fall[k in bobs(a)]: G * x[a][1] } \
         constraints { link[k in links(a, b)]: norm2(x[a] - x[b]) - L^2 } }",
    ];
    for src in cases {
        let out = crate::expand(src.parse().expect("tokens")).to_string();
        assert!(!out.contains("compile_error"), "{out:.400}");
        assert!(out.contains("pub L : f64"), "{out:.400}");
        assert!(out.contains("fn new (__L : f64 , __G : f64)"), "{out:.400}");
        assert!(out.contains("Self { L : __L , G : __G }"), "{out:.400}");
    }
}

/// N ≡ 0 where the degeneracy is not a polynomial identity: with
/// L = q0 p1 − q1 p0 − c and H = |p|²/2 + V(|q|²), {H, L} ≡ 0 and N ≡ 0 for
/// every V; for V = exp(−r²) + r⁶/3 the generated N is −7e-16, which a rank
/// relative to N's own entries took for full. Judged against the size of
/// the products that make up N, it is zero: refused (with `r²` through a
/// `let` and written out). A nondegenerate system of the same shape is not.
#[test]
fn an_n_at_round_off_of_its_terms_is_singular() {
    let radial = |v: &str| {
        format!(
            "struct S {{ parameters {{ c }} dof q[2], p[2]; let r2 = q[0]^2 + q[1]^2; \
             hamiltonian = (p[0]^2 + p[1]^2) / 2 + {v}; \
             constraints {{ l: q[0]*p[1] - q[1]*p[0] - c }} }}"
        )
    };
    for v in [
        "exp(-r2) + r2^3 / 3",
        "exp(-(q[0]^2 + q[1]^2)) + (q[0]^2 + q[1]^2)^3 / 3",
    ] {
        let (_, refused, head) = expand_like_rustc(&radial(v));
        assert!(
            refused && head.contains("nondegeneracy assumption fails"),
            "{v}: {head:.400}"
        );
    }
    // The same potential with a holonomic constraint: N = G A Gᵀ ≠ 0.
    let src = "struct S { parameters { l } dof q[2], p[2]; let r2 = q[0]^2 + q[1]^2; \
               hamiltonian = (p[0]^2 + p[1]^2) / 2 + exp(-r2) + q[1]; \
               constraints { rod: r2 - l^2 } }";
    let (_, refused, head) = expand_like_rustc(src);
    assert!(!refused, "{head:.400}");
}

/// A function of a constant outside its domain folds to NaN or ∞ and made
/// H NaN at every state; it is refused where it is written.
#[test]
fn a_function_of_a_constant_outside_its_domain_is_refused() {
    for (term, says) in [
        ("sqrt(-1) * q[1]", "`sqrt` of the constant -1"),
        ("ln(0) * q[1]", "`ln` of the constant 0"),
        ("ln(1 - 2) + q[1]", "`ln` of the constant -1"),
    ] {
        let src = hostile::parens(0).replacen("q[0]", term, 1);
        let (_, refused, head) = expand_like_rustc(&src);
        assert!(refused && head.contains(says), "{term}: {head:.300}");
    }
    let src = hostile::parens(0).replacen("q[0]", "sqrt(4) * q[1] + sqrt(q[0]^2 + 1)", 1);
    let (_, refused, head) = expand_like_rustc(&src);
    assert!(!refused, "{head:.300}");
}
