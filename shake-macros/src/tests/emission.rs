//! What the macro emits: the fixed-size step's size hook, products of sums
//! kept factored, parameters named as in the mathematics, and the
//! expansion's time and text (ignored tests, for reading).

use crate::lower::{lower, System};
use crate::parse::SystemDef;

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
