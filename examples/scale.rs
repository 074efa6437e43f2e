//! The large-system path from 10³ to 10⁶ constraints: rigid water boxes and
//! fully constrained chains, RATTLE with Störmer–Verlet at tol 1e-10.
//!
//!     cargo run --release --example scale            # the full table (~2 min)
//!     cargo run --release --example scale -- --quick # CI-sized (seconds)
//!     cargo run --release --example scale -- --case water:10000  # one case
//!     cargo run --release --example scale -- --tol 1e-12           # another tolerance
//!
//! One line per case:
//! `scale system=water n=10000 constraints=30000 method=rattle tol=1e-10 us_per_step=… ns_per_constraint=… max_rel_g=… max_hidden=… bytes_per_constraint=…`
//! with extra fields: the solver, Newton iterations (mean per cluster and
//! step, and the largest of any cluster in any step), the relative bond-length error measured from the final state
//! alone (what LAMMPS reports), and the memory split into state, workspace,
//! system tables and one stored trajectory state, per constraint.
//! Water: free flight (no forces), h = 2 fs, 300 K, as the LAMMPS recipe in
//! `shared/peers/lammps/`. `us_per_step` and `ns_per_constraint` are the
//! thread's CPU time (clock_gettime(CLOCK_THREAD_CPUTIME_ID)) over the timed
//! steps, after warm-up steps: the machine is shared, and wall time
//! (`wall_us_per_step`, `std::time::Instant`) also counts other processes.

use std::time::Instant;

use shake::runtime::particles::{
    generate, Options, ParticleState, ParticleSystem, Rattle, SolverChoice,
};

/// CPU time of this thread (the machine is shared: wall time alone would
/// measure the other processes too).
fn thread_cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    extern "C" {
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
}

fn build(case: &Case) -> (ParticleSystem, ParticleState) {
    let seed = 12345;
    match case.system {
        "water" => generate::water(case.n, seed),
        "chain" => generate::chain(case.n, seed),
        "chain_springs" => generate::chain_with_springs(case.n, seed),
        _ => unreachable!(),
    }
    .expect("the generators build valid topologies")
}

fn run(case: &Case, tol: f64) {
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
    let mut rattle = Rattle::new(system, h, options).expect("valid topology");
    rattle.project(&mut state).expect("initial data projects");
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    // Timed steps: 1000, fewer for the largest systems (≈ 10⁸ constraint-steps).
    let steps = (100_000_000 / m).clamp(20, 1000) as u64;
    let warm = (steps / 20).max(2);
    let warmup = rattle.run(&mut state, warm, 0);
    if let Some(e) = warmup.error {
        println!("scale system={} n={} error=\"{e}\"", case.system, case.n);
        return;
    }
    let (t, c) = (Instant::now(), thread_cpu_seconds());
    let out = rattle.run(&mut state, steps, steps);
    let wall = t.elapsed().as_secs_f64();
    let secs = thread_cpu_seconds() - c;
    let traj_bytes = out.trajectory.bytes() as f64 / out.trajectory.len().max(1) as f64;
    let (_, summary) = match out.into_result() {
        Ok(r) => r,
        Err((_, e)) => {
            println!("scale system={} n={} error=\"{e}\"", case.system, case.n);
            return;
        }
    };
    let us = secs * 1e6 / steps as f64;
    let wall_us = wall * 1e6 / steps as f64;
    let len_err = rattle
        .system()
        .constraint_families()
        .iter()
        .map(|f| generate::max_rel_length_error(f.table(), 3, state.q()))
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
        "scale system={} n={} constraints={} method=rattle tol={:e} us_per_step={:.1} ns_per_constraint={:.1} max_rel_g={:.1e} max_hidden={:.1e} bytes_per_constraint={:.0} solver={} steps={} newton_iters_mean={:.2} newton_iters_max={} max_rel_length_error={:.1e} state_bytes={:.0} workspace_bytes={:.0} system_bytes={:.0} traj_bytes_per_state={:.0} wall_us_per_step={:.1}{}",
        case.system,
        case.n,
        m,
        rattle.options().tol,
        us,
        us * 1e3 / m as f64,
        summary.max_rel_g,
        summary.max_hidden,
        state_b + work_b + sys_b + traj_bytes / m as f64,
        rattle.solver_name(),
        steps,
        summary.newton_iterations as f64 / (steps as f64 * rattle.clusters() as f64),
        summary.max_newton_iterations,
        len_err,
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
        });
    }
    for &n in chains {
        cases.push(Case {
            system: "chain",
            n,
            solver: auto,
        });
    }
    let big = if quick { 1000 } else { 10_000 };
    cases.push(Case {
        system: "chain_springs",
        n: big,
        solver: auto,
    });
    cases.push(Case {
        system: "chain",
        n: big,
        solver: SolverChoice::Sparse,
    });
    cases.push(Case {
        system: "water",
        n: big / 10,
        solver: SolverChoice::Sparse,
    });
    // `--tol 1e-12`: another tolerance (default 1e-10).
    let tol: f64 = std::env::args()
        .skip_while(|a| a != "--tol")
        .nth(1)
        .and_then(|t| t.parse().ok())
        .unwrap_or(1e-10);
    // `--case water:10000` runs one case (for profiling).
    let only: Option<String> = std::env::args().skip_while(|a| a != "--case").nth(1);
    for c in &cases {
        if let Some(o) = &only {
            if *o != format!("{}:{}", c.system, c.n) {
                continue;
            }
        }
        run(c, tol);
    }
}
