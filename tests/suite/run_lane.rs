//! A run of a system with a fixed-size classical step loops inside that
//! step (the runtime's `run::lane`), with or without an `on_step`
//! observer; told to (`through_driver`), it takes the driver's own loop,
//! one step at a time through the integrator. Both loops call the same
//! substep, so the two runs must agree bit for bit: the stored states,
//! the observed ones, the events `on_step` sees, a run the observer stops,
//! and on failure the error, its step and time, and the states stored up
//! to it (for a lazily projected run with a stride, the driver's replay of
//! the steps after the last stored one).
//!
//! No timing here: `examples/overhead.rs` times the run.

use std::ops::ControlFlow;

use geoshake::{
    ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian, Integrator, RunOutcome,
    SizeVisitor, State, StepError, StepEvent, Stop, StormerVerlet,
};

/// How a run is set up: SHAKE, RATTLE projecting only what it shows
/// (lazy), or RATTLE projecting every step; the stride; whether states are
/// stored or only observed; Kahan's compensated sum or not.
#[derive(Copy, Clone, Debug)]
struct Setup {
    method: &'static str,
    stride: u64,
    store: bool,
    compensated: bool,
}

type Seen = Vec<(u64, f64, Vec<f64>, Vec<f64>)>;

/// What watches every step: nobody, an `on_step` observer that records
/// each event, or one that also stops the run after the given step.
#[derive(Copy, Clone, Debug, PartialEq)]
enum Watch {
    Nobody,
    Every,
    StopAfter(u64),
}

/// The run of `setup` from `z0`, through the lane or, with `driver`, the
/// driver's loop; the states the observer saw and the events `on_step` saw.
#[allow(clippy::too_many_arguments)]
fn run<S: ConstrainedSystem + Clone>(
    sys: &S,
    z0: &State,
    h: f64,
    steps: u64,
    s: Setup,
    driver: bool,
    watch: Watch,
) -> (RunOutcome, Seen, Vec<StepEvent>) {
    let mut integ = Integrator::new(sys.clone(), StormerVerlet, h).compensated(s.compensated);
    integ = match s.method {
        "shake" => integ.shake(),
        "lazy" => integ.rattle(),
        _ => {
            let mut opts = *integ.rattle().options();
            opts.project_every_step = true;
            Integrator::new(sys.clone(), StormerVerlet, h)
                .compensated(s.compensated)
                .rattle()
                .with_options(opts)
        }
    };
    let mut seen = Seen::new();
    let mut events = Vec::new();
    let mut every = |e: &StepEvent| {
        events.push(*e);
        match watch {
            Watch::StopAfter(k) if e.step == k => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        }
    };
    let mut run = integ
        .run(z0.clone(), Stop::Steps(steps))
        .start_time(0.25)
        .stride(s.stride)
        .store(s.store)
        .observe(|k, t, z| seen.push((k, t, z.q.as_slice().to_vec(), z.p.as_slice().to_vec())));
    if driver {
        run = run.through_driver();
    }
    let out = if watch == Watch::Nobody {
        run.execute()
    } else {
        run.on_step(&mut every).execute()
    };
    (out, seen, events)
}

/// Every setup on `sys` from `z0` with step `h`: the two loops agree.
/// Returns each setup with the step at which its run failed (0 for a run
/// that did not).
fn agree<S: ConstrainedSystem + Clone>(
    name: &str,
    sys: &S,
    z0: &State,
    h: f64,
    steps: u64,
) -> Vec<(Setup, u64)> {
    let mut failed = Vec::new();
    for method in ["shake", "lazy", "every"] {
        for stride in [1, 3, 7] {
            for (store, compensated) in [(true, true), (false, true), (true, false)] {
                let s = Setup {
                    method,
                    stride,
                    store,
                    compensated,
                };
                let (lane, lane_seen, _) = run(sys, z0, h, steps, s, false, Watch::Nobody);
                let (driver, driver_seen, events) = run(sys, z0, h, steps, s, true, Watch::Every);
                assert_eq!(lane, driver, "{name}, h {h}, {s:?}");
                assert_eq!(lane_seen, driver_seen, "{name}, h {h}, {s:?}");
                // Watched, the lane calls `on_step` as the driver does.
                let watched = run(sys, z0, h, steps, s, false, Watch::Every);
                assert_eq!(
                    watched,
                    (driver, driver_seen, events),
                    "{name}, h {h}, {s:?}"
                );
                // And stops where it is told to, the state stored.
                let stop = Watch::StopAfter(steps / 3 + 1);
                let stopped = run(sys, z0, h, steps, s, false, stop);
                let driven = run(sys, z0, h, steps, s, true, stop);
                assert_eq!(stopped, driven, "{name}, h {h}, {s:?}");
                if store {
                    assert_eq!(lane.trajectory.len(), lane_seen.len(), "{name}, {s:?}");
                } else {
                    assert!(lane.trajectory.is_empty());
                }
                failed.push((s, lane.error.as_ref().map_or(0, |e| e.step())));
            }
        }
    }
    failed
}

fn pendulum_start() -> State {
    State::from_slices(&[0.8, -0.6], &[0.9, 1.2])
}

fn double_start() -> State {
    geoshake_testkit::starts::double_pendulum()
}

/// A chain of 8 links at varied angles, moving.
fn chain_start() -> State {
    geoshake_testkit::starts::chain(8)
}

#[test]
fn regular_runs_take_the_same_steps_in_both_loops() {
    let pendulum = geoshake::models::Pendulum::new(1.0, 9.81);
    let failed = agree("pendulum", &pendulum, &pendulum_start(), 0.01, 40);
    assert!(failed.iter().all(|&(_, k)| k == 0), "{failed:?}");
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    let failed = agree("double pendulum", &double, &double_start(), 0.01, 40);
    assert!(failed.iter().all(|&(_, k)| k == 0), "{failed:?}");
    // Eight constraints: SHAKE's Jacobian and N banded on the stack.
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    let failed = agree("chain of 8", &chain, &chain_start(), 0.01, 40);
    assert!(failed.iter().all(|&(_, k)| k == 0), "{failed:?}");
}

#[test]
fn failing_runs_end_alike_in_both_loops() {
    // Steps too long for the pendulum's Newton iteration at some states of
    // its swing but not at the first: the runs fail after a few steps,
    // between stored states for the strides 3 and 7.
    let pendulum = geoshake::models::Pendulum::new(1.0, 9.81);
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    let chain = geoshake::models::Chain8::new(1.0, 1.0);
    let mut between = 0;
    for h in [0.2, 0.3, 0.45, 0.6] {
        for (name, failed) in [
            (
                "pendulum",
                agree("pendulum", &pendulum, &pendulum_start(), h, 60),
            ),
            (
                "double pendulum",
                agree("double", &double, &double_start(), h, 60),
            ),
            (
                "chain of 8",
                agree("chain of 8", &chain, &chain_start(), h, 60),
            ),
        ] {
            let steps: Vec<u64> = failed.iter().map(|&(_, k)| k).collect();
            println!("{name}, h {h}: failed at {steps:?}");
            // A lazy run failing after a stored state other than the
            // first and not right after one: the lane handed over the
            // state before the step and the SHAKE state to replay from.
            between += failed
                .iter()
                .filter(|(s, k)| s.method == "lazy" && *k > s.stride && (k - 1) % s.stride != 0)
                .count();
        }
    }
    assert!(between > 0, "no lazy run failed between stored states");
}

/// A system that offers its sizes to the fixed-size step and counts the
/// calls (one for a whole run through the lane, one a step through the
/// driver's loop); optionally, Π's right-hand side {g, H} made infinite
/// once the first coordinate's height q[1] is above `blow_up` (a Π that
/// overflows where SHAKE did not).
#[derive(Clone)]
struct Counted<S> {
    sys: S,
    calls: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    /// (d, m) offered to the visitor as constants.
    sizes: (usize, usize),
    blow_up: f64,
}

impl<S> Counted<S> {
    fn new(sys: S, sizes: (usize, usize)) -> Self {
        Counted {
            sys,
            calls: Default::default(),
            sizes,
            blow_up: f64::INFINITY,
        }
    }
    fn calls(&self) -> usize {
        self.calls.load(std::sync::atomic::Ordering::Relaxed)
    }
}

impl<S: ConstrainedSystem> Hamiltonian for Counted<S> {
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
        self.sys.grad_q(q, p, h_q)
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        self.sys.grad_p(q, p, h_p)
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        self.sys.hessian(q, p, h_zz)
    }
}

impl<S: ConstrainedSystem> ConstrainedSystem for Counted<S> {
    fn constraint_count(&self) -> usize {
        self.sys.constraint_count()
    }
    fn kind(&self) -> ConstraintKind {
        self.sys.kind()
    }
    fn quadratic_constraints(&self) -> bool {
        self.sys.quadratic_constraints()
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        self.sys.jacobian_pattern()
    }
    fn constraint_name(&self, i: usize) -> &str {
        self.sys.constraint_name(i)
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        self.sys.constraints(q, p, g)
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        self.sys.constraint_jacobian(q, p, g_z)
    }
    fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
        self.sys.constraint_hessian(q, p, lambda, out)
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.sys.hidden_constraints(q, p, out);
        if q[1] > self.blow_up {
            out[0] = f64::INFINITY;
        }
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        self.sys.hidden_constraint_jacobian(q, p, out)
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        self.sys.nondegeneracy_matrix(q, p, n)
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        self.sys.fibre_flow(lambda, q, p)
    }
    fn with_sizes<V: SizeVisitor<Self>>(&self, v: V) -> V::Output {
        self.calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        match self.sizes {
            (2, 1) => v.fixed::<2, 1>(self),
            (4, 2) => v.fixed::<4, 2>(self),
            _ => v.dynamic(self),
        }
    }
}

type Pendulum = geoshake::models::Pendulum;
type Double = geoshake::models::DoublePendulum;

#[test]
fn a_run_takes_the_lane_watched_or_not() {
    let s = Setup {
        method: "lazy",
        stride: 3,
        store: true,
        compensated: true,
    };
    let pendulum = Counted::new(Pendulum::new(1.0, 9.81), (2, 1));
    let double = Counted::new(Double::new(1.0, 0.7, 9.81), (4, 2));
    for (driver, watch) in [
        (false, Watch::Nobody),
        (false, Watch::Every),
        (true, Watch::Every),
    ] {
        let (out, ..) = run(&pendulum, &pendulum_start(), 0.01, 40, s, driver, watch);
        assert!(out.error.is_none());
        let (out, ..) = run(&double, &double_start(), 0.01, 40, s, driver, watch);
        assert!(out.error.is_none());
    }
    // (The run's start evaluates nothing through the hook.) One call for
    // each run through the lane, watched or not, then one a step through
    // the driver: one to eight constraints take the lane.
    assert_eq!(pendulum.calls(), 2 + 40, "one constraint");
    assert_eq!(double.calls(), 2 + 40, "two constraints");
    // And the lane's run of the wrapper is the system's own.
    let (a, ..) = run(
        &pendulum,
        &pendulum_start(),
        0.01,
        40,
        s,
        false,
        Watch::Nobody,
    );
    let (b, ..) = run(
        &pendulum.sys,
        &pendulum_start(),
        0.01,
        40,
        s,
        false,
        Watch::Nobody,
    );
    assert_eq!(a, b);
}

/// A Π that overflows at a stored state ends the run there with the
/// driver's error (`record`'s finiteness check), in both loops, for a
/// lazily projected run (Π of the shown states) and for one projecting
/// every step (where Π follows the step's own finiteness check).
#[test]
fn an_overflowing_projection_ends_both_loops_alike() {
    let mut sys = Counted::new(Pendulum::new(1.0, 9.81), (2, 1));
    // The bob rises from q[1] = −0.6: a few steps in.
    sys.blow_up = -0.55;
    for method in ["lazy", "every"] {
        for stride in [1, 4] {
            let s = Setup {
                method,
                stride,
                store: true,
                compensated: true,
            };
            let (lane, seen_lane, _) =
                run(&sys, &pendulum_start(), 0.01, 200, s, false, Watch::Nobody);
            let (driver, seen_driver, _) =
                run(&sys, &pendulum_start(), 0.01, 200, s, true, Watch::Every);
            assert_eq!(lane, driver, "{s:?}");
            assert_eq!(seen_lane, seen_driver, "{s:?}");
            let e = lane.error.expect("Π overflows");
            assert!(matches!(e, StepError::NonFinite { .. }), "{e:?}");
            assert!(e.step() > stride, "{e:?}");
            // Nothing non-finite was stored or shown.
            assert!(seen_lane
                .iter()
                .all(|(_, _, q, p)| q.iter().chain(p).all(|x| x.is_finite())));
        }
    }
}

/// A run between two single steps leaves nothing the second one reads:
/// `step_in_place` from the state it returned before the run starts from
/// that state as a new integrator would, not from the guard and N's
/// buffers as the run left them (whose fold indicator and condition bound
/// would compare N with N at the run's last state).
#[test]
fn a_run_between_single_steps_changes_nothing_they_read() {
    let double = geoshake::models::DoublePendulum::new(1.0, 0.7, 9.81);
    let fresh = || Integrator::new(double, StormerVerlet, 0.01);
    let mut z = double_start();
    let mut with_run = fresh();
    with_run.step_in_place(&mut z).unwrap();
    let z1 = z.clone();
    let elsewhere = State::from_slices(&[0.0, -1.0, 0.0, -1.7], &[1.0, 0.0, 2.5, 0.0]);
    let out = with_run.run(elsewhere, Stop::Steps(50)).execute();
    assert!(out.error.is_none());
    let info = with_run.step_in_place(&mut z).unwrap();
    let mut expected_z = z1.clone();
    let expected = fresh().step_in_place(&mut expected_z).unwrap();
    assert_eq!(info, expected);
    assert_eq!(z, expected_z);
}

/// From every state of a run that projects every step, without Kahan's
/// carry, `step_in_place` takes the run's next step: the same state bit
/// for bit and the same solves. The run loops in the lane, whose steps
/// the driver's loop takes too (above); `step_in_place` takes the
/// fixed-size step on the caller's numbers, and a slip in what it hands
/// that step (h, Π, the step's index) shows here.
fn single_steps_agree<S: ConstrainedSystem + Clone>(name: &str, sys: &S, z0: &State, h: f64) {
    let s = Setup {
        method: "every",
        stride: 1,
        store: true,
        compensated: false,
    };
    let (out, seen, events) = run(sys, z0, h, 40, s, false, Watch::Every);
    assert!(out.error.is_none(), "{name}: {:?}", out.error);
    let mut integ = Integrator::new(sys.clone(), StormerVerlet, h).rattle();
    let mut z = State::from_slices(&seen[0].2, &seen[0].3);
    for k in 1..seen.len() {
        let info = integ.step_in_place(&mut z).unwrap();
        assert_eq!(z.q.as_slice(), &seen[k].2[..], "{name}, step {k}");
        assert_eq!(z.p.as_slice(), &seen[k].3[..], "{name}, step {k}");
        // The same solves (N's condition is measured against each loop's
        // own reference, not compared here).
        let (a, b) = (info, events[k - 1].info);
        let key =
            |i: geoshake::StepInfo| (i.shake_iterations, i.rattle_iterations, i.lambda, i.det_n);
        assert_eq!(key(a), key(b), "{name}, step {k}");
        // A single step from a state of the run, by a fresh integrator
        // (which checks its start), is the same step.
        let mut again = State::from_slices(&seen[k - 1].2, &seen[k - 1].3);
        Integrator::new(sys.clone(), StormerVerlet, h)
            .rattle()
            .step_in_place(&mut again)
            .unwrap();
        assert_eq!(again, z, "{name}, step {k}");
    }
}

#[test]
fn single_steps_take_the_runs_steps() {
    let pendulum = Pendulum::new(1.0, 9.81);
    single_steps_agree("pendulum", &pendulum, &pendulum_start(), 0.01);
    let double = Double::new(1.0, 0.7, 9.81);
    single_steps_agree("double pendulum", &double, &double_start(), 0.01);
    let chain = geoshake::models::Chain8::new(1.0, 9.81);
    single_steps_agree("chain of 8", &chain, &chain_start(), 0.01);
}

/// `step_in_place` validates h and the options once and again only when
/// they change: a step size made invalid between two steps from the state
/// the first returned is refused, z left as it was, and the valid one
/// steps again as a fresh integrator would. A step that fails (h|p| a
/// hundred rods) leaves z as it was too.
#[test]
fn single_steps_see_a_changed_step_size() {
    let pendulum = Pendulum::new(1.0, 9.81);
    let mut integ = Integrator::new(pendulum, StormerVerlet, 0.01).rattle();
    let mut z = integ.project_to_hidden(&pendulum_start()).unwrap();
    integ.step_in_place(&mut z).unwrap();
    let z1 = z.clone();
    for bad in [0.0, f64::NAN, f64::INFINITY] {
        integ.with_step_size(bad);
        let e = integ.step_in_place(&mut z).unwrap_err();
        assert!(matches!(e, StepError::InvalidInput { .. }), "{bad}: {e:?}");
        assert_eq!(z, z1);
    }
    integ.with_step_size(50.0);
    assert!(integ.step_in_place(&mut z).is_err());
    assert_eq!(z, z1);
    integ.with_step_size(0.01);
    integ.step_in_place(&mut z).unwrap();
    let mut expected = z1.clone();
    Integrator::new(pendulum, StormerVerlet, 0.01)
        .rattle()
        .step_in_place(&mut expected)
        .unwrap();
    assert_eq!(z, expected);
}
