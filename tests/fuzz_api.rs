//! Fuzzing the public API with hostile values: every input class a
//! user can get wrong — parameters, the step size h, the start time, the stop
//! rule, the stride, the options, and the state (wrong length, far from M,
//! zero, non-finite, near the exceptional fibres of the Hopf constraint,
//! Section 5.4.1) — over every base map, a composition, SHAKE and RATTLE,
//! holonomic and momentum-dependent systems.
//!
//! Every case must end in one of two ways:
//! - `Ok`, with finite states on M (|g| within the round-off bound below)
//!   and, for RATTLE and `project_to_hidden`, on M^H;
//! - a typed [`StepError`] with a consistent partial trajectory: an error at
//!   step k ≥ 1 carries the time t0 + k·h and the last stored state is that of
//!   step k − 1 (every stored state is itself on M).
//!
//! Anything else is counted: a *silent* wrong number (an `Ok` off M, a
//! non-finite state, a time that is not t0 + k·h, an inconsistent partial
//! trajectory), a *panic* (caught with `catch_unwind`) or a *hang* (a case
//! that has not answered within [`DEADLINE`] on a watchdog). The test fails
//! if any of the three is non-zero and prints one example of each class.
//!
//! The round-off bounds are those of `runtime_proptest.rs`, made relative
//! to the scale of the terms of g and {g,H} at the state: |g| ≤ 1e-13·s_g
//! with s_g = 1 + |z|∞² (g is a quadratic form in z minus a constant of the
//! same size on M), and |{g,H}| ≤ 1e-12·s_h with s_h = (1 + |z|∞)·(1 + |z|∞ +
//! |∇H|∞) (each term of {g,H} = g_q·H_p − g_p·H_q is a product of a gradient
//! of g, O(|z|), and one of H).
//!
//! `runtime_proptest.rs` checks the accuracy properties (Π∘Sᵏ = Π∘Rᵏ,
//! reversibility) on well-posed random data and `hard_inputs.rs` pins the
//! documented outcome of each hand-picked hard input; this file is their
//! hostile counterpart: random inputs of every class at once, judged only by
//! the contract above, with counts.
//!
//! Modes: `fuzz_api_ci` runs [`CI_CASES`] cases (≈ 10⁴) in the ordinary test
//! run; `fuzz_api_long` (ignored) runs `SHAKE_FUZZ_CASES` cases (default
//! 10⁶) and prints the counts that TESTING.md reports:
//! `SHAKE_FUZZ_CASES=1000000 cargo test --release --test fuzz_api -- --ignored --nocapture`.
//! The case generator is seeded (`SHAKE_FUZZ_SEED`, default 13), so every
//! count is reproducible.

// A NaN must fail every bound: the negated comparisons are the point.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

// The test kit under the name the tests use (`common::models`, …).
use geoshake_testkit as common;

use common::fuzz::{
    assert_clean, env_u64, fuzz_cases, hostile, judge_end, step_error_kind as kind, Verdict,
};
use common::models::*;
use geoshake::{
    BaseMap, Composition, ConstrainedSystem, ImplicitMidpoint, Integrator, NewtonOptions, Options,
    State, StepError, Stop, StormerVerlet, SymplecticEuler,
};
use proptest::prelude::*;
use std::time::Duration;

/// Cases of the CI run.
const CI_CASES: u64 = 10_000;
/// A case that has not answered after this long is a hang (the systems are of
/// the paper's size and runs have at most a few hundred steps: a correct
/// answer takes milliseconds).
const DEADLINE: Duration = Duration::from_secs(5);

// ---------------------------------------------------------------------------
// Cases
// ---------------------------------------------------------------------------

#[derive(Clone, Debug)]
enum Sys {
    /// Holonomic, m = 1, d = 2 (gravity, length).
    Pendulum(f64, f64),
    /// Holonomic, m = 1, d = 3 (gravity, length).
    Spherical(f64, f64),
    /// Holonomic, m = 2, d = 4 (gravity).
    Double(f64),
    /// The same declared with `constrained_system!` (gravity): its
    /// classical steps run on stack arrays (`geoshake::classical::fixed_m`).
    DeclaredDouble(f64),
    /// Non-separable H, holonomic (ε, gravity).
    NonSeparable(f64, f64),
    /// Momentum-dependent g = |z|² − r² (r², γ₁, γ₂), closed-form fibres.
    Hopf(f64, f64, f64),
    /// The same through the general (Newton) fibre flow.
    HopfGeneral(f64, f64, f64),
}

#[derive(Clone, Debug)]
enum Start {
    /// A point of M^H built in closed form from two angles and a speed.
    OnMh(f64, f64, f64),
    /// That point moved by a relative amount in a random direction.
    Near(f64, f64, f64, f64, u64),
    /// Arbitrary entries of any size.
    Far(Vec<f64>),
    Zero,
    /// The point of M^H with one entry replaced (NaN, ±∞, huge).
    NonFinite(f64, f64, usize),
    /// q and p of the given lengths.
    WrongLength(usize, usize),
    /// Hopf: |q| ≈ |p| with q, p almost parallel (false) or orthogonal
    /// (true), off by ε (Section 5.4.1's exceptional fibres).
    Exceptional(f64, bool, f64),
}

#[derive(Clone, Debug)]
enum Op {
    Step,
    Project,
    ProjectToHidden,
    Run {
        stop: StopRule,
        stride: u64,
        t0: f64,
    },
}

#[derive(Clone, Debug)]
enum StopRule {
    Steps(u64),
    /// n steps' worth of time, perturbed relatively by δ.
    NearSteps(u64, f64),
    /// An arbitrary (hostile) time.
    Time(f64),
}

#[derive(Clone, Debug)]
struct Case {
    sys: Sys,
    base: u8,
    triple_jump: bool,
    rattle: bool,
    h: f64,
    options: Options,
    start: Start,
    op: Op,
}

fn sys_strategy() -> impl Strategy<Value = Sys> {
    let g = || hostile(-2.0..2.0);
    let l = || hostile(0.2..3.0);
    prop_oneof![
        (g(), l()).prop_map(|(a, b)| Sys::Pendulum(a, b)),
        (g(), l()).prop_map(|(a, b)| Sys::Spherical(a, b)),
        g().prop_map(Sys::Double),
        g().prop_map(Sys::DeclaredDouble),
        (hostile(0.0..1.0), g()).prop_map(|(a, b)| Sys::NonSeparable(a, b)),
        (l(), g(), g()).prop_map(|(r, a, b)| Sys::Hopf(r, a, b)),
        (l(), g(), g()).prop_map(|(r, a, b)| Sys::HopfGeneral(r, a, b)),
    ]
}

fn start_strategy() -> impl Strategy<Value = Start> {
    let angle = || -3.2f64..3.2;
    prop_oneof![
        6 => (angle(), angle(), -2.0f64..2.0).prop_map(|(a, b, w)| Start::OnMh(a, b, w)),
        3 => (angle(), angle(), -2.0f64..2.0, hostile(1e-12..1e-3), any::<u64>())
            .prop_map(|(a, b, w, e, s)| Start::Near(a, b, w, e, s)),
        1 => prop::collection::vec(hostile(-1e3..1e3), 8).prop_map(Start::Far),
        1 => Just(Start::Zero),
        1 => (angle(), hostile(-1.0..1.0), 0usize..8)
            .prop_map(|(a, x, i)| Start::NonFinite(a, x, i)),
        1 => (0usize..6, 0usize..6).prop_map(|(a, b)| Start::WrongLength(a, b)),
        2 => (angle(), any::<bool>(), hostile(1e-12..1e-2))
            .prop_map(|(a, o, e)| Start::Exceptional(a, o, e)),
    ]
}

fn options_strategy() -> impl Strategy<Value = Options> {
    (
        prop::option::weighted(0.7, Just(())),
        hostile(1e-10..1e-6),
        hostile(1e6..1e12),
        hostile(0.5..2.0),
        any::<bool>(),
        any::<bool>(),
        hostile(1e-16..1e-12),
        hostile(1e-8..1e-4),
        prop_oneof![Just(50usize), 0usize..4, Just(usize::MAX)],
        hostile(1e-8..1e-4),
    )
        .prop_map(
            |(default, tol, cond, jump, comp, every, st, stag, it, rev)| {
                if default.is_some() {
                    return Options::default();
                }
                Options {
                    newton: NewtonOptions {
                        step_tolerance: st,
                        stagnation_threshold: stag,
                        max_iterations: it,
                    },
                    constraint_tolerance: tol,
                    max_condition: cond,
                    jump_ratio: jump,
                    check_component: comp,
                    project_every_step: every,
                    reverse_tolerance: rev,
                }
            },
        )
}

fn op_strategy() -> impl Strategy<Value = Op> {
    let stop = prop_oneof![
        3 => (0u64..30).prop_map(StopRule::Steps),
        2 => (0u64..30, hostile(-1e-10..1e-10)).prop_map(|(n, d)| StopRule::NearSteps(n, d)),
        1 => hostile(-3.0..3.0).prop_map(StopRule::Time),
    ];
    prop_oneof![
        1 => Just(Op::Step),
        1 => Just(Op::Project),
        1 => Just(Op::ProjectToHidden),
        4 => (stop, prop_oneof![4 => Just(1u64), 2 => 2u64..5, 1 => Just(0u64), 1 => Just(u64::MAX)],
              prop_oneof![3 => Just(0.0), 1 => hostile(-1e3..1e3)])
            .prop_map(|(stop, stride, t0)| Op::Run { stop, stride, t0 }),
    ]
}

fn case_strategy() -> impl Strategy<Value = Case> {
    (
        sys_strategy(),
        0u8..3,
        prop::bool::weighted(0.2),
        any::<bool>(),
        prop_oneof![
            6 => (0.005f64..0.2, any::<bool>()).prop_map(|(h, n)| if n { -h } else { h }),
            2 => hostile(1e-14..1e-6),
            2 => hostile(-1e3..1e3),
        ],
        options_strategy(),
        start_strategy(),
        op_strategy(),
    )
        .prop_map(
            |(sys, base, triple_jump, rattle, h, options, start, op)| Case {
                sys,
                base,
                triple_jump,
                rattle,
                h,
                options,
                start,
                op,
            },
        )
}

// ---------------------------------------------------------------------------
// Initial states
// ---------------------------------------------------------------------------

/// A unit vector of dimension n from a seed (a fixed LCG: the direction only
/// needs to be arbitrary, not random in any precise sense).
fn direction(seed: u64, n: usize) -> Vec<f64> {
    let mut x = seed | 1;
    let mut v: Vec<f64> = (0..n)
        .map(|_| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect();
    let n2 = v.iter().map(|a| a * a).sum::<f64>().sqrt().max(1e-300);
    v.iter_mut().for_each(|a| *a /= n2);
    v
}

/// A point of M^H in closed form for each system (for hostile parameters it
/// may be non-finite or off M: that is one more hostile input).
fn on_mh(sys: &Sys, a: f64, b: f64, w: f64) -> State {
    match *sys {
        Sys::Pendulum(gravity, length) => Pendulum { gravity, length }.state(a, w),
        Sys::Spherical(gravity, length) => {
            SphericalPendulum { gravity, length }.state(a, b, w, 0.3)
        }
        Sys::Double(gravity) | Sys::DeclaredDouble(gravity) => DoublePendulum {
            gravity,
            ..DoublePendulum::default()
        }
        .state(a, b, w, -w),
        Sys::NonSeparable(eps, gravity) => NonSeparablePendulum { eps, gravity }.state_on_mh(a, w),
        Sys::Hopf(r2, g1, g2) | Sys::HopfGeneral(r2, g1, g2) => {
            // {g,H} = 2(q + γ)·p: take p ⟂ q + γ and scale it onto |z|² = r².
            let r = r2.sqrt();
            let c = a.cos().abs().max(0.1);
            let q = [r * c * b.cos(), r * c * b.sin()];
            let u = [q[0] + g1, q[1] + g2];
            let nu = (u[0] * u[0] + u[1] * u[1]).sqrt();
            let s = r * (1.0 - c * c).sqrt() / nu;
            State::from_slices(&q, &[-s * u[1], s * u[0]])
        }
    }
}

fn dof(sys: &Sys) -> usize {
    match sys {
        Sys::Pendulum(..) | Sys::NonSeparable(..) | Sys::Hopf(..) | Sys::HopfGeneral(..) => 2,
        Sys::Spherical(..) => 3,
        Sys::Double(..) | Sys::DeclaredDouble(..) => 4,
    }
}

fn initial(sys: &Sys, start: &Start) -> State {
    let d = dof(sys);
    match start {
        Start::OnMh(a, b, w) => on_mh(sys, *a, *b, *w),
        Start::Near(a, b, w, eps, seed) => {
            let mut z = on_mh(sys, *a, *b, *w);
            let scale = z.q.amax().max(z.p.amax());
            let dir = direction(*seed, 2 * d);
            for i in 0..d {
                z.q[i] += eps * scale * dir[i];
                z.p[i] += eps * scale * dir[d + i];
            }
            z
        }
        Start::Far(v) => State::from_slices(&v[..d], &v[4..4 + d]),
        Start::Zero => State::zeros(d),
        Start::NonFinite(a, x, i) => {
            let mut z = on_mh(sys, *a, 0.3, 0.7);
            let i = i % (2 * d);
            let bad = if x.is_finite() && x.abs() < 2.0 {
                f64::NAN
            } else {
                *x
            };
            if i < d {
                z.q[i] = bad;
            } else {
                z.p[i - d] = bad;
            }
            z
        }
        // The fields are public: a mismatched state can be built without a
        // (panicking) constructor, and the library must refuse it.
        Start::WrongLength(a, b) => State {
            q: geoshake::nalgebra::DVector::from_element(*a, 0.5),
            p: geoshake::nalgebra::DVector::from_element(*b, 0.5),
        },
        Start::Exceptional(b, orthogonal, eps) => {
            // |q|² − |p|² = 2ε·r²-ish, with the angle between q and p at
            // 0 or π/2 up to ε: the exceptional fibres of Section 5.4.1 are
            // |q| = |p| (for Hopf; the other systems just see an odd state).
            let r2 = match sys {
                Sys::Hopf(r2, ..) | Sys::HopfGeneral(r2, ..) => *r2,
                _ => 1.0,
            };
            let (qn, pn) = (
                ((1.0 + eps) * r2 / 2.0).sqrt(),
                ((1.0 - eps) * r2 / 2.0).sqrt(),
            );
            let phi = if *orthogonal {
                std::f64::consts::FRAC_PI_2 + eps
            } else {
                *eps
            };
            let mut z = State::zeros(d);
            z.q[0] = qn * b.cos();
            z.q[1] = qn * b.sin();
            z.p[0] = pn * (b + phi).cos();
            z.p[1] = pn * (b + phi).sin();
            z
        }
    }
}

// ---------------------------------------------------------------------------
// Verdicts
// ---------------------------------------------------------------------------

/// The largest bound `Options::constraint_tolerance` puts on |g_i| at z:
/// tol · (s/2)² + 64ε · s · (‖q‖∞, ‖p‖∞ or ‖z‖∞: the variables g_i reads),
/// s = ‖∂g_i/∂z‖₁, the runtime's relative test.
fn tolerance_at<S: ConstrainedSystem>(sys: &S, z: &State, tol: f64) -> f64 {
    let (m, d) = (sys.constraint_count(), sys.dof());
    if m == 0 || z.q.len() != d || z.p.len() != d {
        return tol;
    }
    let mut gz = vec![0.0; m * 2 * d];
    sys.constraint_jacobian(z.q.as_slice(), z.p.as_slice(), &mut gz);
    let (mut size, mut reads_q, mut reads_p) = (vec![0.0; m], vec![false; m], vec![false; m]);
    for &(i, k) in sys.jacobian_pattern() {
        size[i] += gz[i + k * m].abs();
        if k < d {
            reads_q[i] = true;
        } else {
            reads_p[i] = true;
        }
    }
    let (qmax, pmax) = (z.q.amax(), z.p.amax());
    (0..m)
        .map(|i| {
            let scale = match (reads_q[i], reads_p[i]) {
                (true, false) => qmax,
                (false, true) => pmax,
                _ => qmax.max(pmax),
            };
            tol * (0.5 * size[i]).powi(2) + 64.0 * f64::EPSILON * size[i] * scale
        })
        .fold(0.0f64, f64::max)
}

fn amax(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// `None` when z is finite, on M and (if `hidden`) on M^H to round-off;
/// otherwise what is wrong.
/// `slack` widens the bound on |g| for a run's initial state, which the run
/// stores as given once |g| is within `Options::constraint_tolerance`
/// (relative: see `tolerance_at`).
fn off_manifold<S: ConstrainedSystem>(
    sys: &S,
    z: &State,
    hidden: bool,
    slack: f64,
    newton_tolerance: f64,
) -> Option<String> {
    if !z.is_finite() {
        return Some(format!("non-finite state {z:?}"));
    }
    if z.q.len() != sys.dof() || z.p.len() != sys.dof() {
        return Some(format!("state of length {}+{}", z.q.len(), z.p.len()));
    }
    let (q, p) = (z.q.as_slice(), z.p.as_slice());
    let m = sys.constraint_count();
    let (mut g, mut gh) = (vec![0.0; m], vec![0.0; m]);
    sys.constraints(q, p, &mut g);
    let zmax = z.q.amax().max(z.p.amax());
    let s_g = 1.0 + zmax * zmax;
    // Round-off, or what the Newton tolerance the case asked for leaves
    // (a step stops once its update is below step_tolerance relative).
    let floor = 1e-13f64.max(16.0 * newton_tolerance);
    if !(amax(&g) <= (floor * s_g).max(slack)) {
        return Some(format!("|g| = {:.2e} > {floor:.0e}·{s_g:.2e}", amax(&g)));
    }
    if hidden {
        sys.hidden_constraints(q, p, &mut gh);
        let (mut hq, mut hp) = (vec![0.0; sys.dof()], vec![0.0; sys.dof()]);
        sys.gradient(q, p, &mut hq, &mut hp);
        let s_h = (1.0 + zmax) * (1.0 + zmax + amax(&hq).max(amax(&hp)));
        if !(amax(&gh) <= 1e-12 * s_h) {
            return Some(format!("|{{g,H}}| = {:.2e} > 1e-12·{s_h:.2e}", amax(&gh)));
        }
    }
    None
}

fn judge<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: S,
    base: B,
    case: &Case,
    z0: State,
) -> Verdict {
    let mut integ = Integrator::new(sys.clone(), base, case.h).with_options(case.options);
    if case.triple_jump {
        integ = integ.composed(Composition::TRIPLE_JUMP);
    }
    integ = if case.rattle {
        integ.rattle()
    } else {
        integ.shake()
    };
    let single = |r: Result<State, StepError>, hidden: bool| match r {
        Err(e) => Verdict::Typed(kind(&e)),
        Ok(z) => match off_manifold(&sys, &z, hidden, 0.0, case.options.newton.step_tolerance) {
            None => Verdict::Ok,
            Some(why) => Verdict::Silent(format!("Ok but {why}")),
        },
    };
    match &case.op {
        Op::Step => {
            let r = integ.step(&z0);
            single(r, case.rattle)
        }
        // Π's input need only be on M to the tolerance, but its result is
        // on M and M^H to round-off, as `project_to_hidden`'s is.
        Op::Project => single(integ.project(&z0), true),
        Op::ProjectToHidden => {
            let r = integ.project_to_hidden(&z0);
            single(r, true)
        }
        Op::Run { stop, stride, t0 } => {
            let h = case.h;
            let stop = match *stop {
                StopRule::Steps(n) => Stop::Steps(n),
                StopRule::NearSteps(n, d) => Stop::Time(t0 + n as f64 * h * (1.0 + d)),
                StopRule::Time(t) => Stop::Time(t),
            };
            // A valid run of more than 2·10³ steps (a tiny h and an
            // ordinary stop time) is not a hostile input but a long run,
            // which the watchdog would call a hang: it is cut to its last
            // digits. (A composed step with its reverse check over an
            // integrated fibre flow costs ≈ 0.4 ms idle: 8 427 of them took
            // 3.3 s, past the 5 s deadline under load.)
            let stop = match stop {
                Stop::Time(t) => {
                    let n = (t - t0) / h;
                    if n > 2e3 && n <= 9007199254740992.0 {
                        Stop::Steps(n as u64 % 100)
                    } else {
                        Stop::Time(t)
                    }
                }
                s => s,
            };
            let out = integ
                .run(z0, stop)
                .stride(*stride)
                .start_time(*t0)
                .execute();
            let traj = &out.trajectory;
            for i in 0..traj.len() {
                let z = traj.state(i);
                let k = traj.step(i);
                let slack = if k == 0 {
                    tolerance_at(&sys, &z, case.options.constraint_tolerance)
                } else {
                    0.0
                };
                if let Some(why) = off_manifold(
                    &sys,
                    &z,
                    case.rattle,
                    slack,
                    case.options.newton.step_tolerance,
                ) {
                    return Verdict::Silent(format!(
                        "stored state {i} (step {}) {why}",
                        traj.step(i)
                    ));
                }
                let t = t0 + k as f64 * h;
                if traj.time(i) != t {
                    return Verdict::Silent(format!(
                        "step {k} stored at t = {} ≠ t0 + k·h = {t}",
                        traj.time(i)
                    ));
                }
            }
            judge_end(traj, out.error.as_ref(), *t0, h)
        }
    }
}

fn judge_sys<S: ConstrainedSystem + Clone>(sys: S, case: &Case, z0: State) -> Verdict {
    match case.base {
        0 => judge(sys, SymplecticEuler, case, z0),
        1 => judge(sys, StormerVerlet, case, z0),
        _ => judge(sys, ImplicitMidpoint, case, z0),
    }
}

fn run_case(case: &Case) -> Verdict {
    let z0 = initial(&case.sys, &case.start);
    match case.sys {
        Sys::Pendulum(gravity, length) => judge_sys(Pendulum { gravity, length }, case, z0),
        Sys::Spherical(gravity, length) => {
            judge_sys(SphericalPendulum { gravity, length }, case, z0)
        }
        Sys::Double(gravity) => judge_sys(
            DoublePendulum {
                gravity,
                ..DoublePendulum::default()
            },
            case,
            z0,
        ),
        Sys::DeclaredDouble(gravity) => {
            // Unit masses and rods, as `DoublePendulum::default()`.
            judge_sys(
                geoshake::models::DoublePendulum::new(1.0, 1.0, gravity),
                case,
                z0,
            )
        }
        Sys::NonSeparable(eps, gravity) => {
            judge_sys(NonSeparablePendulum { eps, gravity }, case, z0)
        }
        Sys::Hopf(radius2, g1, g2) => judge_sys(
            Hopf {
                radius2,
                gravity: [g1, g2],
            },
            case,
            z0,
        ),
        Sys::HopfGeneral(radius2, g1, g2) => judge_sys(
            AsGeneral(Hopf {
                radius2,
                gravity: [g1, g2],
            }),
            case,
            z0,
        ),
    }
}

// ---------------------------------------------------------------------------
// Driver: the test kit's (`common::fuzz`), with this file's judge
// ---------------------------------------------------------------------------

fn fuzz(cases: u64, seed: u64) -> common::fuzz::Counts {
    common::fuzz::fuzz("fuzz_api", case_strategy(), run_case, DEADLINE, cases, seed)
}

#[test]
fn fuzz_api_ci() {
    let c = fuzz(
        env_u64("SHAKE_FUZZ_CI_CASES", CI_CASES),
        env_u64("SHAKE_FUZZ_SEED", 13),
    );
    assert_clean(&c);
}

#[test]
#[ignore = "long mode: SHAKE_FUZZ_CASES (default 10^6) cases, minutes of release time"]
fn fuzz_api_long() {
    let c = fuzz(
        env_u64("SHAKE_FUZZ_CASES", 1_000_000),
        env_u64("SHAKE_FUZZ_SEED", 13),
    );
    assert_clean(&c);
}

/// `run` and `project_to_hidden` once spun for > 30 s on a parameter
/// of f64::MAX: every parameter of every system at ±f64::MAX (and ±∞, NaN),
/// with every operation, through the same judge (and the same watchdog).
#[test]
fn extreme_parameters_end_in_a_verdict() {
    let mut cases = Vec::new();
    for x in [f64::MAX, -f64::MAX, f64::INFINITY, f64::NAN, 1e300, 1e-300] {
        let systems = [
            Sys::Pendulum(x, 1.0),
            Sys::Pendulum(1.0, x),
            Sys::Spherical(x, 1.0),
            Sys::Spherical(1.0, x),
            Sys::Double(x),
            Sys::DeclaredDouble(x),
            Sys::NonSeparable(x, 1.0),
            Sys::NonSeparable(0.5, x),
            Sys::Hopf(x, 0.0, -1.0),
            Sys::Hopf(1.0, x, -1.0),
            Sys::HopfGeneral(1.0, 0.0, x),
        ];
        for sys in systems {
            for op in [
                Op::Step,
                Op::Project,
                Op::ProjectToHidden,
                Op::Run {
                    stop: StopRule::Steps(5),
                    stride: 2,
                    t0: 0.0,
                },
            ] {
                for (base, rattle) in [(0, true), (1, false), (2, true)] {
                    for start in [
                        Start::OnMh(0.4, 0.3, 0.5),
                        Start::Near(0.4, 0.3, 0.5, 1e-3, 7),
                    ] {
                        cases.push(Case {
                            sys: sys.clone(),
                            base,
                            triple_jump: base == 2,
                            rattle,
                            h: 0.1,
                            options: Options::default(),
                            start,
                            op: op.clone(),
                        });
                    }
                }
            }
        }
    }
    let c = fuzz_cases(cases, run_case, DEADLINE);
    assert_clean(&c);
}
