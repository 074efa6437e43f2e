//! Scaling and "skip what a scene doesn't need", measured:
//!
//!     cargo bench -p geoshake-bench --bench scaling
//!
//! 1. Cost per step of a chain of N links against N (SHAKE and RATTLE runs
//!    with Störmer–Verlet, hand-written and generated code).
//! 2. The projection onto M^H only on observed steps: a long RATTLE run
//!    with output every step against output every 100 steps.
//! 3. Explicit Störmer–Verlet against the implicit midpoint rule on a
//!    separable H.
//! 4. Ensembles: throughput of `run_ensemble` on 1 thread and on all cores.
//!
//! Times are the best of several repetitions (the machine may be shared);
//! the tables are printed as markdown. Nothing asserts.

use geoshake_testkit::bench::{chain, systems};

use chain::{chain_state, HandChain};
use geoshake::{
    run_ensemble, BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, Options, State, Stop,
    StormerVerlet,
};
use std::time::Instant;

/// Best time of `reps` calls of `f`, in seconds.
fn best(reps: usize, mut f: impl FnMut()) -> f64 {
    (0..reps)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Seconds per step of a run of `steps` steps observing only the last state.
fn per_step<S: ConstrainedSystem + Clone, B: BaseMap>(
    integ: &mut Integrator<S, B>,
    z0: &State,
    steps: u64,
    stride: u64,
) -> f64 {
    let z0 = integ.project_to_hidden(z0).expect("near M^H");
    let reps = 5;
    best(reps, || {
        let out = integ
            .run(z0.clone(), Stop::Steps(steps))
            .stride(stride)
            .store(false)
            .execute();
        assert!(out.error.is_none(), "{:?}", out.error);
    }) / steps as f64
}

/// Seconds per `step_in_place` (one step, its checks included).
fn per_step_in_place<S: ConstrainedSystem + Clone, B: BaseMap>(
    integ: &mut Integrator<S, B>,
    z0: &State,
    steps: usize,
) -> f64 {
    let start = integ.project_to_hidden(z0).expect("near M^H");
    best(5, || {
        let mut z = start.clone();
        for _ in 0..steps {
            integ.step_in_place(&mut z).expect("step");
        }
    }) / steps as f64
}

fn chain_row<S: ConstrainedSystem + Clone>(n: usize, sys: S, steps: usize) -> (f64, f64) {
    let z0 = chain_state(n, 1.0);
    let mut shake = Integrator::new(sys.clone(), StormerVerlet, 0.01).shake();
    let mut rattle = Integrator::new(sys, StormerVerlet, 0.01).rattle();
    (
        per_step_in_place(&mut shake, &z0, steps),
        per_step_in_place(&mut rattle, &z0, steps),
    )
}

fn us(s: f64) -> String {
    format!("{:.2} µs", s * 1e6)
}

fn main() {
    // 1. Chains.
    println!("### Chain of N links, Störmer–Verlet, h = 0.01: time per step\n");
    println!(
        "`Integrator::step_in_place` (SHAKE; RATTLE = SHAKE + Π every step), checks included.\n"
    );
    println!("| N | SHAKE hand | SHAKE generated | RATTLE hand | RATTLE generated | SHAKE generated / previous N |");
    println!("|---:|---:|---:|---:|---:|---:|");
    let mut prev: Option<(usize, f64)> = None;
    macro_rules! row {
        ($n:literal, $gen:expr, $steps:expr) => {{
            let hand = chain_row(
                $n,
                HandChain::<$n> {
                    length: 1.0,
                    gravity: 1.0,
                },
                $steps,
            );
            let generated = $gen.map(|g| chain_row($n, g, $steps));
            let growth = match (prev, generated) {
                (Some((pn, pt)), Some(g)) => format!("{:.2} (N × {})", g.0 / pt, $n / pn),
                _ => "—".into(),
            };
            let cell = |x: Option<f64>| x.map(us).unwrap_or_else(|| "—".into());
            println!(
                "| {} | {} | {} | {} | {} | {} |",
                $n,
                us(hand.0),
                cell(generated.map(|g| g.0)),
                us(hand.1),
                cell(generated.map(|g| g.1)),
                growth
            );
            if let Some(g) = generated {
                prev = Some(($n, g.0));
            }
        }};
    }
    row!(4, Some(systems::Chain4::new(1.0, 1.0)), 2000);
    row!(8, None::<systems::Chain4>, 2000);
    row!(16, Some(systems::Chain16::new(1.0, 1.0)), 1000);
    row!(32, None::<systems::Chain4>, 500);
    row!(64, Some(systems::Chain64::new(1.0, 1.0)), 200);
    row!(128, None::<systems::Chain4>, 100);
    row!(256, Some(systems::Chain256::new(1.0, 1.0)), 50);
    let _ = prev;

    // 2. Projection only where observed.
    println!("\n### RATTLE: projection onto M^H only on observed steps\n");
    println!("| scene | output every step | output every 100 steps | ratio | eager projection (every step), output every 100 |");
    println!("|---|---:|---:|---:|---:|");
    {
        let sys = geoshake::models::Pendulum::new(1.0, 1.0);
        let z0 = State::from_slices(
            &[1f64.sin(), -1f64.cos()],
            &[0.5 * 1f64.cos(), 0.5 * 1f64.sin()],
        );
        let mut r = Integrator::new(sys, StormerVerlet, 0.01).rattle();
        let every = per_step(&mut r, &z0, 20_000, 1);
        let sparse = per_step(&mut r, &z0, 20_000, 100);
        let opts = Options {
            project_every_step: true,
            ..Options::default()
        };
        let mut eager = Integrator::new(sys, StormerVerlet, 0.01)
            .rattle()
            .with_options(opts);
        let eager = per_step(&mut eager, &z0, 20_000, 100);
        println!(
            "| pendulum, SV | {} | {} | {:.2} | {} |",
            us(every),
            us(sparse),
            every / sparse,
            us(eager)
        );
    }

    // 3. Explicit SV against the implicit midpoint rule on separable H.
    println!("\n### Separable H: explicit Störmer–Verlet against the implicit midpoint rule (SHAKE step)\n");
    println!("| scene | Störmer–Verlet | midpoint | midpoint / SV |");
    println!("|---|---:|---:|---:|");
    {
        let sys = geoshake::models::Pendulum::new(1.0, 1.0);
        let z0 = State::from_slices(
            &[1f64.sin(), -1f64.cos()],
            &[0.5 * 1f64.cos(), 0.5 * 1f64.sin()],
        );
        let sv = per_step(
            &mut Integrator::new(sys, StormerVerlet, 0.01).shake(),
            &z0,
            20_000,
            20_000,
        );
        let mp = per_step(
            &mut Integrator::new(sys, ImplicitMidpoint, 0.01).shake(),
            &z0,
            20_000,
            20_000,
        );
        println!("| pendulum | {} | {} | {:.2} |", us(sv), us(mp), mp / sv);
        let sys = systems::Chain16::new(1.0, 1.0);
        let z0 = chain_state(16, 1.0);
        let sv = per_step(
            &mut Integrator::new(sys, StormerVerlet, 0.01).shake(),
            &z0,
            1000,
            1000,
        );
        let mp = per_step(
            &mut Integrator::new(sys, ImplicitMidpoint, 0.01).shake(),
            &z0,
            1000,
            1000,
        );
        println!(
            "| chain N = 16 | {} | {} | {:.2} |",
            us(sv),
            us(mp),
            mp / sv
        );
    }

    // 4. Ensembles.
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    println!(
        "\n### Ensembles: 64 pendulums × 20 000 RATTLE steps (SV, h = 0.01, output every 100)\n"
    );
    println!("| threads | wall time | runs / s | speed-up |");
    println!("|---:|---:|---:|---:|");
    {
        let sys = geoshake::models::Pendulum::new(1.0, 1.0);
        let template = Integrator::new(sys, StormerVerlet, 0.01).rattle();
        let starts: Vec<State> = (0..64)
            .map(|k| {
                let a = 0.2 + 0.04 * k as f64;
                State::from_slices(&[a.sin(), -a.cos()], &[0.0, 0.0])
            })
            .collect();
        let mut single = 0.0;
        for threads in [1, cores] {
            let pool = geoshake::rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let t = best(3, || {
                let outs =
                    pool.install(|| run_ensemble(&template, &starts, Stop::Steps(20_000), 100));
                assert!(outs.iter().all(|o| o.error.is_none()));
            });
            if threads == 1 {
                single = t;
            }
            println!(
                "| {threads} | {:.1} ms | {:.0} | {:.2} |",
                t * 1e3,
                64.0 / t,
                single / t
            );
        }
    }
}
