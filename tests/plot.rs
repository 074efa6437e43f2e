//! The one-call figures (`--features plot`): each writes a PNG and an SVG
//! of the documented size, and every bad input is a typed error that
//! writes nothing. The figures of the first test are left in
//! `$TMPDIR/shake_plot_test/` to be looked at.

use geoshake::examples::{HarmonicOscillator, Pendulum};
use geoshake::plot::{self, PlotError, SIZE};
use geoshake::{Integrator, Stop, StormerVerlet, Trajectory};
use std::path::{Path, PathBuf};

fn out_dir() -> PathBuf {
    let dir = std::env::temp_dir().join("shake_plot_test");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Width and height from a PNG's IHDR chunk (bytes 16..24, big-endian).
fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{path:?} is a PNG");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |k: usize| u32::from_be_bytes(bytes[k..k + 4].try_into().unwrap());
    (be(16), be(20))
}

fn svg_size(path: &Path) -> (u32, u32) {
    let text = std::fs::read_to_string(path).unwrap();
    let attr = |name: &str| -> u32 {
        let at = text.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        text[at..].split('"').next().unwrap().parse().unwrap()
    };
    (attr("width"), attr("height"))
}

fn pendulum_run(steps: u64) -> (Pendulum, Trajectory) {
    let pendulum = Pendulum {
        gravity: 9.81,
        length: 1.0,
    };
    let mut rattle = Integrator::new(pendulum, StormerVerlet, 0.01).rattle();
    let z0 = rattle.project_to_hidden(&pendulum.state(2.0, 0.0)).unwrap();
    let traj = rattle
        .run(z0, Stop::Steps(steps))
        .execute()
        .into_result()
        .unwrap();
    (pendulum, traj)
}

#[test]
fn each_figure_is_a_png_and_an_svg_of_the_documented_size() {
    // 10^5 steps (t = 1000): more points than pixel columns, so the log
    // plots draw the per-column maximum.
    let (pendulum, traj) = pendulum_run(100_000);
    let dir = out_dir();
    for ext in ["png", "svg"] {
        let phase = dir.join(format!("phase.{ext}"));
        let energy = dir.join(format!("energy.{ext}"));
        let residual = dir.join(format!("residual.{ext}"));
        for p in [&phase, &energy, &residual] {
            let _ = std::fs::remove_file(p);
        }
        plot::phase_portrait(&traj, &phase).unwrap();
        plot::energy_error(&traj, &pendulum, &energy).unwrap();
        plot::constraint_residual(&traj, &pendulum, &residual).unwrap();
        for p in [&phase, &energy, &residual] {
            // A blank 900×600 PNG compresses to a few kB; text and curves
            // take far more.
            assert!(std::fs::metadata(p).unwrap().len() > 10_000, "{p:?}");
            let size = if ext == "png" {
                png_size(p)
            } else {
                svg_size(p)
            };
            assert_eq!(size, SIZE, "{p:?}");
        }
    }
    let svg = std::fs::read_to_string(dir.join("residual.svg")).unwrap();
    assert!(svg.contains("hidden constraint") && svg.contains("Constraint residuals"));
}

#[test]
fn bad_inputs_are_typed_errors_and_write_nothing() {
    let dir = out_dir();
    let (pendulum, traj) = pendulum_run(10);
    let never = dir.join("never.png");
    let _ = std::fs::remove_file(&never);
    let empty = Trajectory::default();
    assert!(matches!(
        plot::phase_portrait(&empty, &never),
        Err(PlotError::Empty)
    ));
    assert!(matches!(
        plot::energy_error(&empty, &pendulum, &never),
        Err(PlotError::Empty)
    ));
    assert!(matches!(
        plot::energy_error(&traj, &HarmonicOscillator, &never),
        Err(PlotError::DimensionMismatch {
            system: 1,
            trajectory: 2
        })
    ));
    assert!(matches!(
        plot::constraint_residual(&traj, &pendulum, dir.join("residual.jpeg")),
        Err(PlotError::UnknownFormat { .. })
    ));
    assert!(matches!(
        plot::phase_portrait(&traj, dir.join("no/such/dir/phase.svg")),
        Err(PlotError::Drawing { .. })
    ));
    // A state that is not a number is named, not drawn.
    let csv = "# shake trajectory v1 t0=0 h=0.5 stride=1 m=0\nt,step,q[0],q[1],p[0],p[1]\n\
               0,0,0,-1,1,0\n0.5,1,0,-1,NaN,0\n";
    let nan = Trajectory::read_csv(csv.as_bytes()).unwrap();
    assert!(matches!(
        plot::phase_portrait(&nan, &never),
        Err(PlotError::NonFinite {
            quantity: "p",
            step: 1,
            ..
        })
    ));
    assert!(matches!(
        plot::energy_error(&nan, &pendulum, &never),
        Err(PlotError::NonFinite { quantity: "H", step: 1, t, .. }) if t == 0.5
    ));
    assert!(!never.exists());
}
