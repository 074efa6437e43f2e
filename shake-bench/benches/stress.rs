//! Long runs: energy over 10⁷ pendulum steps and 10⁶ steps of the Hopf
//! gravity scene, and the growth law of round-off with and without
//! compensated summation.
//!
//!     cargo bench -p geoshake-bench --bench stress            # full sizes (a few minutes)
//!     cargo bench -p geoshake-bench --bench stress -- --quick # 100× fewer steps
//!     cargo bench -p geoshake-bench --bench stress --features progress  # with progress bars
//!
//! Writes PNG, SVG and CSV into `stress-output/` at the repository root
//! (`--out DIR` elsewhere) and prints a summary.
//!
//! # What is measured
//!
//! 1. `energy_pendulum`: |H(z_n) − H(z_0)| along 10⁷ RATTLE steps of the
//!    pendulum (Störmer–Verlet, h = 0.01, θ0 = 1.2), the largest value in
//!    each window of 10⁴ steps (looked at every 100 steps): bounded, no
//!    drift (the O(h²) oscillation of a symplectic method), plain and
//!    compensated.
//! 2. `energy_hopf`: the same for 10⁶ steps of the Hopf gravity scene
//!    (midpoint, h = 0.1, the paper's z_a on its sphere r² = 0.98).
//! 3. `roundoff`: the round-off part of the energy error. A symmetric
//!    method run n steps forward and n steps back returns *exactly* to its
//!    start in exact arithmetic (R₋ₕ ∘ Rₕ = id), so
//!    e(n) = H(R₋ₕⁿ Rₕⁿ z0) − H(z0) contains no truncation error at all:
//!    it is the sum of the energy perturbations by rounding over 2n steps,
//!    each carried unchanged (to first order) by the near-conservation of
//!    the modified energy. Over an ensemble of initial data the RMS of e(n)
//!    grows like √n if rounding errors are unbiased and independent
//!    (Brouwer's law) and like n if they drift. Plotted against a √n line,
//!    with and without compensated summation, with the fitted exponents.

use geoshake::models::{HopfGravity, Pendulum};
use geoshake::{
    BaseMap, ConstrainedSystem, ImplicitMidpoint, Integrator, State, Stop, StormerVerlet,
};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use std::error::Error;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

type Res<T> = Result<T, Box<dyn Error>>;

struct Sizes {
    pendulum_steps: u64,
    hopf_steps: u64,
    roundoff_max_exp: u32,
    ensemble: usize,
}

fn main() -> Res<()> {
    let args: Vec<String> = std::env::args().collect();
    let quick = args.iter().any(|a| a == "--quick");
    let out = args
        .iter()
        .position(|a| a == "--out")
        .and_then(|i| args.get(i + 1))
        .map(PathBuf::from)
        // cargo runs a bench in its package's directory; the figures go to
        // the repository root, beside those of the examples.
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../stress-output"));
    let sizes = if quick {
        Sizes {
            pendulum_steps: 100_000,
            hopf_steps: 10_000,
            roundoff_max_exp: 5,
            ensemble: 8,
        }
    } else {
        Sizes {
            pendulum_steps: 10_000_000,
            hopf_steps: 1_000_000,
            roundoff_max_exp: 6,
            ensemble: 24,
        }
    };
    std::fs::create_dir_all(&out)?;
    let _ =
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    let mut summary = String::new();

    // 1. Pendulum energy over 10⁷ steps.
    let pendulum = Pendulum::new(1.0, 1.0);
    let zp = pendulum_state(1.2, 0.6);
    let mut series = Vec::new();
    for comp in [false, true] {
        let label = if comp { "compensated" } else { "plain" };
        let (pts, secs) = energy_run(
            &format!("pendulum {label}"),
            pendulum,
            StormerVerlet,
            0.01,
            comp,
            &zp,
            sizes.pendulum_steps,
            (sizes.pendulum_steps / 1000).max(1000),
        )?;
        let max = pts.iter().fold(0.0f64, |a, p| a.max(p.1));
        let (first, last) = halves_max(&pts);
        writeln!(
            summary,
            "pendulum, SV, h = 0.01, {} steps, {label}: max |ΔH| = {max:.3e} (first half {first:.3e}, second half {last:.3e}), {:.2} µs/step",
            sizes.pendulum_steps,
            secs * 1e6 / sizes.pendulum_steps as f64
        )?;
        series.push((label.to_string(), pts));
    }
    log_plot(
        &out,
        "energy_pendulum",
        &format!(
            "Pendulum, RATTLE/Störmer–Verlet, h = 0.01: energy error over {} steps",
            sizes.pendulum_steps
        ),
        "t",
        "|H(z_n) − H(z_0)|",
        &series,
        false,
    )?;

    // 2. Hopf gravity scene over 10⁶ steps.
    let za = [
        -0.78652612,
        -0.4043988,
        -0.3880746864163783,
        0.2173391755798215,
    ];
    let r2: f64 = za.iter().map(|v| v * v).sum();
    let hopf = HopfGravity::new(0.0, -1.0, r2);
    let zh = State::from_slices(&za[..2], &za[2..]);
    let mut series = Vec::new();
    for comp in [false, true] {
        let label = if comp { "compensated" } else { "plain" };
        let (pts, secs) = energy_run(
            &format!("Hopf gravity {label}"),
            hopf,
            ImplicitMidpoint,
            0.1,
            comp,
            &zh,
            sizes.hopf_steps,
            (sizes.hopf_steps / 1000).max(1000),
        )?;
        let max = pts.iter().fold(0.0f64, |a, p| a.max(p.1));
        let (first, last) = halves_max(&pts);
        writeln!(
            summary,
            "Hopf gravity z_a (r² = |z_a|²), midpoint, h = 0.1, {} steps, {label}: max |ΔH| = {max:.3e} (first half {first:.3e}, second half {last:.3e}), {:.2} µs/step",
            sizes.hopf_steps,
            secs * 1e6 / sizes.hopf_steps as f64
        )?;
        series.push((label.to_string(), pts));
    }
    log_plot(
        &out,
        "energy_hopf",
        &format!(
            "Hopf gravity scene (z_a), RATTLE/midpoint, h = 0.1: energy error over {} steps",
            sizes.hopf_steps
        ),
        "t",
        "|H(z_n) − H(z_0)|",
        &series,
        false,
    )?;

    // 3. Round-off growth: forward n, back n.
    let ns: Vec<u64> = (1..=sizes.roundoff_max_exp * 2)
        .map(|k| 10f64.powf(k as f64 / 2.0).round() as u64)
        .filter(|&n| n >= 10)
        .collect();
    let mut series = Vec::new();
    let total: u64 = 2 * 2 * sizes.ensemble as u64 * ns.iter().sum::<u64>();
    let bar = bar(total, "round-off (forward n, back n)");
    for comp in [false, true] {
        let label = if comp { "compensated" } else { "plain" };
        let mut rms = Vec::new();
        for &n in &ns {
            let mut sum2 = 0.0;
            for k in 0..sizes.ensemble {
                // Initial data spread over swings of different amplitude.
                let theta = 0.3 + 2.4 * (k as f64 + 0.5) / sizes.ensemble as f64;
                let omega = 0.1 + 0.2 * ((k * 7) % sizes.ensemble) as f64 / sizes.ensemble as f64;
                let e = there_and_back(
                    pendulum,
                    StormerVerlet,
                    0.01,
                    comp,
                    &pendulum_state(theta, omega),
                    n,
                )?;
                sum2 += e * e;
                bar.inc(2 * n);
            }
            rms.push((n as f64, (sum2 / sizes.ensemble as f64).sqrt()));
        }
        let slope = fit_slope(&rms[rms.len() / 3..]);
        writeln!(
            summary,
            "round-off, pendulum SV h = 0.01, RMS over {} initial data of H(R₋ₕⁿRₕⁿz0) − H(z0), {label}: {} ; fitted exponent {slope:.2}",
            sizes.ensemble,
            rms.iter()
                .map(|(n, e)| format!("n={n:.0}: {e:.2e}"))
                .collect::<Vec<_>>()
                .join(", ")
        )?;
        series.push((format!("{label} (exponent {slope:.2})"), rms));
    }
    bar.finish_and_clear();
    // Reference slopes: √n through the compensated curve's last point, n
    // through the plain curve's (both anchored where round-off dominates).
    let last = |k: usize| *series[k].1.last().expect("points");
    let (nc, ec) = last(1);
    let (np, ep) = last(0);
    let sqrt_line: Vec<(f64, f64)> = ns
        .iter()
        .map(|&n| (n as f64, ec * (n as f64 / nc).sqrt()))
        .collect();
    let lin_line: Vec<(f64, f64)> = ns.iter().map(|&n| (n as f64, ep * n as f64 / np)).collect();
    series.push(("√n".to_string(), sqrt_line));
    series.push(("∝ n".to_string(), lin_line));
    log_plot(
        &out,
        "roundoff",
        "Round-off in energy: RMS of H(R₋ₕⁿ Rₕⁿ z0) − H(z0), pendulum, h = 0.01",
        "n (steps each way)",
        "RMS energy round-off",
        &series,
        true,
    )?;

    std::fs::write(out.join("summary.txt"), &summary)?;
    print!("{summary}");
    println!("figures in {}", out.display());
    Ok(())
}

fn pendulum_state(theta: f64, omega: f64) -> State {
    State::from_slices(
        &[theta.sin(), -theta.cos()],
        &[omega * theta.cos(), omega * theta.sin()],
    )
}

fn bar(total: u64, msg: &str) -> ProgressBar {
    let b = ProgressBar::new(total);
    b.set_style(
        ProgressStyle::with_template(
            "{msg:<36} [{elapsed_precise}] {wide_bar} {percent:>3}% eta {eta}",
        )
        .expect("a valid template"),
    );
    b.set_message(msg.to_string());
    b
}

/// A long RATTLE run; (t, |ΔH|) every `every` steps, and the wall time.
#[allow(clippy::too_many_arguments)]
fn energy_run<S: ConstrainedSystem + Clone, B: BaseMap>(
    name: &str,
    sys: S,
    base: B,
    h: f64,
    compensated: bool,
    z0: &State,
    steps: u64,
    every: u64,
) -> Res<(Vec<(f64, f64)>, f64)> {
    let e0 = sys.hamiltonian(z0.q.as_slice(), z0.p.as_slice());
    // The library's bar on the per-step hook (`--features progress`);
    // without the feature the run is silent until it ends.
    #[cfg(feature = "progress")]
    let mut progress = geoshake::progress::Progress::new(name);
    let mut pts = Vec::with_capacity((steps / every) as usize + 1);
    // The energy is looked at every `every/100` steps; each plotted point is
    // the largest |ΔH| over a window of `every` steps (the envelope: single
    // samples would alias with the period of the motion).
    let look = (every / 100).max(1);
    let mut window = 0.0f64;
    let start = std::time::Instant::now();
    let mut integ = Integrator::new(sys.clone(), base, h).compensated(compensated);
    let run = integ
        .run(z0.clone(), Stop::Steps(steps))
        .stride(look)
        .store(false)
        .observe(|k, t, z| {
            if k > 0 {
                let de = (sys.hamiltonian(z.q.as_slice(), z.p.as_slice()) - e0).abs();
                window = window.max(de);
                if k % every == 0 {
                    pts.push((t, window));
                    window = 0.0;
                }
            }
        });
    #[cfg(feature = "progress")]
    let run = run.on_step(progress.hook());
    let out = run.execute();
    let secs = start.elapsed().as_secs_f64();
    #[cfg(feature = "progress")]
    progress.bar().finish_and_clear();
    if let Some(e) = out.error {
        return Err(format!("{name}: {e}").into());
    }
    Ok((pts, secs))
}

/// H(R₋ₕⁿ Rₕⁿ z0) − H(z0).
fn there_and_back<S: ConstrainedSystem + Clone, B: BaseMap>(
    sys: S,
    base: B,
    h: f64,
    compensated: bool,
    z0: &State,
    n: u64,
) -> Res<f64> {
    let mut integ = Integrator::new(sys.clone(), base, h).compensated(compensated);
    let fwd = integ
        .run(z0.clone(), Stop::Steps(n))
        .stride(n)
        .execute()
        .into_result()
        .map_err(|(_, e)| e.to_string())?;
    let z1 = fwd.last().expect("the last state");
    let back = integ
        .with_step_size(-h)
        .run(z1, Stop::Steps(n))
        .stride(n)
        .execute()
        .into_result()
        .map_err(|(_, e)| e.to_string())?;
    let z2 = &back.last().expect("the last state");
    Ok(sys.hamiltonian(z2.q.as_slice(), z2.p.as_slice())
        - sys.hamiltonian(z0.q.as_slice(), z0.p.as_slice()))
}

/// Largest value over the first and the second half of the samples.
fn halves_max(pts: &[(f64, f64)]) -> (f64, f64) {
    let m = pts.len() / 2;
    let f = |s: &[(f64, f64)]| s.iter().fold(0.0f64, |a, p| a.max(p.1));
    (f(&pts[..m]), f(&pts[m..]))
}

/// Least-squares slope of log y against log x.
fn fit_slope(pts: &[(f64, f64)]) -> f64 {
    let l: Vec<(f64, f64)> = pts
        .iter()
        .filter(|p| p.1 > 0.0)
        .map(|p| (p.0.ln(), p.1.ln()))
        .collect();
    let n = l.len() as f64;
    let mx = l.iter().map(|p| p.0).sum::<f64>() / n;
    let my = l.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = l.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = l.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    sxy / sxx
}

/// A figure with log10 y (and optionally log10 x) axes, as PNG, SVG and
/// CSV. Zeros are clamped to 1e-18.
fn log_plot(
    dir: &Path,
    stem: &str,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[(String, Vec<(f64, f64)>)],
    log_x: bool,
) -> Res<()> {
    let tx = |x: f64| if log_x { x.log10() } else { x };
    let ty = |y: f64| y.max(1e-18).log10();
    let pts: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|(_, s)| s.iter().map(|&(x, y)| (tx(x), ty(y))).collect())
        .collect();
    let all = pts.iter().flatten();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    let (y0, y1) = (y0.floor(), y1.ceil().max(y0.floor() + 1.0));
    let (x0, x1) = if log_x {
        (x0.floor(), x1.ceil())
    } else {
        (x0, x1)
    };
    let frame = Frame {
        title,
        x_label,
        y_label,
        log_x,
        range: (x0..x1, y0..y1),
    };
    draw_chart(
        BitMapBackend::new(&dir.join(format!("{stem}.png")), (1000, 620)).into_drawing_area(),
        &frame,
        series,
        &pts,
    )?;
    draw_chart(
        SVGBackend::new(&dir.join(format!("{stem}.svg")), (1000, 620)).into_drawing_area(),
        &frame,
        series,
        &pts,
    )?;
    let mut csv = format!("# {title}\nseries,x,y\n");
    for (name, s) in series {
        for (x, y) in s {
            writeln!(csv, "{name},{x:e},{y:e}")?;
        }
    }
    std::fs::write(dir.join(format!("{stem}.csv")), csv)?;
    Ok(())
}

struct Frame<'a> {
    title: &'a str,
    x_label: &'a str,
    y_label: &'a str,
    log_x: bool,
    range: (std::ops::Range<f64>, std::ops::Range<f64>),
}

fn draw_chart<DB: DrawingBackend>(
    root: DrawingArea<DB, plotters::coord::Shift>,
    f: &Frame,
    series: &[(String, Vec<(f64, f64)>)],
    pts: &[Vec<(f64, f64)>],
) -> Res<()>
where
    DB::ErrorType: 'static,
{
    let colors = [
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
        RGBColor(80, 80, 80),
        RGBColor(44, 160, 44),
    ];
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(f.title, ("sans-serif", 20))
        .margin(14)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(f.range.0.clone(), f.range.1.clone())?;
    let log_x = f.log_x;
    chart
        .configure_mesh()
        .x_desc(f.x_label)
        .y_desc(f.y_label)
        .label_style(("sans-serif", 15))
        // One label per decade on log axes: plotters then puts them on
        // integers of log10.
        .y_labels((f.range.1.end - f.range.1.start).round() as usize + 1)
        .x_labels(if log_x {
            (f.range.0.end - f.range.0.start).round() as usize + 1
        } else {
            10
        })
        .x_label_formatter(&|x| {
            if log_x {
                format!("1e{x:.0}")
            } else {
                format!("{x:.0}")
            }
        })
        .y_label_formatter(&|y| format!("1e{y:.0}"))
        .draw()?;
    for (k, ((name, _), p)) in series.iter().zip(pts).enumerate() {
        let color = colors[k % colors.len()];
        if name.starts_with('√') || name.starts_with('∝') {
            chart
                .draw_series(DashedLineSeries::new(
                    p.iter().copied(),
                    6,
                    4,
                    color.stroke_width(2),
                ))?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        } else if p.len() > 200 {
            chart
                .draw_series(p.iter().map(|&q| Circle::new(q, 1, color.filled())))?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
        } else {
            chart
                .draw_series(LineSeries::new(p.iter().copied(), color.stroke_width(2)))?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
            chart.draw_series(p.iter().map(|&q| Circle::new(q, 3, color.filled())))?;
        }
    }
    chart
        .configure_series_labels()
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::LowerRight)
        .draw()?;
    root.present()?;
    Ok(())
}
