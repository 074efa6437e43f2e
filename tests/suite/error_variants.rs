//! Every error variant produced by a real failure, with the right step and
//! time: step k fails ⇒ the error says step k and t = t0 + k·h, and the run
//! keeps its states up to k − 1 (also with a stride that does not hit k − 1).
//!
//! The failures are planted in a pendulum that is exact up to a height c of
//! the bob and broken above it (a NaN force, NaN constraint, a singular or
//! shrunken or sign-flipped N, a vanishing constraint Jacobian). The bob
//! rises monotonically at the start of the swing; c is put halfway between
//! its heights at steps K − 1 and K of the unbroken run, so step K is the
//! first whose evaluations see the break (Newton's iterates stay within
//! O(h²) of the states, far below the half step between them).

use geoshake::models::Pendulum;
use geoshake::{
    ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, Integrator, SolveError, Stage,
    State, StepError, Stop, StormerVerlet,
};

const H: f64 = 0.01;
const T0: f64 = 0.5;
const K: u64 = 12;
/// The factor of the [`Break::SteepJacobian`] break, and the jump ratio of
/// its run: the correction (1 − 1/STEEP)λ* = 0.44λ* exceeds JUMP times the
/// prediction λ*/STEEP = 0.56λ*, while Newton, contracting by
/// 1 − 1/STEEP < ½, still converges (at ½ the iteration gives up as
/// stagnant: with the default ratio 1 the two limits coincide, STEEP = 2).
const STEEP: f64 = 1.8;
const JUMP: f64 = 0.5;

#[derive(Copy, Clone, Debug, PartialEq)]
enum Break {
    None,
    NanForce,
    NanConstraint,
    SingularN,
    TinyN,
    FlippedN,
    FlatJacobian,
    SteepJacobian,
}

/// The pendulum, broken by `brk` where the bob is higher than `c`.
#[derive(Copy, Clone, Debug)]
struct Broken {
    sys: Pendulum,
    brk: Break,
    c: f64,
}

impl Broken {
    fn on(&self, b: Break, q: &[f64]) -> bool {
        self.brk == b && q[1] > self.c
    }
}

impl Hamiltonian for Broken {
    fn dof(&self) -> usize {
        self.sys.dof()
    }
    fn separable(&self) -> bool {
        self.sys.separable()
    }
    fn quadratic_kinetic(&self) -> bool {
        self.sys.quadratic_kinetic()
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        self.sys.hamiltonian(q, p)
    }
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        self.sys.grad_q(q, p, h_q);
        if self.on(Break::NanForce, q) {
            h_q[1] = f64::NAN;
        }
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        self.sys.grad_p(q, p, h_p)
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        self.sys.hessian(q, p, h_zz)
    }
}

impl ConstrainedSystem for Broken {
    fn constraint_count(&self) -> usize {
        self.sys.constraint_count()
    }
    fn kind(&self) -> ConstraintKind {
        self.sys.kind()
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        self.sys.jacobian_pattern()
    }
    fn constraint_name(&self, i: usize) -> &str {
        self.sys.constraint_name(i)
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.sys.constraints(q, p, g);
        if self.on(Break::NanConstraint, q) {
            g[0] = f64::NAN;
        }
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        self.sys.constraint_jacobian(q, p, g_z);
        if self.on(Break::FlatJacobian, q) {
            g_z.fill(0.0);
        } else if self.on(Break::SteepJacobian, q) {
            // A Jacobian STEEP times too steep: SHAKE's first Newton
            // iterate λ₁ = λ*/STEEP undershoots, and the corrections that
            // follow (contracting by 1 − 1/STEEP, so Newton still
            // converges to the true λ*) add up to (1 − 1/STEEP)λ*, more
            // than JUMP·λ₁: the jump test's signature of a far root.
            for x in g_z.iter_mut() {
                *x *= STEEP;
            }
        }
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        self.sys.constraint_hessian(q, p, lambda, out)
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.sys.hidden_constraints(q, p, out)
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.sys.hidden_constraint_jacobian(q, p, out)
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        self.sys.nondegeneracy_matrix(q, p, n);
        if self.on(Break::SingularN, q) {
            n[0] = 0.0;
        } else if self.on(Break::TinyN, q) {
            n[0] *= 1e-12;
        } else if self.on(Break::FlippedN, q) {
            n[0] = -n[0];
        }
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        self.sys.fibre_flow(lambda, q, p)
    }
}

/// The bob starts at θ = 0.5 from the bottom, swinging up at ω = 2: it
/// rises by about 0.01 per step for the first K steps.
fn z0() -> State {
    let (s, c) = 0.5f64.sin_cos();
    State::from_slices(&[s, -c], &[2.0 * c, 2.0 * s])
}

/// The break height: halfway between the bob's heights at steps K − 1 and
/// K of the unbroken run.
fn threshold() -> f64 {
    let sys = Broken {
        sys: Pendulum::new(1.0, 9.81),
        brk: Break::None,
        c: 0.0,
    };
    let traj = Integrator::new(sys, StormerVerlet, H)
        .run(z0(), Stop::Steps(K))
        .execute()
        .into_result()
        .unwrap();
    let y: Vec<f64> = traj.states().map(|z| z.q[1]).collect();
    assert!(
        y.windows(2).all(|w| w[1] - w[0] > 1e-3),
        "the bob rises: {y:?}"
    );
    0.5 * (y[K as usize - 1] + y[K as usize])
}

/// Runs the broken pendulum with `stride` and checks where the run ended;
/// returns the error.
fn fails_at_k(brk: Break, stride: u64) -> StepError {
    let sys = Broken {
        sys: Pendulum::new(1.0, 9.81),
        brk,
        c: threshold(),
    };
    let mut integ = Integrator::new(sys, StormerVerlet, H);
    if brk == Break::SteepJacobian {
        // Contracting by 1 − 1/STEEP ≈ 0.44, Newton needs ~45 iterations
        // to reach round-off: let it, so that the jump test, not the
        // iteration count, is what stops the step.
        let mut opts = *integ.options();
        opts.newton.max_iterations = 200;
        opts.jump_ratio = JUMP;
        integ = integ.with_options(opts);
    }
    let out = integ
        .run(z0(), Stop::Steps(3 * K))
        .start_time(T0)
        .stride(stride)
        .execute();
    let e = out
        .error
        .clone()
        .unwrap_or_else(|| panic!("{brk:?}: the run went through"));
    assert_eq!(e.step(), K, "{brk:?}: {e}");
    assert_eq!(e.time(), Some(T0 + K as f64 * H), "{brk:?}: {e}");
    let steps = out.trajectory.steps();
    assert_eq!(
        steps.last(),
        Some(&(K - 1)),
        "{brk:?}, stride {stride}: {steps:?}"
    );
    let expected: Vec<u64> = (0..K).filter(|k| k % stride == 0).chain([K - 1]).collect();
    let mut expected = expected;
    expected.dedup();
    assert_eq!(steps, expected, "{brk:?}, stride {stride}");
    e
}

fn each_stride(brk: Break) -> StepError {
    let e = fails_at_k(brk, 1);
    assert_eq!(fails_at_k(brk, 5), e, "{brk:?}: the stride changes nothing");
    println!("{brk:?}: {e}");
    e
}

#[test]
fn non_finite_state_says_where() {
    let e = each_stride(Break::NanForce);
    // The force is NaN in its y entry: p_y of z = (q, p), entry d + 1 = 3.
    assert!(matches!(e, StepError::NonFinite { entry: 3, .. }), "{e:?}");
    assert!(e.to_string().contains("entry 3"), "{e}");
}

#[test]
fn newton_failure_carries_iterations_and_residual() {
    let e = each_stride(Break::NanConstraint);
    assert!(
        matches!(
            e,
            StepError::NewtonNotConverged {
                stage: Stage::Shake,
                source: SolveError::NonFinite { .. },
                ..
            }
        ),
        "{e:?}"
    );
}

#[test]
fn singular_n_is_its_own_variant() {
    let e = each_stride(Break::SingularN);
    assert!(
        matches!(e, StepError::SingularNondegeneracyMatrix { .. }),
        "{e:?}"
    );
    assert!(!e.to_string().contains("inf"), "{e}");
}

#[test]
fn nondegeneracy_lost_reports_a_computed_condition() {
    let e = each_stride(Break::TinyN);
    match e {
        StepError::NondegeneracyLost {
            condition, limit, ..
        } => {
            // N shrank by 1e12 since the start: the relative condition is 1e12.
            assert!((condition / 1e12 - 1.0).abs() < 1e-6, "{condition:e}");
            assert_eq!(limit, 1e10);
        }
        e => panic!("expected NondegeneracyLost, got {e:?}"),
    }
    let msg = e.to_string();
    assert!(msg.contains("1.0e12") && msg.contains("1.0e10"), "{msg}");
}

#[test]
fn component_jump_when_det_n_changes_sign() {
    let e = each_stride(Break::FlippedN);
    assert!(
        matches!(e, StepError::ComponentJump { det_before, det_after, .. } if det_before > 0.0 && det_after < 0.0),
        "{e:?}"
    );
}

#[test]
fn singular_shake_jacobian_is_not_lost_nondegeneracy() {
    let e = each_stride(Break::FlatJacobian);
    assert!(
        matches!(e, StepError::SingularShakeJacobian { .. }),
        "{e:?}"
    );
    assert!(!e.to_string().contains("nondegeneracy"), "{e}");
}

#[test]
fn a_far_root_is_a_fibre_jump() {
    let e = each_stride(Break::SteepJacobian);
    match e {
        StepError::FibreJump {
            stage: Stage::Shake,
            lambda,
            predicted,
            ..
        } => {
            // λ₁ = λ*/STEEP up to the equation's curvature over the
            // step, O(‖λ‖) = O(h) relative (λ ≈ 0.05 here): what the test
            // compares the correction with.
            assert!(
                (lambda / predicted - STEEP).abs() < 0.01 * STEEP,
                "λ = {lambda:e}, λ₁ = {predicted:e}"
            );
        }
        e => panic!("expected FibreJump, got {e:?}"),
    }
}

#[test]
fn a_single_step_is_step_1_at_t_h() {
    // Broken just above the start: the first step's new state sees it.
    let z = z0();
    let sys = Broken {
        sys: Pendulum::new(1.0, 9.81),
        brk: Break::TinyN,
        c: z.q[1] + 1e-9,
    };
    let e = Integrator::new(sys, StormerVerlet, H).step(&z).unwrap_err();
    assert!(matches!(e, StepError::NondegeneracyLost { .. }), "{e:?}");
    assert_eq!((e.step(), e.time()), (1, Some(H)));
}

#[test]
fn off_m_names_the_constraint_and_keeps_the_cause() {
    let sys = Pendulum::new(1.0, 9.81);
    let off = State::from_slices(&[0.0, -1.1], &[0.0, 0.0]);
    let out = Integrator::new(sys, StormerVerlet, H)
        .run(off, Stop::Steps(3))
        .start_time(T0)
        .execute();
    match out.error {
        Some(StepError::NotOnConstraint {
            step: 0,
            t,
            ref constraint,
            residual,
            ..
        }) => {
            assert_eq!(t, T0);
            assert_eq!(constraint, "rod");
            assert!((residual - 0.21).abs() < 1e-12, "{residual}");
        }
        ref e => panic!("expected NotOnConstraint, got {e:?}"),
    }
    assert!(out.error.unwrap().to_string().contains("`rod`"));
    // Initial data that cannot be brought onto M (q = 0: g_q = 0 there, so
    // Gauss–Newton's matrix is singular) keeps why as its source.
    let e = Integrator::new(sys, StormerVerlet, H)
        .project_to_hidden(&State::from_slices(&[0.0, 0.0], &[0.0, 0.0]))
        .unwrap_err();
    assert!(
        matches!(e, StepError::NotOnConstraint { cause: Some(_), .. }),
        "{e:?}"
    );
    assert!(std::error::Error::source(&e).is_some());
}

#[test]
fn invalid_input_before_any_step() {
    let e = Integrator::new(Pendulum::new(1.0, 9.81), StormerVerlet, 0.0)
        .run(z0(), Stop::Steps(3))
        .execute()
        .error
        .unwrap();
    assert!(matches!(e, StepError::InvalidInput { .. }));
    assert_eq!(e.time(), None);
}
