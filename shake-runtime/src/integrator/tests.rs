//! Tests of the integrator's single steps: S_h alone for a RATTLE
//! integrator has R_h's positions and fails where R_h fails.

use crate::examples::Pendulum;
use crate::{ConstrainedSystem, Integrator, State, StormerVerlet};

/// `shake_in_place` (the sampler's step back) is S_h: R_h's positions
/// bit for bit, its momenta before Π (off M^H), on each path the step
/// can take; and it fails where R_h fails, leaving z as it was.
#[test]
fn shake_in_place_has_the_positions_of_the_rattle_step() {
    for (fast, fixed) in [(true, true), (true, false), (false, true)] {
        let make = |h: f64| {
            Integrator::new(Pendulum::default(), StormerVerlet, h)
                .fast_paths(fast)
                .fixed_size(fixed)
                .rattle()
        };
        let (mut r, mut s) = (make(0.1), make(0.1));
        let mut z = r
            .project_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.0, 1.0]))
            .unwrap();
        for _ in 0..50 {
            let zr = r.step(&z).unwrap();
            let mut zs = z.clone();
            s.shake_in_place(&mut zs).unwrap();
            assert_eq!(zs.q, zr.q, "fast {fast}, fixed {fixed}");
            let mut gh = [0.0];
            r.system()
                .hidden_constraints(zs.q.as_slice(), zs.p.as_slice(), &mut gh);
            assert!(gh[0].abs() > 1e-6, "Π was applied: {gh:?}");
            z = zr;
        }
        // h|p| ≈ 100 times the rod: no solution near the start.
        let (mut r, mut s) = (make(50.0), make(50.0));
        let z = r
            .project_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.6, 1.2]))
            .unwrap();
        let e = r.step(&z).unwrap_err();
        let mut zs = z.clone();
        let es = s.shake_in_place(&mut zs).unwrap_err();
        assert_eq!(std::mem::discriminant(&e), std::mem::discriminant(&es));
        assert_eq!(zs, z);
    }
}
