//! The large-system path from 10³ to 10⁶ constraints: rigid water boxes and
//! fully constrained chains, RATTLE with Störmer–Verlet at the default
//! tolerance (1e-12, a relative bond-length error of 1e-12).
//!
//!     cargo run --release --example scale            # the full table (~2 min)
//!     cargo run --release --example scale -- --quick # CI-sized (seconds)
//!     cargo run --release --example scale -- --case water:10000  # one case
//!     cargo run --release --example scale -- --tol 1e-10           # another tolerance
//!     cargo run --release --example scale -- --case water:100000 --threads 2  # on two threads
//!     cargo run --release --example scale -- --lammps-data water_10000.data --steps 1000 --repeats 3
//!
//! `--lammps-data` runs the very box a LAMMPS data file holds (positions,
//! velocities and masses as LAMMPS reads them, bonds and the H–O–H angle
//! as three distance constraints per water): `bench/lammps/compare.sh` uses
//! it to put LAMMPS `fix rattle` and us side by side on the same initial
//! state. `--repeats R` times the steps R times and reports the median.
//!
//! One line per case:
//! `scale system=water n=10000 constraints=30000 threads=1 method=rattle tol=1e-12 us_per_step=… ns_per_constraint=… max_rel_g=… max_hidden=… max_rel_bond_error=… bytes_per_constraint=…`
//! with extra fields: the solver, Newton iterations (mean per cluster and
//! step, and the largest of any cluster in any step), the relative
//! bond-length error | |r| − l | / l measured from the states alone (what
//! LAMMPS reports; `max_rel_bond_error` is the largest over every distance
//! constraint after every step of an untimed run of as many steps that
//! continues the timed one, `max_rel_length_error` the final state's), and
//! the memory split into state, workspace, system tables and one stored
//! trajectory state, per constraint.
//! Water: free flight (no forces), h = 2 fs, 300 K, as the LAMMPS recipe in
//! `shared/peers/lammps/`. `us_per_step` and `ns_per_constraint` are the
//! thread's CPU time (clock_gettime(CLOCK_THREAD_CPUTIME_ID)) over the timed
//! steps, after warm-up steps: the machine is shared, and wall time
//! (`wall_us_per_step`, `std::time::Instant`) also counts other processes.
//!
//! Every case runs in a rayon pool of `--threads N` threads (default 1),
//! printed as `threads=`: the clusters' solves and the passes over every
//! particle of a large box go to the pool's threads. With N > 1 the
//! calling thread's clock misses the others' work, so `us_per_step` and
//! `ns_per_constraint` are then wall time. The full table adds the largest
//! water box and chain on two threads after the rows on one.

use std::time::Instant;

use geoshake::runtime::particles::io::{read_lammps_data, FileError};
use geoshake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, SolverChoice, Table,
};
use geoshake::runtime::rayon;
use geoshake::runtime::Stop;

/// CPU time of this thread (the machine is shared: wall time alone would
/// measure the other processes too).
fn thread_cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    unsafe extern "C" {
        fn clock_gettime(clock: i32, tp: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec { sec: 0, nsec: 0 };
    // SAFETY: clock_gettime writes one timespec (two 64-bit fields on
    // x86_64/aarch64 Linux) into the pointer given.
    let r = unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) };
    if r == 0 {
        t.sec as f64 + t.nsec as f64 * 1e-9
    } else {
        f64::NAN
    }
}

struct Case {
    system: &'static str,
    n: usize,
    solver: SolverChoice,
    /// A LAMMPS data file to read instead of generating the box.
    data: Option<String>,
}

/// The command-line value after `flag`, parsed.
fn arg<T: std::str::FromStr>(flag: &str) -> Option<T> {
    std::env::args()
        .skip_while(|a| a != flag)
        .nth(1)
        .and_then(|v| v.parse().ok())
}

fn build(case: &Case) -> (ParticleSystem, ParticleState) {
    let seed = 12345;
    if let Some(path) = &case.data {
        return lammps_water(path).unwrap_or_else(|e| {
            eprintln!("scale: {e}");
            std::process::exit(2)
        });
    }
    match case.system {
        "water" => generate::water(case.n, seed),
        "chain" => generate::chain(case.n, seed),
        "chain_springs" => generate::chain_with_springs(case.n, seed),
        _ => unreachable!(),
    }
    .expect("the generators build valid topologies")
}

/// [`run_here`] in a pool of `threads` threads.
fn run(case: &Case, tol: f64, threads: usize) {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build();
    match pool {
        Ok(pool) => pool.install(|| run_here(case, tol, threads)),
        Err(e) => println!("scale system={} n={} error=\"{e}\"", case.system, case.n),
    }
}

fn run_here(case: &Case, tol: f64, threads: usize) {
    let (system, mut state) = build(case);
    let h = 2.0;
    let options = Options {
        solver: case.solver,
        tol,
        ..Options::default()
    };
    let m = system.constraints();
    let system_bytes: usize = system
        .constraint_families()
        .iter()
        .map(|f| f.table().bytes())
        .chain(
            system
                .potential_families()
                .iter()
                .map(|f| f.table().bytes()),
        )
        .sum::<usize>()
        + system.particles() * 16;
    // A data file's box size is known only once it is read.
    let n = if case.data.is_some() {
        system.particles() / 3
    } else {
        case.n
    };
    let mut rattle = Rattle::new(system, h, options).expect("valid topology");
    rattle.project(&mut state).expect("initial data projects");
    if case.data.is_none() {
        // A LAMMPS data file is already at 300 K.
        generate::set_temperature(rattle.system(), &mut state, 300.0);
    }
    // Timed steps: 1000, fewer for the largest systems (≈ 10⁸ constraint-steps).
    let steps = arg("--steps").unwrap_or((100_000_000 / m.max(1)).clamp(20, 1000) as u64);
    let repeats = arg::<usize>("--repeats").unwrap_or(1).max(1);
    let warm = (steps / 20).max(2);
    let warmup = rattle.run_in_place(&mut state, warm);
    if let Some(e) = warmup.error {
        println!("scale system={} n={} error=\"{e}\"", case.system, case.n);
        return;
    }
    // Each repeat continues from where the last one ended; the median time
    // is reported, the last repeat's states are measured.
    let mut timings = Vec::new();
    let mut out = None;
    for _ in 0..repeats {
        let (t, c) = (Instant::now(), thread_cpu_seconds());
        out = Some(rattle.run_in_place(&mut state, steps));
        timings.push((thread_cpu_seconds() - c, t.elapsed().as_secs_f64()));
    }
    timings.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (secs, wall) = timings[timings.len() / 2];
    let out = out.expect("at least one repeat");
    // What one stored state takes in a `Trajectory` (q then p, nothing
    // else: run_in_place itself stores none).
    let traj_bytes = (2 * state.q().len() * std::mem::size_of::<f64>()) as f64;
    if let Some(e) = out.error {
        println!("scale system={} n={} error=\"{e}\"", case.system, case.n);
        return;
    }
    let summary = out.summary;
    let measured = |x: Option<f64>| x.unwrap_or(f64::NAN);
    let wall_us = wall * 1e6 / steps as f64;
    let us = if threads > 1 {
        wall_us
    } else {
        secs * 1e6 / steps as f64
    };
    let bonds: Vec<Table> = rattle
        .system()
        .constraint_families()
        .iter()
        .map(|f| f.table().clone())
        .collect();
    let len_err = max_rel_bond_error(&bonds, state.q());
    // Every step's bonds, in a run of as many steps after the timed ones:
    // measuring them inside the timed run would time the measurement too.
    let mut bond_err = 0.0f64;
    let check = rattle
        .run(&state, Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k > 0 {
                let e = max_rel_bond_error(&bonds, z.q.as_slice());
                // (NaN wins: a broken state must show.)
                if !(bond_err.is_nan() || e <= bond_err) {
                    bond_err = e;
                }
            }
        })
        .execute();
    if let Some(e) = check.error {
        println!("scale system={} n={} error=\"{e}\"", case.system, case.n);
        return;
    }
    let vel_err = rattle
        .system()
        .constraint_families()
        .iter()
        .map(|f| max_rel_velocity(f.table(), rattle.system().inverse_masses(), &state))
        .fold(0.0, f64::max);
    let mut extra = String::new();
    if !rattle.system().potential_families().is_empty() {
        // The same force evaluation alone, as often as the steps did it.
        let mut grad = vec![0.0; state.q().len()];
        let t = thread_cpu_seconds();
        for _ in 0..steps {
            grad.fill(0.0);
            for f in rattle.system().potential_families() {
                std::hint::black_box(f.energy_gradient(state.q(), &mut grad));
            }
        }
        let fus = (thread_cpu_seconds() - t) * 1e6 / steps as f64;
        extra = format!(" force_us_per_step={fus:.1}");
    }
    let state_b = state.bytes() as f64 / m as f64;
    let work_b = rattle.workspace_bytes() as f64 / m as f64;
    let sys_b = system_bytes as f64 / m as f64;
    println!(
        "scale system={} n={} constraints={} threads={threads} method=rattle tol={:e} us_per_step={:.1} ns_per_constraint={:.1} max_rel_g={:.1e} max_hidden={:.1e} max_rel_bond_error={:.1e} bytes_per_constraint={:.0} solver={} steps={} newton_iters_mean={:.2} newton_iters_max={} max_rel_length_error={:.1e} max_rel_velocity={:.1e} state_bytes={:.0} workspace_bytes={:.0} system_bytes={:.0} traj_bytes_per_state={:.0} wall_us_per_step={:.1}{}",
        case.system,
        n,
        m,
        rattle.options().tol,
        us,
        us * 1e3 / m as f64,
        measured(summary.max_residual),
        measured(summary.max_hidden),
        bond_err,
        state_b + work_b + sys_b + traj_bytes / m as f64,
        rattle.solver_name(),
        steps,
        summary.newton_iterations as f64 / (steps as f64 * rattle.clusters() as f64),
        summary.max_newton_iterations,
        len_err,
        vel_err,
        state_b,
        work_b,
        sys_b,
        traj_bytes / m as f64,
        wall_us,
        extra,
    );
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let auto = SolverChoice::Auto;
    let mut cases = Vec::new();
    let waters: &[usize] = if quick {
        &[100, 1000]
    } else {
        &[1000, 10_000, 100_000]
    };
    let chains: &[usize] = if quick {
        &[100, 1000]
    } else {
        &[1000, 10_000, 100_000, 1_000_000]
    };
    for &n in waters {
        cases.push(Case {
            system: "water",
            n,
            solver: auto,
            data: None,
        });
    }
    for &n in chains {
        cases.push(Case {
            system: "chain",
            n,
            solver: auto,
            data: None,
        });
    }
    let big = if quick { 1000 } else { 10_000 };
    cases.push(Case {
        system: "chain_springs",
        n: big,
        solver: auto,
        data: None,
    });
    cases.push(Case {
        system: "chain",
        n: big,
        solver: SolverChoice::Sparse,
        data: None,
    });
    cases.push(Case {
        system: "water",
        n: big / 10,
        solver: SolverChoice::Sparse,
        data: None,
    });
    // `--tol 1e-10`: another tolerance than the default.
    let tol: f64 = arg("--tol").unwrap_or(Options::default().tol);
    let threads: usize = arg("--threads").unwrap_or(1).max(1);
    if let Some(path) = arg::<String>("--lammps-data") {
        let case = Case {
            system: "water",
            n: 0,
            solver: auto,
            data: Some(path),
        };
        run(&case, tol, threads);
        return;
    }
    // `--case water:10000` runs one case (for profiling).
    let only: Option<String> = std::env::args().skip_while(|a| a != "--case").nth(1);
    for c in &cases {
        if let Some(o) = &only
            && *o != format!("{}:{}", c.system, c.n)
        {
            continue;
        }
        run(c, tol, threads);
    }
    // The largest box and chain again on two threads (the full table).
    if !quick && only.is_none() && arg::<usize>("--threads").is_none() {
        for c in cases.iter().filter(|c| c.n >= 100_000 && c.solver == auto) {
            if c.system == "water" || c.n == 1_000_000 {
                run(c, tol, 2);
            }
        }
    }
}

/// The largest relative bond-length error | |r| − l | / l over the
/// distance constraints of every family (rows (a, b; l)), from q alone.
fn max_rel_bond_error(families: &[Table], q: &[f64]) -> f64 {
    families
        .iter()
        .map(|t| generate::max_rel_length_error(t, 3, q))
        .fold(0.0, |a: f64, e| if a.is_nan() || e <= a { a } else { e })
}

/// The largest relative velocity residual |(v_a − v_b)·(x_a − x_b)| /
/// (|v_a − v_b| |x_a − x_b|) over the distance constraints of a family: the
/// hidden constraint, measured from the state alone (as
/// `bench/lammps/dump_error.py` does for LAMMPS).
fn max_rel_velocity(table: &Table, inverse_masses: &[f64], state: &ParticleState) -> f64 {
    let (q, p) = (state.q(), state.p());
    let mut worst = 0.0f64;
    for k in 0..table.len() {
        let ij = table.particles(k);
        let (a, b) = (ij[0] as usize, ij[1] as usize);
        let (mut rv, mut rr, mut vv) = (0.0, 0.0, 0.0);
        for c in 0..3 {
            let r = q[3 * a + c] - q[3 * b + c];
            let v = p[3 * a + c] * inverse_masses[a] - p[3 * b + c] * inverse_masses[b];
            rv += r * v;
            rr += r * r;
            vv += v * v;
        }
        let e = rv.abs() / (rr * vv).sqrt().max(f64::MIN_POSITIVE);
        if e.is_nan() || e > worst {
            worst = e;
        }
    }
    worst
}

/// The rigid waters of a LAMMPS data file (atom_style molecular) written by
/// `bench/lammps/gen_data.py`, read by `particles::io`: unwrapped positions
/// (Å), velocities (Å/fs) and masses (g/mol) turned into p = m v, and per
/// molecule the two O–H bonds (type 1, 1.0 Å) and the H–H distance
/// 2 sin(θ/2) of the H–O–H angle (type 1, θ = 109.47°), which is how
/// LAMMPS' `shake … b 1 a 1` constrains the angle. The constraints are
/// sorted molecule by molecule, so that each cluster's rows are neighbours
/// in memory.
fn lammps_water(path: &str) -> Result<(ParticleSystem, ParticleState), FileError> {
    read_lammps_data(path)?
        .rigid()
        .bond_length(1, 1.0)
        .angle_degrees(1, 109.47)
        .build()
}
