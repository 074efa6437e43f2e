//! Rings and branched molecules under a Langevin thermostat: the coupled
//! constraint clusters LAMMPS' `fix shake` refuses ("Shake clusters are
//! connected"), run to the solver's tolerance.
//!
//! A mixture of benzene-like rings (12 atoms, 21 constraints in one
//! cluster with a cycle: bonds, the C–H angles, a rigid triangle of
//! alternate carbons) and branched united-atom alkanes (8 atoms, 15
//! constraints: every bond and angle of a tree with two branch points),
//! thermostatted by geodesic BAOAB (`--thermostat baoab|gbaoab`). The
//! kinetic temperature is measured with the degrees of freedom the
//! constraints leave, 3N − m (the thermostat does not conserve the total
//! momentum), and compared with the target by the molecules' independent
//! time averages. Ends with one line:
//!
//! ```text
//! md system=rings_branched rings=… branched=… constraints=… solver=… thermostat=… steps=…
//!   dt_fs=… target_temperature=… kinetic_temperature=… kinetic_temperature_se=…
//!   max_rel_bond_error=… ns_per_day=… check=pass|fail
//! ```
//!
//! `check=pass` when the kinetic temperature is within 5 standard errors of
//! the target and the last state's bonds are within the solver's tolerance.
//!
//!     cargo run --release --example rings             # 200 + 200 molecules
//!     cargo run --release --example rings -- --quick  # 50 + 50, for CI
//!
//! `--solver band|sparse` forces a solver (default: the library's choice).

use std::time::Instant;

use geoshake::runtime::particles::generate::{self, KB, MVV2E};
use geoshake::runtime::particles::{Langevin, Options, Rattle, SolverChoice};
use geoshake::runtime::Stop;

mod molecules;

fn arg<T: std::str::FromStr>(flag: &str) -> Option<T> {
    let mut args = std::env::args().skip_while(|a| a != flag);
    args.next()?;
    match args.next().map(|v| v.parse()) {
        Some(Ok(v)) => Some(v),
        _ => fail(&format!("{flag} needs a value")),
    }
}

fn fail(what: &str) -> ! {
    eprintln!("rings: {what}");
    std::process::exit(1)
}

fn main() {
    let quick = std::env::args().any(|a| a == "--quick");
    let rings: usize = arg("--rings").unwrap_or(if quick { 50 } else { 200 });
    let branched: usize = arg("--branched").unwrap_or(if quick { 50 } else { 200 });
    let steps: u64 = arg("--steps").unwrap_or(if quick { 2000 } else { 20_000 });
    let thermostat: String = arg("--thermostat").unwrap_or_else(|| "gbaoab".into());
    let substeps = match thermostat.as_str() {
        "baoab" => 1,
        "gbaoab" => 2,
        other => fail(&format!("--thermostat {other}: baoab or gbaoab")),
    };
    let solver = match arg::<String>("--solver").as_deref() {
        None | Some("auto") => SolverChoice::Auto,
        Some("band") => SolverChoice::Band,
        Some("sparse") => SolverChoice::Sparse,
        Some(other) => fail(&format!("--solver {other}: auto, band or sparse")),
    };
    let (h, kelvin, seed) = (1.0, 300.0, 7);

    let (system, mut state, starts) =
        molecules::mixture(rings, branched, seed).unwrap_or_else(|e| fail(&e.to_string()));
    let (atoms, m) = (system.particles(), system.constraints());
    let masses = system.masses().to_vec();
    let options = Options {
        solver,
        ..Options::default()
    };
    let mut rattle = Rattle::new(system, h, options).unwrap_or_else(|e| fail(&e.to_string()));
    println!(
        "rings: {rings} benzene-like rings and {branched} branched alkanes, {atoms} atoms, \
         {m} constraints, solver {} ({} clusters), h = {h} fs, T = {kelvin} K",
        rattle.solver_name(),
        rattle.clusters()
    );
    rattle
        .project(&mut state)
        .unwrap_or_else(|e| fail(&e.to_string()));
    generate::set_temperature(rattle.system(), &mut state, kelvin);
    let kt = KB * kelvin / MVV2E;
    // γ = 5/ps: the molecules relax in a few hundred steps.
    let langevin = Langevin::new(5e-3, kt, seed)
        .and_then(|l| l.geodesic(substeps))
        .unwrap_or_else(|e| fail(&e.to_string()));
    rattle
        .set_thermostat(Some(langevin))
        .unwrap_or_else(|e| fail(&e.to_string()));

    // The first fifth relaxes; each molecule's kinetic energy is then
    // averaged over the rest, one independent sample per molecule.
    let relax = steps / 5;
    let mut kinetic = vec![0.0; starts.len() - 1];
    let mut last = Vec::new();
    let clock = Instant::now();
    let out = rattle
        .run(&state, Stop::Steps(steps))
        .store(false)
        .observe(|k, _, z| {
            if k == steps {
                last = z.q.as_slice().to_vec();
            }
            if k > relax {
                let p = z.p.as_slice();
                for (j, e) in kinetic.iter_mut().enumerate() {
                    *e += (3 * starts[j]..3 * starts[j + 1])
                        .map(|c| p[c] * p[c] / (2.0 * masses[c / 3]))
                        .sum::<f64>();
                }
            }
        })
        .execute();
    let wall = clock.elapsed().as_secs_f64();
    if let Some(e) = out.error {
        fail(&e.to_string());
    }
    let bonds = rattle.system().constraint_families()[0].table();
    let worst_bond = generate::max_rel_length_error(bonds, 3, &last);
    let tol = rattle.options().tol;

    // Degrees of freedom per molecule: 3 per atom less its constraints.
    let per = |j: usize| -> f64 {
        let atoms = starts[j + 1] - starts[j];
        (3 * atoms - if atoms == 12 { 21 } else { 15 }) as f64
    };
    let samples = (steps - relax) as f64;
    let t: Vec<f64> = kinetic
        .iter()
        .enumerate()
        .map(|(j, e)| 2.0 * e / samples / (per(j) * kt) * kelvin)
        .collect();
    let n = t.len() as f64;
    let mean = t.iter().sum::<f64>() / n;
    let se = (t.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
    let ns_per_day = steps as f64 * h * 1e-6 / wall * 86_400.0;
    let pass = (mean - kelvin).abs() < 5.0 * se && worst_bond <= tol;
    println!(
        "{steps} steps in {wall:.2} s ({:.1} µs per step); largest residual {:.1e}, hidden {:.1e}",
        wall / steps as f64 * 1e6,
        out.summary.max_residual.unwrap_or(f64::NAN),
        out.summary.max_hidden.unwrap_or(f64::NAN)
    );
    println!(
        "md system=rings_branched rings={rings} branched={branched} constraints={m} solver={} \
         thermostat={thermostat} steps={steps} dt_fs={h} target_temperature={kelvin} \
         kinetic_temperature={mean:.2} kinetic_temperature_se={se:.2} \
         max_rel_bond_error={worst_bond:.2e} ns_per_day={ns_per_day:.2} check={}",
        rattle.solver_name(),
        if pass { "pass" } else { "fail" }
    );
    if !pass {
        std::process::exit(1);
    }
}
