//! `project_momenta_to_hidden`: q is kept bit for bit, p lands on M^H, and
//! the correction is the constraint impulse the physics prescribes
//! (checked against a closed form computed here), not some other
//! projection; q off M and p-dependent constraints are typed errors.

use geoshake::examples::HopfHarmonic;
use geoshake::prelude::*;

constrained_system! {
    /// Two point masses joined by a rigid rod (a dumbbell in the plane).
    pub struct Dumbbell {
        parameters { m1 = 1.0, m2 = 3.0, length = 1.0 }
        dof q[4], p[4];
        hamiltonian = (p[0]^2 + p[1]^2) / (2 * m1) + (p[2]^2 + p[3]^2) / (2 * m2);
        constraints { rod: (q[0] - q[2])^2 + (q[1] - q[3])^2 - length^2 }
    }
}

#[test]
fn the_momenta_get_the_rod_impulse_and_the_positions_stay() {
    let sys = Dumbbell::default();
    let mut integ = Integrator::new(sys, StormerVerlet, 0.01);
    // On the rod exactly: x1 - x2 = (0.6, 0.8).
    let (q, p) = ([0.6, 0.8, 0.0, 0.0], [0.3, -1.1, 0.7, 0.2]);
    let z = integ
        .project_momenta_to_hidden(&State::from_slices(&q, &p))
        .unwrap();
    assert_eq!(z.q.as_slice(), &q, "q returned bit for bit");

    // The closed form: an impulse ±J along the rod e = x1 - x2 (equal and
    // opposite, so total momentum is kept) that makes the relative
    // velocity along the rod vanish: (v1 - v2)·e = 0 with
    // v1 = (p1 + J e)/m1, v2 = (p2 - J e)/m2.
    let e = [q[0] - q[2], q[1] - q[3]];
    let (m1, m2) = (sys.m1, sys.m2);
    let rel = |a: f64, b: f64, k: usize| (a / m1 - b / m2) * e[k];
    let along = rel(p[0], p[2], 0) + rel(p[1], p[3], 1);
    let j = -along / ((1.0 / m1 + 1.0 / m2) * (e[0] * e[0] + e[1] * e[1]));
    let expected = [
        p[0] + j * e[0],
        p[1] + j * e[1],
        p[2] - j * e[0],
        p[3] - j * e[1],
    ];
    for (k, (got, want)) in z.p.iter().zip(expected).enumerate() {
        // Round-off: a few ulps of numbers of size ~1.
        assert!(
            (got - want).abs() < 4.0 * f64::EPSILON,
            "p[{k}] = {got} against {want}"
        );
    }
    let mut gh = [0.0];
    sys.hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    assert!(gh[0].abs() < 4.0 * f64::EPSILON);
    // project_to_hidden agrees here (q on M: its Gauss–Newton has nothing
    // to do), to round-off.
    let w = integ
        .project_to_hidden(&State::from_slices(&q, &p))
        .unwrap();
    assert!((&w.p - &z.p).amax() < 4.0 * f64::EPSILON);
}

#[test]
fn what_cannot_keep_q_is_a_typed_error() {
    let mut integ = Integrator::new(Dumbbell::default(), StormerVerlet, 0.01);
    let off = State::from_slices(&[0.6, 0.81, 0.0, 0.0], &[0.0; 4]);
    assert!(matches!(
        integ.project_momenta_to_hidden(&off),
        Err(StepError::NotOnConstraint { residual, .. }) if (residual - 0.0161).abs() < 1e-12
    ));
    let nan = State::from_slices(&[0.6, 0.8, 0.0, 0.0], &[f64::NAN, 0.0, 0.0, 0.0]);
    assert!(matches!(
        integ.project_momenta_to_hidden(&nan),
        Err(StepError::NonFinite { .. })
    ));
    let short = State::from_slices(&[0.6, 0.8], &[0.0, 0.0]);
    assert!(matches!(
        integ.project_momenta_to_hidden(&short),
        Err(StepError::InvalidInput { .. })
    ));
    // Constraints on p: their fibres move q.
    let mut hopf = Integrator::new(HopfHarmonic::unit(), ImplicitMidpoint, 0.1);
    let d = hopf.system().dof();
    let (mut q, mut p) = (vec![0.0; d], vec![0.0; d]);
    (q[0], p[0]) = (0.6, 0.8);
    assert!(matches!(
        hopf.project_momenta_to_hidden(&State::from_slices(&q, &p)),
        Err(StepError::InvalidInput { what, .. }) if what.contains("holonomic")
    ));
}
