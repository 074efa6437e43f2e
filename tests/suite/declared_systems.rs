//! Systems declared at run time (`geoshake::declared`) against the same
//! systems declared with the macro: the same steps, the same refusals.
//!
//! The tape evaluates each node with the operations, in the order, of the
//! code the macro emits, so the two trajectories agree to round-off; they
//! are compared to a few ulps of the state (any difference in the
//! evaluation, a wrong sign or a missing term, is O(h) or O(1)).

use geoshake::declared::{DeclareError, DeclaredSystem};
use geoshake::models::{DoublePendulum, HopfGravity, Pendulum};
use geoshake::{ConstrainedSystem, ImplicitMidpoint, Integrator, State, StormerVerlet};

const PENDULUM: &str = "
/// The planar pendulum (Example 1.3).
pub struct Pendulum {
    parameters { length, gravity }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 + gravity * q[1];
    constraints { rod: q[0]^2 + q[1]^2 - length^2 }
}";

const HOPF: &str = "
pub struct HopfGravity {
    parameters { g0, g1, radius2 }
    dof q[2], p[2];
    hamiltonian = (p[0]^2 + p[1]^2) / 2 - (g0 * q[0] + g1 * q[1]);
    constraints { sphere: q[0]^2 + q[1]^2 + p[0]^2 + p[1]^2 - radius2 }
}";

/// The largest difference between two runs of `steps` steps from `z0`,
/// relative to the size of the state.
fn max_difference<A, B>(
    mut a: Integrator<A, B>,
    mut b: Integrator<DeclaredSystem, B>,
    z0: &State,
    steps: usize,
) -> f64
where
    A: ConstrainedSystem,
    B: geoshake::BaseMap + Clone,
{
    let (mut za, mut zb) = (
        a.project_to_hidden(z0).unwrap(),
        b.project_to_hidden(z0).unwrap(),
    );
    let mut worst = 0.0_f64;
    for _ in 0..steps {
        za = a.step(&za).unwrap();
        zb = b.step(&zb).unwrap();
        let dq = (&za.q - &zb.q).amax();
        let dp = (&za.p - &zb.p).amax();
        let scale = za.q.amax().max(za.p.amax()).max(1.0);
        worst = worst.max(dq.max(dp) / scale);
    }
    worst
}

#[test]
fn pendulum_from_a_string_steps_as_the_macro_one() {
    let declared = DeclaredSystem::new(PENDULUM, &[("gravity", 9.81), ("length", 1.5)]).unwrap();
    assert_eq!(declared.kind(), Pendulum::new(1.5, 9.81).kind());
    let z0 = State::from_slices(&[1.5, 0.0], &[0.0, 0.3]);
    for rattle in [false, true] {
        let mut a = Integrator::new(Pendulum::new(1.5, 9.81), ImplicitMidpoint, 0.05);
        let mut b = Integrator::new(declared.clone(), ImplicitMidpoint, 0.05);
        if rattle {
            (a, b) = (a.rattle(), b.rattle());
        }
        let diff = max_difference(a, b, &z0, 100);
        assert!(diff <= 8.0 * f64::EPSILON, "rattle {rattle}: {diff:e}");
    }
}

#[test]
fn hopf_from_a_string_steps_as_the_macro_one() {
    let (g0, g1, r2) = (0.0, -1.0, 0.98);
    let declared = DeclaredSystem::new(HOPF, &[("g0", g0), ("g1", g1), ("radius2", r2)]).unwrap();
    let compiled = HopfGravity::new(g0, g1, r2);
    assert_eq!(declared.kind(), compiled.kind());
    // On M (|q|² + |p|² = 0.98), away from the points where N vanishes.
    let z0 = State::from_slices(&[0.8, 0.2], &[0.3, 0.21f64.sqrt()]);
    let a = Integrator::new(compiled, StormerVerlet, 0.1).rattle();
    let b = Integrator::new(declared, StormerVerlet, 0.1).rattle();
    let diff = max_difference(a, b, &z0, 100);
    assert!(diff <= 8.0 * f64::EPSILON, "{diff:e}");
}

/// Two coupled rods on the classical path, where an interpreted system
/// (`ConstrainedSystem::interpreted`) forms SHAKE's kick from the G0 the
/// kernel keeps and Δq from A's diagonal, while the compiled one calls its
/// closed-form fibre flow and `grad_p` (and steps on stack arrays): one
/// RATTLE step from each state of a compiled trajectory agrees to
/// round-off. A wrong sign or a missing term in the kick would move the
/// step by O(h²|λ|), here above 1e-4.
#[test]
fn a_declared_double_pendulum_takes_the_compiled_steps() {
    let src = "struct DoublePendulum {
        parameters { l1, l2, gravity }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2 + p[2]^2 + p[3]^2) / 2 + gravity * (q[1] + q[3]);
        constraints {
            rod1: q[0]^2 + q[1]^2 - l1^2,
            rod2: (q[2] - q[0])^2 + (q[3] - q[1])^2 - l2^2,
        }
    }";
    let declared =
        DeclaredSystem::new(src, &[("l1", 1.0), ("l2", 1.0), ("gravity", 9.81)]).unwrap();
    assert!(declared.interpreted());
    let compiled = DoublePendulum::new(1.0, 1.0, 9.81);
    assert!(!compiled.interpreted());
    let h = 0.05;
    let mut a = Integrator::new(compiled, StormerVerlet, h).rattle();
    let mut b = Integrator::new(declared, StormerVerlet, h).rattle();
    let s = 0.5f64.sqrt();
    let mut z = a
        .project_to_hidden(&State::from_slices(
            &[s, -s, s + 0.6, -s - 0.8],
            &[1.0, 0.5, -0.3, 2.0],
        ))
        .unwrap();
    let mut worst = 0.0f64;
    for _ in 0..250 {
        let za = a.step(&z).unwrap();
        let zb = b.step(&z).unwrap();
        let scale = za.q.amax().max(za.p.amax());
        worst = worst.max((&za.q - &zb.q).amax().max((&za.p - &zb.p).amax()) / scale);
        z = za;
    }
    // Round-off of one step through two Newton solves with N = G Gᵀ of
    // condition ≈ 10 at these states: tens of ε.
    assert!(
        worst <= 64.0 * f64::EPSILON,
        "{:.1} ε",
        worst / f64::EPSILON
    );
}

#[test]
fn a_typo_is_refused_at_its_line_and_column() {
    let src = PENDULUM.replace("gravity * q[1]", "gravty * q[1]");
    let e = DeclaredSystem::new(&src, &[("gravity", 9.81), ("length", 1.0)]).unwrap_err();
    let DeclareError::Declaration(e) = e else {
        panic!("{e}")
    };
    // Line 6 of PENDULUM (it starts with a newline), where `gravty` starts.
    let line = src.lines().nth(5).unwrap();
    assert_eq!(e.line, 6, "{e}");
    assert_eq!(e.column, line.find("gravty").unwrap() + 1, "{e}");
    assert!(e.message.contains("`gravity`"), "{e}");
}

#[test]
fn a_syntax_error_is_refused_at_its_position() {
    let src = PENDULUM.replace("(p[0]^2 + p[1]^2) / 2", "(p[0]^2 + p[1]^2) / / 2");
    let Err(DeclareError::Declaration(e)) = DeclaredSystem::new(&src, &[]) else {
        panic!("accepted")
    };
    let line = src.lines().nth(5).unwrap();
    assert_eq!(
        (e.line, e.column),
        (6, line.find("/ 2").unwrap() + 1),
        "{e}"
    );
    // An unclosed parenthesis: the string does not even split into tokens.
    let src = PENDULUM.replace("(p[0]^2 + p[1]^2) / 2", "(p[0]^2 + p[1]^2 / 2");
    let Err(DeclareError::Declaration(e)) = DeclaredSystem::new(&src, &[]) else {
        panic!("accepted")
    };
    assert!(e.message.contains("unbalanced"), "{e}");
}

/// The refusal case (shake-ui/tests/ui/NAME.rs) read at run time is refused
/// with the first error of its expected compiler output (NAME.stderr), at
/// the same line and column.
fn refused_as_the_macro(name: &str) {
    let rs = std::fs::read_to_string(format!("shake-ui/tests/ui/{name}.rs")).unwrap();
    let stderr = std::fs::read_to_string(format!("shake-ui/tests/ui/{name}.stderr")).unwrap();
    // Everything outside the macro call blanked, lines kept, so positions
    // are the file's.
    let start = rs.find("constrained_system! {").unwrap() + "constrained_system! {".len();
    let end = rs.rfind("fn main").unwrap();
    let end = rs[..end].rfind('}').unwrap();
    let blank = |s: &str| {
        s.chars()
            .map(|c| if c == '\n' { '\n' } else { ' ' })
            .collect::<String>()
    };
    let src = format!("{}{}", blank(&rs[..start]), &rs[start..end]);
    let Err(DeclareError::Declaration(e)) = DeclaredSystem::new(&src, &[]) else {
        panic!("{name}: accepted")
    };
    let message = stderr
        .lines()
        .next()
        .unwrap()
        .strip_prefix("error: ")
        .unwrap();
    let at = stderr
        .lines()
        .nth(1)
        .unwrap()
        .trim()
        .strip_prefix("--> ")
        .unwrap();
    assert_eq!(e.message, message, "{name}");
    assert_eq!(
        format!("tests/ui/{name}.rs:{}:{}", e.line, e.column),
        at,
        "{name}"
    );
}

#[test]
fn refused_systems_are_refused_with_the_macros_message() {
    for name in [
        "not_coisotropic",
        "nondegeneracy_singular_everywhere",
        "dependent_constraints",
        "constraint_independent_of_state",
        "more_constraints_than_coordinates",
        "unknown_symbol",
        "index_out_of_range",
    ] {
        refused_as_the_macro(name);
    }
}

#[test]
fn parameters_are_checked_by_name() {
    let e = DeclaredSystem::new(PENDULUM, &[("length", 1.0)]).unwrap_err();
    assert_eq!(
        e,
        DeclareError::MissingParameter {
            name: "gravity".into()
        }
    );
    let e = DeclaredSystem::new(PENDULUM, &[("length", 1.0), ("g", 9.81)]).unwrap_err();
    assert!(
        matches!(e, DeclareError::UnknownParameter { ref name, .. } if name == "g"),
        "{e}"
    );
    let e = DeclaredSystem::new(PENDULUM, &[("length", 1.0), ("length", 2.0)]).unwrap_err();
    assert_eq!(
        e,
        DeclareError::DuplicateParameter {
            name: "length".into()
        }
    );
    // A value that is not finite would make every number of the tape NaN
    // or infinite, far from the name that caused it.
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let e = DeclaredSystem::new(PENDULUM, &[("length", 1.0), ("gravity", bad)]).unwrap_err();
        assert!(
            matches!(e, DeclareError::NonFiniteParameter { ref name, value } if name == "gravity" && value.to_bits() == bad.to_bits()),
            "{e}"
        );
    }
}
