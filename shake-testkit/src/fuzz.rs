//! The hostile-input suites' driver (`tests/fuzz_api.rs`,
//! `tests/fuzz_particles.rs`): cases drawn from a seeded proptest strategy
//! (ChaCha, no shrinking), each judged by the suite's own function on a
//! worker thread under `catch_unwind` and a watchdog, and counted by verdict.
//!
//! A case ends in one of four [`Verdict`]s, or in none within the deadline
//! (a *hang*). A suite fails when any silent wrong number, panic or hang is
//! counted ([`assert_clean`]); [`fuzz_cases`] prints the counts, a count per
//! class of failure and one example of each class.
//!
//! Environment, shared by the suites:
//! - `SHAKE_FUZZ_PRINT_SILENT`: print every silent case, not one per class;
//! - `SHAKE_FUZZ_PRINT_TYPED=Kind`: print every case refused with that kind.

use geoshake::{SolveError, StepError, Trajectory};
use proptest::strategy::{Strategy, ValueTree};
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::collections::BTreeMap;
use std::fmt::Debug;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How one case ended (a hang has no verdict: the watchdog counts it).
#[derive(Clone, Debug)]
pub enum Verdict {
    /// The call succeeded and its result meets the suite's contract.
    Ok,
    /// A typed error of the library, by kind.
    Typed(&'static str),
    /// A wrong number returned without an error: what is wrong.
    Silent(String),
    /// A panic, with its message.
    Panic(String),
}

/// The verdicts of a fuzz run.
#[derive(Default, Debug)]
pub struct Counts {
    /// Cases run.
    pub cases: u64,
    /// `Verdict::Ok`.
    pub ok: u64,
    /// Typed errors by kind.
    pub typed: BTreeMap<&'static str, u64>,
    /// Silent wrong numbers.
    pub silent: u64,
    /// Panics.
    pub panics: u64,
    /// Cases with no answer within the deadline.
    pub hangs: u64,
    /// One example per failure class.
    pub examples: Vec<String>,
    /// Failures by class (their detail up to the first digit).
    pub silent_classes: BTreeMap<String, u64>,
}

impl Counts {
    /// All typed errors.
    pub fn typed_total(&self) -> u64 {
        self.typed.values().sum()
    }

    fn note(&mut self, what: &str, case: &dyn Debug, detail: &str) {
        // One example per class (the first words of the detail), and a
        // count per class for the report.
        let class: String = format!(
            "{what}: {}",
            detail
                .split(|c: char| c.is_ascii_digit() || c == '(')
                .next()
                .unwrap_or("")
        );
        let n = self.silent_classes.entry(class).or_insert(0);
        *n += 1;
        if *n == 1 && self.examples.len() < 40 {
            self.examples
                .push(format!("{what}: {detail}\n    {case:?}"));
        }
    }
}

/// A worker that evaluates cases sent to it; a panic inside a case is caught
/// and reported as such.
fn spawn_worker<C: Send + 'static>(
    judge: fn(&C) -> Verdict,
) -> (mpsc::Sender<C>, mpsc::Receiver<Verdict>) {
    let (tx_case, rx_case) = mpsc::channel::<C>();
    let (tx_v, rx_v) = mpsc::channel::<Verdict>();
    std::thread::spawn(move || {
        for case in rx_case {
            let v = catch_unwind(AssertUnwindSafe(|| judge(&case))).unwrap_or_else(|p| {
                let msg = p
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| p.downcast_ref::<String>().cloned())
                    .unwrap_or_default();
                Verdict::Panic(msg)
            });
            if tx_v.send(v).is_err() {
                return;
            }
        }
    });
    (tx_case, rx_v)
}

/// `cases` values of `strategy` from a ChaCha generator seeded with `seed`
/// (the current value of each tree: no shrinking).
pub fn draw<S: Strategy>(strategy: S, cases: u64, seed: u64) -> impl Iterator<Item = S::Value> {
    let mut seed_bytes = [0u8; 32];
    seed_bytes[..8].copy_from_slice(&seed.to_le_bytes());
    let mut runner = TestRunner::new_with_rng(
        Config::default(),
        TestRng::from_seed(RngAlgorithm::ChaCha, &seed_bytes),
    );
    (0..cases).map(move |_| strategy.new_tree(&mut runner).unwrap().current())
}

/// Draws `cases` cases of `strategy` (seed `seed`) and runs them through
/// [`fuzz_cases`], printing the time taken under `name`.
pub fn fuzz<S>(
    name: &str,
    strategy: S,
    judge: fn(&S::Value) -> Verdict,
    deadline: Duration,
    cases: u64,
    seed: u64,
) -> Counts
where
    S: Strategy,
    S::Value: Clone + Debug + Send + 'static,
{
    let started = Instant::now();
    let counts = fuzz_cases(draw(strategy, cases, seed), judge, deadline);
    eprintln!(
        "{name}: {} cases in {:.1} s (seed {seed})",
        counts.cases,
        started.elapsed().as_secs_f64()
    );
    counts
}

/// Runs the cases on a worker thread, each under a watchdog of `deadline`,
/// and counts the verdicts. After a hang the stuck worker is left behind
/// (a thread cannot be killed) and a fresh one takes the next case; after
/// eight the run stops.
pub fn fuzz_cases<C: Clone + Debug + Send + 'static>(
    cases: impl IntoIterator<Item = C>,
    judge: fn(&C) -> Verdict,
    deadline: Duration,
) -> Counts {
    // Panics are counted, not printed (each would print a backtrace line).
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut counts = Counts::default();
    let (mut tx, mut rx) = spawn_worker(judge);
    for case in cases {
        counts.cases += 1;
        tx.send(case.clone()).unwrap();
        match rx.recv_timeout(deadline) {
            Ok(Verdict::Ok) => counts.ok += 1,
            Ok(Verdict::Typed(k)) => {
                // Audit one kind of refusal: are they all deserved?
                if std::env::var("SHAKE_FUZZ_PRINT_TYPED").is_ok_and(|v| v == k) {
                    eprintln!("typed {k}: {case:?}");
                }
                *counts.typed.entry(k).or_insert(0) += 1
            }
            Ok(Verdict::Silent(why)) => {
                counts.silent += 1;
                // The long mode can list every silent case, not one per
                // class: each is a lead to follow.
                if std::env::var_os("SHAKE_FUZZ_PRINT_SILENT").is_some() {
                    eprintln!("silent case: {why}\n    {case:?}");
                }
                counts.note("silent", &case, &why);
            }
            Ok(Verdict::Panic(msg)) => {
                counts.panics += 1;
                counts.note("panic", &case, &msg);
            }
            Err(_) => {
                counts.hangs += 1;
                counts.note("hang", &case, "no answer within the deadline");
                (tx, rx) = spawn_worker(judge);
                if counts.hangs >= 8 {
                    eprintln!("stopping after 8 hangs (each leaves a spinning thread)");
                    break;
                }
            }
        }
    }
    std::panic::set_hook(hook);
    eprintln!(
        "{} cases: ok {}, typed errors {} {:?}, silent {}, panics {}, hangs {}",
        counts.cases,
        counts.ok,
        counts.typed_total(),
        counts.typed,
        counts.silent,
        counts.panics,
        counts.hangs
    );
    for (class, n) in &counts.silent_classes {
        eprintln!("  {n:>8}  {class}");
    }
    for e in &counts.examples {
        eprintln!("{e}");
    }
    counts
}

/// An environment variable as a u64, or `default`.
pub fn env_u64(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Fails on any silent wrong number, panic or hang, and checks that every
/// case got one verdict.
pub fn assert_clean(c: &Counts) {
    assert_eq!(
        (c.silent, c.panics, c.hangs),
        (0, 0, 0),
        "silent wrong numbers, panics, hangs (examples above)"
    );
    assert_eq!(
        c.ok + c.typed_total() + c.silent + c.panics + c.hangs,
        c.cases
    );
}

/// A value a hostile user might pass where one from `normal` is expected:
/// mostly normal, otherwise a special value (0, −0, NaN, ±∞, ±f64::MAX,
/// the smallest normal and subnormal, ε, 10^±300, −1) or a random power of
/// ten of either sign.
pub fn hostile(normal: std::ops::Range<f64>) -> impl Strategy<Value = f64> {
    use proptest::prelude::*;
    prop_oneof![
        8 => normal,
        1 => prop::sample::select(vec![
            0.0,
            -0.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            -f64::MAX,
            f64::MIN_POSITIVE,
            5e-324,
            f64::EPSILON,
            1e-300,
            1e300,
            -1.0,
        ]),
        1 => (-320i32..309, any::<bool>())
            .prop_map(|(e, neg)| if neg { -(10f64.powi(e)) } else { 10f64.powi(e) }),
    ]
}

/// The end of a run under both suites' contract: `Ok` with a non-empty
/// trajectory, or a typed error whose time is t0 + k·h for its step k (NaN
/// when that is NaN) and, for k ≥ 1, whose step follows the last stored
/// one (the partial trajectory ends at step k − 1). The stored states
/// themselves are the caller's to judge.
pub fn judge_end(traj: &Trajectory, error: Option<&StepError>, t0: f64, h: f64) -> Verdict {
    let Some(e) = error else {
        if traj.is_empty() {
            return Verdict::Silent("Ok with an empty trajectory".into());
        }
        return Verdict::Ok;
    };
    let k = e.step();
    if let Some(te) = e.time() {
        let t = t0 + k as f64 * h;
        if !(te == t || (te.is_nan() && t.is_nan())) {
            return Verdict::Silent(format!(
                "{} at step {k} reports t = {te}, not t0 + k·h = {t}",
                step_error_kind(e)
            ));
        }
    }
    if k >= 1 {
        match traj.len().checked_sub(1).map(|i| traj.step(i)) {
            Some(last) if last + 1 == k => {}
            last => {
                return Verdict::Silent(format!(
                    "{} at step {k} but the last stored step is {last:?}",
                    step_error_kind(e)
                ))
            }
        }
    }
    Verdict::Typed(step_error_kind(e))
}

/// The kind of a [`StepError`], for the counts (an error at a particle
/// family's member with its solver's reason).
pub fn step_error_kind(e: &StepError) -> &'static str {
    match e {
        StepError::InvalidInput { .. } => "InvalidInput",
        StepError::Shape { .. } => "Shape",
        StepError::Topology(_) => "Topology",
        StepError::Solver { .. } => "Solver",
        StepError::Unavailable { .. } => "Unavailable",
        StepError::AtMember { source, .. } => match source {
            SolveError::NotConverged { .. } => "AtMember/NotConverged",
            SolveError::Singular { .. } => "AtMember/Singular",
            SolveError::NonFinite { .. } => "AtMember/NonFinite",
        },
        StepError::Storage { .. } => "Storage",
        StepError::NonFinite { .. } => "NonFinite",
        StepError::NewtonNotConverged { .. } => "NewtonNotConverged",
        StepError::NondegeneracyLost { .. } => "NondegeneracyLost",
        StepError::SingularShakeJacobian { .. } => "SingularShakeJacobian",
        StepError::SingularNondegeneracyMatrix { .. } => "SingularNondegeneracyMatrix",
        StepError::ComponentJump { .. } => "ComponentJump",
        StepError::FibreJump { .. } => "FibreJump",
        StepError::BranchJump { .. } => "BranchJump",
        StepError::NotOnConstraint { .. } => "NotOnConstraint",
    }
}
