//! Declarations read from strings at and past the limits of the grammar,
//! each on a thread with the 2 MiB stack Rust gives a spawned thread (the
//! smallest a declaration is read on): a long sum or product is declared, a
//! string nested past a limit is a `DeclError` at the line and column where
//! the limit is passed, and nothing overflows the stack (an overflow would
//! abort this test binary).

use geoshake_symbolic::parse::{MAX_BRACKET_DEPTH, MAX_NESTING};
use geoshake_symbolic::tape::Program;
use geoshake_symbolic::{declare, DeclError};

/// Runs `f` on a thread with a 2 MiB stack.
fn on_2_mib<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new()
        .stack_size(2 << 20)
        .spawn(f)
        .expect("thread")
        .join()
        .expect("the declaration panicked")
}

const Q: [f64; 2] = [1.1, -0.7];
const P: [f64; 2] = [0.3, -0.4];

/// Declares `src` on a 2 MiB stack; H and g at (Q, P), or the refusal.
fn values(src: String) -> Result<(f64, f64), DeclError> {
    on_2_mib(move || {
        let decl = declare(&src)?;
        let (s, d) = decl.analysis.values();
        let prog = Program::compile(s, d, &[]);
        let (mut h, mut g) = (f64::NAN, f64::NAN);
        prog.eval(&prog.hamiltonian, &Q, &P, &[], |_, v| h = v);
        prog.eval(&prog.constraints, &Q, &P, &[], |_, v| g = v);
        Ok((h, g))
    })
}

/// The refusal of `src`, read on a 2 MiB stack.
fn refusal(src: String) -> DeclError {
    on_2_mib(move || declare(&src).err().expect("declared"))
}

/// H = (p₀² + p₁²)/2 + v with `let v = {v};`, g = q₀² + q₁² − 1 + {g},
/// and `x` = q₀ (a leaf without the level of `q[0]`'s index).
fn system(v: &str, g: &str) -> String {
    format!(
        "struct S {{\n    dof q[2], p[2];\n    let x = q[0];\n    let v = {v};\n    \
         hamiltonian = (p[0]^2 + p[1]^2) / 2 + v;\n    \
         constraints {{ c: q[0]^2 + q[1]^2 - 1 + {g} }}\n}}\n"
    )
}

fn kinetic() -> f64 {
    (P[0] * P[0] + P[1] * P[1]) / 2.0
}

fn circle() -> f64 {
    Q[0] * Q[0] + Q[1] * Q[1] - 1.0
}

/// The (line, column) `DeclError` gives byte `at` of `src` (1-based,
/// columns in characters).
fn position(src: &str, at: usize) -> (usize, usize) {
    let before = &src[..at];
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (
        before.matches('\n').count() + 1,
        before[line_start..].chars().count() + 1,
    )
}

/// The byte offset of the `n`-th (1-based) `pat` in `src` after `from`.
fn nth(src: &str, from: &str, pat: &str, n: usize) -> usize {
    let start = src.find(from).expect("from");
    start + src[start..].match_indices(pat).nth(n - 1).expect("nth").0
}

fn assert_at(e: &DeclError, src: &str, at: usize, says: &str) {
    assert_eq!((e.line, e.column), position(src, at), "{e}");
    assert!(e.message.contains(says), "{e}");
}

/// Equal up to the round-off of summing in another order.
#[track_caller]
fn assert_close(a: f64, b: f64) {
    assert!((a - b).abs() <= 1e-13 * b.abs().max(1.0), "{a} ≠ {b}");
}

#[test]
fn a_sum_of_100000_terms_is_declared() {
    // Σ ±q[k % 2]^2, every fourth term subtracted.
    let mut coef = [0.0; 2];
    let mut v = String::from("q[0]^2");
    coef[0] += 1.0;
    for k in 1..100_000 {
        let sign = if k % 4 == 3 { -1.0 } else { 1.0 };
        v.push_str(if sign < 0.0 { " - " } else { " + " });
        v.push_str(&format!("q[{}]^2", k % 2));
        coef[k % 2] += sign;
    }
    let (h, g) = values(system(&v, "0")).unwrap();
    let want = kinetic() + coef[0] * Q[0] * Q[0] + coef[1] * Q[1] * Q[1];
    assert_close(h, want);
    assert_close(g, circle());
}

/// The terms of a chain form one sum, so like terms cancel however far
/// apart: q₀ + q₀² + … + q₀²⁰⁰ − q₀ − … − q₀²⁰⁰ is exactly 0 (summed two
/// at a time, partial sums of more than 64 terms were kept whole and
/// nothing cancelled).
#[test]
fn a_long_sum_collects_like_terms_along_its_whole_length() {
    let up: Vec<String> = (1..=200).map(|k| format!("q[0]^{k}")).collect();
    let v = format!("{} - {}", up.join(" + "), up.join(" - "));
    let (h, _) = values(system(&v, "0")).unwrap();
    assert_eq!(h, kinetic());
}

#[test]
fn a_sum_of_100000_terms_in_a_constraint_is_declared() {
    let g = vec!["q[1] - q[1]"; 50_000].join(" + ");
    let (h, gv) = values(system("0", &g)).unwrap();
    assert_close(h, kinetic());
    assert_close(gv, circle());
}

#[test]
fn a_product_of_100000_factors_is_declared() {
    // 2 · q₀ / 2 · 2 / 2 …: powers of two, so exactly q₀.
    let v = format!("2 * q[0]{}", " / 2 * 2".repeat(49_999) + " / 2");
    let (h, _) = values(system(&v, "0")).unwrap();
    assert_close(h, kinetic() + Q[0]);
}

/// q₀ · q₀ · … makes q₀^(k+1) at the k-th `*`: refused at the 1024th, where
/// the exponent passes 1024.
#[test]
fn a_long_product_past_the_exponent_limit_is_refused_at_its_operator() {
    let v = vec!["q[0]"; 100_000].join(" * ");
    let src = system(&v, "0");
    let e = refusal(src.clone());
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "*", 1024),
        "exponent too large",
    );
}

#[test]
fn a_million_nested_parentheses_are_refused_at_the_first_bracket_past_the_limit() {
    let n = 1_000_000;
    let src = system(&format!("{}q[0]{}", "(".repeat(n), ")".repeat(n)), "0");
    let e = refusal(src.clone());
    // The struct's braces are depth 1: the k-th `(` is at depth k + 1.
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "(", MAX_BRACKET_DEPTH),
        "nested too deeply",
    );
    assert!(e
        .to_string()
        .starts_with(&format!("{}:{}: ", e.line, e.column)));
}

#[test]
fn a_million_nested_parentheses_in_a_constraint_are_refused() {
    let n = 1_000_000;
    let src = system("0", &format!("{}q[0]{}", "(".repeat(n), ")".repeat(n)));
    let e = refusal(src.clone());
    // Inside `constraints { }` the first `(` is at depth 3.
    assert_at(
        &e,
        &src,
        nth(&src, "c: ", "(", MAX_BRACKET_DEPTH - 1),
        "nested too deeply",
    );
}

/// The `let`'s expression is level 1; the operand of the k-th sign is
/// level k + 1 (and the index of `q[0]` would be one more).
#[test]
fn unary_minus_nests_to_the_limit_and_is_refused_past_it() {
    let signs = |n: usize| format!("{}x", "- ".repeat(n));
    let (h, _) = values(system(&signs(MAX_NESTING - 1), "0")).unwrap();
    assert_close(h, kinetic() - Q[0]);
    let src = system(&signs(10_000), "0");
    let e = refusal(src.clone());
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "-", MAX_NESTING + 1),
        "more than 256 levels",
    );
}

#[test]
fn unary_minus_nested_in_a_constraint_is_refused_on_its_line() {
    let src = system("0", &format!("{}q[0]", "- ".repeat(10_000)));
    let e = refusal(src.clone());
    // The constraint's expression `q[0]^2 + ...` is level 1 and the operand
    // of its last `+` level 2, so the k-th sign's operand is level k + 2:
    // level 257 starts at the 256th sign.
    assert_at(
        &e,
        &src,
        nth(&src, "+ - ", "-", MAX_NESTING),
        "more than 256 levels",
    );
}

#[test]
fn calls_nest_to_the_limit_and_are_refused_past_it() {
    let calls = |n: usize| format!("{}x{}", "sin(".repeat(n), ")".repeat(n));
    let (h, _) = values(system(&calls(MAX_NESTING - 1), "0")).unwrap();
    let mut want = Q[0];
    for _ in 0..MAX_NESTING - 1 {
        want = want.sin();
    }
    assert_close(h, kinetic() + want);
    // Just past the parser's limit: the argument of the 256th call is level
    // 257, refused at its first token, the 257th `sin`.
    let src = system(&calls(MAX_NESTING + 1), "0");
    let e = refusal(src.clone());
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "sin", MAX_NESTING + 1),
        "more than 256 levels",
    );
    // Far past it: refused on the tokens, at the first bracket too deep.
    let src = system(&calls(10_000), "0");
    let e = refusal(src.clone());
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "(", MAX_BRACKET_DEPTH),
        "nested too deeply",
    );
}

/// `^` is right-associative: the exponent of the k-th `^` is level k + 1.
#[test]
fn powers_nest_to_the_limit_and_are_refused_past_it() {
    let chain = |n: usize| format!("x{}", "^1".repeat(n));
    let (h, _) = values(system(&chain(MAX_NESTING - 1), "0")).unwrap();
    assert_close(h, kinetic() + Q[0]);
    let src = system(&chain(10_000), "0");
    let e = refusal(src.clone());
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "^", MAX_NESTING) + 1,
        "more than 256 levels",
    );
}

/// Nested `if`s and `sum`s are the forms whose recursion takes the most
/// stack per level: at the limit they still fit in 2 MiB.
#[test]
fn nested_ifs_and_sums_at_the_limit_fit_in_2_mib() {
    let n = MAX_NESTING - 1;
    let ifs = format!("{}x{}", "if 1 < 2 { ".repeat(n), " } else { x }".repeat(n));
    assert_close(values(system(&ifs, "0")).unwrap().0, kinetic() + Q[0]);
    let sums: String = (0..n).map(|k| format!("sum i{k} in 0..1 {{ ")).collect();
    let sums = format!("{sums}x{}", " }".repeat(n));
    assert_close(values(system(&sums, "0")).unwrap().0, kinetic() + Q[0]);
    let src = system(&format!("if 1 < 2 {{ {} }} else {{ q[1] }}", sums), "0");
    let e = refusal(src.clone());
    // The `if` is level 1 and its branch level 2, so the k-th sum is level
    // k + 1, its bounds and body k + 2: refused at the lower bound of the
    // 255th.
    assert_at(
        &e,
        &src,
        nth(&src, "let v", "in 0", n) + 3,
        "more than 256 levels",
    );
}

#[test]
fn a_condition_of_100000_comparisons_is_declared() {
    let all = vec!["1 < 2"; 100_000].join(" && ");
    let any = vec!["1 > 2"; 100_000].join(" || ");
    let v = format!("q[if {all} {{ 1 }} else {{ 0 }}] + q[if {any} {{ 1 }} else {{ 0 }}]");
    let (h, _) = values(system(&v, "0")).unwrap();
    assert_close(h, kinetic() + Q[1] + Q[0]);
}

/// Chains apply their operators left to right, and `&&` binds tighter
/// than `||`: each index below is 1, and 0 or out of range otherwise.
#[test]
fn chains_keep_left_associativity_and_precedence() {
    for index in [
        "7 - 4 - 2",
        "8 / 4 / 2",
        "2 * 3 % 4 - 1",
        "1 + 2 * 3 - 6",
        "2 ^ 3 ^ 0 - 1",
        "if 1 > 2 && 1 < 2 || 2 > 1 { 1 } else { 0 }",
        "if 2 > 1 || 1 > 2 && 1 > 2 { 1 } else { 0 }",
    ] {
        let (h, _) =
            values(system(&format!("q[{index}]"), "0")).unwrap_or_else(|e| panic!("{index}: {e}"));
        assert_close(h, kinetic() + Q[1]);
    }
    let (h, _) = values(system("2 / 4 / 8 * q[0] - q[1] - q[1]", "0")).unwrap();
    assert_close(h, kinetic() + Q[0] / 16.0 - 2.0 * Q[1]);
}

/// An error inside a chain is at its operator, as it was when chains were
/// trees.
#[test]
fn an_error_in_a_chain_is_at_its_operator() {
    let src = system("q[3 - 1 / 0]", "0");
    let e = refusal(src.clone());
    assert_at(&e, &src, nth(&src, "let v", "/", 1), "division by zero");
    let src = system("q[0] + q[1] * q[0] % 2", "0");
    let e = refusal(src.clone());
    assert_at(&e, &src, nth(&src, "let v", "%", 1), "`%` is only allowed");
}
