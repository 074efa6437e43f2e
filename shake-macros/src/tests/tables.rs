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
