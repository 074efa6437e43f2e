//! The constraints of an integrator that moves the particles itself
//! ([`Rattle::shake_positions`], [`Rattle::project_momenta`]): bit for bit
//! the stages of a step, on every solver; the projections they must be,
//! checked from their defining conditions without the solver; and the
//! refusals of bad input, which leave the arrays as they were.

use geoshake::runtime::particles::{
    generate, stencils::Distance, ConstraintForces, Method, Options, ParticleState, ParticleSystem,
    Rattle, SolverChoice, Table,
};
use geoshake::runtime::{SolveError, Stage, StepError};

/// A weak harmonic tether of every coordinate, brought as forces: with a
/// potential the velocity stage is a stage of its own (without one the
/// cluster path folds it into the position stage).
fn tether(q: &[f64], f: &mut [f64]) -> f64 {
    let mut v = 0.0;
    for (f, q) in f.iter_mut().zip(q) {
        let x = q - 3.0;
        *f -= 2e-3 * x;
        v += 1e-3 * x * x;
    }
    v
}

/// The solvers: rigid water in closed form and on the fixed-size and the
/// general Newton cluster kernels, a chain on the band and the sparse coupled solvers.
#[derive(Copy, Clone, Debug)]
enum Case {
    WaterSettle,
    WaterFixed,
    WaterGeneral,
    ChainBand,
    ChainSparse,
}

const CASES: [Case; 5] = [
    Case::WaterSettle,
    Case::WaterFixed,
    Case::WaterGeneral,
    Case::ChainBand,
    Case::ChainSparse,
];

/// The case's system (with the tether when `forces`) and a state on M^H
/// at 300 K, not tied to any solver (stamp cleared), and a solver for it.
fn setup(case: Case, method: Method, forces: bool, tol: f64) -> (Rattle, ParticleState) {
    let (system, state) = match case {
        Case::WaterSettle | Case::WaterFixed | Case::WaterGeneral => {
            generate::water(12, 7).unwrap()
        }
        Case::ChainBand | Case::ChainSparse => generate::chain(40, 7).unwrap(),
    };
    let solver = match case {
        Case::ChainBand => SolverChoice::Band,
        Case::ChainSparse => SolverChoice::Sparse,
        _ => SolverChoice::Clusters,
    };
    let system = if forces {
        system.with_forces(tether)
    } else {
        system
    };
    let options = Options {
        tol,
        method,
        solver,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, 2.0, options).unwrap();
    match case {
        Case::WaterGeneral => rattle.use_general_cluster_kernel(),
        Case::WaterFixed => rattle.use_newton_cluster_kernel(),
        _ => {}
    }
    let mut state = state;
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    (rattle, state)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn shake_positions_is_the_position_stage_of_a_step() {
    for case in CASES {
        let (mut rattle, mut state) = setup(case, Method::Shake, false, 1e-12);
        let (q0, p0) = (state.q().to_vec(), state.p().to_vec());
        let h = rattle.step_size();
        // x̃ = q0 + h M⁻¹ p0, in the step's own expression.
        let inv_m = rattle.system().inverse_masses().to_vec();
        let mut x = q0.clone();
        for (a, w) in inv_m.iter().enumerate() {
            let w = h * w;
            for c in 3 * a..3 * a + 3 {
                x[c] = q0[c] + w * p0[c];
            }
        }
        let unconstrained = x.clone();
        // A state no solver made: the step starts cold, as the call does.
        rattle.step(&mut state).unwrap();
        let (mut other, _) = setup(case, Method::Shake, false, 1e-12);
        let info = other.shake_positions(&q0, &mut x).unwrap();
        assert_eq!(bits(&x), bits(state.q()), "{case:?}");
        assert!(info.residual.unwrap() <= 1e-12, "{case:?}: {info:?}");
        assert!(
            x != unconstrained,
            "{case:?}: the constraints moved nothing"
        );
    }
}

#[test]
fn project_momenta_is_the_velocity_stage_of_a_step() {
    for case in CASES {
        let (mut shake, mut s_shake) = setup(case, Method::Shake, true, 1e-12);
        let (mut rattle, mut s_rattle) = setup(case, Method::Rattle, true, 1e-12);
        assert_eq!(bits(s_shake.q()), bits(s_rattle.q()));
        assert_eq!(bits(s_shake.p()), bits(s_rattle.p()));
        shake.step(&mut s_shake).unwrap();
        rattle.step(&mut s_rattle).unwrap();
        // The same position stage, and SHAKE's p is p′ = p½ − (h/2) ∇V(q1).
        assert_eq!(bits(s_shake.q()), bits(s_rattle.q()), "{case:?}");
        let mut p = s_shake.p().to_vec();
        let info = shake.project_momenta(s_shake.q(), &mut p).unwrap();
        assert_eq!(bits(&p), bits(s_rattle.p()), "{case:?}");
        assert!(info.hidden.unwrap() < 1e-12, "{case:?}: {info:?}");
        assert!(p != s_shake.p(), "{case:?}: the projection moved nothing");
    }
}

/// A small deterministic generator (xorshift*), uniform in [−1, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let r = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d);
        (r >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn at(v: &[f64], a: usize) -> [f64; 3] {
    [v[3 * a], v[3 * a + 1], v[3 * a + 2]]
}

/// Rigid water from the conditions that define the result, without the
/// solver: a molecule's 9 coordinates are fixed by its 3 bond lengths and
/// by forces along the bonds at q0, which carry no net force (3) and no
/// torque about the origin (3). So after `shake_positions` every bond has
/// its length, and Σ_a m_a (x_a − x̃_a) and Σ_a q0_a × m_a (x_a − x̃_a)
/// vanish per molecule; after `project_momenta` every bond's relative
/// velocity is across it, and the change of p has no net force or torque
/// about q's origin. Both ways of solving a rigid water: in closed form
/// and by Newton.
#[test]
fn the_results_are_the_projections_they_must_be() {
    for case in [Case::WaterSettle, Case::WaterFixed] {
        the_results_are_the_projections_on(case);
    }
}

fn the_results_are_the_projections_on(case: Case) {
    let (mut rattle, state) = setup(case, Method::Rattle, false, 1e-13);
    let q0 = state.q().to_vec();
    let m = rattle.system().masses().to_vec();
    let lengths: Vec<f64> = rattle.system().constraint_families()[0]
        .table()
        .all_data()
        .to_vec();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let kicked: Vec<f64> = q0.iter().map(|q| q + 0.05 * rng.next()).collect();
    let mut x = kicked.clone();
    let info = rattle.shake_positions(&q0, &mut x).unwrap();
    // Newton iterates; the closed form does not.
    match case {
        Case::WaterSettle => assert_eq!(info.shake_iterations, 0, "{info:?}"),
        _ => assert!(info.shake_iterations >= 2, "{info:?}"),
    }
    let scale = q0.iter().fold(0.0f64, |s, q| s.max(q.abs()));
    for mol in 0..q0.len() / 9 {
        let atoms = [3 * mol, 3 * mol + 1, 3 * mol + 2];
        for (k, (a, b)) in [(0, 1), (0, 2), (1, 2)].into_iter().enumerate() {
            let (xa, xb) = (at(&x, atoms[a]), at(&x, atoms[b]));
            let r = (0..3).map(|c| (xa[c] - xb[c]).powi(2)).sum::<f64>().sqrt();
            let l = lengths[3 * mol + k];
            assert!(
                (r - l).abs() <= 2e-13 * l,
                "molecule {mol}: |r| = {r}, l = {l}"
            );
        }
        // Each m_a (x_a − x̃_a) carries the rounding of the positions'
        // digits, ε m_a |x_a|; the torque's lever is at most `scale`.
        let (mut force, mut torque) = ([0.0; 3], [0.0; 3]);
        let (mut size, mut digits) = (0.0f64, 0.0);
        for &a in &atoms {
            let dp: [f64; 3] = std::array::from_fn(|c| m[a] * (x[3 * a + c] - kicked[3 * a + c]));
            let t = cross(at(&q0, a), dp);
            for c in 0..3 {
                force[c] += dp[c];
                torque[c] += t[c];
                size = size.max(dp[c].abs());
                digits += m[a] * x[3 * a + c].abs().max(kicked[3 * a + c].abs());
            }
        }
        // Not vacuous: the constraints moved every molecule.
        assert!(size > 1e-3, "molecule {mol}: moved by {size}");
        let bound = 8.0 * f64::EPSILON * digits;
        for c in 0..3 {
            assert!(force[c].abs() <= bound, "net force {force:?} > {bound}");
            assert!(torque[c].abs() <= 2.0 * bound * scale, "torque {torque:?}");
        }
    }
    // Momenta at the new positions (on M), drawn at random.
    let p_in: Vec<f64> = (0..q0.len()).map(|_| 10.0 * rng.next()).collect();
    let mut p = p_in.clone();
    rattle.project_momenta(&x, &mut p).unwrap();
    for mol in 0..q0.len() / 9 {
        let atoms = [3 * mol, 3 * mol + 1, 3 * mol + 2];
        for (a, b) in [(0, 1), (0, 2), (1, 2)] {
            let (ia, ib) = (atoms[a], atoms[b]);
            let (mut dot, mut size) = (0.0, 0.0);
            for c in 0..3 {
                let dv = p[3 * ia + c] / m[ia] - p[3 * ib + c] / m[ib];
                let dr = x[3 * ia + c] - x[3 * ib + c];
                dot += dv * dr;
                size += (p[3 * ia + c] / m[ia])
                    .abs()
                    .max((p[3 * ib + c] / m[ib]).abs())
                    * dr.abs();
            }
            assert!(
                dot.abs() <= 64.0 * f64::EPSILON * size,
                "(v_a − v_b)·r = {dot}"
            );
        }
        let (mut force, mut torque) = ([0.0; 3], [0.0; 3]);
        let (mut size, mut digits) = (0.0f64, 0.0);
        for &a in &atoms {
            let dp: [f64; 3] = std::array::from_fn(|c| p[3 * a + c] - p_in[3 * a + c]);
            let t = cross(at(&x, a), dp);
            for c in 0..3 {
                force[c] += dp[c];
                torque[c] += t[c];
                size = size.max(dp[c].abs());
                digits += p[3 * a + c].abs().max(p_in[3 * a + c].abs());
            }
        }
        assert!(size > 1e-2, "molecule {mol}: p changed by {size}");
        let bound = 64.0 * f64::EPSILON * digits;
        for c in 0..3 {
            assert!(force[c].abs() <= bound, "net force {force:?} > {bound}");
            assert!(torque[c].abs() <= 2.0 * bound * scale, "torque {torque:?}");
        }
    }
}

/// Momenta are projected wherever the positions are, on M or not, and the
/// same way by every solver: the coupled ones check a position stage's
/// result, not positions someone else made.
#[test]
fn project_momenta_takes_positions_off_m_on_every_solver() {
    let mut results = Vec::new();
    for case in [Case::ChainBand, Case::ChainSparse] {
        let (mut rattle, state) = setup(case, Method::Rattle, false, 1e-10);
        let mut rng = Rng(17);
        let q: Vec<f64> = state.q().iter().map(|q| q + 0.01 * rng.next()).collect();
        let mut p = state.p().to_vec();
        let info = rattle.project_momenta(&q, &mut p).unwrap();
        assert!(info.hidden.unwrap() < 1e-12, "{case:?}: {info:?}");
        results.push(p);
    }
    // The same chain on the cluster path (one cluster of 40 constraints is
    // too large for it): split into two chains by dropping one bond.
    let (system, state) = generate::chain(40, 7).unwrap();
    let bonds = system.constraint_families()[0].table().clone();
    let mut split = Table::new(2, 1);
    for k in 0..bonds.len() {
        if k % 10 != 9 {
            let ab = bonds.particles(k);
            split
                .push(&[ab[0] as usize, ab[1] as usize], bonds.data(k))
                .unwrap();
        }
    }
    let system = ParticleSystem::new(3, system.masses().to_vec())
        .unwrap()
        .with_constraints("bond", Distance::<3>, split)
        .unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    assert_eq!(rattle.solver_name(), "clusters");
    let mut rng = Rng(17);
    let q: Vec<f64> = state.q().iter().map(|q| q + 0.01 * rng.next()).collect();
    let mut p = state.p().to_vec();
    let info = rattle.project_momenta(&q, &mut p).unwrap();
    assert!(info.hidden.unwrap() < 1e-12, "{info:?}");
    // Band and sparse: the same linear solve, to round-off.
    let worst = results[0]
        .iter()
        .zip(&results[1])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let size = results[0].iter().fold(0.0f64, |s, p| s.max(p.abs()));
    assert!(worst <= 1e-12 * size, "band and sparse differ by {worst}");
}

/// A dimer of masses 1 and 3, bond length 1 along x.
fn dimer(solver: SolverChoice) -> Rattle {
    let mut bonds = Table::new(2, 1);
    bonds.push(&[0, 1], &[1.0]).unwrap();
    let system = ParticleSystem::new(3, vec![1.0, 3.0])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bonds)
        .unwrap();
    let options = Options {
        solver,
        ..Options::default()
    };
    Rattle::new(system, 1.0, options).unwrap()
}

#[test]
fn bad_shapes_and_non_finite_entries_are_refused_untouched() {
    let shape = |e: StepError| match e {
        StepError::Shape {
            what,
            got,
            expected,
        } => Some((what, got, expected)),
        _ => None,
    };
    let mut r = dimer(SolverChoice::Clusters);
    let q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let mut x = [0.0, 0.1, 0.0, 1.2, 0.0, 0.0];
    let x_in = x;
    let e = r.shake_positions(&q0[..5], &mut x).unwrap_err();
    assert_eq!(shape(e), Some(("q0", 5, 6)));
    let e = r.shake_positions(&q0, &mut x[..4]).unwrap_err();
    assert_eq!(shape(e), Some(("x", 4, 6)));
    let mut bad = q0;
    bad[4] = f64::NAN;
    let e = r.shake_positions(&bad, &mut x).unwrap_err();
    assert!(
        matches!(e, StepError::NonFinite { what, entry: 4, step: 0, .. } if what.contains("q0")),
        "{e}"
    );
    let mut bad_x = x;
    bad_x[1] = f64::INFINITY;
    let e = r.shake_positions(&q0, &mut bad_x).unwrap_err();
    assert!(matches!(e, StepError::NonFinite { entry: 1, .. }), "{e}");
    assert_eq!(x, x_in);

    let mut p = [1.0, 0.5, 0.0, 0.0, 0.0, 0.0];
    let p_in = p;
    let e = r.project_momenta(&q0, &mut p[..5]).unwrap_err();
    assert_eq!(shape(e), Some(("p", 5, 6)));
    let e = r.project_momenta(&q0[1..], &mut p).unwrap_err();
    assert_eq!(shape(e), Some(("q", 5, 6)));
    let mut bad_p = p;
    bad_p[2] = f64::NAN;
    let e = r.project_momenta(&q0, &mut bad_p).unwrap_err();
    // Entries count z = (q, p): p's third is entry 6 + 2.
    assert!(matches!(e, StepError::NonFinite { entry: 8, .. }), "{e}");
    assert_eq!(p, p_in);
}

/// No point of the fibre through x̃ is on M: x̃'s bond is across q0's and
/// longer than l, and moving along q0's bond only lengthens it. Newton
/// fails at the member, on every solver, and says it is SHAKE's equation.
#[test]
fn an_unreachable_constraint_is_a_typed_failure_at_its_member() {
    for solver in [
        SolverChoice::Clusters,
        SolverChoice::Band,
        SolverChoice::Sparse,
    ] {
        let mut r = dimer(solver);
        let q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let mut x = [0.0, 0.0, 0.0, 0.01, 1.5, 0.0];
        let x_in = x;
        let e = r.shake_positions(&q0, &mut x).unwrap_err();
        assert!(
            matches!(
                e,
                StepError::AtMember { stage: Stage::Shake, member: 0, ref family, step: 0, .. }
                    if family == "bond"
            ),
            "{solver:?}: {e}"
        );
        assert_eq!(x, x_in, "{solver:?}");
        // Both particles at one point: no bond direction, N = 0.
        let q = [0.5, 0.0, 0.0, 0.5, 0.0, 0.0];
        let mut p = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let e = r.project_momenta(&q, &mut p).unwrap_err();
        assert!(
            matches!(
                e,
                StepError::AtMember {
                    stage: Stage::Rattle,
                    source: SolveError::Singular { .. },
                    ..
                }
            ),
            "{solver:?}: {e}"
        );
        assert_eq!(p, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0], "{solver:?}");
    }
}

/// The calls overwrite the caches a step leaves for the next (ν, N's
/// factor): the last step's constraint forces are no longer available.
#[test]
fn the_calls_forget_the_last_step() {
    for case in [Case::WaterFixed, Case::ChainBand] {
        let (mut rattle, mut state) = setup(case, Method::Rattle, false, 1e-10);
        let mut fc = ConstraintForces::new(rattle.system());
        rattle.step(&mut state).unwrap();
        rattle.constraint_forces(&state, &mut fc).unwrap();
        let q = state.q().to_vec();
        let mut x = q.clone();
        rattle.shake_positions(&q, &mut x).unwrap();
        let e = rattle.constraint_forces(&state, &mut fc).unwrap_err();
        assert!(matches!(e, StepError::Unavailable { .. }), "{case:?}: {e}");

        rattle.step(&mut state).unwrap();
        rattle.constraint_forces(&state, &mut fc).unwrap();
        let mut p = state.p().to_vec();
        rattle.project_momenta(&q, &mut p).unwrap();
        let e = rattle.constraint_forces(&state, &mut fc).unwrap_err();
        assert!(matches!(e, StepError::Unavailable { .. }), "{case:?}: {e}");
    }
}
