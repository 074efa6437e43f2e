//! Constrained HMC (`geoshake::sampler`) on five targets with known answers,
//! one line each for static HMC (L = 10) and for the dynamic integration
//! time (multinomial HMC with the no-U-turn criterion, depth ≤ 10):
//!
//! ```text
//! sampler target=… integration=static|dynamic dim=… constraints=… chains=… draws=… acceptance=… rejected_reverse=…
//!   rejected_newton=… ess_per_s=… rhat=… check=pass|fail (then rejected_nonfinite=…
//!   rejected_degenerate=… rejected_jump=… step_size=… seconds=…)
//! ```
//!
//! `ess_per_s` is the smallest bulk ESS over the checked expectations
//! divided by the wall time of the whole run (warm-up included, chains in
//! parallel); `rhat` the largest rank-normalised split-R̂ over them;
//! `check=pass` when every expectation is within 4.5 Monte Carlo standard
//! errors of its exact value, with R̂ < 1.05 and an ESS of at least 400
//! (as tests/suite/sampler.rs checks them).
//!
//! `cargo run --release --example sampler`

use std::time::Instant;

use geoshake::sampler::{sample, Estimate, SamplerOptions, Samples};
use geoshake::ConstrainedSystem;

mod targets;
use targets::{simpson, Rotation, Sphere, Torus, VonMisesFisher, Wavy};

/// An expectation: its name, f, and the exact value.
type Expectation = (&'static str, fn(&[f64]) -> f64, f64);

fn options() -> SamplerOptions {
    SamplerOptions {
        chains: 4,
        draws: 5000,
        warmup: 1000,
        steps: 10,
        step_size: 0.2,
        step_size_jitter: 0.5,
        seed: 2024,
        ..SamplerOptions::default()
    }
}

/// Samples `system` from `starts` with the static and the dynamic
/// integration time, checks the expectations and prints one line for each.
fn run<S, Q>(name: &str, system: &S, starts: &[Q], expectations: &[Expectation]) -> bool
where
    S: ConstrainedSystem + Clone + Send + Sync,
    Q: AsRef<[f64]> + Sync,
{
    let fixed = run_one(name, system, starts, expectations, None);
    let dynamic = run_one(name, system, starts, expectations, Some(10));
    fixed && dynamic
}

fn run_one<S, Q>(
    name: &str,
    system: &S,
    starts: &[Q],
    expectations: &[Expectation],
    max_tree_depth: Option<u32>,
) -> bool
where
    S: ConstrainedSystem + Clone + Send + Sync,
    Q: AsRef<[f64]> + Sync,
{
    let opts = SamplerOptions {
        max_tree_depth,
        ..options()
    };
    let integration = if max_tree_depth.is_some() {
        "dynamic"
    } else {
        "static"
    };
    let clock = Instant::now();
    let samples: Samples = match sample(system, starts, &opts) {
        Ok(s) => s,
        Err(e) => {
            println!("sampler target={name} integration={integration} error=\"{e}\" check=fail");
            return false;
        }
    };
    let seconds = clock.elapsed().as_secs_f64();
    let mut pass = true;
    let (mut ess, mut rhat) = (f64::INFINITY, 0.0f64);
    for (_, f, exact) in expectations {
        let e = Estimate::of(&samples.series(f));
        pass &= (e.mean - exact).abs() < 4.5 * e.mcse && e.rhat < 1.05 && e.ess_mean >= 400.0;
        ess = ess.min(e.ess_bulk);
        rhat = rhat.max(e.rhat);
    }
    let summary = samples.summary();
    let r = summary.rejected();
    let mean_h = samples.step_size.iter().sum::<f64>() / samples.step_size.len() as f64;
    println!(
        "sampler target={name} integration={integration} dim={} constraints={} chains={} draws={} acceptance={:.3} \
         rejected_reverse={} rejected_newton={} ess_per_s={:.0} rhat={:.4} check={} \
         rejected_nonfinite={} rejected_degenerate={} rejected_jump={} step_size={:.3} seconds={:.3}",
        system.dof(),
        system.constraint_count(),
        opts.chains,
        opts.draws,
        summary.acceptance(),
        r.reverse,
        r.newton,
        ess / seconds,
        rhat,
        if pass { "pass" } else { "fail" },
        r.non_finite,
        r.degenerate,
        r.jump,
        mean_h,
        seconds
    );
    pass
}

fn main() {
    let sphere_starts = [
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let mut all = true;

    all &= run(
        "sphere_uniform",
        &Sphere {},
        &sphere_starts,
        &[
            ("E[x^2]", |q| q[0] * q[0], 1.0 / 3.0),
            ("E[z^4]", |q| q[2].powi(4), 0.2),
        ],
    );

    // E[z] = coth κ − 1/κ, E[z²] = 1 − 2E[z]/κ.
    const KAPPA: f64 = 3.0;
    let a = 1.0 / KAPPA.tanh() - 1.0 / KAPPA;
    let vmf: [Expectation; 2] = [
        ("E[z]", |q| q[2], a),
        ("E[z^2]", |q| q[2] * q[2], 1.0 - 2.0 * a / KAPPA),
    ];
    all &= run(
        "vmf_sphere",
        &VonMisesFisher { kappa: KAPPA },
        &sphere_starts,
        &vmf,
    );

    // Moments by the trapezoidal rule, exact for smooth periodic integrands.
    let (k1, k2, nu) = (1.0f64, 0.5, 1.0);
    let n = 256;
    let (mut z, mut c1, mut c12) = (0.0, 0.0, 0.0);
    for i in 0..n {
        for j in 0..n {
            let t1 = 2.0 * std::f64::consts::PI * i as f64 / n as f64;
            let t2 = 2.0 * std::f64::consts::PI * j as f64 / n as f64;
            let w = (k1 * t1.cos() + k2 * t2.cos() + nu * (t1 - t2).cos()).exp();
            z += w;
            c1 += w * t1.cos();
            c12 += w * (t1 - t2).cos();
        }
    }
    let torus: [Expectation; 2] = [
        ("E[cos t1]", |q| q[0], c1 / z),
        ("E[cos(t1-t2)]", |q| q[0] * q[2] + q[1] * q[3], c12 / z),
    ];
    all &= run(
        "torus",
        &Torus { k1, k2, nu },
        &[
            [1.0, 0.0, 1.0, 0.0],
            [-1.0, 0.0, 1.0, 0.0],
            [0.0, 1.0, 0.0, -1.0],
            [-1.0, 0.0, -1.0, 0.0],
        ],
        &torus,
    );

    // tr R = 1 + 2 cos θ, θ with density ∝ (1 − cos θ) e^{κ tr R} on [0, π].
    let kappa = 1.0;
    let weight = |t: f64| (1.0 - t.cos()) * (kappa * (1.0 + 2.0 * t.cos())).exp();
    let pi = std::f64::consts::PI;
    let trace = simpson(|t| weight(t) * (1.0 + 2.0 * t.cos()), 0.0, pi, 2000)
        / simpson(weight, 0.0, pi, 2000);
    let so3: [Expectation; 1] = [("E[tr R]", |q| q[0] + q[4] + q[8], trace)];
    all &= run(
        "so3_matrix_fisher",
        &Rotation { kappa },
        &[[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]],
        &so3,
    );

    // E[x²] and E[y²] with respect to arc length, by Simpson on [−12, 12].
    let (a, w) = (0.5f64, 3.0f64);
    let density = |x: f64| (-x * x / 2.0).exp() * (1.0 + (a * w * (w * x).cos()).powi(2)).sqrt();
    let norm = simpson(density, -12.0, 12.0, 200_000);
    let y2 = simpson(
        |x| (a * (w * x).sin()).powi(2) * density(x),
        -12.0,
        12.0,
        200_000,
    ) / norm;
    let wavy: [Expectation; 1] = [("E[y^2]", |q| q[1] * q[1], y2)];
    all &= run("wavy_curve", &Wavy { a, w }, &[[0.0, 0.0]], &wavy);

    if !all {
        std::process::exit(1);
    }
}
