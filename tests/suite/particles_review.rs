//! Defects found by the hostile review of the large-system path, each a
//! failing case before its fix.

use geoshake::runtime::particles::{generate, Options, ParticleState, Rattle, SolverChoice};
use geoshake::runtime::{StepError, Stop};

fn fresh_step(system_seed: u64, z: &ParticleState, solver: SolverChoice) -> ParticleState {
    let (sys, _) = generate::chain(40, system_seed).unwrap();
    let mut r = Rattle::new(
        sys,
        2.0,
        Options {
            solver,
            ..Options::default()
        },
    )
    .unwrap();
    let mut z = ParticleState::new(z.q().to_vec(), z.p().to_vec());
    r.step(&mut z).unwrap();
    z
}

/// `project` on another state overwrites N's factor and G(q0): the next
/// step of the first state must not reuse them (it did, and returned a step
/// off by 1e-4 Å with a small reported residual).
#[test]
fn projecting_another_state_does_not_corrupt_the_next_step() {
    for solver in [SolverChoice::Band, SolverChoice::Sparse] {
        let (sys, mut a) = generate::chain(40, 1).unwrap();
        let mut r = Rattle::new(
            sys,
            2.0,
            Options {
                solver,
                ..Options::default()
            },
        )
        .unwrap();
        r.project(&mut a).unwrap();
        generate::set_temperature(r.system(), &mut a, 300.0);
        r.step(&mut a).unwrap();
        let mut b = a.clone();
        for (i, x) in b.q_mut().iter_mut().enumerate() {
            *x += 1e-2 * ((i * 7919 % 13) as f64 - 6.0) / 6.0;
        }
        r.project(&mut b).unwrap();
        let expected = fresh_step(1, &a, solver);
        r.step(&mut a).unwrap();
        // Same equations from the same state to tol 1e-10: the two differ
        // by the Newton tolerance at most (relative 1e-10 of a 1.5 Å bond).
        let dq = a
            .q()
            .iter()
            .zip(expected.q())
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        assert!(dq < 1e-9, "{solver:?}: the step differs by {dq:e} Å");
    }
}

/// Relative residuals are scale invariant down to tiny length scales: a
/// chain scaled by 1e-80 either meets its constraints to the tolerance or
/// fails with a typed error (the squared residual underflowed to 0 and
/// Newton stopped at once, leaving 0.4% length errors).
#[test]
fn tiny_length_scales_are_not_silently_wrong() {
    for solver in [SolverChoice::Band, SolverChoice::Sparse] {
        let (sys, z) = generate::chain(20, 3).unwrap();
        let s = 1e-80;
        let table = sys.constraint_families()[0].table();
        let mut scaled = geoshake::runtime::particles::Table::new(2, 1);
        for k in 0..table.len() {
            let ij = table.particles(k);
            scaled
                .push(&[ij[0] as usize, ij[1] as usize], &[table.data(k)[0] * s])
                .unwrap();
        }
        let sys = geoshake::runtime::particles::ParticleSystem::new(3, sys.masses().to_vec())
            .unwrap()
            .with_constraints(
                "link",
                geoshake::runtime::particles::stencils::Distance::<3>,
                scaled.clone(),
            )
            .unwrap();
        let q: Vec<f64> = z.q().iter().map(|x| x * s).collect();
        let p: Vec<f64> = z.p().iter().map(|x| x * s).collect();
        let mut z = ParticleState::new(q, p);
        let mut r = Rattle::new(
            sys,
            2.0,
            Options {
                solver,
                ..Options::default()
            },
        )
        .unwrap();
        let ok = r.project(&mut z).is_ok() && r.run_in_place(&mut z, 50).error.is_none();
        if ok {
            let err = generate::max_rel_length_error(&scaled, 3, z.q());
            assert!(err <= 1e-9, "{solver:?}: Ok with length error {err:e}");
        }
    }
}

/// Tolerances outside [4ε, 1) and an empty iteration budget are refused.
#[test]
fn options_are_validated() {
    for tol in [0.0, -1.0, 1.0, f64::NAN, f64::INFINITY] {
        let (sys, _) = generate::chain(5, 1).unwrap();
        let e = Rattle::new(
            sys,
            2.0,
            Options {
                tol,
                ..Options::default()
            },
        )
        .err();
        assert!(
            matches!(e, Some(StepError::InvalidInput { what, .. }) if what.starts_with("tol")),
            "tol {tol}"
        );
    }
    let (sys, _) = generate::chain(5, 1).unwrap();
    let e = Rattle::new(
        sys,
        2.0,
        Options {
            max_iter: 0,
            ..Options::default()
        },
    )
    .err();
    assert!(matches!(
        e,
        Some(StepError::InvalidInput { what, .. }) if what.starts_with("max_iter")
    ));
    let (sys, _) = generate::chain(5, 1).unwrap();
    assert!(matches!(
        Rattle::new(sys, 5e-324, Options::default()).err(),
        Some(StepError::InvalidInput { what, .. }) if what.contains("step size")
    ));
}

/// A trajectory too large to store is a typed error before the first step,
/// not an abort in the allocator.
#[test]
fn an_unstorable_trajectory_is_refused() {
    let (sys, mut z) = generate::chain(5, 1).unwrap();
    let mut r = Rattle::new(sys, 2.0, Options::default()).unwrap();
    r.project(&mut z).unwrap();
    // 2^52 states of 30 numbers: a count that fits, memory that does not
    // (more than 2^53 steps is refused before the count: see
    // shake-runtime/tests/run_limits.rs).
    let out = r.run(&z, Stop::Steps(1 << 52)).execute();
    assert!(matches!(
        out.error,
        Some(StepError::Storage { step: 0, .. })
    ));
    assert_eq!(z.step(), 0, "no step was taken");
}
