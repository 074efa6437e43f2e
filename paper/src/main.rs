//! The paper's scenes: every example of McLachlan, Modin, Verdier and Wilkins,
//! *Geometric generalisations of SHAKE and RATTLE*, run with shake, with its
//! figures drawn and its claims checked.
//!
//!     cargo run --release -p geoshake-paper [-- --quick] [--out DIR]
//!
//! Writes PNG, SVG and CSV figures and `claims.md` / `claims.csv` (claim,
//! measured value, the bound the theory gives, pass/fail) into `DIR`
//! (default `paper-output/`), and exits with status 1 if any claim fails.
//! `--quick` runs shorter trajectories and fewer step sizes. `claims.md`
//! opens with a preamble saying what was run, where and when (commit, date,
//! machine, command line), so a table found later can be traced to its run.

mod claims;
use geoshake_testkit::{models, plot, reference};
mod run_info;
mod scenes;

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

/// What every scene gets: where to write, and how much to run.
pub struct Ctx {
    pub out: PathBuf,
    pub quick: bool,
}

fn main() -> ExitCode {
    let mut ctx = Ctx {
        out: PathBuf::from("paper-output"),
        quick: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--quick" => ctx.quick = true,
            "--out" => match args.next() {
                Some(d) => ctx.out = PathBuf::from(d),
                None => {
                    eprintln!("--out needs a directory");
                    return ExitCode::from(2);
                }
            },
            "-h" | "--help" => {
                println!("usage: paper [--quick] [--out DIR]");
                return ExitCode::SUCCESS;
            }
            other => {
                eprintln!("unknown argument {other:?}; usage: paper [--quick] [--out DIR]");
                return ExitCode::from(2);
            }
        }
    }
    plot::init_fonts();
    let mut claims = claims::Claims::default();
    let start = Instant::now();
    for (name, scene) in scenes::ALL {
        println!("== {name}");
        let t = Instant::now();
        if let Err(e) = scene(&ctx, &mut claims) {
            // A scene that cannot finish is a failed claim, not a crash: the
            // other scenes still run and the table says what broke.
            claims.check(
                "-",
                &format!("scene '{name}' ran to the end"),
                &format!("error: {e}"),
                f64::NAN,
                claims::Bound::AtMost(0.0),
                "a scene must not fail",
            );
        }
        println!("   ({:.1} s)", t.elapsed().as_secs_f64());
    }
    let elapsed = start.elapsed().as_secs_f64();
    let preamble = run_info::preamble(ctx.quick, elapsed);
    if let Err(e) = claims.save(&ctx.out, &preamble) {
        eprintln!("could not write the claims table: {e}");
        return ExitCode::FAILURE;
    }
    // Each claim was printed once, as it was checked; the table itself is in
    // claims.md (printing it here again is what used to show every claim twice).
    println!(
        "\n{} claims, {} failed, {:.1} s; claims.md, claims.csv and the figures are in {}",
        claims.len(),
        claims.failures(),
        elapsed,
        ctx.out.display()
    );
    if claims.all_pass() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
