//! The one-call figures (`--features plot`): each writes a PNG and an SVG
//! of the documented size, and every bad input is a typed error that
//! writes nothing. The figures of the first test are left in
//! `$TMPDIR/shake_plot_test/` to be looked at.

use geoshake::examples::{HarmonicOscillator, Pendulum};
use geoshake::particles::{generate, Options, ParticleState, Rattle};
use geoshake::plot::{self, Energy, PlotError, Residuals, SIZE};
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

/// `dir/name`, with no file there yet.
fn fresh(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

/// Asserts that `path` holds a drawn figure of the documented size: a
/// blank 900×600 PNG compresses to a few kB, text and curves take far
/// more.
fn assert_drawn(path: &Path) {
    assert!(std::fs::metadata(path).unwrap().len() > 10_000, "{path:?}");
    let size = if path.extension().is_some_and(|e| e == "png") {
        png_size(path)
    } else {
        svg_size(path)
    };
    assert_eq!(size, SIZE, "{path:?}");
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
        let phase = fresh(&dir, &format!("phase.{ext}"));
        let energy = fresh(&dir, &format!("energy.{ext}"));
        let residual = fresh(&dir, &format!("residual.{ext}"));
        plot::phase_portrait(&traj, &phase).unwrap();
        plot::energy_error(&traj, &pendulum, &energy).unwrap();
        plot::constraint_residual(&traj, &pendulum, &residual).unwrap();
        for p in [&phase, &energy, &residual] {
            assert_drawn(p);
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

/// A box of `n` rigid waters (`generate::water`: O–H 1 Å, H–O–H 109.47°,
/// LAMMPS `real` units) at 300 K, projected onto M and M^H, with steps of
/// 2 fs; with `tether`, every atom also feels a weak harmonic pull to the
/// origin, so that H has a potential.
fn waters(n: usize, tether: bool) -> (Rattle, ParticleState) {
    let (system, mut state) = generate::water(n, 5).unwrap();
    let system = if tether {
        system.with_forces(|q: &[f64], f: &mut [f64]| {
            f.iter_mut().zip(q).for_each(|(f, q)| *f -= TETHER * q);
            0.5 * TETHER * q.iter().map(|q| q * q).sum::<f64>()
        })
    } else {
        system
    };
    let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    rattle.project(&mut state).unwrap();
    generate::set_temperature(rattle.system(), &mut state, 300.0);
    (rattle, state)
}

/// `steps` steps of `rattle` from `state`, every `stride`-th stored.
fn water_run(rattle: &mut Rattle, state: &ParticleState, steps: u64, stride: u64) -> Trajectory {
    let run = rattle.run(state, Stop::Steps(steps)).stride(stride);
    run.execute().into_result().unwrap()
}

/// The tether's spring constant, g/mol/fs² (about 0.02 kcal/mol/Å²).
const TETHER: f64 = 1e-5;

#[test]
fn a_particle_run_is_drawn_as_a_png_and_an_svg() {
    // 27 waters, 5000 steps of 2 fs (10 ps): more states than pixel
    // columns, so the energy error is drawn as its band.
    let (mut rattle, state) = waters(27, false);
    let traj = water_run(&mut rattle, &state, 5000, 1);
    let dir = out_dir();
    for ext in ["png", "svg"] {
        let energy = fresh(&dir, &format!("water_energy.{ext}"));
        let residual = fresh(&dir, &format!("water_residual.{ext}"));
        plot::energy_error(&traj, &mut rattle, &energy).unwrap();
        plot::constraint_residual(&traj, &mut rattle, &residual).unwrap();
        for p in [&energy, &residual] {
            assert_drawn(p);
        }
    }
    let svg = std::fs::read_to_string(dir.join("water_residual.svg")).unwrap();
    assert!(svg.contains("relative residual") && svg.contains("hidden constraint"));
    let svg = std::fs::read_to_string(dir.join("water_energy.svg")).unwrap();
    assert!(svg.contains("Energy error"));
}

/// |r² − l²| / (2 r²) and |r · (v_a − v_b)| / (√2 |r| √(|v_a|² + |v_b|²))
/// of every bond (a, b; l) of the waters, written out from q, p and the
/// masses: a distance constraint's two relative residuals, computed
/// without the solver's families.
fn bond_residuals(rattle: &Rattle, q: &[f64], p: &[f64]) -> [f64; 2] {
    let system = rattle.system();
    let w = system.inverse_masses();
    let bonds = system.constraint_families()[0].table();
    let (mut g, mut hidden) = (0.0f64, 0.0f64);
    for k in 0..bonds.len() {
        let (a, b) = (
            bonds.particles(k)[0] as usize,
            bonds.particles(k)[1] as usize,
        );
        let l = bonds.data(k)[0];
        let (mut rr, mut rv, mut vv) = (0.0, 0.0, 0.0);
        for c in 0..3 {
            let r = q[3 * a + c] - q[3 * b + c];
            let (va, vb) = (w[a] * p[3 * a + c], w[b] * p[3 * b + c]);
            rr += r * r;
            rv += r * (va - vb);
            vv += va * va + vb * vb;
        }
        g = g.max((rr - l * l).abs() / (2.0 * rr));
        hidden = hidden.max(rv.abs() / (2.0 * rr * vv).sqrt());
    }
    [g, hidden]
}

#[test]
fn a_particle_figure_measures_the_energy_and_the_bond_errors_of_each_state() {
    let (mut rattle, state) = waters(8, true);
    let traj = water_run(&mut rattle, &state, 200, 50);
    // The stored states (on M and M^H to round-off), and one moved off
    // both: every coordinate and momentum changed by up to a percent.
    let mut states: Vec<(Vec<f64>, Vec<f64>)> = (0..traj.len())
        .map(|i| (traj.q(i).to_vec(), traj.p(i).to_vec()))
        .collect();
    let mut rng = generate::SplitMix64::new(9);
    let (q, p) = &states[2];
    let q = q.iter().map(|x| x + 0.01 * rng.normal()).collect();
    let p = p.iter().map(|x| x * (1.0 + 0.01 * rng.normal())).collect();
    states.push((q, p));
    let masses = rattle.system().masses().to_vec();
    let mut measured = &mut rattle;
    for (i, (q, p)) in states.iter().enumerate() {
        let kinetic: f64 = (0..q.len())
            .map(|j| p[j] * p[j] / (2.0 * masses[j / 3]))
            .sum();
        let potential = 0.5 * TETHER * q.iter().map(|q| q * q).sum::<f64>();
        let h = measured.energy(q, p);
        let want = kinetic + potential;
        assert!(
            (h - want).abs() <= 1e-13 * want,
            "state {i}: H = {h}, by hand {want}"
        );
        let [g, hidden] = measured.residuals(q, p);
        let [g_want, hidden_want] = bond_residuals(measured, q, p);
        // g is evaluated alike by both, so it agrees at round-off level too.
        assert!(
            (g - g_want).abs() <= 1e-12 * g_want,
            "state {i}: {g:e} vs {g_want:e}"
        );
        if i == states.len() - 1 {
            // Off M and M^H by about the percent the state was moved.
            assert!(
                g_want > 1e-4 && hidden_want > 1e-4,
                "{g_want:e} {hidden_want:e}"
            );
            assert!(
                (hidden - hidden_want).abs() <= 1e-12 * hidden_want,
                "{hidden:e} vs {hidden_want:e}"
            );
        } else {
            // On them, to the solver's tolerance (10⁻¹²) or better.
            assert!(g <= 1e-12, "state {i}: {g:e}");
            assert!(
                hidden <= 1e-12 && hidden_want <= 1e-12,
                "state {i}: {hidden:e}"
            );
        }
    }
    assert_eq!(Residuals::constraint_count(&measured), 24);
}

#[test]
fn a_particle_state_that_is_not_a_number_is_named_and_a_wrong_size_refused() {
    let dir = out_dir();
    let never = dir.join("never_water.png");
    let _ = std::fs::remove_file(&never);
    let (mut rattle, state) = waters(8, true);
    let traj = water_run(&mut rattle, &state, 10, 1);
    // Step 7's x of atom 0 is NaN: H (through V) and g are not numbers there.
    let mut csv = Vec::new();
    traj.write_csv(&mut csv).unwrap();
    let mut lines: Vec<String> = String::from_utf8(csv)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let mut row: Vec<&str> = lines[2 + 7].split(',').collect();
    assert_eq!(row[1], "7");
    row[2] = "NaN";
    lines[2 + 7] = row.join(",");
    let nan = Trajectory::read_csv(lines.join("\n").as_bytes()).unwrap();
    assert!(matches!(
        plot::energy_error(&nan, &mut rattle, &never),
        Err(PlotError::NonFinite { quantity: "H", step: 7, t, .. }) if t == 14.0
    ));
    assert!(matches!(
        plot::constraint_residual(&nan, &mut rattle, &never),
        Err(PlotError::NonFinite {
            quantity: "relative |g|",
            step: 7,
            ..
        })
    ));
    // A pendulum's trajectory is not the waters'.
    let (_, pendulum) = pendulum_run(10);
    assert!(matches!(
        plot::constraint_residual(&pendulum, &mut rattle, &never),
        Err(PlotError::DimensionMismatch {
            system: 72,
            trajectory: 2
        })
    ));
    assert!(!never.exists());
}

#[test]
fn drawing_a_particle_run_leaves_the_next_steps_as_they_were() {
    // The figure evaluates V with the solver's force buffer: a run
    // continued after it takes the steps it takes without it.
    let continued = |draw: bool| {
        let (mut rattle, mut state) = waters(8, true);
        let first = rattle.run(&state, Stop::Steps(20)).execute();
        assert!(rattle.run_in_place(&mut state, 20).error.is_none());
        if draw {
            let path = out_dir().join("water_between.svg");
            plot::energy_error(&first.trajectory, &mut rattle, path).unwrap();
        }
        assert!(rattle.run_in_place(&mut state, 20).error.is_none());
        state
    };
    let (a, b) = (continued(false), continued(true));
    assert_eq!((a.q(), a.p()), (b.q(), b.p()));
}
