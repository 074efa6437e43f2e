//! Cost of one SHAKE step and one RATTLE step, for the same system three
//! ways through the same driver (`Integrator::step_in_place`):
//!
//! - `generated`: declared with `constrained_system!`;
//! - `hand`: hand-written analytic Rust (the physical limit);
//! - `num-dual`: H and g written once, derivatives by forward-mode AD at
//!   run time.
//!
//! Scenes: the pendulum (Störmer–Verlet and midpoint), the spherical
//! pendulum (Störmer–Verlet), the Hopf constraint with gravity (midpoint,
//! Section 5.4.2) and chains of N = 4, 16, 64, 256 links (Störmer–Verlet).
//! After criterion's own report, the ratios generated/hand and
//! num-dual/generated are printed as markdown tables (from criterion's
//! median estimates of this run). Reduced measurement times keep the whole
//! bench within a few minutes on two cores:
//!
//!     cargo bench -p geoshake-bench --bench step_cost
//!
//! Nothing here asserts: benchmarks print.

use geoshake_testkit::bench::{chain, dual, report, systems};
use geoshake_testkit::models;

use chain::{chain_state, HandChain};
use criterion::{measurement::WallTime, BenchmarkGroup, Criterion};
use dual::Ad;
use geoshake::{BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, State, StormerVerlet};
use std::hint::black_box;
use std::time::Duration;
use systems::*;

/// Times `step_in_place` for SHAKE and for RATTLE, as `<method>/<variant>`.
fn steps<S: ConstrainedSystem + Clone, B: BaseMap>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    variant: &str,
    sys: S,
    base: B,
    h: f64,
    z0: &State,
) {
    for method in ["shake", "rattle"] {
        let integ = Integrator::new(sys.clone(), base, h);
        let mut integ = if method == "shake" {
            integ.shake()
        } else {
            integ.rattle()
        };
        let start = integ
            .project_to_hidden(z0)
            .expect("bench scenes start near M^H");
        let mut z = start.clone();
        group.bench_function(format!("{method}/{variant}"), |b| {
            b.iter(|| {
                if integ.step_in_place(black_box(&mut z)).is_err() {
                    z = start.clone();
                }
            })
        });
    }
}

fn pendulums(c: &mut Criterion) {
    let z0 = models::Pendulum::default().state(1.0, 0.5);
    let mut g = c.benchmark_group("pendulum-sv");
    steps(
        &mut g,
        "hand",
        models::Pendulum::default(),
        StormerVerlet,
        0.01,
        &z0,
    );
    steps(
        &mut g,
        "generated",
        geoshake::models::Pendulum::new(1.0, 1.0),
        StormerVerlet,
        0.01,
        &z0,
    );
    let ad = Ad::new(PendulumG {
        length: 1.0,
        gravity: 1.0,
    });
    steps(&mut g, "num-dual", ad, StormerVerlet, 0.01, &z0);
    g.finish();

    let mut g = c.benchmark_group("pendulum-midpoint");
    steps(
        &mut g,
        "hand",
        models::Pendulum::default(),
        ImplicitMidpoint,
        0.01,
        &z0,
    );
    steps(
        &mut g,
        "generated",
        geoshake::models::Pendulum::new(1.0, 1.0),
        ImplicitMidpoint,
        0.01,
        &z0,
    );
    let ad = Ad::new(PendulumG {
        length: 1.0,
        gravity: 1.0,
    });
    steps(&mut g, "num-dual", ad, ImplicitMidpoint, 0.01, &z0);
    g.finish();

    let z0 = models::SphericalPendulum::default().state(1.0, 0.3, 0.5, 0.8);
    let mut g = c.benchmark_group("spherical-sv");
    steps(
        &mut g,
        "hand",
        models::SphericalPendulum::default(),
        StormerVerlet,
        0.01,
        &z0,
    );
    let generated = geoshake::models::SphericalPendulum::new(1.0, 1.0);
    steps(&mut g, "generated", generated, StormerVerlet, 0.01, &z0);
    let ad = Ad::new(SphericalG {
        length: 1.0,
        gravity: 1.0,
    });
    steps(&mut g, "num-dual", ad, StormerVerlet, 0.01, &z0);
    g.finish();
}

fn hopf(c: &mut Criterion) {
    // z_a of the paper's table, brought onto the unit M^H by the driver.
    let z0 = State::from_slices(
        &[-0.78652612, -0.4043988],
        &[-0.3880746864163783, 0.2173391755798215],
    );
    let mut g = c.benchmark_group("hopf-gravity-midpoint");
    steps(
        &mut g,
        "hand",
        models::Hopf::gravity(),
        ImplicitMidpoint,
        0.1,
        &z0,
    );
    let generated = geoshake::models::HopfGravity::new(0.0, -1.0, 1.0);
    steps(&mut g, "generated", generated, ImplicitMidpoint, 0.1, &z0);
    let ad = Ad::new(HopfG {
        gravity: [0.0, -1.0],
        radius2: 1.0,
    });
    steps(&mut g, "num-dual", ad, ImplicitMidpoint, 0.1, &z0);
    g.finish();
}

macro_rules! chain_scene {
    ($c:expr, $n:literal, $gen:ident, $dual:expr) => {{
        let z0 = chain_state($n, 1.0);
        let mut g = $c.benchmark_group(concat!("chain-", $n, "-sv"));
        let hand = HandChain::<$n> {
            length: 1.0,
            gravity: 1.0,
        };
        steps(&mut g, "hand", hand, StormerVerlet, 0.01, &z0);
        steps(
            &mut g,
            "generated",
            $gen::new(1.0, 1.0),
            StormerVerlet,
            0.01,
            &z0,
        );
        if $dual {
            let ad = Ad::new(ChainG::<$n> {
                length: 1.0,
                gravity: 1.0,
            });
            steps(&mut g, "num-dual", ad, StormerVerlet, 0.01, &z0);
        }
        g.finish();
    }};
}

fn chains(c: &mut Criterion) {
    chain_scene!(c, 4, Chain4, true);
    chain_scene!(c, 16, Chain16, true);
    // num-dual: every derivative of a 64-link chain is dense (AD does not
    // know the sparsity): N alone costs m²/2 hyper-dual passes of H.
    chain_scene!(c, 64, Chain64, false);
    chain_scene!(c, 256, Chain256, false);
}

fn main() {
    let mut c = Criterion::default()
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_millis(1200))
        .sample_size(20)
        .configure_from_args();
    pendulums(&mut c);
    hopf(&mut c);
    chains(&mut c);
    c.final_summary();
    report::step_cost_tables(&[
        "pendulum-sv",
        "pendulum-midpoint",
        "spherical-sv",
        "hopf-gravity-midpoint",
        "chain-4-sv",
        "chain-16-sv",
        "chain-64-sv",
        "chain-256-sv",
    ]);
}
