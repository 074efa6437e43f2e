//! Property tests of the whole expansion (`expand`: parse, lower,
//! differentiate, check, emit) under random input.
//!
//! Two generators: random *expressions* in the macro's grammar (with
//! deliberate mistakes mixed in: unknown names and functions, indices out
//! of range, non-constant or huge exponents, divisions by zero, empty sums)
//! placed into a system declaration, and random *token soup* built from the
//! grammar's vocabulary. Properties: the macro never panics; its output is
//! either Rust items that parse (a generated system) or contains
//! `compile_error!` (a refusal), never both missing; and a refusal of a
//! well-formed declaration carries at least one message.

use proptest::prelude::*;

/// A random expression over q[0..2], p[0..2], parameters a, b, and some
/// names that do not exist.
fn expr() -> impl Strategy<Value = String> {
    let leaf = prop_oneof![
        (0usize..3).prop_map(|i| format!("q[{i}]")),
        (0usize..3).prop_map(|i| format!("p[{i}]")),
        Just("a".to_string()),
        Just("b".to_string()),
        Just("zz".to_string()),
        (-3i64..40).prop_map(|n| n.to_string()),
        prop_oneof![
            Just("0.5"),
            Just("1e-300"),
            Just("1e300"),
            Just("0.0"),
            Just("3.25")
        ]
        .prop_map(str::to_string),
    ];
    leaf.prop_recursive(5, 40, 3, |inner| {
        prop_oneof![
            (
                inner.clone(),
                prop_oneof![Just("+"), Just("-"), Just("*"), Just("/")],
                inner.clone()
            )
                .prop_map(|(a, op, b)| format!("({a} {op} {b})")),
            (inner.clone(), -2i64..7).prop_map(|(a, n)| format!("({a})^{n}")),
            (inner.clone(), inner.clone()).prop_map(|(a, b)| format!("({a})^({b})")),
            inner.clone().prop_map(|a| format!("-{a}")),
            (
                prop_oneof![
                    Just("sqrt"),
                    Just("sin"),
                    Just("cos"),
                    Just("tan"),
                    Just("exp"),
                    Just("ln"),
                    Just("abs"),
                    Just("atan2")
                ],
                inner.clone()
            )
                .prop_map(|(f, a)| format!("{f}({a})")),
            (0i64..3, 0i64..4, inner.clone())
                .prop_map(|(lo, hi, a)| format!("sum i in {lo}..{hi} {{ {a} + q[i] }}")),
            (0i64..3, inner.clone(), inner.clone())
                .prop_map(|(k, a, b)| format!("if {k} > 1 {{ {a} }} else {{ {b} }}")),
        ]
    })
}

/// Expands `src` and checks the properties; returns whether it was refused.
fn expands_cleanly(src: &str) -> Result<bool, TestCaseError> {
    let Ok(tokens) = src.parse::<proc_macro2::TokenStream>() else {
        return Ok(true); // not even tokens: rustc would refuse it before us
    };
    let out = std::panic::catch_unwind(|| crate::expand(tokens).to_string());
    let out = match out {
        Ok(s) => s,
        Err(_) => return Err(TestCaseError::fail(format!("the macro panicked on: {src}"))),
    };
    let refused = out.contains("compile_error");
    if !refused {
        prop_assert!(
            syn::parse_str::<syn::File>(&out).is_ok(),
            "accepted but emitted unparsable code for: {src}"
        );
    }
    Ok(refused)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 192, ..ProptestConfig::default() })]

    #[test]
    fn random_expressions_never_panic(h in expr(), g1 in expr(), g2 in expr(), m in 0usize..3) {
        let cons = match m {
            0 => String::new(),
            1 => format!("constraints {{ c1: {g1} }}"),
            _ => format!("constraints {{ c1: {g1}, c2: {g2} }}"),
        };
        let src = format!(
            "pub struct Fuzz {{ parameters {{ a, b }} dof q[2], p[2]; hamiltonian = {h}; {cons} }}"
        );
        expands_cleanly(&src)?;
    }

    #[test]
    fn random_token_soup_never_panics(words in prop::collection::vec(prop_oneof![
        Just("struct"), Just("S"), Just("{"), Just("}"), Just("parameters"), Just("dof"),
        Just("q"), Just("p"), Just("["), Just("]"), Just("2"), Just("0"), Just(","),
        Just(";"), Just("hamiltonian"), Just("="), Just("constraints"), Just(":"),
        Just("+"), Just("*"), Just("^"), Just("("), Just(")"), Just("let"), Just("const"),
        Just("N"), Just("sum"), Just("in"), Just(".."), Just("if"), Just("else"),
        Just("coordinates"), Just("momenta"), Just("x"), Just("sqrt"), Just("-"),
    ], 0..40)) {
        expands_cleanly(&words.join(" "))?;
    }
}

#[test]
fn a_well_formed_system_expands_and_a_broken_one_is_refused() {
    let ok = "pub struct P { parameters { a } dof q[2], p[2]; \
              hamiltonian = (p[0]^2 + p[1]^2)/2 + a*q[1]; constraints { c: q[0]^2 + q[1]^2 - 1 } }";
    assert!(!expands_cleanly(ok).unwrap());
    let bad = "pub struct P { dof q[2], p[2]; hamiltonian = zz * q[0]; }";
    assert!(expands_cleanly(bad).unwrap());
}

#[test]
fn the_generator_reaches_both_outcomes() {
    // A fuzzer that only ever produced refusals (or only successes) would
    // test little: both must be common.
    use proptest::strategy::ValueTree;
    use proptest::test_runner::TestRunner;
    let mut runner = TestRunner::deterministic();
    let (mut accepted, mut refused) = (0, 0);
    for _ in 0..200 {
        let h = expr().new_tree(&mut runner).unwrap().current();
        let src = format!(
            "pub struct Fuzz {{ parameters {{ a, b }} dof q[2], p[2]; \
             hamiltonian = {h} + p[0]^2 + p[1]^2; constraints {{ c: q[0]^2 + q[1]^2 - 1 }} }}"
        );
        if expands_cleanly(&src).unwrap() {
            refused += 1;
        } else {
            accepted += 1;
        }
    }
    println!("accepted {accepted}, refused {refused}");
    assert!(
        accepted >= 20 && refused >= 20,
        "accepted {accepted}, refused {refused}"
    );
}
