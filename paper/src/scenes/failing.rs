//! Failing nondegeneracy, Section 5.2 (claim 5 in the README's table).
//!
//! The paper's two systems on R⁴ with g = q̄: H = p²/2 + p̄ q, for which
//! N = {{H,g},g} ≡ 0 (H is linear along the fibre; the problem has index 5),
//! and H = p²/2, for which H is constant on the fibres (M^H = M, infinitely
//! many solutions). Declared with `constrained_system!`, both are refused at
//! compile time (shake-ui/tests/ui/nondegeneracy_*.rs; their messages are printed
//! below). Written by hand against the runtime's traits, they are refused at
//! run time with a typed error, and so is a system whose N is singular only
//! at some points (the exceptional fibres of the Hopf constraint, 5.4.1,
//! and a system whose N changes sign across q = 0).

use std::fmt::Display;

use geoshake::models::HopfFree;
use geoshake::{ConstrainedSystem, ImplicitMidpoint, Integrator, State, StepError, Stop};

use crate::claims::{Bound, Claims};
use crate::models as m;
use crate::plot::PlotResult;
use crate::Ctx;

pub fn run(_ctx: &Ctx, claims: &mut Claims) -> PlotResult<()> {
    compile_time_messages();
    let h = 0.1;
    // (q, q̄) = (0.3, 0), (p, p̄) = (0.2, 0.1): on M, and off M^H = {q = 0}.
    let z = State::from_slices(&[0.3, 0.0], &[0.2, 0.1]);
    refused(claims, "H = p²/2 + p̄q (index 5)", m::IndexFive, &z, h, true);
    refused(
        claims,
        "H = p²/2 (H constant on fibres)",
        m::FlatFibres,
        &z,
        h,
        true,
    );
    // The Hopf constraint with H = |p|²/2: N ∝ |q|² − |p|² vanishes on the
    // exceptional fibres |q| = |p| (5.4.1); this point is on M^H there.
    let s = 0.5f64.sqrt();
    let z = State::from_slices(&[s, 0.0], &[0.0, s]);
    refused(
        claims,
        "Hopf, H = |p|²/2, on an exceptional fibre |q| = |p|",
        HopfFree::new(1.0),
        &z,
        h,
        false,
    );
    crossing(claims)?;
    Ok(())
}

/// Prints the compile-time refusals that the trybuild tests check.
fn compile_time_messages() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../shake-ui/tests/ui");
    for case in [
        "nondegeneracy_index_five",
        "nondegeneracy_constant_on_fibres",
    ] {
        match std::fs::read_to_string(format!("{dir}/{case}.stderr")) {
            Ok(text) => {
                let first = text.lines().next().unwrap_or("");
                println!(
                    "   compile time, shake-ui/tests/ui/{case}.rs is refused with:\n     {first}"
                );
            }
            Err(_) => println!("   (shake-ui/tests/ui/{case}.stderr not found)"),
        }
    }
}

fn show(e: &impl Display) -> String {
    let s = e.to_string();
    if s.chars().count() > 110 {
        format!("{}…", s.chars().take(110).collect::<String>())
    } else {
        s
    }
}

/// Initial data and one step are refused with a typed error, never numbers.
fn refused<S: ConstrainedSystem + Clone>(
    claims: &mut Claims,
    what: &str,
    sys: S,
    z: &State,
    h: f64,
    step_too: bool,
) {
    let mut integ = Integrator::new(sys.clone(), ImplicitMidpoint, h).rattle();
    let typed = |r: Result<State, StepError>| match r {
        Ok(_) => 0.0,
        Err(e) => {
            println!("   {what}: {}", show(&e));
            1.0
        }
    };
    claims.check(
        "5",
        &format!("{what}: initial data refused at run time with a typed error"),
        "typed errors / attempts",
        typed(integ.project_to_hidden(z)),
        Bound::AtLeast(1.0),
        "N singular: Mᴴ is not a symplectic manifold here (Thm 2.3)",
    );
    if step_too {
        let mut shake = Integrator::new(sys, ImplicitMidpoint, h).shake();
        claims.check(
            "5",
            &format!("{what}: a SHAKE step refused with a typed error"),
            "typed errors / attempts",
            typed(shake.step(z)),
            Bound::AtLeast(1.0),
            "N ≡ 0: the sliding equation has no isolated solution (Thm 4.1 fails)",
        );
    }
}

/// A run that crosses a point where N changes sign stops there, with a
/// typed error and the trajectory so far.
fn crossing(claims: &mut Claims) -> PlotResult<()> {
    let h = 0.05;
    let mut integ = Integrator::new(m::SignChange, ImplicitMidpoint, h).rattle();
    // q < 0 moving right (p > 0): N = q reaches 0 at t ≈ 0.5/0.8.
    let z0 = integ.project_to_hidden(&State::from_slices(&[-0.5, 0.0], &[0.8, 0.0]))?;
    let out = integ.run(z0, Stop::Steps(100)).execute();
    let stored = out.trajectory.len();
    let stopped = match &out.error {
        Some(e) => {
            println!(
                "   N changes sign at q = 0: {} (after {stored} stored states)",
                show(e)
            );
            matches!(
                e,
                StepError::NondegeneracyLost { .. }
                    | StepError::SingularNondegeneracyMatrix { .. }
                    | StepError::SingularShakeJacobian { .. }
                    | StepError::ComponentJump { .. }
                    | StepError::NewtonNotConverged { .. }
                    | StepError::FibreJump { .. }
            )
        }
        None => false,
    };
    claims.check(
        "5",
        "N singular at a point (N = q): the run stops there with a typed error",
        "states kept before the error (0 if no error)",
        if stopped { stored as f64 } else { 0.0 },
        Bound::Within(2.0, 20.0),
        "q reaches 0 near t = 0.625 (step ~13); all earlier states kept",
    );
    Ok(())
}
