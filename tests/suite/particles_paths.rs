//! The large-system path against independent references: the dense path on
//! a system that fits both, its three linear solvers against each other,
//! and the exact discrete solution of RATTLE for a free rigid dimer.

use crate::common;

use common::models::DoublePendulum;
use geoshake::runtime::particles::{
    generate,
    stencils::{Anchor, Distance, LinearField},
    Options, ParticleState, ParticleSystem, Rattle, SolverChoice, Table,
};
use geoshake::{Integrator, StormerVerlet};

/// The double pendulum of the dense test models as particles: a pivot
/// (`Anchor`), a link (`Distance`) and gravity (`LinearField`), in R².
fn double_pendulum_particles(dp: &DoublePendulum) -> ParticleSystem {
    let mut pivot = Table::new(1, 1);
    pivot.push(&[0], &[dp.l1]).unwrap();
    let mut link = Table::new(2, 1);
    link.push(&[0, 1], &[dp.l2]).unwrap();
    let mut gravity = Table::new(1, 2);
    gravity.push(&[0], &[0.0, dp.gravity * dp.m1]).unwrap();
    gravity.push(&[1], &[0.0, dp.gravity * dp.m2]).unwrap();
    ParticleSystem::new(2, vec![dp.m1, dp.m2])
        .unwrap()
        .with_constraints("upper rod", Anchor::<2>, pivot)
        .unwrap()
        .with_constraints("lower rod", Distance::<2>, link)
        .unwrap()
        .with_potential("gravity", LinearField::<2>, gravity)
        .unwrap()
}

/// (i) The particle path (band solver, simplified Newton) and the dense
/// path (`Integrator` with Störmer–Verlet, RATTLE) take the same steps. The
/// dense path's λ is the fibre parameter, ours the classical multiplier
/// times h: only the states are compared. Both solve every step to
/// round-off (tol 1e-15 here), so after 200 steps they agree to a few
/// hundred ulps of the O(1) coordinates.
#[test]
fn particle_and_dense_paths_take_the_same_steps() {
    let dp = DoublePendulum {
        l1: 1.0,
        l2: 0.7,
        m1: 1.0,
        m2: 2.5,
        gravity: 9.81,
    };
    let h = 0.01;
    let z0 = dp.state(0.9, -0.4, 0.5, -1.2);
    let mut dense = Integrator::new(dp, StormerVerlet, h).rattle();
    let options = Options {
        tol: 1e-15,
        ..Options::default()
    };
    let mut rattle = Rattle::new(double_pendulum_particles(&dp), h, options).unwrap();
    assert_eq!(rattle.solver_name(), "band");
    let mut state = ParticleState::new(z0.q.as_slice().to_vec(), z0.p.as_slice().to_vec());
    let mut z = z0.clone();
    let mut worst = 0.0f64;
    for _ in 0..200 {
        z = dense.step(&z).unwrap();
        rattle.step(&mut state).unwrap();
        for c in 0..4 {
            worst = worst
                .max((z.q[c] - state.q()[c]).abs())
                .max((z.p[c] - state.p()[c]).abs());
        }
    }
    assert!(worst < 1e-12, "paths differ by {worst:e}");
    assert_eq!(state.step(), 200);
    assert_eq!(state.time(), 200.0 * h);
}

/// The state of a run of `steps` steps with a given solver (tol 1e-14,
/// so that every solver's Newton ends at round-off of the same solution).
fn run_with(
    system: ParticleSystem,
    state: &ParticleState,
    solver: SolverChoice,
    steps: u64,
) -> (ParticleState, &'static str) {
    let options = Options {
        tol: 1e-14,
        solver,
        ..Options::default()
    };
    let mut r = Rattle::new(system, 2.0, options).unwrap();
    let mut s = state.clone();
    let out = r.run_in_place(&mut s, steps);
    assert!(out.error.is_none(), "{:?}", out.error);
    assert!(out.summary.max_residual.unwrap() <= 1e-14 && out.summary.max_hidden.unwrap() < 1e-13);
    (s, r.solver_name())
}

fn max_diff(a: &ParticleState, b: &ParticleState) -> f64 {
    a.q()
        .iter()
        .zip(b.q())
        .chain(a.p().iter().zip(b.p()))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// (ii) Clusters, band and sparse (faer) solvers take the same steps on a
/// box of waters (block-diagonal N: all three apply).
#[test]
fn cluster_band_and_sparse_solvers_agree_on_water() {
    let (system, mut state) = generate::water(27, 11).unwrap();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    r.project(&mut state).unwrap();
    generate::set_temperature(r.system(), &mut state, 300.0);
    let state = ParticleState::new(state.q().to_vec(), state.p().to_vec());
    let steps = 50;
    let (a, na) = run_with(
        generate::water(27, 11).unwrap().0,
        &state,
        SolverChoice::Clusters,
        steps,
    );
    let (b, nb) = run_with(
        generate::water(27, 11).unwrap().0,
        &state,
        SolverChoice::Band,
        steps,
    );
    let (c, nc) = run_with(
        generate::water(27, 11).unwrap().0,
        &state,
        SolverChoice::Sparse,
        steps,
    );
    assert_eq!((na, nb, nc), ("clusters", "band", "sparse"));
    // Coordinates are O(10 Å), momenta O(0.1): round-off of 50 steps.
    let (ab, ac) = (max_diff(&a, &b), max_diff(&a, &c));
    assert!(
        ab < 1e-11 && ac < 1e-11,
        "clusters-band {ab:e}, clusters-sparse {ac:e}"
    );
}

/// The cluster path's fixed-size kernel (every water: 3 constraints on 3
/// particles, sizes known at compile time) and its general kernel (run-time
/// sizes) take the same steps to round-off: 50 steps of 27 waters at
/// tol 1e-14, free flight (velocity stage fused) and a projection.
#[test]
fn fixed_and_general_cluster_kernels_agree_on_water() {
    let (system, mut state) = generate::water(27, 11).unwrap();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    r.project(&mut state).unwrap();
    generate::set_temperature(r.system(), &mut state, 300.0);
    let state = ParticleState::new(state.q().to_vec(), state.p().to_vec());
    let options = Options {
        tol: 1e-14,
        solver: SolverChoice::Clusters,
        ..Options::default()
    };
    let run = |general: bool| {
        let mut r = Rattle::new(generate::water(27, 11).unwrap().0, 2.0, options).unwrap();
        if general {
            r.use_general_cluster_kernel();
        }
        let mut s = state.clone();
        let out = r.run_in_place(&mut s, 50);
        assert!(out.error.is_none(), "{:?}", out.error);
        assert!(
            out.summary.max_residual.unwrap() <= 1e-14 && out.summary.max_hidden.unwrap() < 1e-13
        );
        // A perturbed state, projected back onto M and M^H.
        let mut t = s.clone();
        let q: Vec<f64> = t
            .q()
            .iter()
            .enumerate()
            .map(|(i, v)| v + 1e-3 * ((i % 7) as f64 - 3.0))
            .collect();
        t = ParticleState::new(q, t.p().to_vec());
        r.project(&mut t).unwrap();
        (s, t)
    };
    let ((a, pa), (b, pb)) = (run(false), run(true));
    let (d, dp) = (max_diff(&a, &b), max_diff(&pa, &pb));
    // Round-off of 50 steps (coordinates O(10 Å), momenta O(0.1)), as for
    // the cluster/band/sparse agreement above.
    assert!(d < 1e-11 && dp < 1e-11, "steps {d:e}, projection {dp:e}");
    // The two kernels sum in different orders: equal bits would mean the
    // switch did not reach the general kernel.
    assert!(d > 0.0, "the same bits: was the general kernel used?");
}

/// (ii) Band and sparse solvers take the same steps on a chain (the
/// cluster solver refuses it: one cluster of 40 constraints).
#[test]
fn band_and_sparse_solvers_agree_on_a_chain() {
    let (system, mut state) = generate::chain(40, 5).unwrap();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    r.project(&mut state).unwrap();
    generate::set_temperature(r.system(), &mut state, 300.0);
    let state = ParticleState::new(state.q().to_vec(), state.p().to_vec());
    let (a, _) = run_with(
        generate::chain(40, 5).unwrap().0,
        &state,
        SolverChoice::Band,
        50,
    );
    let (b, _) = run_with(
        generate::chain(40, 5).unwrap().0,
        &state,
        SolverChoice::Sparse,
        50,
    );
    let d = max_diff(&a, &b);
    assert!(d < 1e-11, "band-sparse {d:e}");
    let e = Rattle::new(
        generate::chain(40, 5).unwrap().0,
        2.0,
        Options {
            solver: SolverChoice::Clusters,
            ..Options::default()
        },
    );
    assert!(e.is_err());
}

/// (iii) A free rigid dimer. RATTLE with Störmer–Verlet has an exact
/// discrete solution: with r the relative vector (|r| = l), v its velocity
/// (r·v = 0) and s = h|v|/l, each step rotates r by φ = arcsin(s) in the
/// plane of (r, v), keeps |v| (so the kinetic energy), and moves the centre
/// of mass uniformly. (From r1 = √(1−s²) r0 + h v0 and the projection of
/// p½ orthogonal to r1: |p1| = |p0|√(1−s²) + |p0|(1−√(1−s²)) = |p0|.)
#[test]
fn free_rigid_dimer_rotates_uniformly() {
    let (m1, m2, l) = (3.0, 1.0, 1.3);
    let mut bond = Table::new(2, 1);
    bond.push(&[0, 1], &[l]).unwrap();
    let system = ParticleSystem::new(3, vec![m1, m2])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bond)
        .unwrap();
    let h = 0.05;
    let options = Options {
        tol: 1e-15,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, h, options).unwrap();
    // r = x1 − x0 along e, relative velocity along f, plus a drift V.
    let e = [0.6, 0.8, 0.0];
    let f = [0.0, 0.0, 1.0];
    let (w, vcom) = (0.9, [0.1, -0.2, 0.3]); // |v_rel| = w l
    let mt = m1 + m2;
    let c0 = [1.0, 2.0, -1.0];
    let mut q = vec![0.0; 6];
    let mut p = vec![0.0; 6];
    for k in 0..3 {
        q[k] = c0[k] - m2 / mt * l * e[k];
        q[3 + k] = c0[k] + m1 / mt * l * e[k];
        let vr = w * l * f[k];
        p[k] = m1 * (vcom[k] - m2 / mt * vr);
        p[3 + k] = m2 * (vcom[k] + m1 / mt * vr);
    }
    let mut state = ParticleState::new(q, p);
    let angular = |s: &ParticleState| {
        let (q, p) = (s.q(), s.p());
        let mut lz = [0.0; 3];
        for a in 0..2 {
            let (x, y) = (&q[3 * a..3 * a + 3], &p[3 * a..3 * a + 3]);
            lz[0] += x[1] * y[2] - x[2] * y[1];
            lz[1] += x[2] * y[0] - x[0] * y[2];
            lz[2] += x[0] * y[1] - x[1] * y[0];
        }
        lz
    };
    let energy = |s: &ParticleState| {
        let p = s.p();
        (0..3)
            .map(|k| p[k] * p[k] / m1 + p[3 + k] * p[3 + k] / m2)
            .sum::<f64>()
            / 2.0
    };
    let (l0, e0) = (angular(&state), energy(&state));
    let phi = (h * w).asin();
    let n = 400;
    for k in 1..=n {
        let r = rattle.step(&mut state).unwrap();
        assert!(r.residual.unwrap() <= 1e-15 && r.hidden.unwrap() < 1e-14);
        let (q, p) = (state.q(), state.p());
        let t = k as f64 * phi;
        for c in 0..3 {
            let rel = q[3 + c] - q[c];
            let exact = l * (t.cos() * e[c] + t.sin() * f[c]);
            // Round-off grows like k·ε in the angle.
            assert!(
                (rel - exact).abs() < 1e-13 * k as f64,
                "step {k}: {rel} vs {exact}"
            );
            let com = (m1 * q[c] + m2 * q[3 + c]) / mt;
            let com_exact = c0[c] + k as f64 * h * vcom[c];
            assert!((com - com_exact).abs() < 1e-13 * k as f64);
        }
        let len = (0..3)
            .map(|c| (q[3 + c] - q[c]).powi(2))
            .sum::<f64>()
            .sqrt();
        // Newton stops at relative residual ≤ tol = 1e-15; the length
        // itself is measured with a few ulps of error.
        assert!(((len - l) / l).abs() < 1e-15 + 4e-16, "bond {len}");
        let _ = p;
    }
    let (l1, e1) = (angular(&state), energy(&state));
    for c in 0..3 {
        assert!(
            (l1[c] - l0[c]).abs() < 1e-13,
            "angular momentum {l0:?} -> {l1:?}"
        );
    }
    assert!(((e1 - e0) / e0).abs() < 1e-13, "energy {e0} -> {e1}");
}

/// A chain far from the origin satisfies its constraints as well as at the
/// origin: the stencils are written on differences.
#[test]
fn translated_chain_keeps_its_constraints() {
    let measure = |shift: f64| {
        let (system, mut state) = generate::chain(30, 9).unwrap();
        for x in state.q_mut() {
            *x += shift;
        }
        let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
        r.project(&mut state).unwrap();
        generate::set_temperature(r.system(), &mut state, 300.0);
        let out = r.run_in_place(&mut state, 200);
        assert!(out.error.is_none());
        let t = r.system().constraint_families()[0].table();
        generate::max_rel_length_error(t, 3, state.q())
    };
    let (near, far) = (measure(0.0), measure(1e3));
    assert!(near <= 1e-10 && far <= 1e-10, "near {near:e}, far {far:e}");
}

/// (ii) With a potential the cluster path runs its velocity stage as a
/// second pass (after ∇V(q1)) and its Newton simplified; it still takes the
/// steps of the band and sparse solvers. Water in a uniform field plus
/// springs between the oxygens of neighbouring molecules.
#[test]
fn solvers_agree_on_water_with_forces() {
    use geoshake::runtime::particles::stencils::{LinearField, Spring};
    let build = || {
        let (system, state) = generate::water(8, 4).unwrap();
        let mut field = Table::new(1, 3);
        let mut springs = Table::new(2, 2);
        for (a, &m) in system.masses().iter().enumerate() {
            field.push(&[a], &[0.0, 0.0, 1e-4 * m]).unwrap();
        }
        for k in 0..7 {
            springs.push(&[3 * k, 3 * k + 3], &[0.05, 3.0]).unwrap();
        }
        let system = system
            .with_potential("field", LinearField::<3>, field)
            .unwrap()
            .with_potential("springs", Spring::<3>, springs)
            .unwrap();
        (system, state)
    };
    let (system, mut state) = build();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    r.project(&mut state).unwrap();
    generate::set_temperature(r.system(), &mut state, 300.0);
    let state = ParticleState::new(state.q().to_vec(), state.p().to_vec());
    let (a, na) = run_with(build().0, &state, SolverChoice::Clusters, 50);
    let (b, nb) = run_with(build().0, &state, SolverChoice::Band, 50);
    let (c, nc) = run_with(build().0, &state, SolverChoice::Sparse, 50);
    assert_eq!((na, nb, nc), ("clusters", "band", "sparse"));
    let (ab, ac) = (max_diff(&a, &b), max_diff(&a, &c));
    assert!(
        ab < 1e-11 && ac < 1e-11,
        "clusters-band {ab:e}, clusters-sparse {ac:e}"
    );
    // The forces did something: the states differ from free flight.
    let (f, _) = run_with(
        generate::water(8, 4).unwrap().0,
        &state,
        SolverChoice::Clusters,
        50,
    );
    assert!(max_diff(&a, &f) > 1e-6);
}
