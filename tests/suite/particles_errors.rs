//! Typed errors of the large-system path: every bad input is refused with
//! the family, member, step and time that explain it, and a run that fails
//! at step k returns the states up to k − 1.

use geoshake::runtime::particles::{
    generate, stencils::Distance, Options, ParticleState, ParticleSystem, Rattle, Stencil, Table,
    TopologyError,
};
use geoshake::runtime::{SolveError, Stage, StepError, Stop};

fn bonds(rows: &[(usize, usize, f64)]) -> Table {
    let mut t = Table::new(2, 1);
    for &(i, j, l) in rows {
        t.push(&[i, j], &[l]).unwrap();
    }
    t
}

#[test]
fn dangling_index_names_family_and_member() {
    let e = ParticleSystem::new(3, vec![1.0; 3])
        .unwrap()
        .with_constraints("bond", Distance::<3>, bonds(&[(0, 1, 1.0), (1, 7, 1.0)]))
        .err()
        .unwrap();
    assert_eq!(
        e,
        TopologyError::DanglingParticle {
            family: "bond".into(),
            member: 1,
            particle: 7,
            particles: 3
        }
    );
}

#[test]
fn duplicate_member_is_refused() {
    let e = ParticleSystem::new(3, vec![1.0; 3])
        .unwrap()
        .with_constraints(
            "bond",
            Distance::<3>,
            bonds(&[(0, 1, 1.0), (1, 2, 1.0), (1, 0, 1.0)]),
        )
        .err()
        .unwrap();
    assert_eq!(
        e,
        TopologyError::DuplicateMember {
            family: "bond".into(),
            first: 0,
            second: 2
        }
    );
}

#[test]
fn repeated_particle_in_a_row_is_refused() {
    let mut t = Table::new(2, 1);
    let e = t.push(&[4, 4], &[1.0]).unwrap_err();
    assert!(matches!(
        e,
        TopologyError::RepeatedParticle {
            member: 0,
            particle: 4,
            ..
        }
    ));
    assert!(t.is_empty());
}

#[test]
fn more_constraints_than_coordinates_in_a_cluster() {
    // Three different lengths between two particles on a line: 3
    // constraints on 2 coordinates (a separate, valid cluster comes first).
    let system = ParticleSystem::new(1, vec![1.0; 4])
        .unwrap()
        .with_constraints(
            "rod",
            Distance::<1>,
            bonds(&[(0, 1, 1.0), (2, 3, 1.0), (3, 2, 2.0), (2, 3, 3.0)]),
        )
        .unwrap();
    let e = Rattle::new(system, 0.1, Options::default()).err().unwrap();
    assert_eq!(
        e,
        StepError::Topology(TopologyError::TooManyConstraints {
            family: "rod".into(),
            member: 1,
            constraints: 3,
            coordinates: 2
        })
    );
}

#[test]
fn step_size_must_be_finite_and_positive() {
    for h in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let (system, _) = generate::chain(3, 1).unwrap();
        let e = Rattle::new(system, h, Options::default()).err().unwrap();
        assert!(
            matches!(e, StepError::InvalidInput { what, .. } if what.contains("step size")),
            "{h}: {e}"
        );
    }
}

#[test]
fn nan_in_the_state_is_reported_where_it_is() {
    let (system, mut state) = generate::chain(3, 1).unwrap();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    state.p_mut()[7] = f64::NAN;
    let e = r.step(&mut state).unwrap_err();
    assert_eq!(
        e,
        // p[7] is entry d + 7 of z = (q, p), d = 12.
        StepError::NonFinite {
            what: "initial state",
            step: 1,
            t: 2.0,
            entry: 19
        }
    );
    assert_eq!(state.step(), 0);
}

#[test]
fn wrong_state_shape_is_refused() {
    let (system, _) = generate::chain(3, 1).unwrap();
    let mut r = Rattle::new(system, 2.0, Options::default()).unwrap();
    let mut s = ParticleState::new(vec![0.0; 5], vec![0.0; 12]);
    assert!(matches!(
        r.step(&mut s),
        Err(StepError::Shape {
            what: "q",
            got: 5,
            expected: 12
        })
    ));
}

/// A huge h: no point of M is reached along the fibre, Newton fails at
/// step 1, time t0 + h; the run keeps state 0 only.
#[test]
fn huge_step_fails_at_the_first_step() {
    for solver in ["clusters", "band"] {
        let (system, mut state) = if solver == "clusters" {
            generate::water(8, 3).unwrap()
        } else {
            generate::chain(20, 3).unwrap()
        };
        let mut r = Rattle::new(system, 2.0e4, Options::default()).unwrap();
        assert_eq!(r.solver_name(), solver);
        r.project(&mut state).unwrap();
        generate::set_temperature(r.system(), &mut state, 300.0);
        let mut state = state.with_time(10.0);
        let before = state.clone();
        let out = r.run(&state, Stop::Steps(5)).execute();
        assert_eq!(out, r.run(&state, Stop::Steps(5)).execute(), "a second try");
        // In place: the same error, and the state left as it was.
        assert_eq!(r.run_in_place(&mut state, 5).error, out.error);
        let (traj, e) = out.into_result().unwrap_err();
        match e {
            StepError::AtMember {
                stage: Stage::Shake,
                step,
                t,
                ref family,
                source: SolveError::NotConverged { iterations, .. },
                ..
            } => {
                assert_eq!((step, t, family.as_str()), (1, 10.0 + 2.0e4, "bond"));
                assert!(iterations > 0);
            }
            StepError::AtMember {
                step,
                t,
                source: SolveError::Singular { .. },
                ..
            } => {
                assert_eq!((step, t), (1, 10.0 + 2.0e4))
            }
            other => panic!("{solver}: {other}"),
        }
        assert_eq!((traj.len(), traj.step(0)), (1, 0));
        assert_eq!(state, before, "a failed step leaves the state as it was");
    }
}

/// V = −τ θ(x_b − x_a) in the plane: a constant torque spins a dimer up,
/// ω(t) = ω0 + τ t / I, until h ω > 1 and |r1| = l has no solution along
/// the fibre: the step that fails is some k > 1, found by the run.
struct Torque;

impl Stencil for Torque {
    const ARITY: usize = 2;
    const DIM: usize = 2;
    const DATA: usize = 1;
    fn value(&self, x: &[f64], c: &[f64]) -> f64 {
        -c[0] * (x[3] - x[1]).atan2(x[2] - x[0])
    }
    fn gradient(&self, x: &[f64], c: &[f64], g: &mut [f64]) -> f64 {
        let (rx, ry) = (x[2] - x[0], x[3] - x[1]);
        let r2 = rx * rx + ry * ry;
        // dθ/dr = (−r_y, r_x)/|r|².
        let (tx, ty) = (-ry / r2, rx / r2);
        g[0] = c[0] * tx;
        g[1] = c[0] * ty;
        g[2] = -c[0] * tx;
        g[3] = -c[0] * ty;
        self.value(x, c)
    }
}

#[test]
fn newton_failure_at_step_k_returns_states_up_to_k_minus_1() {
    let mut torque = Table::new(2, 1);
    torque.push(&[0, 1], &[5.0]).unwrap();
    let system = ParticleSystem::new(2, vec![1.0, 1.0])
        .unwrap()
        .with_constraints("bond", Distance::<2>, bonds(&[(0, 1, 1.0)]))
        .unwrap()
        .with_potential("torque", Torque, torque)
        .unwrap();
    let h = 0.1;
    let mut r = Rattle::new(system, h, Options::default()).unwrap();
    let t0 = 3.0;
    let mut state = ParticleState::new(vec![0.0, 0.0, 1.0, 0.0], vec![0.0; 4]).with_time(t0);
    // Stride 3: the last good state is stored whether or not it is on it.
    let out = r.run(&state, Stop::Steps(10_000)).stride(3).execute();
    assert_eq!(out.summary.steps + 1, out.error.as_ref().unwrap().step());
    let (traj, e) = out.into_result().unwrap_err();
    let k = match e {
        StepError::AtMember {
            step,
            t: time,
            source: SolveError::NotConverged { residual, .. },
            ref family,
            member,
            ..
        } => {
            assert_eq!(time, t0 + step as f64 * h);
            assert!(residual > 1e-10);
            assert_eq!((family.as_str(), member), ("bond", 0));
            step
        }
        StepError::AtMember {
            step,
            t: time,
            source: SolveError::Singular { .. },
            ..
        } => {
            assert_eq!(time, t0 + step as f64 * h);
            step
        }
        other => panic!("{other}"),
    };
    assert!(k > 10, "the dimer must spin up first (failed at {k})");
    let last = traj.len() - 1;
    assert_eq!(traj.step(last), k - 1);
    assert_eq!(traj.time(last), t0 + (k - 1) as f64 * h);
    // The same run in place ends at the same state, counted as step k − 1.
    let e = r.run_in_place(&mut state, 10_000).error.unwrap();
    assert_eq!(e.step(), k);
    assert_eq!(state.step(), k - 1);
    assert_eq!((traj.q(last), traj.p(last)), (state.q(), state.p()));
}
