//! The library's cost per step against a hand-written straight-line RATTLE
//! (the limit, `shake-testkit/src/bench/limit.rs`), in one run:
//!
//!     cargo run --release --example overhead
//!
//! For the pendulum and chains of 4, 16 and 64 links (256 on request),
//! RATTLE over Störmer–Verlet at h = 0.01 from the same state on M^H, one
//! line per system and mode:
//!
//!     overhead system=… mode=run|observed|step_in_place run_us=… limit_us=… ratio=… max_rel_g=… …
//!
//! - `mode=run`: the library's `run`, every state projected onto M^H and
//!   shown to the driver (stride 1, nothing stored);
//! - `mode=observed`: the same run with an `on_step` observer that counts
//!   the steps (what a progress bar's hook costs at least);
//! - `mode=step_in_place`: the library's `step_in_place` in a loop;
//! - `run_us`: the mode's time per step, `limit_us` the hand-written RATTLE
//!   step's, `ratio` = run_us / limit_us;
//! - `max_rel_g`: the largest |g|/ℓ² of the library's run states (and
//!   `limit_rel_g` of the limit's), both evaluated by the limit's own code
//!   (link vectors first, then their lengths: the generated g expands the
//!   squares and loses digits like ε|q|², 1e-12 for 64 links), `dE`/`limit_dE` the largest energy
//!   error of each, `dz` the largest difference between the two
//!   trajectories after the timed number of steps, `iters`/`limit_iters`
//!   the Newton updates of the position stage per step (the limit's
//!   pendulum takes its root in closed form: 0).
//!
//! Times are the minimum over 7 repetitions after a warm-up (the machine
//! may be shared: the ratios, taken in one run, are what to compare). Then
//! the memory of a stored trajectory of 10⁶ pendulum states: the bytes the
//! trajectory holds (as requested from the allocator) and the growth of the
//! resident set, per stored state. Nothing asserts.
//!
//! For instruction counts, `OVERHEAD_MODE=run|observed|step_in_place|limit`
//! with `OVERHEAD_STEPS=n` takes that one mode once, n steps, for the
//! systems `OVERHEAD_ONLY` selects, and prints nothing: under
//! `valgrind --tool=callgrind` at two step counts, the difference of the
//! totals over the difference of the steps is the mode's cost per step.

use geoshake_testkit::bench::limit;

use geoshake::{constrained_system, ConstrainedSystem, Integrator, State, Stop, StormerVerlet};
use limit::{limit_chain_state, pairs, LimitChain, LimitPendulum};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Counts the bytes currently allocated (as requested).
struct Bytes;
static LIVE: AtomicUsize = AtomicUsize::new(0);
unsafe impl GlobalAlloc for Bytes {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size(), Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        LIVE.fetch_add(new_size, Ordering::Relaxed);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
#[global_allocator]
static GLOBAL: Bytes = Bytes;

macro_rules! chain {
    ($name:ident, $n:literal) => {
        constrained_system! {
            /// A hanging chain of unit masses joined by rods of one length,
            /// the first anchored at the origin.
            pub struct $name {
                parameters { length, gravity }
                const N = $n;
                dof q[2*N], p[2*N];
                hamiltonian = sum i in 0..N { (p[2*i]^2 + p[2*i+1]^2) / 2 + gravity * q[2*i+1] };
                constraints {
                    link[k in 0..N]: if k == 0 { q[0]^2 + q[1]^2 - length^2 }
                        else { (q[2*k] - q[2*k-2])^2 + (q[2*k+1] - q[2*k-1])^2 - length^2 },
                }
            }
        }
    };
}
chain!(Chain4, 4);
chain!(Chain16, 16);
chain!(Chain64, 64);
chain!(Chain256, 256);

const H: f64 = 0.01;
const REPS: usize = 7;

/// Minimum over `REPS` timed calls (after one warm-up call) of `f`, in µs
/// per step for `steps` steps.
fn time_us(steps: u64, mut f: impl FnMut()) -> f64 {
    f();
    (0..REPS)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
        * 1e6
        / steps as f64
}

struct Row {
    run_us: f64,
    observed_us: f64,
    step_us: f64,
    limit_us: f64,
    max_rel_g: f64,
    limit_rel_g: f64,
    de: f64,
    limit_de: f64,
    dz: f64,
    iterations: f64,
    limit_iterations: f64,
}

/// The library's side: run and step timings, and the run's |g| and energy.
fn library<S: ConstrainedSystem + Clone>(
    sys: S,
    z0: &State,
    steps: u64,
    rel_g: impl Fn(&State) -> f64,
) -> (f64, f64, f64, f64, f64, State, f64) {
    let mut integ = Integrator::new(sys, StormerVerlet, H).rattle();
    let run_us = time_us(steps, || {
        let out = integ
            .run(z0.clone(), Stop::Steps(steps))
            .store(false)
            .execute();
        assert!(out.error.is_none(), "{:?}", out.error);
    });
    let mut seen = 0u64;
    let mut count = |_: &geoshake::StepEvent| {
        seen += 1;
        std::ops::ControlFlow::Continue(())
    };
    let observed_us = time_us(steps, || {
        let out = integ
            .run(z0.clone(), Stop::Steps(steps))
            .store(false)
            .on_step(&mut count)
            .execute();
        assert!(out.error.is_none(), "{:?}", out.error);
    });
    std::hint::black_box(seen);
    let step_us = time_us(steps, || {
        let mut z = z0.clone();
        for _ in 0..steps {
            integ.step_in_place(&mut z).expect("a regular step");
        }
        std::hint::black_box(&z);
    });
    // Newton iterations of the position stage per step (not timed).
    let mut z = z0.clone();
    let mut iterations = 0;
    for _ in 0..steps {
        iterations += integ
            .step_in_place(&mut z)
            .expect("a regular step")
            .shake_iterations;
    }
    // Accuracy of the same run (not timed).
    let sys = integ.system().clone();
    let e0 = sys.hamiltonian(z0.q.as_slice(), z0.p.as_slice());
    let (mut max_g, mut de) = (0.0f64, 0.0f64);
    let mut last = z0.clone();
    let out = integ
        .run(z0.clone(), Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k == 0 {
                // As for the limit: the states the steps computed.
                return;
            }
            max_g = max_g.max(rel_g(z));
            de = de.max((sys.hamiltonian(z.q.as_slice(), z.p.as_slice()) - e0).abs());
            last = z.clone();
        })
        .execute();
    assert!(out.error.is_none());
    (
        run_us,
        observed_us,
        step_us,
        max_g,
        de,
        last,
        iterations as f64 / steps as f64,
    )
}

fn pendulum(steps: u64) -> Row {
    let (length, gravity) = (1.0, 1.0);
    let (th, om) = (1.0f64, 0.5);
    let q0 = [length * th.sin(), -length * th.cos()];
    let p0 = [length * om * th.cos(), length * om * th.sin()];
    let z0 = State::from_slices(&q0, &p0);
    let lim = LimitPendulum { length, gravity };
    let (run_us, observed_us, step_us, max_rel_g, de, last, iterations) = library(
        geoshake::models::Pendulum::new(length, gravity),
        &z0,
        steps,
        |z| lim.relative_g(&[z.q[0], z.q[1]]),
    );
    let limit_us = time_us(steps, || {
        let (mut q, mut p) = (q0, p0);
        for _ in 0..steps {
            lim.step(H, &mut q, &mut p);
        }
        std::hint::black_box((q, p));
    });
    let (mut q, mut p) = (q0, p0);
    let e0 = lim.energy(&q, &p);
    let (mut lg, mut lde) = (0.0f64, 0.0f64);
    // The limit's pendulum takes the root in closed form: no iteration.
    for _ in 0..steps {
        lim.step(H, &mut q, &mut p);
        lg = lg.max(lim.relative_g(&q));
        lde = lde.max((lim.energy(&q, &p) - e0).abs());
    }
    let dz = State::from_slices(&q, &p).distance(&last);
    Row {
        run_us,
        observed_us,
        step_us,
        limit_us,
        max_rel_g,
        limit_rel_g: lg,
        de,
        limit_de: lde,
        dz,
        iterations,
        limit_iterations: 0.0,
    }
}

fn chain<const N: usize, S: ConstrainedSystem + Clone>(sys: S, steps: u64) -> Row {
    let (length, gravity) = (1.0, 1.0);
    let (q0, p0) = limit_chain_state(N, length);
    let (q0, p0) = (pairs::<N>(&q0), pairs::<N>(&p0));
    let z0 = State::from_slices(q0.as_flattened(), p0.as_flattened());
    let mut lim = LimitChain::<N>::new(length, gravity);
    let (run_us, observed_us, step_us, max_rel_g, de, last, iterations) =
        library(sys, &z0, steps, |z| {
            lim.relative_g(&pairs::<N>(z.q.as_slice()))
        });
    let limit_us = time_us(steps, || {
        let (mut q, mut p) = (q0, p0);
        for _ in 0..steps {
            lim.step(H, &mut q, &mut p);
        }
        std::hint::black_box((&q, &p));
    });
    let (mut q, mut p) = (q0, p0);
    let e0 = lim.energy(&q, &p);
    let (mut lg, mut lde) = (0.0f64, 0.0f64);
    let mut limit_iterations = 0;
    for _ in 0..steps {
        limit_iterations += lim.step(H, &mut q, &mut p);
        lg = lg.max(lim.relative_g(&q));
        lde = lde.max((lim.energy(&q, &p) - e0).abs());
    }
    let dz = State::from_slices(q.as_flattened(), p.as_flattened()).distance(&last);
    Row {
        run_us,
        observed_us,
        step_us,
        limit_us,
        max_rel_g,
        limit_rel_g: lg,
        de,
        limit_de: lde,
        dz,
        iterations,
        limit_iterations: limit_iterations as f64 / steps as f64,
    }
}

fn print(name: &str, r: &Row) {
    for (mode, us) in [
        ("run", r.run_us),
        ("observed", r.observed_us),
        ("step_in_place", r.step_us),
    ] {
        println!(
            "overhead system={name} mode={mode} run_us={us:.4} limit_us={:.4} ratio={:.2} max_rel_g={:.1e} limit_rel_g={:.1e} dE={:.1e} limit_dE={:.1e} dz={:.1e} iters={:.2} limit_iters={:.2}",
            r.limit_us,
            us / r.limit_us,
            r.max_rel_g,
            r.limit_rel_g,
            r.de,
            r.limit_de,
            r.dz,
            r.iterations,
            r.limit_iterations
        );
    }
}

/// One mode, once, `steps` steps from `z0`, for instruction counts
/// (`OVERHEAD_MODE`).
fn probe_library<S: ConstrainedSystem>(sys: S, z0: &State, mode: &str, steps: u64) {
    let mut integ = Integrator::new(sys, StormerVerlet, H).rattle();
    match mode {
        "run" => {
            let out = integ
                .run(z0.clone(), Stop::Steps(steps))
                .store(false)
                .execute();
            assert!(out.error.is_none(), "{:?}", out.error);
        }
        "observed" => {
            let mut seen = 0u64;
            let out = integ
                .run(z0.clone(), Stop::Steps(steps))
                .store(false)
                .on_step(&mut |_: &geoshake::StepEvent| {
                    seen += 1;
                    std::ops::ControlFlow::Continue(())
                })
                .execute();
            assert!(out.error.is_none(), "{:?}", out.error);
            std::hint::black_box(seen);
        }
        "step_in_place" => {
            let mut z = z0.clone();
            for _ in 0..steps {
                integ.step_in_place(&mut z).expect("a regular step");
            }
            std::hint::black_box(&z);
        }
        _ => panic!("OVERHEAD_MODE: run, observed, step_in_place or limit"),
    }
}

fn probe_pendulum(mode: &str, steps: u64) {
    let (th, om) = (1.0f64, 0.5);
    let q0 = [th.sin(), -th.cos()];
    let p0 = [om * th.cos(), om * th.sin()];
    if mode == "limit" {
        let lim = LimitPendulum {
            length: 1.0,
            gravity: 1.0,
        };
        let (mut q, mut p) = (q0, p0);
        for _ in 0..steps {
            lim.step(H, &mut q, &mut p);
        }
        std::hint::black_box((q, p));
    } else {
        let z0 = State::from_slices(&q0, &p0);
        probe_library(geoshake::models::Pendulum::new(1.0, 1.0), &z0, mode, steps);
    }
}

fn probe_chain<const N: usize, S: ConstrainedSystem>(sys: S, mode: &str, steps: u64) {
    let (q0, p0) = limit_chain_state(N, 1.0);
    if mode == "limit" {
        let mut lim = LimitChain::<N>::new(1.0, 1.0);
        let (mut q, mut p) = (pairs::<N>(&q0), pairs::<N>(&p0));
        for _ in 0..steps {
            lim.step(H, &mut q, &mut p);
        }
        std::hint::black_box((&q, &p));
    } else {
        probe_library(sys, &State::from_slices(&q0, &p0), mode, steps);
    }
}

/// Resident set size of this process, in bytes.
fn rss() -> usize {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap_or_default();
    let pages: usize = statm
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    pages * 4096
}

fn memory() {
    let n: u64 = 1_000_000;
    let sys = geoshake::models::Pendulum::new(1.0, 1.0);
    let mut integ = Integrator::new(sys, StormerVerlet, H).rattle();
    let z0 = State::from_slices(
        &[1f64.sin(), -1f64.cos()],
        &[0.5 * 1f64.cos(), 0.5 * 1f64.sin()],
    );
    let (live0, rss0) = (LIVE.load(Ordering::Relaxed), rss());
    let out = integ.run(z0, Stop::Steps(n - 1)).execute();
    let (live1, rss1) = (LIVE.load(Ordering::Relaxed), rss());
    let traj = out.into_result().expect("a regular run");
    let len = traj.len() as f64;
    println!(
        "memory system=pendulum states={} state_bytes={:.1}MB bytes={:.1}MB bytes_per_state={:.1} rss_growth={:.1}MB rss_per_state={:.1}",
        traj.len(),
        traj.state_bytes() as f64 / 1e6,
        (live1 - live0) as f64 / 1e6,
        (live1 - live0) as f64 / len,
        rss1.saturating_sub(rss0) as f64 / 1e6,
        rss1.saturating_sub(rss0) as f64 / len,
    );
    drop(traj);
}

fn main() {
    // `OVERHEAD_ONLY=chain_16` measures one system (for profiling).
    let only = std::env::var("OVERHEAD_ONLY").ok();
    let want = |name: &str| only.as_deref().is_none_or(|o| o == name);
    if let Ok(mode) = std::env::var("OVERHEAD_MODE") {
        let steps: u64 = std::env::var("OVERHEAD_STEPS")
            .ok()
            .and_then(|s| s.parse().ok())
            .expect("OVERHEAD_STEPS: the number of steps");
        if want("pendulum") {
            probe_pendulum(&mode, steps);
        }
        if want("chain_4") {
            probe_chain::<4, _>(Chain4::new(1.0, 1.0), &mode, steps);
        }
        if want("chain_16") {
            probe_chain::<16, _>(Chain16::new(1.0, 1.0), &mode, steps);
        }
        if want("chain_64") {
            probe_chain::<64, _>(Chain64::new(1.0, 1.0), &mode, steps);
        }
        if only.as_deref() == Some("chain_256") {
            probe_chain::<256, _>(Chain256::new(1.0, 1.0), &mode, steps);
        }
        return;
    }
    if want("pendulum") {
        print("pendulum", &pendulum(20_000));
    }
    if want("chain_4") {
        print("chain_4", &chain::<4, _>(Chain4::new(1.0, 1.0), 10_000));
    }
    if want("chain_16") {
        print("chain_16", &chain::<16, _>(Chain16::new(1.0, 1.0), 4_000));
    }
    if want("chain_64") {
        print("chain_64", &chain::<64, _>(Chain64::new(1.0, 1.0), 1_000));
    }
    // Not in the default table (the four sizes): 256 links, on
    // request, to see how the ratio grows with the chain.
    if only.as_deref() == Some("chain_256") {
        print("chain_256", &chain::<256, _>(Chain256::new(1.0, 1.0), 250));
    }
    if want("memory") {
        memory();
    }
}
