//! One-call figures of a [`Trajectory`] (the `plot` feature): the three a
//! user looks at first after a run.
//!
//! - [`phase_portrait`]: each coordinate's (q_k, p_k) curve.
//! - [`energy_error`]: (H(z_n) − H(z_0)) / |H(z_0)| against time. For
//!   SHAKE and RATTLE this oscillates, O(h²) for the second-order base
//!   maps, without drift over exponentially long times (the methods are
//!   symplectic on M resp. M^H, the paper's Theorems 3.1 and 4.1), so the
//!   figure of a long run is the check that matters.
//! - [`constraint_residual`]: max_i |g_i| and max_i |{g_i, H}| against time,
//!   on a log axis: SHAKE keeps g to round-off, RATTLE both (Section 4).
//!
//! The figure is a PNG or an SVG by the path's extension, [`SIZE`] pixels.
//! The values are computed from the stored states with the system itself
//! (diagnostics need not be on). Exact zeros are drawn at [`LOG_FLOOR`]
//! (the figure says so). A run of more points than the plot has pixel
//! columns is drawn per column: the energy error as the band from its
//! least to its largest value there, the residuals as their largest value,
//! so a spike is never thinned away. Text is drawn with the DejaVu font the `dejavu` crate ships: no
//! system font is needed.
//!
//! ```
//! use geoshake::prelude::*;
//! use geoshake::examples::Pendulum;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let pendulum = Pendulum { gravity: 9.81, length: 1.0 };
//! let mut rattle = Integrator::new(pendulum, StormerVerlet, 0.01).rattle();
//! let traj = rattle.run(pendulum.state(1.0, 0.0), Stop::Time(20.0)).execute().trajectory;
//! let dir = std::env::temp_dir();
//! geoshake::plot::phase_portrait(&traj, dir.join("phase.png"))?;
//! geoshake::plot::energy_error(&traj, &pendulum, dir.join("energy.svg"))?;
//! geoshake::plot::constraint_residual(&traj, &pendulum, dir.join("residual.png"))?;
//! # Ok(())
//! # }
//! ```
//!
//! # A particle run
//!
//! The solver of a particle run ([`particles::Rattle`](crate::particles::Rattle))
//! is no [`Hamiltonian`](crate::Hamiltonian): pass it as `&mut rattle`
//! where a system is `&system`. What a figure measures of a stored state,
//! the energy and the two residuals, is the trait pair [`Energy`] and
//! [`Residuals`], implemented for both; the drawing is the same. A
//! particle run's residuals are relative to each member's own scale, as
//! the solver's tolerance judges them (the axis says so): for a bond, the
//! relative error of its length to first order.
//!
//! ```
//! use geoshake::particles::{generate, Options, Rattle};
//! use geoshake::Stop;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // 8 rigid waters (LAMMPS `real` units: Å, fs), 2 fs steps.
//! let (system, mut state) = generate::water(8, 1)?;
//! let mut rattle = Rattle::new(system, 2.0, Options::default())?;
//! rattle.project(&mut state)?;
//! generate::set_temperature(rattle.system(), &mut state, 300.0);
//! let out = rattle.run(&state, Stop::Steps(500)).execute();
//! assert!(out.error.is_none());
//! let traj = out.trajectory;
//! let dir = std::env::temp_dir();
//! geoshake::plot::energy_error(&traj, &mut rattle, dir.join("water_energy.png"))?;
//! geoshake::plot::constraint_residual(&traj, &mut rattle, dir.join("water_residual.svg"))?;
//! # Ok(())
//! # }
//! ```

mod measure;
mod text;

use crate::Trajectory;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

pub use measure::{Energy, Residuals};

/// Width and height of every figure, in pixels (SVG: user units).
pub const SIZE: (u32, u32) = (900, 600);

/// The smallest value a logarithmic axis shows; exact zeros sit here.
pub const LOG_FLOOR: f64 = 1e-18;

/// Why a figure was not written.
///
/// ```
/// use geoshake::plot::{phase_portrait, PlotError};
/// let empty = geoshake::Trajectory::default();
/// assert!(matches!(phase_portrait(&empty, "never.png"), Err(PlotError::Empty)));
/// ```
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The trajectory holds no state.
    #[error("the trajectory holds no state: nothing to plot")]
    Empty,
    /// The system's dimension is not the trajectory's.
    #[error("the system has {system} degrees of freedom, the trajectory {trajectory}")]
    DimensionMismatch {
        /// d of the system.
        system: usize,
        /// d of the stored states.
        trajectory: usize,
    },
    /// A plotted value is NaN or infinite (the figure would hide it).
    #[error("{quantity} is {value} at step {step} (t = {t})")]
    NonFinite {
        /// What was computed.
        quantity: &'static str,
        /// The value.
        value: f64,
        /// The step of the state.
        step: u64,
        /// Its time.
        t: f64,
    },
    /// The path does not end in `.png` or `.svg`.
    #[error("{path:?}: the figure's format comes from the extension, .png or .svg")]
    UnknownFormat {
        /// The path given.
        path: PathBuf,
    },
    /// Drawing or writing the file failed (plotters' message).
    #[error("drawing {path:?} failed: {message}")]
    Drawing {
        /// The path given.
        path: PathBuf,
        /// What plotters reported (e.g. a missing directory).
        message: String,
    },
}

/// The qualitative palette of the paper's figures (Okabe–Ito), readable
/// in print and by colour-blind readers.
const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
];

/// One named curve.
struct Curve {
    name: String,
    points: Vec<(f64, f64)>,
}

/// How the curves of a figure are drawn.
#[derive(Clone, Copy, PartialEq)]
enum Look {
    /// Lines through every point, the start marked (phase portraits).
    Lines,
    /// A signed quantity over a long time: lines while there are fewer
    /// points than pixel columns, then per column the band from the least
    /// to the largest value (what a line through all of them would fill).
    Bands,
    /// A round-off-level quantity on a log axis: per pixel column the
    /// largest value, as a dot (lines between round-off values only
    /// scribble).
    Dots,
}

/// What a figure shows, before it is drawn.
struct Chart {
    title: String,
    x_label: String,
    y_label: String,
    look: Look,
    curves: Vec<Curve>,
    note: Option<String>,
}

/// The phase portrait: for each coordinate k, the curve (q_k, p_k) through
/// the stored states, one colour per coordinate, named as the system
/// declared them ([`Trajectory::variable_name`]: `(x, p_x)` for
/// `coordinates x, y; momenta p_x, p_y;`, `(q[1], p[1])` for arrays).
/// The start is marked with a dot.
///
/// ```
/// use geoshake::prelude::*;
/// use geoshake::examples::Pendulum;
/// let p = Pendulum::default();
/// let traj = Integrator::new(p, StormerVerlet, 0.05).run(p.state(0.5, 0.0), Stop::Steps(200)).execute().trajectory;
/// let path = std::env::temp_dir().join("shake_doc_phase.svg");
/// geoshake::plot::phase_portrait(&traj, &path).unwrap();
/// assert!(std::fs::read_to_string(&path).unwrap().contains("q[1]"));
/// ```
pub fn phase_portrait(traj: &Trajectory, path: impl AsRef<Path>) -> Result<(), PlotError> {
    if traj.is_empty() {
        return Err(PlotError::Empty);
    }
    let d = traj.q(0).len();
    let mut curves = Vec::with_capacity(d);
    for k in 0..d {
        let mut points = Vec::with_capacity(traj.len());
        for i in 0..traj.len() {
            let (q, p) = (traj.q(i)[k], traj.p(i)[k]);
            for (quantity, value) in [("q", q), ("p", p)] {
                finite(traj, i, quantity, value)?;
            }
            points.push((q, p));
        }
        curves.push(Curve {
            name: format!("({}, {})", traj.variable_name(k), traj.variable_name(d + k)),
            points,
        });
    }
    let chart = Chart {
        title: "Phase portrait".into(),
        x_label: "q".into(),
        y_label: "p".into(),
        look: Look::Lines,
        curves,
        note: Some(format!(
            "{} states, t = {} … {}; dots: the start",
            traj.len(),
            short(traj.time(0)),
            short(traj.time(traj.len() - 1))
        )),
    };
    chart.write(path.as_ref())
}

/// The energy error against time: (H(z_n) − H(z_0)) / |H(z_0)|, or the
/// absolute error H(z_n) − H(z_0) when H(z_0) = 0 (the axis label says
/// which), on a linear axis (a drift shows as a trend). `system` is `&S`
/// for a [`Hamiltonian`](crate::Hamiltonian) S, or `&mut rattle` for a particle run
/// ([`Energy`]).
///
/// ```
/// use geoshake::prelude::*;
/// use geoshake::examples::Pendulum;
/// let p = Pendulum::default();
/// let traj = Integrator::new(p, StormerVerlet, 0.05).rattle().run(p.state(0.5, 0.0), Stop::Steps(200)).execute().trajectory;
/// geoshake::plot::energy_error(&traj, &p, std::env::temp_dir().join("shake_doc_energy.png")).unwrap();
/// ```
pub fn energy_error<S: Energy>(
    traj: &Trajectory,
    mut system: S,
    path: impl AsRef<Path>,
) -> Result<(), PlotError> {
    check(traj, system.dof())?;
    let e0 = system.energy(traj.q(0), traj.p(0));
    finite(traj, 0, "H", e0)?;
    let scale = if e0 == 0.0 { 1.0 } else { e0.abs() };
    let mut points = Vec::with_capacity(traj.len());
    for i in 0..traj.len() {
        let e = system.energy(traj.q(i), traj.p(i));
        finite(traj, i, "H", e)?;
        points.push((traj.time(i), (e - e0) / scale));
    }
    let y_label = if e0 == 0.0 {
        "H − H(0)"
    } else {
        "(H − H(0)) / |H(0)|"
    };
    let chart = Chart {
        title: "Energy error".into(),
        x_label: "t".into(),
        y_label: y_label.into(),
        look: Look::Bands,
        curves: vec![Curve {
            name: "energy error".into(),
            points,
        }],
        note: Some(format!(
            "H(0) = {}; {} states, t = {} … {}",
            short(e0),
            traj.len(),
            short(traj.time(0)),
            short(traj.time(traj.len() - 1))
        )),
    };
    chart.write(path.as_ref())
}

/// The constraint residuals against time, on a logarithmic axis: max_i
/// |g_i(z_n)| (the constraint, M) and max_i |{g_i, H}(z_n)| (the hidden
/// constraint, M^H). `system` is `&S` for a [`ConstrainedSystem`](crate::ConstrainedSystem) S, or
/// `&mut rattle` for a particle run, whose residuals are relative to each
/// member's scale ([`Residuals`]).
///
/// ```
/// use geoshake::prelude::*;
/// use geoshake::examples::Pendulum;
/// let p = Pendulum::default();
/// let traj = Integrator::new(p, StormerVerlet, 0.05).shake().run(p.state(0.5, 0.0), Stop::Steps(200)).execute().trajectory;
/// geoshake::plot::constraint_residual(&traj, &p, std::env::temp_dir().join("shake_doc_residual.svg")).unwrap();
/// ```
pub fn constraint_residual<S: Residuals>(
    traj: &Trajectory,
    mut system: S,
    path: impl AsRef<Path>,
) -> Result<(), PlotError> {
    check(traj, system.dof())?;
    let m = system.constraint_count();
    // (What is plotted, its legend and the axis.)
    let (names, legends, y_label) = if S::RELATIVE {
        (
            ["relative |g|", "relative |{g,H}|"],
            [
                "|g| / (|∇g| · extent): constraint",
                "|{g,H}| / (|∇g| · |M⁻¹p|): hidden constraint",
            ],
            "relative residual (max over constraints)",
        )
    } else {
        (
            ["|g|", "|{g,H}|"],
            ["|g|: constraint", "|{g,H}|: hidden constraint"],
            "residual (max over constraints)",
        )
    };
    let (mut primary, mut hidden) = (Vec::new(), Vec::new());
    for i in 0..traj.len() {
        let [r, s] = system.residuals(traj.q(i), traj.p(i));
        finite(traj, i, names[0], r)?;
        finite(traj, i, names[1], s)?;
        primary.push((traj.time(i), r));
        hidden.push((traj.time(i), s));
    }
    let chart = Chart {
        title: "Constraint residuals".into(),
        x_label: "t".into(),
        y_label: y_label.into(),
        look: Look::Dots,
        curves: vec![
            Curve {
                name: legends[0].into(),
                points: primary,
            },
            Curve {
                name: legends[1].into(),
                points: hidden,
            },
        ],
        note: Some(format!(
            "{m} constraint(s); exact zeros drawn at {LOG_FLOOR:e}"
        )),
    };
    chart.write(path.as_ref())
}

fn check(traj: &Trajectory, dof: usize) -> Result<(), PlotError> {
    if traj.is_empty() {
        return Err(PlotError::Empty);
    }
    let d = traj.q(0).len();
    if d != dof {
        return Err(PlotError::DimensionMismatch {
            system: dof,
            trajectory: d,
        });
    }
    Ok(())
}

fn finite(
    traj: &Trajectory,
    i: usize,
    quantity: &'static str,
    value: f64,
) -> Result<(), PlotError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(PlotError::NonFinite {
            quantity,
            value,
            step: traj.step(i),
            t: traj.time(i),
        })
    }
}

/// A number for a note: six significant digits at most.
fn short(x: f64) -> String {
    let s = format!("{x}");
    if s.len() <= 8 {
        s
    } else if (1e-3..1e5).contains(&x.abs()) {
        let digits = (5 - x.abs().log10().floor() as i32).max(0) as usize;
        let s = format!("{x:.digits$}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{x:.5e}")
    }
}

/// Per pixel column (the points binned by x into `columns` equal bins):
/// (x of the column's first point, least y, largest y).
fn columns(points: &[(f64, f64)], columns: usize) -> Vec<(f64, f64, f64)> {
    let (x0, x1) = (points[0].0, points[points.len() - 1].0);
    let width = (x1 - x0) / columns as f64;
    let mut out: Vec<(f64, f64, f64)> = Vec::with_capacity(columns + 1);
    let mut bin = usize::MAX;
    for &(x, y) in points {
        let b = if width > 0.0 {
            (((x - x0) / width) as usize).min(columns - 1)
        } else {
            0
        };
        match out.last_mut() {
            Some(last) if b == bin => {
                last.1 = last.1.min(y);
                last.2 = last.2.max(y);
            }
            _ => {
                out.push((x, y, y));
                bin = b;
            }
        }
    }
    out
}

/// A tick label for `v` on the axis from `lo` to `hi`: one format for the
/// whole axis (scientific when its largest value is below 1e-3 or from
/// 1e5 on), with enough digits that neighbouring ticks (about a tenth of
/// the span apart) differ, and no more.
fn tick(v: f64, lo: f64, hi: f64) -> String {
    let step = ((hi - lo) / 10.0).abs().max(f64::MIN_POSITIVE);
    if v.abs() < step * 1e-6 {
        return "0".into();
    }
    let step_exp = step.log10().floor() as i32;
    let axis_exp = lo.abs().max(hi.abs()).log10().floor() as i32;
    if !(-3..5).contains(&axis_exp) {
        let m = v / 10f64.powi(axis_exp);
        let digits = (axis_exp - step_exp).clamp(0, 6) as usize;
        format!("{m:.digits$}e{axis_exp}")
    } else {
        format!("{v:.*}", (-step_exp).clamp(0, 8) as usize)
    }
}

/// A label for a tick at log10(value) = `v`: "1e-15" on whole decades.
fn log_tick(v: f64) -> String {
    let k = v.round();
    if (v - k).abs() < 1e-9 {
        format!("1e{}", k as i64)
    } else {
        format!("{:.1e}", 10f64.powf(v))
    }
}

impl Chart {
    /// Draws into `path`, a PNG or an SVG by its extension.
    fn write(&self, path: &Path) -> Result<(), PlotError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        text::register_font();
        let result = match ext.as_deref() {
            Some("png") => {
                self.draw(&text::Crisp(BitMapBackend::new(path, SIZE)).into_drawing_area())
            }
            Some("svg") => self.draw(&SVGBackend::new(path, SIZE).into_drawing_area()),
            _ => {
                return Err(PlotError::UnknownFormat {
                    path: path.to_path_buf(),
                })
            }
        };
        result.map_err(|message| PlotError::Drawing {
            path: path.to_path_buf(),
            message,
        })
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let log_y = self.look == Look::Dots;
        let ty = |y: f64| {
            if log_y {
                y.abs().max(LOG_FLOOR).log10()
            } else {
                y
            }
        };
        // What is drawn of each curve, in plot units: per pixel column
        // (x, low, high), or every point as (x, y, y).
        let n_columns = SIZE.0 as usize;
        let drawn: Vec<Vec<(f64, f64, f64)>> = self
            .curves
            .iter()
            .map(|c| {
                let dense = self.look != Look::Lines && c.points.len() > n_columns;
                let cols = if dense {
                    columns(&c.points, n_columns)
                } else {
                    c.points.iter().map(|&(x, y)| (x, y, y)).collect()
                };
                cols.into_iter()
                    .map(|(x, lo, hi)| (x, ty(lo), ty(hi)))
                    .collect()
            })
            .collect();
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, lo, hi) in drawn.iter().flatten() {
            // Dots draw a column's largest value only.
            let lo = if self.look == Look::Dots { hi } else { lo };
            (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(lo), y1.max(hi));
        }
        let pad = |a: f64, b: f64, f: f64| {
            let w = if b > a { b - a } else { a.abs().max(1.0) * 0.1 };
            (a - f * w, b + f * w)
        };
        let (x0, x1) = pad(x0, x1, 0.02);
        // A log axis spans whole decades (at least two), one label each.
        let (y0, y1) = if log_y {
            let (a, b) = (y0.floor(), y1.ceil());
            (a, b.max(a + 2.0))
        } else {
            // Room at the top for the legend.
            let (a, b) = pad(y0, y1, 0.06);
            (a, b + 0.1 * (b - a))
        };
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 26))
            .margin(16)
            .margin_bottom(30)
            .x_label_area_size(52)
            .y_label_area_size(100)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        let y_span = y1 - y0;
        let fx = move |v: &f64| tick(*v, x0, x1);
        let fy = move |v: &f64| {
            if log_y {
                log_tick(*v)
            } else {
                tick(*v, y0, y1)
            }
        };
        let y_labels = if log_y {
            (y_span as usize + 1).min(12)
        } else {
            10
        };
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&fx)
            .y_label_formatter(&fy)
            .y_labels(y_labels)
            .label_style(("sans-serif", 17))
            .axis_desc_style(("sans-serif", 20))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()
            .map_err(e)?;
        for (k, (curve, cols)) in self.curves.iter().zip(&drawn).enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            let banded = cols.len() < curve.points.len();
            // plotters' bitmap backend draws wide, nearly vertical segments
            // with stray spikes: dense curves are drawn one pixel wide.
            let width = if cols.len() > 2 * n_columns { 1 } else { 2 };
            let anno = match (self.look, banded) {
                (Look::Dots, _) => chart
                    .draw_series(
                        cols.iter()
                            .map(|&(x, _, hi)| Circle::new((x, hi), 2, color.filled())),
                    )
                    .map_err(e)?,
                (Look::Bands, true) => chart
                    .draw_series(cols.iter().map(|&(x, lo, hi)| {
                        PathElement::new(vec![(x, lo), (x, hi)], color.stroke_width(1))
                    }))
                    .map_err(e)?,
                // A dense orbit as points: chords between stored states
                // would cut its corners and thicken it into a band.
                (Look::Lines, _) if cols.len() > 4 * n_columns => chart
                    .draw_series(cols.iter().map(|&(x, y, _)| Pixel::new((x, y), color)))
                    .map_err(e)?,
                _ => chart
                    .draw_series(LineSeries::new(
                        cols.iter().map(|&(x, y, _)| (x, y)),
                        color.stroke_width(width),
                    ))
                    .map_err(e)?,
            };
            let dots = self.look == Look::Dots;
            anno.label(&curve.name).legend(move |(x, y)| {
                let swatch: DynElement<'static, DB, (i32, i32)> = if dots {
                    Circle::new((x + 11, y), 4, color.filled()).into_dyn()
                } else {
                    PathElement::new(vec![(x, y), (x + 22, y)], color.stroke_width(3)).into_dyn()
                };
                swatch
            });
            if self.look == Look::Lines {
                chart
                    .draw_series(
                        cols.first()
                            .map(|&(x, y, _)| Circle::new((x, y), 5, color.filled())),
                    )
                    .map_err(e)?;
            }
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 17))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(e)?;
        let limit = if self.look == Look::Lines {
            4 * n_columns
        } else {
            n_columns
        };
        let dense = self.curves.iter().any(|c| c.points.len() > limit);
        let how = match self.look {
            _ if !dense => "",
            Look::Lines => "; drawn as points",
            Look::Bands => "; per pixel column: least to largest value",
            Look::Dots => "; per pixel column: largest value",
        };
        let note = self.note.as_ref().map(|n| format!("{n}{how}"));
        if let Some(note) = &note {
            // Below the axis, at the left: it never covers data.
            let font: TextStyle = ("sans-serif", 15).into_font().color(&RGBColor(80, 80, 80));
            let y = SIZE.1 as i32 - 24;
            root.draw(&Text::new(note.clone(), (12, y), font))
                .map_err(e)?;
        }
        root.present().map_err(e)?;
        Ok(())
    }
}
