//! The macro's limits: bad or hostile input is a compile error with a
//! message, never a panic, a hang or a stack overflow, and shared `let`s
//! cost linear work (with the timings of BENCHMARKS.md, ignored).

use super::hostile::{self, expand_like_rustc, phases};
use crate::lower::lower;
use crate::parse::SystemDef;

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
