//! Molecular dynamics of liquid water with forces the user brings: rigid
//! SPC/E molecules (the constraints of `generate::water`) interacting by
//! the charges and Lennard-Jones of `spce.rs`, a force field written in
//! plain Rust and handed to the integrator with `ParticleSystem::with_forces`.
//! RATTLE with Störmer–Verlet at h = 2 fs, microcanonical by default (H =
//! K + V is the quantity to watch), or with a Langevin thermostat (BAOAB or
//! geodesic BAOAB with 2 drift substeps, γ = 1/ps, at 300 K: the kinetic
//! temperature is the quantity to watch).
//!
//!     cargo run --release --example water_md                 # 1000 waters, 10⁴ steps (20 ps), ~5 min
//!     cargo run --release --example water_md -- --quick      # 216 waters, 500 steps (CI), ~5 s
//!     cargo run --release --example water_md -- --waters 512 --steps 2000 --cutoff 8
//!     cargo run --release --example water_md -- --quick --thermostat gbaoab
//!
//! Options: `--waters N` (1000), `--steps N` (10⁴), `--equilibrate N`
//! (2500), `--every N` (1000), `--cutoff R` (9 Å; every box side must be at
//! least 2 R), `--thermostat none|baoab|gbaoab` (none).
//!
//! The waters start on the lattice of `generate::water` (liquid density, the
//! periodic box `generate::water_box`), randomly oriented, at 300 K after
//! the momenta are projected onto the hidden constraints. `--equilibrate`
//! steps with the momenta rescaled to 300 K every 10 steps take them into
//! the liquid; the microcanonical run then starts at step 0. One row every
//! `--every` steps: the step, the time, H and V (kcal/mol), the kinetic
//! temperature (dof = 3N − m − 3), the largest relative bond-length error
//! |r − l|/l, and the largest solver residual of the steps since the last
//! row. At the end, the energy drift: the slope of a least-squares line
//! through H(t), sampled every 10 steps, in kcal/mol/ns and per degree of
//! freedom in units of k_B·T̄ per ns (T̄ the mean kinetic temperature), what
//! the line changes over the run against the RMS of H about it, the
//! configurational temperature, and the wall time per step of the run (the
//! steps only: the samples' own force calls are not counted). The last
//! line sums the run up:
//!
//!     md system=water n=… thermostat=… steps=… dt_fs=… energy_drift_per_ns=…
//!        kinetic_temperature=… configurational_temperature=…
//!        max_rel_bond_error=… ns_per_day=…
//!
//! (one line; the drift in kcal/mol/ns, `n/a` with a thermostat; the
//! kinetic temperature the run's mean, with 3N − m − 3 degrees of freedom
//! without a thermostat and 3N − m with one, which does not conserve the
//! total momentum; the configurational temperature is the translational
//! estimator k_B T = ⟨Σ_i |F_i|²⟩ / ⟨Σ_i ∇²_{R_i} V⟩ over the molecules'
//! centres of mass, sampled every 10 steps, `Spce::translational_terms`
//! says why it measures T; its standard error from 10 batch means is
//! printed above the line.)

use std::time::Instant;

use geoshake::runtime::particles::generate::{self, KB, MVV2E};
use geoshake::runtime::particles::{Langevin, Options, ParticleState, Rattle};

mod spce;
use spce::{configurational_temperature, Spce};

/// Steps between two samples of H (the points of the drift's fit).
const SAMPLE: u64 = 10;

/// The command-line value after `flag`, parsed.
fn arg<T: std::str::FromStr>(flag: &str) -> Option<T> {
    std::env::args()
        .skip_while(|a| a != flag)
        .nth(1)
        .and_then(|v| v.parse().ok())
}

/// H = K + V of the state, in kcal/mol (the potential is the one the last
/// step computed, so this costs no force call along the run).
fn energy(rattle: &mut Rattle, state: &ParticleState) -> (f64, f64) {
    let v = rattle.potential_energy(state).expect("finite forces");
    let k = rattle.system().kinetic_energy(state.p());
    ((k + v) * MVV2E, v * MVV2E)
}

/// The slope b of the least-squares line y ≈ a + b·x, and the RMS of y
/// about it.
fn linear_fit(x: &[f64], y: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(x, y)| (x - mx) * (y - my)).sum();
    let sxx: f64 = x.iter().map(|x| (x - mx) * (x - mx)).sum();
    let b = sxy / sxx;
    let rss: f64 = x
        .iter()
        .zip(y)
        .map(|(x, y)| (y - my - b * (x - mx)).powi(2))
        .sum();
    (b, (rss / n).sqrt())
}

fn fail(what: &str) -> ! {
    eprintln!("water_md: {what}");
    std::process::exit(1)
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let waters: usize = arg("--waters").unwrap_or(if quick { 216 } else { 1000 });
    let steps: u64 = arg("--steps").unwrap_or(if quick { 500 } else { 10_000 });
    let every: u64 = arg("--every").unwrap_or(if quick { 100 } else { 1000 });
    let equilibrate: u64 = arg("--equilibrate").unwrap_or(if quick { 500 } else { 2500 });
    let cutoff: f64 = arg("--cutoff").unwrap_or(9.0);
    let (h, kelvin, seed) = (2.0, 300.0, 2024);
    let thermostat: String = arg("--thermostat").unwrap_or_else(|| "none".into());
    let substeps = match thermostat.as_str() {
        "none" => 0,
        "baoab" => 1,
        "gbaoab" => 2,
        other => fail(&format!("--thermostat {other}: none, baoab or gbaoab")),
    };

    let (system, mut state) = generate::water(waters, seed).expect("a valid water topology");
    let box_len = generate::water_box(waters);
    let field = Spce::new(box_len, cutoff).unwrap_or_else(|e| fail(&e));
    // The integrator owns `field`; the estimator's samples use their own.
    let mut probe = Spce::new(box_len, cutoff).unwrap_or_else(|e| fail(&e));
    let [lx, ly, lz] = box_len;
    let pairs = match field.cells() {
        Some([nx, ny, nz]) => format!("cell list {nx}×{ny}×{nz}"),
        None => "all pairs (fewer than 3 cells per side)".into(),
    };
    let (atoms, m) = (system.particles(), system.constraints());
    let dof = (3 * atoms - m - 3) as f64;
    println!(
        "water_md: {waters} SPC/E waters ({atoms} atoms, {m} constraints), \
         box {lx:.2}×{ly:.2}×{lz:.2} Å, r_c = {cutoff} Å, shifted-force Coulomb and LJ, {pairs}"
    );
    println!(
        "h = {h} fs, {steps} steps, T0 = {kelvin} K, RATTLE tol {:e}",
        Options::default().tol
    );

    let mut rattle = Rattle::new(system.with_forces(field), h, Options::default())
        .unwrap_or_else(|e| fail(&e.to_string()));
    rattle
        .project(&mut state)
        .unwrap_or_else(|e| fail(&e.to_string()));
    generate::set_temperature(rattle.system(), &mut state, kelvin);

    // On the lattice, randomly oriented, V ≈ +0.6 kcal/mol per water,
    // against ≈ −10 in the liquid: left to itself the box would heat to
    // ≈ 1200 K. Rescaling the momenta to T0 every `SAMPLE` steps takes the
    // heat away (the scaling keeps G M⁻¹ p = 0); the run proper then starts
    // at step 0 from the liquid.
    let clock = Instant::now();
    for _ in 0..equilibrate.div_ceil(SAMPLE) {
        let out = rattle.run_in_place(&mut state, SAMPLE);
        if let Some(e) = out.error {
            fail(&e.to_string());
        }
        generate::set_temperature(rattle.system(), &mut state, kelvin);
    }
    let v = energy(&mut rattle, &state).1;
    if substeps > 0 {
        // γ = 1/ps; k_B T in the integrator's units (g/mol Å²/fs²).
        let langevin = Langevin::new(1e-3, KB * kelvin / MVV2E, seed)
            .and_then(|l| l.geodesic(substeps))
            .unwrap_or_else(|e| fail(&e.to_string()));
        rattle
            .set_thermostat(Some(langevin))
            .unwrap_or_else(|e| fail(&e.to_string()));
    }
    println!(
        "equilibrated: {} steps ({:.1} ps) rescaled to {kelvin} K every {SAMPLE}: V = {v:.4} kcal/mol ({:.1} s)",
        state.step(),
        state.time() * 1e-3,
        clock.elapsed().as_secs_f64()
    );
    let mut state = state.with_time(0.0);

    let bond_error = |rattle: &Rattle, state: &ParticleState| {
        let table = rattle.system().constraint_families()[0].table();
        generate::max_rel_length_error(table, 3, state.q())
    };
    println!(
        "{:>7} {:>7} {:>14} {:>14} {:>8} {:>10} {:>10}",
        "step", "t/ps", "H/(kcal/mol)", "V/(kcal/mol)", "T/K", "bond err", "residual"
    );
    let row = |rattle: &mut Rattle, state: &ParticleState, residual: f64| {
        let (e, v) = energy(rattle, state);
        println!(
            "{:>7} {:>7.2} {:>14.4} {:>14.4} {:>8.2} {:>10.2e} {:>10.2e}",
            state.step(),
            state.time() * 1e-3,
            e,
            v,
            generate::temperature(rattle.system(), state),
            bond_error(rattle, state),
            residual
        );
    };
    row(&mut rattle, &state, 0.0);

    let (mut times, mut energies, mut temperatures) = (vec![0.0], vec![], vec![]);
    energies.push(energy(&mut rattle, &state).0);
    temperatures.push(generate::temperature(rattle.system(), &state));
    let mut residual = 0.0f64;
    let mut worst_bond = bond_error(&rattle, &state);
    // Σ_i |F_i|² and Σ_i ∇²_{R_i} V at every sample (kcal/mol/Å units).
    let mut configurational = vec![probe.translational_terms(state.q())];
    let mut wall = 0.0;
    while state.step() < steps {
        let chunk = SAMPLE.min(steps - state.step());
        let clock = Instant::now();
        let out = rattle.run_in_place(&mut state, chunk);
        wall += clock.elapsed().as_secs_f64();
        if let Some(e) = out.error {
            fail(&e.to_string());
        }
        residual = residual.max(out.summary.max_residual.unwrap_or(f64::NAN));
        times.push(state.time() * 1e-6);
        energies.push(energy(&mut rattle, &state).0);
        temperatures.push(generate::temperature(rattle.system(), &state));
        configurational.push(probe.translational_terms(state.q()));
        worst_bond = worst_bond.max(bond_error(&rattle, &state));
        if state.step() % every == 0 || state.step() == steps {
            row(&mut rattle, &state, residual);
            residual = 0.0;
        }
    }

    let (slope, rms) = linear_fit(&times, &energies);
    let t_mean = temperatures.iter().sum::<f64>() / temperatures.len() as f64;
    let kt = KB * t_mean;
    println!(
        "drift: {slope:+.4} kcal/mol/ns = {:+.3e} k_B·T per dof per ns (dof = {dof}, mean T = {t_mean:.2} K)",
        slope / (dof * kt)
    );
    // A slope is a drift only when the line it draws rises above the
    // fluctuation of H about it.
    println!(
        "the line changes by {:+.4} kcal/mol over the run; H about it: RMS {rms:.4} kcal/mol = {:.2e} k_B·T per dof",
        slope * times[times.len() - 1],
        rms / (dof * kt)
    );
    let (t_conf, t_conf_error) = configurational_temperature(&configurational);
    println!(
        "configurational temperature (translational): {t_conf:.2} K ± {t_conf_error:.2} K \
         (standard error of 10 batch means of {} samples)",
        configurational.len()
    );
    println!(
        "wall: {:.3} ms per step ({:.1} s for {steps} steps)",
        wall / steps as f64 * 1e3,
        wall
    );
    // With a thermostat the total momentum is not conserved: 3N − m.
    let t_kinetic = if substeps > 0 {
        t_mean * dof / (dof + 3.0)
    } else {
        t_mean
    };
    let drift = if substeps > 0 {
        "n/a".to_string()
    } else {
        format!("{slope:.4}")
    };
    let ns_per_day = steps as f64 * h * 1e-6 / wall * 86_400.0;
    println!(
        "md system=water n={waters} thermostat={thermostat} steps={steps} dt_fs={h} \
         energy_drift_per_ns={drift} kinetic_temperature={t_kinetic:.2} \
         configurational_temperature={t_conf:.2} max_rel_bond_error={worst_bond:.2e} \
         ns_per_day={ns_per_day:.3}"
    );
}
