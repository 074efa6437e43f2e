//! Data out of a run, the ways a user takes it: the multipliers and the
//! rod's force per stored state, the trajectory as CSV and as an Arrow IPC
//! (Feather v2) file for pandas/polars, and the three first-look figures.
//!
//! ```text
//! cargo run --release --example data_out --features arrow,plot
//! ```
//!
//! A pendulum (unit mass, L = 1, g = 9.81) started at 2 rad, integrated with
//! RATTLE over Störmer–Verlet, h = 0.01, for 10⁴ time units (10⁶ steps,
//! every 10th state stored): the energy error stays bounded (no drift, the
//! paper's point) and both constraints stay at round-off. Everything goes to
//! `data-out/`.

use geoshake::examples::Pendulum;
use geoshake::prelude::*;
use std::error::Error;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::time::Instant;

/// Writes one output file.
type Writer<'a> = &'a dyn Fn(&Path) -> Result<(), Box<dyn Error>>;

fn main() -> Result<(), Box<dyn Error>> {
    let dir = Path::new("data-out");
    std::fs::create_dir_all(dir)?;
    let pendulum = Pendulum {
        gravity: 9.81,
        length: 1.0,
    };
    let mut rattle = Integrator::new(pendulum, StormerVerlet, 0.01)
        .rattle()
        .with_diagnostics();
    let z0 = rattle.project_to_hidden(&pendulum.state(2.0, 0.0))?;
    let clock = Instant::now();
    let traj = rattle
        .run(z0, Stop::Time(1e4))
        .stride(10)
        .execute()
        .into_result()
        .map_err(|(_, e)| e)?;
    println!(
        "run: {} steps, {} states stored, {:.2} s",
        traj.step(traj.len() - 1),
        traj.len(),
        clock.elapsed().as_secs_f64()
    );

    // The rod's pull at a stored state, from the multipliers (λ + σ)/h.
    let mut force = [0.0; 2];
    if traj.constraint_force(&pendulum, 1, &mut force) {
        println!(
            "state 1: λ = {:.6e}, σ = {:.6e}, rod force = ({:.6}, {:.6})",
            traj.lambda(1)[0],
            traj.sigma(1)[0],
            force[0],
            force[1]
        );
    }

    let write = |name: &str, f: Writer| {
        let path = dir.join(name);
        let clock = Instant::now();
        f(&path)?;
        println!(
            "{:<24} {:>10} bytes  {:>7.3} s",
            path.display(),
            std::fs::metadata(&path)?.len(),
            clock.elapsed().as_secs_f64()
        );
        Ok::<(), Box<dyn Error>>(())
    };
    write("pendulum.csv", &|p| {
        Ok(traj.write_csv(BufWriter::new(File::create(p)?))?)
    })?;
    write("pendulum.arrow", &|p| {
        Ok(traj.write_arrow(BufWriter::new(File::create(p)?))?)
    })?;
    write("phase.png", &|p| {
        Ok(geoshake::plot::phase_portrait(&traj, p)?)
    })?;
    write("energy.png", &|p| {
        Ok(geoshake::plot::energy_error(&traj, &pendulum, p)?)
    })?;
    write("residual.png", &|p| {
        Ok(geoshake::plot::constraint_residual(&traj, &pendulum, p)?)
    })?;

    // Both files read back to the same trajectory, bit for bit.
    let from_csv = Trajectory::read_csv(std::io::BufReader::new(File::open(
        dir.join("pendulum.csv"),
    )?))?;
    let from_arrow = Trajectory::read_arrow(File::open(dir.join("pendulum.arrow"))?)?;
    assert!(from_csv == traj && from_arrow == traj);
    println!("read back: CSV and Arrow both equal the run, bit for bit");
    println!("pandas: pd.read_feather(\"data-out/pendulum.arrow\")");
    Ok(())
}
