//! The constraint forces and their virial ([`ConstraintForces`]), checked
//! against what is known without the solver's multipliers: the position
//! update they must explain (to round-off, on every solver and both
//! methods), a rigid rotor's tension in closed form (to O(h²)), and the
//! refusals when a state has no such forces.

use geoshake::runtime::particles::{
    generate, stencils::Distance, ConstraintForces, Langevin, Method, Options, ParticleState,
    ParticleSystem, Rattle, SolverChoice, Table,
};
use geoshake::runtime::StepError;

const EPS: f64 = f64::EPSILON;

/// A weak harmonic tether of every coordinate to a point: forces brought
/// by the user, so that the unconstrained update has a force term.
fn tether(q: &[f64], f: &mut [f64]) -> f64 {
    let mut v = 0.0;
    for (f, q) in f.iter_mut().zip(q) {
        let x = q - 3.0;
        *f -= 2e-3 * x;
        v += 1e-3 * x * x;
    }
    v
}

/// Steps `state` a few times, then one more step from (q0, p0) to q1, and
/// compares the library's f_c with the force that the position update
/// needs: q1 = x̃ + (h²/2) M⁻¹ f_c with x̃ = q0 + h M⁻¹ (p0 + (h/2) F(q0)),
/// computed here from the state alone. q1 − x̃ cancels the digits of |q|:
/// the bound is a few ulps of |q| times 2m/h², plus a few of |f_c|.
fn forces_explain_the_update(
    system: ParticleSystem,
    state: ParticleState,
    h: f64,
    options: Options,
    forces: bool,
) {
    let m: Vec<f64> = system.masses().to_vec();
    let mut rattle = Rattle::new(system, h, options).unwrap();
    let mut state = state;
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    for _ in 0..3 {
        rattle.step(&mut state).unwrap();
    }
    let (q0, p0) = (state.q().to_vec(), state.p().to_vec());
    let mut f = vec![0.0; q0.len()];
    if forces {
        tether(&q0, &mut f);
    }
    rattle.step(&mut state).unwrap();
    let mut fc = ConstraintForces::new(rattle.system());
    rattle.constraint_forces(&state, &mut fc).unwrap();
    assert_eq!((fc.step, fc.time), (4, 3.0 * h));
    let q1 = state.q();
    let d = 3;
    let mut worst = 0.0f64;
    for c in 0..q0.len() {
        let ma = m[c / d];
        let xt = q0[c] + h / ma * (p0[c] + 0.5 * h * f[c]);
        let need = 2.0 * ma / (h * h) * (q1[c] - xt);
        let bound = 8.0 * EPS * (2.0 * ma / (h * h)) * q1[c].abs().max(xt.abs())
            + 8.0 * EPS * fc.forces[c].abs();
        worst = worst.max((fc.forces[c] - need).abs() / bound);
    }
    assert!(
        worst <= 1.0,
        "f_c off the position update by {worst} of its round-off bound"
    );
    // Not trivially zero: the constraints pull.
    let norm: f64 = fc.forces.iter().map(|f| f * f).sum::<f64>().sqrt();
    assert!(norm > 1e-3, "|f_c| = {norm}");
    // W against Σ_a x_a ⊗ f_a summed here in absolute positions (which
    // loses the digits of |x|: bounded by them).
    for r in 0..3 {
        for c in 0..3 {
            let (mut w, mut scale) = (0.0, 0.0);
            for a in 0..q0.len() / 3 {
                w += q0[3 * a + r] * fc.forces[3 * a + c];
                scale += (q0[3 * a + r] * fc.forces[3 * a + c]).abs();
            }
            let got = fc.virial[r * 3 + c];
            assert!(
                (got - w).abs() <= 16.0 * EPS * scale,
                "W[{r}][{c}] = {got}, by hand {w} (scale {scale})"
            );
        }
    }
    // Constraints between particles only: Newton's third law and no torque.
    let total = (0..3).map(|c| fc.forces.iter().skip(c).step_by(3).sum::<f64>().abs());
    let abs: f64 = fc.forces.iter().map(|f| f.abs()).sum();
    assert!(total.fold(0.0, f64::max) <= 64.0 * EPS * abs);
    let wscale = fc.virial.iter().map(|w| w.abs()).fold(0.0, f64::max);
    assert!((fc.virial[1] - fc.virial[3]).abs() <= 1e-12 * wscale);
}

fn water_with_tether() -> (ParticleSystem, ParticleState) {
    let (system, state) = generate::water(27, 5).unwrap();
    (system.with_forces(tether), state)
}

#[test]
fn forces_explain_the_update_on_the_cluster_solver() {
    let (system, state) = water_with_tether();
    forces_explain_the_update(system, state, 1.0, Options::default(), true);
}

#[test]
fn forces_explain_the_update_without_potential() {
    // No potential: the cluster solver projects the momenta inside the
    // position stage (the fused path).
    let (system, state) = generate::water(27, 6).unwrap();
    forces_explain_the_update(system, state, 1.0, Options::default(), false);
}

#[test]
fn forces_explain_the_update_on_the_global_solvers() {
    for solver in [SolverChoice::Sparse, SolverChoice::Band] {
        let (system, state) = water_with_tether();
        let options = Options {
            solver,
            ..Options::default()
        };
        forces_explain_the_update(system, state, 1.0, options, true);
    }
}

#[test]
fn forces_explain_the_update_of_shake_on_a_chain() {
    let (system, state) = generate::chain(40, 2).unwrap();
    let options = Options {
        method: Method::Shake,
        ..Options::default()
    };
    forces_explain_the_update(system.with_forces(tether), state, 2.0, options, true);
}

/// A rigid dimer (masses 1 and 3, length 1) spinning at ω = 1 about its
/// centre of mass, placed 10⁵ from the origin: the bond's tension is
/// μ ω² l (μ the reduced mass), so Λ = μ ω² / 2, to O(h²).
fn rotor(h: f64) -> (f64, ConstraintForces, Vec<f64>) {
    let (m1, m2, l, omega, far) = (1.0, 3.0, 1.0, 1.0, 1e5);
    let (r1, r2) = (m2 / (m1 + m2) * l, -m1 / (m1 + m2) * l);
    let q = vec![far + r1, far, far, far + r2, far, far];
    let p = vec![0.0, m1 * omega * r1, 0.0, 0.0, m2 * omega * r2, 0.0];
    let mut bond = Table::new(2, 1);
    bond.push(&[0, 1], &[l]).unwrap();
    let system = ParticleSystem::new(3, vec![m1, m2])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bond)
        .unwrap();
    let mut rattle = Rattle::new(system, h, Options::default()).unwrap();
    let mut state = ParticleState::new(q, p);
    rattle.project(&mut state).unwrap();
    let mut fc = ConstraintForces::new(rattle.system());
    let mut q0 = state.q().to_vec();
    for _ in 0..7 {
        q0 = state.q().to_vec();
        rattle.step(&mut state).unwrap();
    }
    rattle.constraint_forces(&state, &mut fc).unwrap();
    let mu = m1 * m2 / (m1 + m2);
    (
        (fc.multipliers[0] - 0.5 * mu * omega * omega).abs() / (0.5 * mu),
        fc,
        q0,
    )
}

#[test]
fn a_rotors_tension_is_the_centripetal_force_to_second_order() {
    let (e1, _, _) = rotor(0.1);
    let (e2, fc, q0) = rotor(0.05);
    assert!(e1 < 0.01 && e2 < e1, "errors {e1}, {e2}");
    let order = (e1 / e2).log2();
    assert!((1.8..=2.2).contains(&order), "order {order} ({e1}, {e2})");
    // W = Σ x_a ⊗ f_a = −2Λ r ⊗ r with r = x_1 − x_2 at q0, exactly in the
    // bond's own scale although |x| = 10⁵ (summed in absolute positions, W
    // would carry errors of 10⁵ ulps of it).
    let lambda = fc.multipliers[0];
    let r: Vec<f64> = (0..3).map(|c| q0[c] - q0[3 + c]).collect();
    for a in 0..3 {
        for b in 0..3 {
            let want = -2.0 * lambda * r[a] * r[b];
            let got = fc.virial[a * 3 + b];
            assert!(
                (got - want).abs() <= 1e-13 * lambda,
                "W[{a}][{b}] = {got}, want {want}"
            );
        }
    }
    // tr W = −2 × the rotor's kinetic energy μω²l²/2, to the same O(h²).
    assert!((fc.virial_trace() + 0.75).abs() <= 2.0 * e2 * 0.75);
}

#[test]
fn states_without_constraint_forces_are_refused() {
    let (system, mut state) = generate::water(8, 1).unwrap();
    let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    let mut fc = ConstraintForces::new(rattle.system());
    let unavailable = |r: Result<(), StepError>| matches!(r, Err(StepError::Unavailable { .. }));
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    assert!(
        unavailable(rattle.constraint_forces(&state, &mut fc)),
        "initial data"
    );
    rattle.step(&mut state).unwrap();
    let older = state.clone();
    rattle.step(&mut state).unwrap();
    assert!(
        unavailable(rattle.constraint_forces(&older, &mut fc)),
        "an older state"
    );
    let mut touched = state.clone();
    touched.p_mut()[0] += 0.0;
    assert!(
        unavailable(rattle.constraint_forces(&touched, &mut fc)),
        "changed by hand"
    );
    assert!(rattle.constraint_forces(&state, &mut fc).is_ok());
    let mut other = ConstraintForces::new(&generate::water(9, 1).unwrap().0);
    assert!(matches!(
        rattle.constraint_forces(&state, &mut other),
        Err(StepError::Shape { .. })
    ));
    let mut projected = state.clone();
    rattle.project(&mut projected).unwrap();
    assert!(
        unavailable(rattle.constraint_forces(&state, &mut fc)),
        "after a projection"
    );
    rattle
        .set_thermostat(Some(Langevin::new(0.01, 0.6, 1).unwrap()))
        .unwrap();
    rattle.step(&mut projected).unwrap();
    assert!(
        unavailable(rattle.constraint_forces(&projected, &mut fc)),
        "thermostatted"
    );
    // A refusal leaves what `out` held.
    assert_eq!(fc.step, 2);
}

#[test]
fn a_run_on_the_driver_ends_with_the_same_forces_as_single_steps() {
    let (system, state) = water_with_tether();
    let mut one = Rattle::new(system, 1.0, Options::default()).unwrap();
    let mut s1 = state.clone();
    one.project(&mut s1).unwrap();
    generate::set_temperature(one.system(), &mut s1, 300.0);
    let mut s2 = s1.clone();
    let (system, _) = water_with_tether();
    let mut two = Rattle::new(system, 1.0, Options::default()).unwrap();
    for _ in 0..5 {
        one.step(&mut s1).unwrap();
    }
    assert!(two.run_in_place(&mut s2, 5).error.is_none());
    let (mut f1, mut f2) = (
        ConstraintForces::new(one.system()),
        ConstraintForces::new(two.system()),
    );
    one.constraint_forces(&s1, &mut f1).unwrap();
    two.constraint_forces(&s2, &mut f2).unwrap();
    assert_eq!(f1, f2);
}
