//! Property tests: random initial data near M^H (a random point near the
//! constraint set, brought onto M^H by `project_to_hidden`), random step
//! sizes of either sign and every base map. Properties: nothing panics; a
//! failure is a typed error with the partial trajectory; a successful run
//! keeps |g| at round-off (SHAKE and RATTLE), |{g,H}| at round-off
//! (RATTLE), Π∘Sᵏ = Π∘Rᵏ, and RATTLE over a symmetric map is reversible.

use crate::common;

use common::models::*;
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, State, Stop, StormerVerlet,
    SymplecticEuler,
};
use proptest::prelude::*;

fn residuals<S: ConstrainedSystem>(sys: &S, z: &State) -> (f64, f64) {
    let m = sys.constraint_count();
    let (mut g, mut gh) = (vec![0.0; m], vec![0.0; m]);
    sys.constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    sys.hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    let n = |v: &[f64]| v.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    (n(&g), n(&gh))
}

fn scale(z: &State) -> f64 {
    1.0 + z.q.amax().max(z.p.amax()).powi(2)
}

fn property<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: S,
    base: B,
    guess: State,
    h: f64,
) -> Result<(), TestCaseError> {
    let mut rattle = Integrator::new(sys.clone(), base, h).rattle();
    let Ok(z0) = rattle.project_to_hidden(&guess) else {
        // A typed refusal of bad initial data is an allowed outcome.
        return Ok(());
    };
    let steps = 20;
    let r = rattle.run(z0.clone(), Stop::Steps(steps)).execute();
    let mut shake = Integrator::new(sys.clone(), base, h).shake();
    let s = shake.run(z0.clone(), Stop::Steps(steps)).execute();
    for out in [&r, &s] {
        prop_assert!(
            !out.trajectory.is_empty(),
            "the initial state is always kept"
        );
        if let Some(e) = &out.error {
            // The partial trajectory ends just before the failing step.
            prop_assert_eq!(*out.trajectory.steps().last().unwrap() + 1, e.step());
        }
        for z in out.trajectory.states() {
            let z = &z;
            let (g, _) = residuals(&sys, z);
            prop_assert!(g <= 1e-13 * scale(z), "|g| = {:e}", g);
        }
    }
    for z in r.trajectory.states() {
        let z = &z;
        let (_, gh) = residuals(&sys, z);
        prop_assert!(gh <= 1e-12 * scale(z), "|{{g,H}}| = {:e}", gh);
    }
    if r.error.is_none() && s.error.is_none() {
        let zs = shake.project(&s.trajectory.last().unwrap()).unwrap();
        let zr = &r.trajectory.last().unwrap();
        prop_assert!(
            zs.distance(zr) <= 1e-11 * scale(zr),
            "Π∘Sᵏ vs Π∘Rᵏ: {:e}",
            zs.distance(zr)
        );
        if B::SYMMETRIC {
            let z1 = rattle.step(&z0).unwrap();
            if let Ok(back) = rattle.with_step_size(-h).step(&z1) {
                prop_assert!(
                    back.distance(&z0) <= 1e-12 * scale(&z0),
                    "R₋ₕ∘Rₕ: {:e}",
                    back.distance(&z0)
                );
            }
        }
    }
    Ok(())
}

fn any_base<S: ConstrainedSystem + Clone>(
    sys: S,
    which: u8,
    guess: State,
    h: f64,
) -> Result<(), TestCaseError> {
    match which % 3 {
        0 => property(sys, ImplicitMidpoint, guess, h),
        1 => property(sys, StormerVerlet, guess, h),
        _ => property(sys, SymplecticEuler, guess, h),
    }
}

fn step_size() -> impl Strategy<Value = f64> {
    (0.005f64..0.1, any::<bool>()).prop_map(|(h, neg)| if neg { -h } else { h })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn pendulum(theta in -3.0f64..3.0, omega in -3.0f64..3.0, off in -0.2f64..0.2, which in 0u8..3, h in step_size()) {
        let sys = Pendulum::default();
        let mut z = sys.state(theta, omega);
        z.q *= 1.0 + off;
        z.p[0] += off;
        any_base(sys, which, z, h)?;
    }

    #[test]
    fn spherical_pendulum(q in prop::array::uniform3(-1.0f64..1.0), p in prop::array::uniform3(-2.0f64..2.0), which in 0u8..3, h in step_size()) {
        prop_assume!(q.iter().map(|x| x * x).sum::<f64>() > 0.05);
        any_base(SphericalPendulum::default(), which, State::from_slices(&q, &p), h)?;
    }

    #[test]
    fn double_pendulum(a in -2.0f64..2.0, b in -2.0f64..2.0, w in prop::array::uniform2(-2.0f64..2.0), off in -0.1f64..0.1, which in 0u8..3, h in step_size()) {
        let sys = DoublePendulum::default();
        let mut z = sys.state(a, b, w[0], w[1]);
        z.q[2] += off;
        any_base(sys, which, z, h)?;
    }

    #[test]
    fn hopf(z in prop::array::uniform4(-1.0f64..1.0), gravity in any::<bool>(), which in 0u8..3, h in step_size()) {
        prop_assume!(z.iter().map(|x| x * x).sum::<f64>() > 0.1);
        let sys = if gravity { Hopf::gravity() } else { Hopf::free() };
        any_base(sys, which, State::from_slices(&z[..2], &z[2..]), h)?;
    }

    #[test]
    fn hopf_general_fibre(z in prop::array::uniform4(-1.0f64..1.0), which in 0u8..3, h in step_size()) {
        prop_assume!(z.iter().map(|x| x * x).sum::<f64>() > 0.1);
        any_base(AsGeneral(Hopf::gravity()), which, State::from_slices(&z[..2], &z[2..]), h)?;
    }
}
