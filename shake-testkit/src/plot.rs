//! Figures of the paper scene.
//!
//! A figure is described once ([`Figure`] for curves, [`Heatmap`] for the fibre
//! picture) and written three ways: PNG and SVG drawn with plotters, and the
//! data behind it as CSV, so that every curve in a picture can be checked
//! against numbers.
//!
//! Logarithmic axes are drawn by plotting log10 of the data on a linear axis
//! and labelling the ticks 1e-k: one coordinate type for every figure, and
//! zeros (exact residuals) are clamped to a floor stated in the CSV header
//! rather than dropped.

// A small toolkit shared by the scenes: not every scene uses every option.
#![allow(dead_code)]

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters_backend::{BackendColor, BackendCoord, DrawingErrorKind};
use std::error::Error;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

/// What any drawing step may fail with.
pub type PlotResult<T> = Result<T, Box<dyn Error>>;

/// The smallest value shown on a logarithmic axis; exact zeros sit here.
pub const LOG_FLOOR: f64 = 1e-18;

/// Registers the bundled DejaVu font under the family name plotters asks for.
/// Call once before drawing; later calls are harmless.
pub fn init_fonts() {
    // ab_glyph needs a font registered by name; the `dejavu` crate ships it,
    // so a machine without system fonts draws the same picture.
    let _ =
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
}

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mark {
    /// A solid polyline.
    Line,
    /// A dashed polyline (reference slopes, marker lines).
    Dashed,
    /// One dot per point.
    Points,
    /// Dots joined by a thin line.
    LinePoints,
    /// One open circle per point (points drawn on top of another series).
    Rings,
    /// One large filled dot per point (a few marked points).
    BigDots,
}

/// One named curve of a [`Figure`].
#[derive(Clone, Debug)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub mark: Mark,
    pub color: RGBColor,
}

/// A 2-D plot of named curves.
#[derive(Clone)]
pub struct Figure {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub log_x: bool,
    pub log_y: bool,
    /// Same scale on both axes (trajectories in the complex plane).
    pub equal_aspect: bool,
    pub size: (u32, u32),
    pub series: Vec<Series>,
    /// Optional fixed ranges (in data units, before any log).
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Where the legend sits (upper right unless it hides data).
    pub legend: SeriesLabelPosition,
    /// Lines of text printed in a box at the lower left of the plot: what a
    /// reader must know to read the figure (a caption that travels with it).
    pub notes: Vec<String>,
    /// Where the note box's top edge sits, as a fraction of the plot's
    /// height from its top; `None`: the box sits at the bottom.
    pub notes_top: Option<f64>,
}

/// A qualitative palette that stays readable in print.
pub const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(120, 120, 120),
    RGBColor(0, 0, 0),
];

impl Figure {
    /// An empty figure with a title and axis labels.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Figure {
            title: title.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            log_x: false,
            log_y: false,
            equal_aspect: false,
            size: (900, 600),
            series: Vec::new(),
            x_range: None,
            y_range: None,
            legend: SeriesLabelPosition::UpperRight,
            notes: Vec::new(),
            notes_top: None,
        }
    }

    /// Puts the note box's top edge at `frac` of the plot's height from the
    /// top (where the data leave room), instead of at the bottom.
    pub fn notes_at(mut self, frac: f64) -> Self {
        self.notes_top = Some(frac);
        self
    }

    /// Adds a line to the note box drawn inside the plot (lower left).
    pub fn note(mut self, line: &str) -> Self {
        self.notes.push(line.to_string());
        self
    }

    pub fn legend_at(mut self, pos: SeriesLabelPosition) -> Self {
        self.legend = pos;
        self
    }

    pub fn log_x(mut self) -> Self {
        self.log_x = true;
        self
    }

    pub fn log_y(mut self) -> Self {
        self.log_y = true;
        self
    }

    pub fn equal_aspect(mut self) -> Self {
        self.equal_aspect = true;
        self.size = (800, 800);
        self
    }

    pub fn size(mut self, w: u32, h: u32) -> Self {
        self.size = (w, h);
        self
    }

    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    /// Adds a curve; colours cycle through [`PALETTE`] unless set later.
    pub fn series(mut self, name: &str, points: Vec<(f64, f64)>, mark: Mark) -> Self {
        let color = PALETTE[self.series.len() % PALETTE.len()];
        self.series.push(Series {
            name: name.to_string(),
            points,
            mark,
            color,
        });
        self
    }

    /// Adds a curve with a chosen colour.
    pub fn series_colored(
        mut self,
        name: &str,
        points: Vec<(f64, f64)>,
        mark: Mark,
        color: RGBColor,
    ) -> Self {
        self.series.push(Series {
            name: name.to_string(),
            points,
            mark,
            color,
        });
        self
    }

    fn tx(&self, x: f64) -> f64 {
        if self.log_x {
            x.abs().max(LOG_FLOOR).log10()
        } else {
            x
        }
    }

    fn ty(&self, y: f64) -> f64 {
        if self.log_y {
            y.abs().max(LOG_FLOOR).log10()
        } else {
            y
        }
    }

    /// The plotted ranges, in transformed (possibly log10) units.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let pts = self.series.iter().flat_map(|s| s.points.iter());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in pts {
            let (x, y) = (self.tx(x), self.ty(y));
            if x.is_finite() && y.is_finite() {
                x0 = x0.min(x);
                x1 = x1.max(x);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if let Some((a, b)) = self.x_range {
            (x0, x1) = (self.tx(a), self.tx(b));
        }
        if let Some((a, b)) = self.y_range {
            (y0, y1) = (self.ty(a), self.ty(b));
        }
        let pad = |a: f64, b: f64, f: f64| {
            let w = if b > a { b - a } else { a.abs().max(1.0) * 0.1 };
            (a - f * w, b + f * w)
        };
        let (mut xr, mut yr) = (pad(x0, x1, 0.02), pad(y0, y1, 0.05));
        if self.x_range.is_some() {
            xr = (x0, x1);
        }
        if self.y_range.is_some() {
            yr = (y0, y1);
        }
        if self.equal_aspect {
            let (cx, cy) = ((xr.0 + xr.1) / 2.0, (yr.0 + yr.1) / 2.0);
            let half = (xr.1 - xr.0).max(yr.1 - yr.0) / 2.0;
            xr = (cx - half, cx + half);
            yr = (cy - half, cy + half);
        }
        (xr, yr)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> PlotResult<()>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let ((x0, x1), (y0, y1)) = self.ranges();
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 26))
            .margin(16)
            .x_label_area_size(52)
            .y_label_area_size(78)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        let (log_x, log_y) = (self.log_x, self.log_y);
        let fx = move |v: &f64| axis_label(*v, log_x);
        let fy = move |v: &f64| axis_label(*v, log_y);
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&fx)
            .y_label_formatter(&fy)
            .label_style(("sans-serif", 17))
            .axis_desc_style(("sans-serif", 20))
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(205, 205, 205))
            .draw()?;
        for s in &self.series {
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .map(|&(x, y)| (self.tx(x), self.ty(y)))
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            let color = s.color;
            let mark = s.mark;
            // The swatch draws the series the way the plot does: a line, a
            // dashed line, a dot, or a line through a dot.
            let legend = move |(x, y): (i32, i32)| {
                // One element type for every mark: three segments and a dot,
                // the parts a mark does not use drawn transparent.
                let none = RGBAColor(0, 0, 0, 0.0);
                let seg = |a: i32, b: i32, w: u32, on: bool| {
                    let c = if on { color.to_rgba() } else { none };
                    PathElement::new(vec![(x + a, y), (x + b, y)], c.stroke_width(w))
                };
                let dashed = mark == Mark::Dashed;
                let (solid, width) = match mark {
                    Mark::Line => (true, 2),
                    Mark::LinePoints => (true, 1),
                    _ => (false, 1),
                };
                let dot = matches!(
                    mark,
                    Mark::Points | Mark::LinePoints | Mark::Rings | Mark::BigDots
                );
                let dot_color = if dot { color.to_rgba() } else { none };
                let dot_style = if mark == Mark::Rings {
                    dot_color.stroke_width(2)
                } else {
                    dot_color.filled()
                };
                EmptyElement::at((0, 0))
                    + seg(0, 22, width, solid)
                    + seg(0, 6, 2, dashed)
                    + seg(9, 14, 2, dashed)
                    + seg(17, 22, 2, dashed)
                    + Circle::new(
                        (x + 11, y),
                        if mark == Mark::BigDots { 6 } else { 4 },
                        dot_style,
                    )
            };
            let anno = match s.mark {
                Mark::Line => chart.draw_series(LineSeries::new(pts, color.stroke_width(2)))?,
                Mark::Dashed => {
                    chart.draw_series(DashedLineSeries::new(pts, 8, 6, color.stroke_width(2)))?
                }
                Mark::Points => {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 2, color.filled())))?
                }
                Mark::LinePoints => {
                    chart.draw_series(LineSeries::new(pts.clone(), color.stroke_width(1)))?;
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?
                }
                Mark::Rings => chart.draw_series(
                    pts.iter()
                        .map(|&p| Circle::new(p, 6, color.stroke_width(2))),
                )?,
                Mark::BigDots => {
                    chart.draw_series(pts.iter().map(|&p| Circle::new(p, 9, color.filled())))?
                }
            };
            // Helper strokes (arrow heads, guides) carry no name and no legend.
            if !s.name.is_empty() {
                anno.label(&s.name).legend(legend);
            }
        }
        if self.series.iter().any(|s| !s.name.is_empty()) {
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 17))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(self.legend.clone())
                .draw()?;
        }
        if !self.notes.is_empty() {
            let (xs, ys) = chart.plotting_area().get_pixel_range();
            let font: TextStyle = ("sans-serif", 16).into_font().into();
            let line_h = 21;
            let width = self
                .notes
                .iter()
                .map(|l| {
                    root.estimate_text_size(l, &font)
                        .map_or(0, |(w, _)| w as i32)
                })
                .max()
                .unwrap_or(0);
            let height = line_h * self.notes.len() as i32;
            let x0 = xs.start + 10;
            let (y0, y1) = match self.notes_top {
                Some(f) => {
                    let y0 = ys.start + (f * (ys.end - ys.start) as f64) as i32;
                    (y0, y0 + height + 10)
                }
                None => (ys.end - 20 - height, ys.end - 10),
            };
            root.draw(&Rectangle::new(
                [(x0, y0), (x0 + width + 16, y1)],
                WHITE.mix(0.9).filled(),
            ))?;
            root.draw(&Rectangle::new(
                [(x0, y0), (x0 + width + 16, y1)],
                BLACK.stroke_width(1),
            ))?;
            for (k, l) in self.notes.iter().enumerate() {
                root.draw(&Text::new(
                    l.clone(),
                    (x0 + 8, y0 + 6 + line_h * k as i32),
                    font.clone(),
                ))?;
            }
        }
        root.present()?;
        Ok(())
    }

    /// Writes `stem.png`, `stem.svg` and `stem.csv` into `dir`.
    pub fn save(&self, dir: &Path, stem: &str) -> PlotResult<Vec<PathBuf>> {
        fs::create_dir_all(dir)?;
        let png = dir.join(format!("{stem}.png"));
        let svg = dir.join(format!("{stem}.svg"));
        let csv = dir.join(format!("{stem}.csv"));
        self.draw(&Crisp(BitMapBackend::new(&png, self.size)).into_drawing_area())?;
        self.draw(&SVGBackend::new(&svg, self.size).into_drawing_area())?;
        fs::write(&csv, self.csv())?;
        Ok(vec![png, svg, csv])
    }

    /// The data in long form: one row per point, `series,x,y`.
    pub fn csv(&self) -> String {
        let mut out = format!("# {}\n", self.title);
        for n in &self.notes {
            let _ = writeln!(out, "# {n}");
        }
        if self.log_x || self.log_y {
            let _ = writeln!(
                out,
                "# log axes clamp |v| below {LOG_FLOOR:e} to that floor"
            );
        }
        let _ = writeln!(
            out,
            "series,{},{}",
            csv_field(&self.x_label),
            csv_field(&self.y_label)
        );
        for s in &self.series {
            for &(x, y) in &s.points {
                let _ = writeln!(out, "{},{x:e},{y:e}", csv_field(&s.name));
            }
        }
        out
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A polyline drawing an arrow from `a` to `b` with a head of length `head`
/// (data units; use with an equal-aspect figure).
pub fn arrow(a: (f64, f64), b: (f64, f64), head: f64) -> Vec<(f64, f64)> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = dx.hypot(dy).max(f64::MIN_POSITIVE);
    let (ux, uy) = (dx / len, dy / len);
    let (c, s) = (0.93f64, 0.36f64); // cos, sin of the head's half-angle (~21 degrees)
    let left = (
        b.0 - head * (c * ux - s * uy),
        b.1 - head * (s * ux + c * uy),
    );
    let right = (
        b.0 - head * (c * ux + s * uy),
        b.1 - head * (-s * ux + c * uy),
    );
    vec![a, b, left, b, right]
}

/// The largest |v| in each of `windows` equal windows of `t`, as (window
/// end, max) points: a long oscillating record drawn as its envelope, so a
/// figure shows growth or its absence instead of a solid band.
pub fn envelope(t: &[f64], v: &[f64], windows: usize) -> Vec<(f64, f64)> {
    let n = t.len().min(v.len());
    if n == 0 || windows == 0 {
        return Vec::new();
    }
    let per = n.div_ceil(windows);
    (0..n)
        .step_by(per)
        .map(|a| {
            let b = (a + per).min(n);
            let m = v[a..b].iter().fold(0.0f64, |m, x| m.max(x.abs()));
            (t[b - 1], m)
        })
        .collect()
}

/// Tick labels: plain numbers, or 1e-k on a log axis.
fn axis_label(v: f64, log: bool) -> String {
    if log {
        let k = v.round();
        if (v - k).abs() < 1e-9 {
            format!("1e{}", k as i64)
        } else {
            format!("{:.1e}", 10f64.powf(v))
        }
    } else if v.abs() < 1e-12 {
        // A tick at zero computed as −2e-16 is zero.
        "0".to_string()
    } else if v.abs() < 1e-3 || v.abs() >= 1e5 {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" {
            "0".to_string()
        } else {
            s.to_string()
        }
    }
}

/// A scalar field on a rectangle, drawn as an image with a colour scale
/// (the paper's fibre figure: time across, fibre coordinate up).
#[derive(Clone, Debug)]
pub struct Heatmap {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_range: (f64, f64),
    pub y_range: (f64, f64),
    /// What the colour means, written along the colour bar.
    pub value_label: String,
    /// `values[j][i]`: row j (bottom to top), column i (left to right).
    pub values: Vec<Vec<f64>>,
    /// Horizontal dashed marker lines at these y values.
    pub dashed_y: Vec<f64>,
    /// Vertical dashed marker lines at these x values.
    pub dashed_x: Vec<f64>,
    pub size: (u32, u32),
}

impl Heatmap {
    /// Black at 0, through blue and yellow to white at the largest value, so
    /// the zero set (the paper's black curves) stands out.
    fn color(v: f64, vmax: f64) -> RGBColor {
        let t = (v / vmax).clamp(0.0, 1.0).sqrt();
        let stops = [
            (0.0, (0.0, 0.0, 0.0)),
            (0.25, (30.0, 40.0, 140.0)),
            (0.6, (60.0, 170.0, 160.0)),
            (0.85, (240.0, 220.0, 80.0)),
            (1.0, (255.0, 255.0, 240.0)),
        ];
        for w in stops.windows(2) {
            let ((a, ca), (b, cb)) = (w[0], w[1]);
            if t <= b {
                let s = (t - a) / (b - a);
                let mix = |x: f64, y: f64| (x + s * (y - x)).round() as u8;
                return RGBColor(mix(ca.0, cb.0), mix(ca.1, cb.1), mix(ca.2, cb.2));
            }
        }
        RGBColor(255, 255, 240)
    }

    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        stride: usize,
    ) -> PlotResult<()>
    where
        DB::ErrorType: 'static,
    {
        root.fill(&WHITE)?;
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        // Title across the whole width, then the image and its colour bar.
        let body = root.titled(&self.title, ("sans-serif", 24))?;
        let (w, _) = body.dim_in_pixel();
        let (main, bar) = body.split_horizontally(w.saturating_sub(150));
        let mut chart = ChartBuilder::on(&main)
            .margin(16)
            .x_label_area_size(52)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style(("sans-serif", 17))
            .axis_desc_style(("sans-serif", 20))
            .draw()?;
        let rows = self.values.len();
        let cols = self.values.first().map_or(0, Vec::len);
        let vmax = self
            .values
            .iter()
            .flatten()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            .max(f64::MIN_POSITIVE);
        let dx = (x1 - x0) / cols.max(1) as f64;
        let dy = (y1 - y0) / rows.max(1) as f64;
        let cells = (0..rows)
            .step_by(stride)
            .flat_map(|j| (0..cols).step_by(stride).map(move |i| (i, j)));
        chart.draw_series(cells.map(|(i, j)| {
            // The cell shows the smallest |H'| it covers, so a thin zero
            // curve is not lost when the SVG is drawn coarser.
            let mut v = f64::MAX;
            for jj in j..(j + stride).min(rows) {
                for ii in i..(i + stride).min(cols) {
                    v = v.min(self.values[jj][ii]);
                }
            }
            let (xa, ya) = (x0 + i as f64 * dx, y0 + j as f64 * dy);
            let (xb, yb) = (xa + dx * stride as f64, ya + dy * stride as f64);
            Rectangle::new([(xa, ya), (xb, yb)], Self::color(v, vmax).filled())
        }))?;
        // The colour bar: the same colour map, labelled in the values' units.
        let mut scale = ChartBuilder::on(&bar)
            .margin_top(16)
            .margin_bottom(16 + 52)
            .margin_left(8)
            .set_label_area_size(LabelAreaPosition::Right, 80)
            .margin_right(6)
            .build_cartesian_2d(0.0..1.0, 0.0..vmax)?;
        scale
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .axis_style(WHITE)
            .y_desc(&self.value_label)
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 18))
            .y_label_formatter(&|v: &f64| axis_label(*v, false))
            .draw()?;
        let levels = 256;
        scale.draw_series((0..levels).map(|k| {
            let (a, b) = (
                vmax * k as f64 / levels as f64,
                vmax * (k + 1) as f64 / levels as f64,
            );
            Rectangle::new(
                [(0.0, a), (0.75, b)],
                Self::color(0.5 * (a + b), vmax).filled(),
            )
        }))?;
        scale.draw_series(std::iter::once(Rectangle::new(
            [(0.0, 0.0), (0.75, vmax)],
            BLACK.stroke_width(1),
        )))?;
        for &y in &self.dashed_y {
            chart.draw_series(DashedLineSeries::new(
                vec![(x0, y), (x1, y)],
                10,
                6,
                WHITE.stroke_width(2),
            ))?;
        }
        for &x in &self.dashed_x {
            chart.draw_series(DashedLineSeries::new(
                vec![(x, y0), (x, y1)],
                10,
                6,
                WHITE.stroke_width(2),
            ))?;
        }
        root.present()?;
        Ok(())
    }

    /// Writes `stem.png`, `stem.svg` (coarsened so the file stays small) and
    /// `stem.csv` (the full grid, one row per cell).
    pub fn save(&self, dir: &Path, stem: &str) -> PlotResult<Vec<PathBuf>> {
        fs::create_dir_all(dir)?;
        let png = dir.join(format!("{stem}.png"));
        let svg = dir.join(format!("{stem}.svg"));
        let csv = dir.join(format!("{stem}.csv"));
        self.draw(
            &Crisp(BitMapBackend::new(&png, self.size)).into_drawing_area(),
            1,
        )?;
        let cells = self.values.len() * self.values.first().map_or(0, Vec::len);
        let stride = ((cells as f64 / 40_000.0).sqrt().ceil() as usize).max(1);
        self.draw(
            &SVGBackend::new(&svg, self.size).into_drawing_area(),
            stride,
        )?;
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_range;
        let rows = self.values.len();
        let mut out = format!(
            "# {}\n{},{},{}\n",
            self.title,
            csv_field(&self.x_label),
            csv_field(&self.y_label),
            csv_field(&self.value_label)
        );
        for (j, row) in self.values.iter().enumerate() {
            let cols = row.len();
            for (i, v) in row.iter().enumerate() {
                let x = x0 + (i as f64 + 0.5) * (x1 - x0) / cols as f64;
                let y = y0 + (j as f64 + 0.5) * (y1 - y0) / rows as f64;
                let _ = writeln!(out, "{x:e},{y:e},{v:e}");
            }
        }
        fs::write(&csv, out)?;
        Ok(vec![png, svg, csv])
    }
}

/// A bitmap backend whose text is drawn glyph by glyph with ab_glyph at
/// sub-pixel positions on one baseline.
///
/// plotters' own ab_glyph path rounds every glyph's offset to whole pixels
/// separately (towards zero, so glyphs above and below the rounding point go
/// different ways): letters with flat tops such as x, v and z sit a pixel high
/// and some pairs drift apart ("SH AKE"). Everything but text is passed to the
/// wrapped backend unchanged, and the text box (hence the layout) is the one
/// plotters computes, so only the glyphs' placement changes.
pub struct Crisp<B>(pub B);

impl<B: DrawingBackend> DrawingBackend for Crisp<B> {
    type ErrorType = B::ErrorType;

    fn get_size(&self) -> (u32, u32) {
        self.0.get_size()
    }
    fn ensure_prepared(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.ensure_prepared()
    }
    fn present(&mut self) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.present()
    }
    fn draw_pixel(
        &mut self,
        point: BackendCoord,
        color: BackendColor,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_pixel(point, color)
    }
    fn draw_line<S: plotters_backend::BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_line(from, to, style)
    }
    fn draw_rect<S: plotters_backend::BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_rect(upper_left, bottom_right, style, fill)
    }
    fn draw_path<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_path(path, style)
    }
    fn draw_circle<S: plotters_backend::BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.draw_circle(center, radius, style, fill)
    }
    fn fill_polygon<S: plotters_backend::BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.fill_polygon(vert, style)
    }
    fn blit_bitmap(
        &mut self,
        pos: BackendCoord,
        iwh: (u32, u32),
        src: &[u8],
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        self.0.blit_bitmap(pos, iwh, src)
    }
    fn estimate_text_size<TStyle: plotters_backend::BackendTextStyle>(
        &self,
        text: &str,
        style: &TStyle,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        self.0.estimate_text_size(text, style)
    }

    fn draw_text<TStyle: plotters_backend::BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> Result<(), DrawingErrorKind<Self::ErrorType>> {
        use ab_glyph::{Font, FontRef, ScaleFont};
        use plotters_backend::text_anchor::{HPos, VPos};
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let font = FontRef::try_from_slice(dejavu::sans::regular())
            .map_err(|e| DrawingErrorKind::FontError(Box::new(e)))?;
        let size = style.size() as f32;
        let scaled = font.as_scaled(size);
        // The same box plotters lays out (advances plus kerning, height
        // size/1.24), with the baseline where plotters puts it (size/2 below
        // the top), so titles and tick labels keep their places.
        let (w, h) = self.estimate_text_size(text, style)?;
        let (w, h) = (w as f32, h as f32);
        let dx = match style.anchor().h_pos {
            HPos::Left => 0.0,
            HPos::Right => -w,
            HPos::Center => -w / 2.0,
        };
        let dy = match style.anchor().v_pos {
            VPos::Top => 0.0,
            VPos::Center => -h / 2.0,
            VPos::Bottom => -h,
        };
        let baseline = dy + size / 2.0;
        let trans = style.transform();
        let (width, height) = self.get_size();
        let mut x = dx;
        let mut prev = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(p) = prev {
                x += scaled.kern(p, id);
            }
            prev = Some(id);
            let glyph = id.with_scale_and_position(size, ab_glyph::point(x, baseline));
            x += scaled.h_advance(id);
            let Some(outline) = font.outline_glyph(glyph) else {
                continue;
            };
            let b = outline.px_bounds();
            let mut result = Ok(());
            outline.draw(|gx, gy, coverage| {
                if result.is_err() || coverage <= 0.0 {
                    return;
                }
                let (px, py) = (b.min.x as i32 + gx as i32, b.min.y as i32 + gy as i32);
                let (tx, ty) = trans.transform(px, py);
                let (tx, ty) = (pos.0 + tx, pos.1 + ty);
                if tx >= 0 && ty >= 0 && (tx as u32) < width && (ty as u32) < height {
                    let a = color.alpha * f64::from(coverage.min(1.0));
                    result = self.0.draw_pixel(
                        (tx, ty),
                        BackendColor {
                            alpha: a,
                            rgb: color.rgb,
                        },
                    );
                }
            });
            result?;
        }
        Ok(())
    }
}
