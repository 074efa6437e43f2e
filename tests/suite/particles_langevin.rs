//! Langevin dynamics on M by (g-)BAOAB: the stationary distribution's
//! moments against closed forms, the bonds at round-off, and the noise
//! reproducible bit for bit.
//!
//! The systems are sets of independent molecules, so that the molecules'
//! time averages are independent samples and the standard error of their
//! mean is their spread over √(molecules): every gate below is 5 such
//! standard errors (a false failure about once in 10⁶ per gate; the seeds
//! are fixed, so a run is deterministic) plus nothing for the O(h²) bias
//! of BAOAB, which is below 0.1 % at the steps used (h ω ≤ 0.05).

use geoshake::runtime::particles::{
    generate, stencils::Distance, Langevin, Options, ParticleState, ParticleSystem, Rattle, Table,
};
use geoshake::runtime::{StepError, Stop};
use geoshake_testkit::same_bits::assert_same_bits;

/// `n` dimers of unit masses and unit bond length, every atom in the trap
/// V = (κ/2) |x_a|²: the centre of mass X of a dimer (mass 2) feels
/// V = κ |X|² + const, so E|X|² = 3 k_B T / (2κ); its orientation is free.
fn trapped_dimers(n: usize, kappa: f64) -> (ParticleSystem, ParticleState) {
    let mut bonds = Table::new(2, 1);
    let mut q = Vec::with_capacity(6 * n);
    for j in 0..n {
        bonds.push(&[2 * j, 2 * j + 1], &[1.0]).unwrap();
        let c = [
            (j % 7) as f64 * 0.1,
            (j % 5) as f64 * 0.1,
            (j % 3) as f64 * 0.1,
        ];
        let u = [((j % 4) as f64).cos(), ((j % 4) as f64).sin(), 0.0];
        for s in [0.5, -0.5] {
            q.extend((0..3).map(|i| c[i] + s * u[i]));
        }
    }
    let trap = move |q: &[f64], f: &mut [f64]| {
        for (f, q) in f.iter_mut().zip(q) {
            *f -= kappa * q;
        }
        0.5 * kappa * q.iter().map(|q| q * q).sum::<f64>()
    };
    let system = ParticleSystem::new(3, vec![1.0; 2 * n])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bonds)
        .unwrap()
        .with_forces(trap);
    (system, ParticleState::new(q, vec![0.0; 6 * n]))
}

/// Mean and standard error of independent samples.
fn mean_se(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

/// Per-dimer time averages of |X|² and of the kinetic energy over
/// `steps` steps after `burn` steps of (g-)BAOAB with K = `substeps`.
fn dimer_averages(substeps: usize) -> (Vec<f64>, Vec<f64>, f64) {
    let (n, kappa, kt, gamma, h) = (400, 1.0, 1.0, 1.0, 0.05);
    let (system, mut state) = trapped_dimers(n, kappa);
    let mut rattle = Rattle::new(system, h, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    let th = Langevin::new(gamma, kt, 2024)
        .unwrap()
        .geodesic(substeps)
        .unwrap();
    rattle.set_thermostat(Some(th)).unwrap();
    // 10 relaxation times 1/γ.
    let out = rattle.run_in_place(&mut state, 200);
    assert!(out.error.is_none(), "{:?}", out.error);
    let (mut x2, mut ke) = (vec![0.0; n], vec![0.0; n]);
    let (steps, mut worst) = (4000, 0.0f64);
    for _ in 0..steps {
        let r = rattle.step(&mut state).unwrap();
        worst = worst.max(r.residual.unwrap()).max(r.hidden.unwrap());
        let (q, p) = (state.q(), state.p());
        for j in 0..n {
            let (a, b) = (6 * j, 6 * j + 3);
            x2[j] += (0..3)
                .map(|c| (0.5 * (q[a + c] + q[b + c])).powi(2))
                .sum::<f64>();
            ke[j] += 0.5 * (0..6).map(|c| p[a + c].powi(2)).sum::<f64>();
        }
    }
    for v in x2.iter_mut().chain(ke.iter_mut()) {
        *v /= steps as f64;
    }
    (x2, ke, worst)
}

/// E|X|² = 3 k_B T/(2κ) (configurations) and E K = (6 − 1)/2 k_B T per
/// dimer (momenta: 6 coordinates, 1 constraint; the thermostat does not
/// conserve the total momentum, so no 3 are taken off).
fn check_dimers(substeps: usize) {
    let (x2, ke, worst) = dimer_averages(substeps);
    let (mx, sx) = mean_se(&x2);
    let (mk, sk) = mean_se(&ke);
    assert!(
        (mx - 1.5).abs() < 5.0 * sx,
        "K = {substeps}: E|X|² = {mx} ± {sx}, want 1.5"
    );
    assert!(
        (mk - 2.5).abs() < 5.0 * sk,
        "K = {substeps}: E K = {mk} ± {sk}, want 2.5"
    );
    // The gates are tight enough to see a wrong number of degrees of
    // freedom (3 instead of 2.5) or a wrong temperature by 5 %.
    assert!(sk < 0.1 && sx < 0.06, "standard errors {sk}, {sx}");
    assert!(worst <= 1e-10, "largest relative residual {worst:e}");
}

#[test]
fn baoab_samples_the_trapped_dimers_canonical_distribution() {
    check_dimers(1);
}

#[test]
fn geodesic_baoab_samples_the_trapped_dimers_canonical_distribution() {
    check_dimers(3);
}

/// Rigid waters without interactions at 300 K (LAMMPS `real` units): the
/// kinetic temperature with 3N − m degrees of freedom (6 per molecule)
/// reaches the target, each molecule's average being independent.
#[test]
fn a_water_box_reaches_the_kinetic_temperature_with_bonds_at_round_off() {
    let (system, mut state) = generate::water(216, 5).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 10.0);
    let kt = generate::KB * 300.0 / generate::MVV2E;
    // γ = 10/ps: relaxation in 50 steps of 2 fs.
    let th = Langevin::new(1e-2, kt, 9).unwrap().geodesic(2).unwrap();
    rattle.set_thermostat(Some(th)).unwrap();
    assert!(rattle.run_in_place(&mut state, 500).error.is_none());
    let mut per_molecule = vec![0.0; 216];
    let mut last = Vec::new();
    let steps = 2000;
    let out = rattle
        .run(&state, Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k == steps {
                last = z.q.as_slice().to_vec();
            }
            if k > 0 {
                for (j, e) in per_molecule.iter_mut().enumerate() {
                    let p = &z.p.as_slice()[9 * j..9 * j + 9];
                    let m = [generate::M_O, generate::M_H, generate::M_H];
                    *e += (0..9).map(|c| p[c] * p[c] / (2.0 * m[c / 3])).sum::<f64>();
                }
            }
        })
        .execute();
    assert!(out.error.is_none());
    assert!(out.summary.max_residual.unwrap() <= 1e-10);
    assert!(out.summary.max_hidden.unwrap() <= 1e-12);
    let t: Vec<f64> = per_molecule
        .iter()
        .map(|e| 2.0 * e / steps as f64 / (6.0 * kt) * 300.0)
        .collect();
    let (m, se) = mean_se(&t);
    assert!((m - 300.0).abs() < 5.0 * se, "T = {m} ± {se} K");
    assert!(se < 6.0, "standard error {se} K");
    let bonds = rattle.system().constraint_families()[0].table();
    assert!(generate::max_rel_length_error(bonds, 3, &last) < 1e-10);
}

/// The noise of step k depends on the seed and k only: a run in chunks is
/// the run in one piece bit for bit, the driver's run is the steps by
/// hand, and another seed gives another run.
#[test]
fn the_noise_is_reproducible_bit_for_bit() {
    let setup = |seed| {
        let (system, mut state) = trapped_dimers(50, 1.0);
        let mut rattle = Rattle::new(system, 0.05, Options::default()).unwrap();
        rattle.project(&mut state).unwrap();
        let th = Langevin::new(1.0, 1.0, seed).unwrap().geodesic(2).unwrap();
        rattle.set_thermostat(Some(th)).unwrap();
        (rattle, state)
    };
    let (mut a, s) = setup(1);
    let whole = a.run(&s, Stop::Steps(60)).stride(20).execute();
    assert!(whole.error.is_none(), "{:?}", whole.error);

    let (mut b, mut chunked) = setup(1);
    let mut by_hand = chunked.clone();
    for k in 1..=3 {
        assert!(b.run_in_place(&mut chunked, 20).error.is_none());
        assert_eq!(chunked.q(), whole.trajectory.q(k));
        assert_eq!(chunked.p(), whole.trajectory.p(k));
    }
    let (mut c, _) = setup(1);
    for _ in 0..60 {
        c.step(&mut by_hand).unwrap();
    }
    assert_eq!((by_hand.q(), by_hand.p()), (chunked.q(), chunked.p()));
    assert_eq!(
        (by_hand.step(), by_hand.time()),
        (chunked.step(), chunked.time())
    );

    let (mut d, s) = setup(2);
    let other = d.run(&s, Stop::Steps(60)).stride(20).execute();
    assert_ne!(other.trajectory.q(3), whole.trajectory.q(3));
    let (mut e, s) = setup(1);
    assert_same_bits(
        &whole.trajectory,
        &e.run(&s, Stop::Steps(60)).stride(20).execute().trajectory,
    );
}

/// γ = 0 is no thermostat: the step is the Hamiltonian flow split as
/// B A A B, which conserves H to O(h²) like RATTLE itself.
#[test]
fn without_friction_the_energy_is_conserved_to_second_order() {
    let worst = |h: f64| {
        let (system, mut state) = trapped_dimers(20, 1.0);
        let mut rattle = Rattle::new(system, h, Options::default()).unwrap();
        rattle.project(&mut state).unwrap();
        for (i, p) in state.p_mut().iter_mut().enumerate() {
            *p = ((i * 7919) % 13) as f64 / 13.0 - 0.5;
        }
        rattle.project(&mut state).unwrap();
        rattle
            .set_thermostat(Some(Langevin::new(0.0, 1.0, 3).unwrap()))
            .unwrap();
        let energy = |r: &mut Rattle, s: &ParticleState| {
            r.potential_energy(s).unwrap() + r.system().kinetic_energy(s.p())
        };
        let h0 = energy(&mut rattle, &state);
        let mut err = 0.0f64;
        for _ in 0..(5.0 / h) as usize {
            rattle.step(&mut state).unwrap();
            err = err.max((energy(&mut rattle, &state) - h0).abs());
        }
        err
    };
    let ratio = worst(0.1) / worst(0.05);
    assert!((3.0..5.0).contains(&ratio), "error ratio {ratio}");
}

/// Bad thermostats are refused: SHAKE has no cotangent projection.
#[test]
fn a_thermostat_on_shake_is_refused() {
    use geoshake::runtime::particles::Method;
    let (system, _) = trapped_dimers(2, 1.0);
    let options = Options {
        method: Method::Shake,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, 0.1, options).unwrap();
    let th = Langevin::new(1.0, 1.0, 0).unwrap();
    assert!(matches!(
        rattle.set_thermostat(Some(th)),
        Err(StepError::InvalidInput { .. })
    ));
    assert!(rattle.thermostat().is_none());
}
