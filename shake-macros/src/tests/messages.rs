//! What a user reads when a declaration is refused: a suggestion for a
//! misspelt name, and the checks' messages at the term at fault.

use super::hostile::{self, expand_like_rustc};

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
