//! Extended XYZ, as ASE and OVITO read it: [`ExtXyzWriter`] and
//! [`ExtXyzReader`].
//!
//! A frame is a line with the number of atoms n, a comment line of
//! `key=value` pairs, and n rows. The writer's comment line is
//!
//! ```text
//! Lattice="ax ay az bx by bz cx cy cz" Origin="xlo ylo zlo" Properties=species:S:1:pos:R:3:momenta:R:3 Time=t step=k pbc="T T T"
//! ```
//!
//! (the box's edge vectors, its lower corner, then per row the species
//! and the position and momentum of the atom), which
//! `ase.io.read(path, index=":", format="extxyz")` turns into `Atoms` with
//! that cell, positions and momenta, `Time` and `step` in `atoms.info`.
//! Momenta are written in the run's units (p = m v with the system's masses,
//! lengths and times): ASE takes them as its own units, so convert before
//! computing energies there. Numbers are written so that reading them back
//! gives the same f64 bit for bit. Format reference: the extended XYZ
//! specification (github.com/libAtoms/extxyz) and ASE's `ase.io.extxyz`.

use super::number::{parse, push_f64};
use super::stream::FrameSink;
use super::{FileError, SimBox};
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

/// One frame of an extended XYZ file.
#[derive(Clone, Debug, PartialEq)]
pub struct XyzFrame {
    /// `step=` (0 when absent).
    pub step: u64,
    /// `Time=` (NaN when absent).
    pub time: f64,
    /// The box, from `Lattice=` (a lower-triangular cell; an upper corner
    /// lo + l rounded once) and `Origin=` (0 when absent).
    pub sim_box: Option<SimBox>,
    /// The species column.
    pub species: Vec<String>,
    /// The `pos` columns, 3 per atom.
    pub positions: Vec<f64>,
    /// The `momenta` columns, 3 per atom (empty when absent).
    pub momenta: Vec<f64>,
}

/// Writes states as extended XYZ frames, one frame a call; see the module
/// documentation for the format, and [`FrameSink`] for writing while a run
/// runs.
///
/// ```
/// use geoshake_runtime::particles::io::{ExtXyzReader, ExtXyzWriter, SimBox};
/// let mut out = ExtXyzWriter::new(Vec::new(), vec!["O".into(), "H".into()])
///     .with_box(SimBox::orthogonal([0.0; 3], [10.0; 3]));
/// let q = [0.1, 0.2, 0.3, 1.0 / 3.0, 0.5, 0.6];
/// let p = [0.0, 1e-20, -2.0, 0.5, 0.25, 7.0];
/// out.write_frame(10, 20.0, &q, &p).unwrap();
/// let bytes = out.finish().unwrap();
/// let frames: Vec<_> = ExtXyzReader::new(&bytes[..], "mem").collect::<Result<_, _>>().unwrap();
/// assert_eq!((frames[0].step, frames[0].time), (10, 20.0));
/// assert_eq!(frames[0].positions, q); // bit for bit
/// assert_eq!(frames[0].momenta, p);
/// ```
#[derive(Debug)]
pub struct ExtXyzWriter<W: Write> {
    out: W,
    file: PathBuf,
    species: Vec<String>,
    sim_box: Option<SimBox>,
    frames: u64,
    buf: String,
    error: Option<FileError>,
}

impl ExtXyzWriter<std::io::BufWriter<std::fs::File>> {
    /// A writer that creates (or truncates) the file at `path`.
    pub fn create(path: impl AsRef<Path>, species: Vec<String>) -> Result<Self, FileError> {
        let path = path.as_ref();
        let f = std::fs::File::create(path).map_err(|e| FileError::io(path, e))?;
        Ok(Self::new(std::io::BufWriter::new(f), species).named(path))
    }
}

impl<W: Write> ExtXyzWriter<W> {
    /// A writer to `out`, one species (chemical symbol) per atom.
    pub fn new(out: W, species: Vec<String>) -> Self {
        ExtXyzWriter {
            out,
            file: PathBuf::from("<stream>"),
            species,
            sim_box: None,
            frames: 0,
            buf: String::new(),
            error: None,
        }
    }

    /// The name its errors give (default `<stream>`; the path for
    /// [`create`](ExtXyzWriter::create)).
    pub fn named(mut self, name: impl AsRef<Path>) -> Self {
        self.file = name.as_ref().to_path_buf();
        self
    }

    /// Write this box as `Lattice=` and `Origin=` (default: no box).
    pub fn with_box(mut self, sim_box: SimBox) -> Self {
        self.sim_box = Some(sim_box);
        self
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Writes one frame: positions q and momenta p, 3 per atom, at `step`
    /// and `time`. The frame is formatted first, then written with one
    /// `write_all` and flushed: a frame that cannot be written leaves the
    /// frames before it as they were.
    pub fn write_frame(
        &mut self,
        step: u64,
        time: f64,
        q: &[f64],
        p: &[f64],
    ) -> Result<(), FileError> {
        let n = self.species.len();
        for (what, x) in [("positions", q), ("momenta", p)] {
            if x.len() != 3 * n {
                return Err(FileError::Shape {
                    file: self.file.clone(),
                    frame: self.frames,
                    what,
                    got: x.len(),
                    expected: 3 * n,
                    atoms: n,
                });
            }
        }
        let b = &mut self.buf;
        b.clear();
        b.push_str(&n.to_string());
        b.push('\n');
        if let Some(s) = &self.sim_box {
            b.push_str("Lattice=\"");
            for (i, x) in s.edges().iter().flatten().enumerate() {
                if i > 0 {
                    b.push(' ');
                }
                push_f64(b, *x);
            }
            b.push_str("\" Origin=\"");
            for (i, x) in s.lo.iter().enumerate() {
                if i > 0 {
                    b.push(' ');
                }
                push_f64(b, *x);
            }
            b.push_str("\" ");
        }
        b.push_str("Properties=species:S:1:pos:R:3:momenta:R:3 Time=");
        push_f64(b, time);
        b.push_str(&format!(" step={step}"));
        if self.sim_box.is_some() {
            b.push_str(" pbc=\"T T T\"");
        }
        b.push('\n');
        for (a, s) in self.species.iter().enumerate() {
            b.push_str(s);
            for x in q[3 * a..3 * a + 3].iter().chain(&p[3 * a..3 * a + 3]) {
                b.push(' ');
                push_f64(b, *x);
            }
            b.push('\n');
        }
        let file = &self.file;
        self.out
            .write_all(self.buf.as_bytes())
            .and_then(|()| self.out.flush())
            .map_err(|e| FileError::io(file, e))?;
        self.frames += 1;
        Ok(())
    }

    /// Flushes and returns the output, or the first error a
    /// [`FrameSink`] observer met.
    pub fn finish(mut self) -> Result<W, FileError> {
        if let Some(e) = self.error.take() {
            return Err(e);
        }
        self.out.flush().map_err(|e| FileError::io(&self.file, e))?;
        Ok(self.out)
    }
}

impl<W: Write> FrameSink for ExtXyzWriter<W> {
    fn write_state(&mut self, step: u64, time: f64, q: &[f64], p: &[f64]) -> Result<(), FileError> {
        self.write_frame(step, time, q, p)
    }

    fn deferred_error(&mut self) -> &mut Option<FileError> {
        &mut self.error
    }
}

/// Reads an extended XYZ file frame by frame: an iterator of
/// `Result<XyzFrame, FileError>` that ends after the first error.
///
/// The comment line is read as `key=value` pairs (values quoted with `"`
/// when they hold spaces); `Properties` must name `species:S:1` and
/// `pos:R:3` and may name `momenta:R:3` and other columns (skipped).
pub struct ExtXyzReader<R: BufRead> {
    input: R,
    file: PathBuf,
    line: usize,
    done: bool,
}

impl ExtXyzReader<std::io::BufReader<std::fs::File>> {
    /// A reader of the file at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, FileError> {
        let path = path.as_ref();
        let f = std::fs::File::open(path).map_err(|e| FileError::io(path, e))?;
        Ok(Self::new(std::io::BufReader::new(f), path))
    }
}

/// `key=value` pairs of an extended XYZ comment line.
fn pairs(line: &str) -> Vec<(String, String)> {
    let mut out = Vec::new();
    let mut chars = line.trim().chars().peekable();
    loop {
        while chars.next_if(|c| c.is_whitespace()).is_some() {}
        let key: String =
            std::iter::from_fn(|| chars.next_if(|&c| c != '=' && !c.is_whitespace())).collect();
        if key.is_empty() {
            break;
        }
        let mut value = String::new();
        if chars.next_if_eq(&'=').is_some() {
            if chars.next_if_eq(&'"').is_some() {
                value = std::iter::from_fn(|| chars.next_if(|&c| c != '"')).collect();
                chars.next();
            } else {
                value = std::iter::from_fn(|| chars.next_if(|c| !c.is_whitespace())).collect();
            }
        }
        out.push((key, value));
    }
    out
}

impl<R: BufRead> ExtXyzReader<R> {
    /// A reader of `input`; `name` is the file its errors name.
    pub fn new(input: R, name: impl AsRef<Path>) -> Self {
        ExtXyzReader {
            input,
            file: name.as_ref().to_path_buf(),
            line: 0,
            done: false,
        }
    }

    /// The next line (without its end), or `None` at the end of the input.
    fn next_line(&mut self, buf: &mut String) -> Result<Option<()>, FileError> {
        buf.clear();
        let n = self
            .input
            .read_line(buf)
            .map_err(|e| FileError::io(&self.file, e))?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        while buf.ends_with(['\n', '\r']) {
            buf.pop();
        }
        Ok(Some(()))
    }

    fn malformed(&self, expected: impl Into<String>) -> FileError {
        FileError::Malformed {
            file: self.file.clone(),
            line: self.line,
            expected: expected.into(),
        }
    }

    fn frame(&mut self) -> Result<Option<XyzFrame>, FileError> {
        let mut buf = String::new();
        // The count line (blank lines between frames are skipped).
        loop {
            if self.next_line(&mut buf)?.is_none() {
                return Ok(None);
            }
            if !buf.trim().is_empty() {
                break;
            }
        }
        let n: usize = parse(
            &self.file,
            self.line,
            Some(buf.trim()),
            "the number of atoms",
        )?;
        if self.next_line(&mut buf)?.is_none() {
            return Err(self.malformed("the comment line of a frame"));
        }
        let mut frame = XyzFrame {
            step: 0,
            time: f64::NAN,
            sim_box: None,
            species: Vec::with_capacity(n),
            positions: Vec::with_capacity(3 * n),
            momenta: Vec::new(),
        };
        let (mut lattice, mut origin) = (None, [0.0; 3]);
        let mut columns: Option<Vec<(String, char, usize)>> = None;
        let floats =
            |s: &str, what: &str, line: usize, file: &Path| -> Result<Vec<f64>, FileError> {
                s.split_whitespace()
                    .map(|t| parse(file, line, Some(t), what))
                    .collect()
            };
        for (k, v) in pairs(&buf) {
            match k.as_str() {
                "Lattice" => {
                    let e = floats(&v, "a Lattice entry", self.line, &self.file)?;
                    if e.len() != 9 {
                        return Err(self.malformed("9 numbers in Lattice"));
                    }
                    lattice = Some(e);
                }
                "Origin" => {
                    let o = floats(&v, "an Origin entry", self.line, &self.file)?;
                    if o.len() != 3 {
                        return Err(self.malformed("3 numbers in Origin"));
                    }
                    origin = [o[0], o[1], o[2]];
                }
                "Time" => frame.time = parse(&self.file, self.line, Some(&v), "the time")?,
                "step" => frame.step = parse(&self.file, self.line, Some(&v), "the step")?,
                "Properties" => {
                    let f: Vec<&str> = v.split(':').collect();
                    if !f.len().is_multiple_of(3) {
                        return Err(self.malformed("Properties as name:type:count triples"));
                    }
                    let mut cols = Vec::new();
                    for t in f.chunks(3) {
                        let count = parse(
                            &self.file,
                            self.line,
                            Some(t[2]),
                            "a property's column count",
                        )?;
                        cols.push((t[0].to_string(), t[1].chars().next().unwrap_or('?'), count));
                    }
                    columns = Some(cols);
                }
                _ => {}
            }
        }
        if let Some(e) = lattice {
            if e[1] != 0.0 || e[2] != 0.0 || e[5] != 0.0 {
                return Err(self.malformed(
                    "a lower-triangular Lattice (a along x, b in the xy plane), as LAMMPS boxes are",
                ));
            }
            frame.sim_box = Some(SimBox {
                lo: origin,
                hi: [origin[0] + e[0], origin[1] + e[4], origin[2] + e[8]],
                tilt: [e[3], e[6], e[7]],
            });
        }
        let columns =
            columns.unwrap_or_else(|| vec![("species".into(), 'S', 1), ("pos".into(), 'R', 3)]);
        let mut at = 0;
        let (mut species, mut pos, mut mom) = (None, None, None);
        for (name, _, count) in &columns {
            match (name.as_str(), count) {
                ("species", 1) => species = Some(at),
                ("pos", 3) => pos = Some(at),
                ("momenta", 3) => mom = Some(at),
                _ => {}
            }
            at += count;
        }
        let (Some(species), Some(pos)) = (species, pos) else {
            return Err(self.malformed("Properties naming species:S:1 and pos:R:3"));
        };
        for _ in 0..n {
            if self.next_line(&mut buf)?.is_none() {
                return Err(FileError::Malformed {
                    file: self.file.clone(),
                    line: self.line + 1,
                    expected: format!("{n} atom rows, the file ended first"),
                });
            }
            let t: Vec<&str> = buf.split_whitespace().collect();
            if t.len() != at {
                return Err(self.malformed(format!("{at} columns, found {}", t.len())));
            }
            frame.species.push(t[species].to_string());
            for c in 0..3 {
                frame.positions.push(parse(
                    &self.file,
                    self.line,
                    Some(t[pos + c]),
                    "a position",
                )?);
            }
            if let Some(m) = mom {
                for c in 0..3 {
                    frame
                        .momenta
                        .push(parse(&self.file, self.line, Some(t[m + c]), "a momentum")?);
                }
            }
        }
        Ok(Some(frame))
    }
}

impl<R: BufRead> Iterator for ExtXyzReader<R> {
    type Item = Result<XyzFrame, FileError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let r = self.frame().transpose();
        if !matches!(r, Some(Ok(_))) {
            self.done = true;
        }
        r
    }
}
