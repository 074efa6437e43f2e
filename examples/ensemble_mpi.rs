//! An ensemble of pendulums, or of boxes of rigid water, over MPI ranks
//! (`--features mpi`).
//!
//! ```sh
//! cargo build --release --features mpi --example ensemble_mpi
//! mpirun -n 2 --oversubscribe target/release/examples/ensemble_mpi --members 10000 --threads 1
//! ```
//!
//! (As root, Open MPI also wants `--allow-run-as-root`, or
//! `OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1`.)
//!
//! Member k is the pendulum of the paper's Example 1.3 released at angle
//! θ_k = 3 (k + ½)/N from the downward vertical with angular velocity
//! ω_k = ½ sin k, run with RATTLE over Störmer–Verlet. With `--system
//! water`, member k is a box of `--waters W` (default 20) rigid waters on
//! the particle path at 100 + 300 (k + ½)/N K, h = 2 fs unless `--h` says
//! otherwise. Options:
//!
//! - `--system pendulum|water` (pendulum);
//! - `--members N` (default 2000), `--steps S` (1000), `--h H` (0.01),
//!   `--stride K` (S: the first and last state are kept);
//! - `--threads T`: rayon threads per rank (default: rayon's choice);
//! - `--batch B` (1024), `--store DIR` (record and resume; see
//!   `geoshake_runtime::ensemble_store`), `--max-batches M` (stop after M
//!   batches, as a job at its wall-time limit would);
//! - `--fail k1,k2,…`: make these members fail, alternately with a NaN
//!   initial state (an error at step 0) and spinning at ω = 100 (a SHAKE
//!   Newton failure a few steps in, with a partial trajectory); for water,
//!   a NaN momentum, and a molecule collapsed onto its oxygen (a failure at
//!   its first bond in step 1, the start state kept);
//! - `--check`: rank 0 also runs the ensemble in this process with
//!   `geoshake_runtime::run_ensemble` and checks every gathered outcome against
//!   it bit for bit, and the injected failures; exit status 1 if not.
//!
//! The last line printed (by rank 0) is
//! `ensemble members=… ok=… failed=… ranks=… threads=… members_per_s=…`.

use geoshake::ensemble::{pack_outcome, Template};
use geoshake::ensemble_mpi::{run_ensemble_mpi, MpiEnsemble};
use geoshake::examples::Pendulum;
use geoshake::mpi::{self, traits::Communicator, Threading};
use geoshake::particles::{generate, Options, ParticleState, Rattle};
use geoshake::{run_ensemble, Integrator, State, Stop, StormerVerlet};
use std::process::ExitCode;

struct Args {
    water: bool,
    waters: usize,
    members: usize,
    steps: u64,
    h: Option<f64>,
    stride: Option<u64>,
    threads: Option<usize>,
    options: MpiEnsemble,
    fail: Vec<usize>,
    check: bool,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        water: false,
        waters: 20,
        members: 2000,
        steps: 1000,
        h: None,
        stride: None,
        threads: None,
        options: MpiEnsemble::default(),
        fail: Vec::new(),
        check: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        if flag == "--check" {
            a.check = true;
            continue;
        }
        let value = it.next().ok_or(format!("{flag} needs a value"))?;
        let bad = |e: &dyn std::fmt::Display| format!("{flag} {value}: {e}");
        match flag.as_str() {
            "--system" => {
                a.water = match value.as_str() {
                    "pendulum" => false,
                    "water" => true,
                    _ => return Err(bad(&"not pendulum or water")),
                }
            }
            "--waters" => a.waters = value.parse().map_err(|e| bad(&e))?,
            "--members" => a.members = value.parse().map_err(|e| bad(&e))?,
            "--steps" => a.steps = value.parse().map_err(|e| bad(&e))?,
            "--h" => a.h = Some(value.parse().map_err(|e| bad(&e))?),
            "--stride" => a.stride = Some(value.parse().map_err(|e| bad(&e))?),
            "--threads" => a.threads = Some(value.parse().map_err(|e| bad(&e))?),
            "--batch" => a.options.batch = value.parse().map_err(|e| bad(&e))?,
            "--store" => a.options.store = Some(value.into()),
            "--max-batches" => a.options.max_batches = Some(value.parse().map_err(|e| bad(&e))?),
            "--fail" => {
                a.fail = value
                    .split(',')
                    .map(|k| k.parse().map_err(|e| bad(&e)))
                    .collect::<Result<_, _>>()?
            }
            _ => return Err(format!("unknown option {flag}")),
        }
    }
    Ok(a)
}

/// Member k's initial state (the same on every rank).
fn pendulums(a: &Args) -> Vec<State> {
    let pendulum = Pendulum::default();
    (0..a.members)
        .map(|k| match a.fail.iter().position(|&f| f == k) {
            Some(j) if j % 2 == 0 => State::from_slices(&[f64::NAN, -1.0], &[0.0, 0.0]),
            Some(_) => pendulum.state(0.0, 100.0),
            None => {
                let theta = 3.0 * (k as f64 + 0.5) / a.members as f64;
                pendulum.state(theta, 0.5 * (k as f64).sin())
            }
        })
        .collect()
}

/// The water boxes' solver and member k's initial state.
fn waters(a: &Args) -> Result<(Rattle, Vec<ParticleState>), String> {
    let (system, mut state) = generate::water(a.waters, 1).map_err(|e| e.to_string())?;
    let h = a.h.unwrap_or(2.0);
    let mut rattle = Rattle::new(system, h, Options::default()).map_err(|e| e.to_string())?;
    rattle.project(&mut state).map_err(|e| e.to_string())?;
    let starts = (0..a.members)
        .map(|k| {
            let mut s = state.clone();
            let kelvin = 100.0 + 300.0 * (k as f64 + 0.5) / a.members as f64;
            generate::set_temperature(rattle.system(), &mut s, kelvin);
            match a.fail.iter().position(|&f| f == k) {
                Some(j) if j % 2 == 0 => s.p_mut()[0] = f64::NAN,
                Some(_) => {
                    let q = s.q_mut();
                    let oxygen = [q[0], q[1], q[2]];
                    q[3..6].copy_from_slice(&oxygen);
                    q[6..9].copy_from_slice(&oxygen);
                }
                None => {}
            }
            s
        })
        .collect();
    Ok((rattle, starts))
}

fn main() -> ExitCode {
    let a = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("ensemble_mpi: {e}");
            return ExitCode::from(2);
        }
    };
    // Rayon's workers never call MPI: Funneled is enough.
    let Some((universe, _)) = mpi::initialize_with_threading(Threading::Funneled) else {
        eprintln!("ensemble_mpi: MPI could not be initialised");
        return ExitCode::from(2);
    };
    // The global pool: `run_ensemble_mpi` (and MPI) stay on this thread,
    // only the members run on the pool's.
    if let Some(t) = a.threads {
        geoshake::rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build_global()
            .expect("the global rayon pool is built once");
    }
    let code = run(&a, &universe.world());
    drop(universe); // MPI_Finalize before the exit status
    code
}

fn run(a: &Args, world: &impl Communicator) -> ExitCode {
    if !a.water {
        let h = a.h.unwrap_or(0.01);
        let rattle = Integrator::new(Pendulum::default(), StormerVerlet, h).rattle();
        let job = format!("pendulum rattle stormer-verlet h={h:e}");
        return run_members(a, world, &rattle, &pendulums(a), &job);
    }
    match waters(a) {
        Ok((rattle, starts)) => {
            let job = format!("water waters={} h={:e}", a.waters, rattle.step_size());
            run_members(a, world, &rattle, &starts, &job)
        }
        Err(e) => {
            eprintln!("ensemble_mpi: {e}");
            ExitCode::from(2)
        }
    }
}

/// The ensemble of `starts` from `template`, over the ranks of `world`.
fn run_members<T: Template>(
    a: &Args,
    world: &impl Communicator,
    template: &T,
    starts: &[T::Start],
    job: &str,
) -> ExitCode {
    let stop = Stop::Steps(a.steps);
    let stride = a.stride.unwrap_or(a.steps.max(1));
    let mut options = a.options.clone();
    // What identifies this ensemble in a store's manifest.
    options.job = format!(
        "ensemble_mpi {job} steps={} stride={stride} fail={:?}",
        a.steps, a.fail
    );
    options.collect = a.check;
    let results = match run_ensemble_mpi(world, template, starts, stop, stride, &options) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("ensemble_mpi (rank {}): {e}", world.rank());
            return ExitCode::FAILURE;
        }
    };
    let Some(results) = results else {
        return ExitCode::SUCCESS; // not rank 0
    };
    let s = &results.summary;
    let mut code = ExitCode::SUCCESS;
    if a.check {
        match check(a, template, starts, stop, stride, &results.outcomes) {
            Ok(n) => println!("check ok: {n} gathered members bit-identical to run_ensemble"),
            Err(e) => {
                println!("check FAILED: {e}");
                code = ExitCode::FAILURE;
            }
        }
    }
    println!(
        "computed={} resumed={} pending={} seconds={:.3} steps_per_member={} gathered_bytes_per_member={:.1}",
        s.computed,
        s.resumed,
        s.pending,
        s.seconds,
        a.steps,
        8.0 * s.words as f64 / s.computed.max(1) as f64
    );
    println!("{s}");
    code
}

/// Every finished member against the same ensemble run in this process,
/// compared as packed words (IEEE bits); the injected failures must have
/// failed, with their error, and every other member must have succeeded.
fn check<T: Template>(
    a: &Args,
    template: &T,
    starts: &[T::Start],
    stop: Stop,
    stride: u64,
    gathered: &[Option<geoshake::RunOutcome>],
) -> Result<usize, String> {
    let here = run_ensemble(template, starts, stop, stride);
    let mut n = 0;
    for (k, (mine, theirs)) in here.iter().zip(gathered).enumerate() {
        let Some(theirs) = theirs else { continue };
        let (mut x, mut y) = (Vec::new(), Vec::new());
        pack_outcome(k, mine, &mut x);
        pack_outcome(k, theirs, &mut y);
        if x != y {
            return Err(format!("member {k} differs from run_ensemble"));
        }
        match (&theirs.error, a.fail.iter().position(|&f| f == k)) {
            (None, None) => {}
            (Some(e), Some(_)) => println!(
                "member {k} failed as injected: {e} (partial trajectory: {} states)",
                theirs.trajectory.len()
            ),
            (Some(e), None) => return Err(format!("member {k} failed: {e}")),
            (None, Some(_)) => return Err(format!("member {k} should have failed")),
        }
        n += 1;
    }
    Ok(n)
}
