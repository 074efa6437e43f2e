use super::*;
use crate::error::{SolveError, Stage, StepError};
use crate::examples::Pendulum;
use crate::particles::TopologyError;
use crate::{Stop, StormerVerlet, Trajectory};

fn bits(k: usize, out: &RunOutcome) -> Vec<u64> {
    let mut w = Vec::new();
    pack_outcome(k, out, &mut w);
    w
}

/// A member's outcome must not depend on which members ran before it
/// on the same integrator (a rayon worker or an MPI rank reuses one):
/// an integrator that has run another member first gives the same bits
/// as a fresh one. (SHAKE's difference-quotient scale used to be kept
/// from the first run, which changed the last bits of later ones.)
#[test]
fn a_member_does_not_depend_on_its_predecessors() {
    let p = Pendulum::default();
    let template = Integrator::new(p, StormerVerlet, 0.01).rattle();
    for k in 1..8 {
        let z = p.state(0.4 * k as f64, (k as f64).sin());
        let fresh = template
            .clone()
            .run(z.clone(), Stop::Steps(200))
            .stride(50)
            .execute();
        let mut reused = template.clone();
        let _ = reused.run(p.state(0.05, 0.0), Stop::Steps(10)).execute();
        let again = reused.run(z, Stop::Steps(200)).stride(50).execute();
        assert_eq!(bits(k, &fresh), bits(k, &again), "member {k}");
    }
}

/// A particle member that fails at its start stores no state, yet its
/// record names the system's d and m, larger than the record itself: it
/// reads back whole, as does a member that ran.
#[test]
fn a_large_system_without_stored_states_reads_back() {
    use crate::particles::{generate, Options, Rattle};
    let (system, mut state) = generate::water(20, 1).unwrap();
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    let mut broken = state.clone();
    broken.p_mut()[0] = f64::NAN;
    for (z, stored) in [(broken, 0), (state, 6)] {
        let out = rattle.run(&z, Stop::Steps(5)).execute();
        assert_eq!(out.trajectory.len(), stored);
        let words = bits(3, &out);
        assert_eq!(words.len() < 180, stored == 0);
        let (k, back, used) = unpack_outcome(&words).unwrap();
        assert_eq!((k, used), (3, words.len()));
        assert_eq!(bits(3, &back), words);
    }
}

/// Every error variant reads back as itself, after the trajectory and
/// diagnostics; a truncated record is an error at every cut.
#[test]
fn any_number_of_distinct_names_read_back_whole() {
    // Names and formatted reasons are owned texts: the 256 distinct
    // messages kept for `&'static str` fields do not bound them.
    let mut out = RunOutcome {
        trajectory: Trajectory::default(),
        summary: Default::default(),
        error: None,
    };
    for i in 0..400 {
        out.error = Some(if i % 2 == 0 {
            StepError::AtMember {
                stage: Stage::Shake,
                step: i,
                t: 0.5,
                family: format!("family_{i}"),
                member: i as usize,
                source: SolveError::Singular { iterations: 1 },
            }
        } else {
            StepError::Solver {
                solver: "band",
                why: format!("N's half-bandwidth is {i} (at most 64)"),
            }
        });
        let (_, back, _) = unpack_outcome(&bits(1, &out)).unwrap();
        assert_eq!(back, out);
    }
}

#[test]
fn every_error_round_trips() {
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.05)
        .rattle()
        .with_diagnostics();
    let mut out = integ
        .run(Pendulum::default().state(1.0, -0.3), Stop::Steps(9))
        .stride(4)
        .execute();
    assert_eq!(out.trajectory.diagnostics.len(), 4);
    let errors = [
        StepError::InvalidInput {
            what: "stride must be at least 1",
            value: -0.0,
        },
        StepError::NonFinite {
            what: "a message that is longer than eight bytes",
            step: 3,
            t: f64::NAN,
            entry: 5,
        },
        StepError::NewtonNotConverged {
            stage: Stage::BaseMap,
            step: u64::MAX,
            t: 1.5,
            source: SolveError::NotConverged {
                iterations: 50,
                residual: 1e-3,
            },
        },
        StepError::NewtonNotConverged {
            stage: Stage::Fibre,
            step: 1,
            t: 0.0,
            source: SolveError::Singular { iterations: 2 },
        },
        StepError::NewtonNotConverged {
            stage: Stage::ProjectionOntoM,
            step: 1,
            t: 0.0,
            source: SolveError::NonFinite { iterations: 7 },
        },
        StepError::NondegeneracyLost {
            stage: Stage::Rattle,
            step: 4,
            t: 0.2,
            condition: f64::INFINITY,
            limit: 1e12,
        },
        StepError::ComponentJump {
            step: 5,
            t: 0.25,
            det_before: 1.0,
            det_after: -2.0,
        },
        StepError::FibreJump {
            stage: Stage::Shake,
            step: 6,
            t: 0.3,
            lambda: 2.0,
            predicted: 1e-3,
        },
        StepError::NotOnConstraint {
            step: 0,
            t: 0.0,
            residual: 0.1,
            tolerance: 1e-10,
            constraint: "rod".to_string(),
            cause: None,
        },
        StepError::NotOnConstraint {
            step: 0,
            t: 0.0,
            residual: 0.3,
            tolerance: 1e-8,
            constraint: "link 3".to_string(),
            cause: Some(SolveError::Singular { iterations: 4 }),
        },
        StepError::SingularShakeJacobian {
            step: 9,
            t: 0.45,
            iterations: 3,
        },
        StepError::Storage {
            step: 0,
            states: u64::MAX,
            dof: 6,
        },
        StepError::SingularNondegeneracyMatrix {
            stage: Stage::Rattle,
            step: 2,
            t: 0.1,
        },
        StepError::BranchJump {
            step: 12,
            t: 0.6,
            miss: Some(0.86),
            tolerance: 1e-6,
            cause: None,
        },
        StepError::BranchJump {
            step: 13,
            t: 0.65,
            miss: None,
            tolerance: 2e-6,
            cause: Some(Box::new(StepError::FibreJump {
                stage: Stage::Rattle,
                step: 13,
                t: 0.65,
                lambda: 0.5,
                predicted: 1e-2,
            })),
        },
        StepError::Shape {
            what: "q",
            got: 7,
            expected: 9,
        },
        StepError::AtMember {
            stage: Stage::Shake,
            step: 3,
            t: 6.0,
            family: "bond".to_string(),
            member: 123_456,
            source: SolveError::NotConverged {
                iterations: 50,
                residual: 3e-4,
            },
        },
        StepError::Solver {
            solver: "band",
            why: "N's half-bandwidth is 80 (at most 64)".to_string(),
        },
        StepError::Unavailable {
            what: "constraint forces",
            why: "a thermostatted step",
        },
    ];
    let topology = [
        TopologyError::RowShape {
            family: "angle".to_string(),
            member: 2,
            what: "particles",
            got: 2,
            expected: 3,
        },
        TopologyError::RepeatedParticle {
            family: "bond".to_string(),
            member: 4,
            particle: 1,
        },
        TopologyError::DanglingParticle {
            family: "bond".to_string(),
            member: 5,
            particle: 10,
            particles: 9,
        },
        TopologyError::DuplicateMember {
            family: "bond".to_string(),
            first: 0,
            second: 3,
        },
        TopologyError::BadValue {
            family: "bond".to_string(),
            member: 1,
            value: -1.0,
            why: "a length must be positive",
        },
        TopologyError::TooManyConstraints {
            family: "ring".to_string(),
            member: 0,
            constraints: 7,
            coordinates: 6,
        },
        TopologyError::Dimension {
            family: "planar".to_string(),
            stencil: 2,
            system: 3,
        },
    ];
    let errors = errors
        .into_iter()
        .chain(topology.into_iter().map(StepError::Topology));
    // A branch jump whose cause is a branch jump never comes out of a run;
    // read from a corrupt record it is an error, not a deep recursion.
    out.error = Some(StepError::BranchJump {
        step: 1,
        t: 0.1,
        miss: None,
        tolerance: 1e-6,
        cause: Some(Box::new(StepError::BranchJump {
            step: 1,
            t: 0.1,
            miss: Some(1.0),
            tolerance: 1e-6,
            cause: None,
        })),
    });
    assert!(unpack_outcome(&bits(11, &out)).is_err());
    for e in errors {
        out.error = Some(e.clone());
        let w = bits(11, &out);
        let (k, back, used) = unpack_outcome(&w).unwrap();
        assert_eq!((k, used), (11, w.len()));
        assert_eq!(bits(11, &back), w, "{e}");
        assert_eq!(back.error.unwrap().to_string(), e.to_string());
        for cut in 0..w.len() {
            assert!(unpack_outcome(&w[..cut]).is_err(), "cut {cut} of {e}");
        }
    }
}

/// Records follow each other in one buffer (as in a gather).
#[test]
fn records_concatenate() {
    let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    let outs: Vec<_> = (0..3)
        .map(|k| {
            integ
                .run(
                    Pendulum::default().state(0.1 * k as f64, 0.0),
                    Stop::Steps(k),
                )
                .execute()
        })
        .collect();
    let mut w = Vec::new();
    for (k, o) in outs.iter().enumerate() {
        pack_outcome(10 + k, o, &mut w);
    }
    let mut rest = &w[..];
    for (k, o) in outs.iter().enumerate() {
        let (member, back, used) = unpack_outcome(rest).unwrap();
        assert_eq!((member, &back), (10 + k, o));
        rest = &rest[used..];
    }
    assert!(rest.is_empty());
}
