//! LAMMPS dump files, text form (the `dump atom`/`dump custom` commands'
//! output, docs.lammps.org/dump.html): [`DumpWriter`] and [`DumpReader`].
//!
//! A frame is
//!
//! ```text
//! ITEM: TIME
//! 20
//! ITEM: TIMESTEP
//! 10
//! ITEM: NUMBER OF ATOMS
//! 3
//! ITEM: BOX BOUNDS pp pp pp
//! xlo xhi
//! ylo yhi
//! zlo zhi
//! ITEM: ATOMS id type xu yu zu vx vy vz
//! 1 1 0.5 0.25 1 0.001 0 -0.002
//! …
//! ```
//!
//! `ITEM: TIME` is what LAMMPS writes with `dump_modify time yes` (the
//! writer's default; [`DumpWriter::time`] turns it off for tools that
//! expect the TIMESTEP first). A triclinic box is written as LAMMPS does:
//! `ITEM: BOX BOUNDS xy xz yz pp pp pp` and rows `xlo_bound xhi_bound xy`,
//! `ylo_bound yhi_bound xz`, `zlo zhi yz`, the bounds enclosing the tilted
//! box. Positions are the run's, which are never wrapped into the box:
//! they are written as the unwrapped columns `xu yu zu` (LAMMPS' `x y z`
//! are wrapped), velocities v = p/m. Numbers are written so that reading
//! them back gives the same f64 bit for bit; the box of a triclinic frame
//! comes back to within the rounding of one addition (its bounds add the
//! tilts).

use super::number::{parse, push_f64};
use super::stream::FrameSink;
use super::{FileError, LammpsData, SimBox};
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};

/// One frame of a dump file, rows in the file's order.
#[derive(Clone, Debug, PartialEq)]
pub struct DumpFrame {
    /// ITEM: TIMESTEP.
    pub step: u64,
    /// ITEM: TIME, when the frame has it.
    pub time: Option<f64>,
    /// ITEM: BOX BOUNDS.
    pub sim_box: SimBox,
    /// The `id` column (1, 2, … when absent).
    pub ids: Vec<u64>,
    /// The `type` column (1 when absent).
    pub types: Vec<u32>,
    /// `xu yu zu`, or `x y z` when those are the columns (then see
    /// `unwrapped`), 3 per atom.
    pub positions: Vec<f64>,
    /// Whether the positions are the unwrapped columns.
    pub unwrapped: bool,
    /// `vx vy vz`, 3 per atom (empty when absent).
    pub velocities: Vec<f64>,
}

/// Writes states as LAMMPS dump frames; see the module documentation for
/// the format, and [`FrameSink`] for writing while a run runs.
///
/// ```
/// use geoshake_runtime::particles::io::{DumpReader, DumpWriter, SimBox};
/// let b = SimBox::orthogonal([0.0; 3], [5.0; 3]);
/// let mut out = DumpWriter::new(Vec::new(), b, vec![1, 2], vec![2.0, 1.0]).with_ids(vec![4, 9]);
/// out.write_frame(3, 6.0, &[0.1, 0.2, 0.3, 1.0, 2.0, 3.0], &[2.0, 0.0, 0.0, 0.0, 0.5, 0.0]).unwrap();
/// let bytes = out.finish().unwrap();
/// let f = DumpReader::new(&bytes[..], "mem").next().unwrap().unwrap();
/// assert_eq!((f.step, f.time, f.ids, f.sim_box), (3, Some(6.0), vec![4, 9], b));
/// assert_eq!(f.velocities, [1.0, 0.0, 0.0, 0.0, 0.5, 0.0]); // v = p/m
/// ```
#[derive(Debug)]
pub struct DumpWriter<W: Write> {
    out: W,
    file: PathBuf,
    sim_box: SimBox,
    ids: Vec<u64>,
    types: Vec<u32>,
    masses: Vec<f64>,
    time: bool,
    frames: u64,
    buf: String,
    error: Option<FileError>,
}

impl DumpWriter<std::io::BufWriter<std::fs::File>> {
    /// A writer that creates (or truncates) the file at `path`, for the
    /// atoms of a data file: its ids, types, masses and box.
    pub fn create(path: impl AsRef<Path>, data: &LammpsData) -> Result<Self, FileError> {
        let path = path.as_ref();
        let f = std::fs::File::create(path).map_err(|e| FileError::io(path, e))?;
        Ok(Self::for_data(std::io::BufWriter::new(f), data).named(path))
    }
}

impl<W: Write> DumpWriter<W> {
    /// A writer to `out` of atoms with these types and masses (ids 1, 2,
    /// …) in `sim_box`.
    pub fn new(out: W, sim_box: SimBox, types: Vec<u32>, masses: Vec<f64>) -> Self {
        DumpWriter {
            out,
            file: PathBuf::from("<stream>"),
            sim_box,
            ids: (1..=types.len() as u64).collect(),
            types,
            masses,
            time: true,
            frames: 0,
            buf: String::new(),
            error: None,
        }
    }

    /// A writer to `out` for the atoms of a data file: its ids, types,
    /// masses and box.
    pub fn for_data(out: W, data: &LammpsData) -> Self {
        Self::new(out, data.sim_box, data.types.clone(), data.masses.clone())
            .with_ids(data.ids.clone())
    }

    /// The atoms' ids (default 1, 2, …).
    pub fn with_ids(mut self, ids: Vec<u64>) -> Self {
        self.ids = ids;
        self
    }

    /// Whether to write `ITEM: TIME` (default yes).
    pub fn time(mut self, yes: bool) -> Self {
        self.time = yes;
        self
    }

    /// The name its errors give (default `<stream>`; the path for
    /// [`create`](DumpWriter::create)).
    pub fn named(mut self, name: impl AsRef<Path>) -> Self {
        self.file = name.as_ref().to_path_buf();
        self
    }

    /// Frames written so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// Writes one frame: positions q and momenta p, 3 per atom (written as
    /// v = p/m), at `step` and `time`. The frame is formatted first, then
    /// written with one `write_all` and flushed: a frame that cannot be
    /// written leaves the frames before it as they were.
    pub fn write_frame(
        &mut self,
        step: u64,
        time: f64,
        q: &[f64],
        p: &[f64],
    ) -> Result<(), FileError> {
        let n = self.types.len();
        for (what, x) in [("positions", q), ("momenta", p)] {
            if x.len() != 3 * n || self.ids.len() != n || self.masses.len() != n {
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
        if self.time {
            b.push_str("ITEM: TIME\n");
            push_f64(b, time);
            b.push('\n');
        }
        b.push_str(&format!(
            "ITEM: TIMESTEP\n{step}\nITEM: NUMBER OF ATOMS\n{n}\n"
        ));
        let s = &self.sim_box;
        if s.is_triclinic() {
            b.push_str("ITEM: BOX BOUNDS xy xz yz pp pp pp\n");
            for (c, [lo, hi]) in s.dump_bounds().into_iter().enumerate() {
                push_f64(b, lo);
                b.push(' ');
                push_f64(b, hi);
                b.push(' ');
                push_f64(b, s.tilt[c]);
                b.push('\n');
            }
        } else {
            b.push_str("ITEM: BOX BOUNDS pp pp pp\n");
            for c in 0..3 {
                push_f64(b, s.lo[c]);
                b.push(' ');
                push_f64(b, s.hi[c]);
                b.push('\n');
            }
        }
        b.push_str("ITEM: ATOMS id type xu yu zu vx vy vz\n");
        for a in 0..n {
            b.push_str(&format!("{} {}", self.ids[a], self.types[a]));
            for &x in &q[3 * a..3 * a + 3] {
                b.push(' ');
                push_f64(b, x);
            }
            for &x in &p[3 * a..3 * a + 3] {
                b.push(' ');
                push_f64(b, x / self.masses[a]);
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

impl<W: Write> FrameSink for DumpWriter<W> {
    fn write_state(&mut self, step: u64, time: f64, q: &[f64], p: &[f64]) -> Result<(), FileError> {
        self.write_frame(step, time, q, p)
    }

    fn deferred_error(&mut self) -> &mut Option<FileError> {
        &mut self.error
    }
}

/// Reads a LAMMPS dump file (text) frame by frame: an iterator of
/// `Result<DumpFrame, FileError>` that ends after the first error. Reads
/// the items TIME (optional), TIMESTEP, NUMBER OF ATOMS, BOX BOUNDS
/// (orthogonal or triclinic) and ATOMS with the columns `id`, `type`,
/// `xu yu zu` or `x y z`, `vx vy vz` (others skipped).
pub struct DumpReader<R: BufRead> {
    input: R,
    file: PathBuf,
    line: usize,
    done: bool,
    /// A line read ahead.
    pending: Option<String>,
}

impl DumpReader<std::io::BufReader<std::fs::File>> {
    /// A reader of the file at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, FileError> {
        let path = path.as_ref();
        let f = std::fs::File::open(path).map_err(|e| FileError::io(path, e))?;
        Ok(Self::new(std::io::BufReader::new(f), path))
    }
}

impl<R: BufRead> DumpReader<R> {
    /// A reader of `input`; `name` is the file its errors name.
    pub fn new(input: R, name: impl AsRef<Path>) -> Self {
        DumpReader {
            input,
            file: name.as_ref().to_path_buf(),
            line: 0,
            done: false,
            pending: None,
        }
    }

    fn next_line(&mut self) -> Result<Option<String>, FileError> {
        if let Some(l) = self.pending.take() {
            return Ok(Some(l));
        }
        let mut buf = String::new();
        let n = self
            .input
            .read_line(&mut buf)
            .map_err(|e| FileError::io(&self.file, e))?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        while buf.ends_with(['\n', '\r']) {
            buf.pop();
        }
        Ok(Some(buf))
    }

    fn expect_line(&mut self, what: &str) -> Result<String, FileError> {
        self.next_line()?.ok_or_else(|| FileError::Malformed {
            file: self.file.clone(),
            line: self.line + 1,
            expected: format!("{what}, the file ended first"),
        })
    }

    fn item(&mut self, name: &str) -> Result<String, FileError> {
        let l = self.expect_line(&format!("ITEM: {name}"))?;
        match l.strip_prefix("ITEM: ") {
            Some(rest) if rest.starts_with(name) => Ok(rest[name.len()..].trim().to_string()),
            _ => Err(FileError::Malformed {
                file: self.file.clone(),
                line: self.line,
                expected: format!("ITEM: {name}, found `{l}`"),
            }),
        }
    }

    fn frame(&mut self) -> Result<Option<DumpFrame>, FileError> {
        let first = loop {
            match self.next_line()? {
                None => return Ok(None),
                Some(l) if l.trim().is_empty() => continue,
                Some(l) => break l,
            }
        };
        self.pending = Some(first.clone());
        let mut time = None;
        if first.trim() == "ITEM: TIME" {
            self.item("TIME")?;
            let l = self.expect_line("the time")?;
            time = Some(parse(&self.file, self.line, Some(l.trim()), "the time")?);
        }
        self.item("TIMESTEP")?;
        let l = self.expect_line("the timestep")?;
        let step = parse(
            &self.file,
            self.line,
            Some(l.trim()),
            "the timestep (an integer)",
        )?;
        self.item("NUMBER OF ATOMS")?;
        let l = self.expect_line("the number of atoms")?;
        let n: usize = parse(&self.file, self.line, Some(l.trim()), "the number of atoms")?;
        let kind = self.item("BOX BOUNDS")?;
        let triclinic = kind.starts_with("xy xz yz");
        let (mut bounds, mut tilt) = ([[0.0; 2]; 3], [0.0; 3]);
        for c in 0..3 {
            let l = self.expect_line("a box bounds row")?;
            let t: Vec<&str> = l.split_whitespace().collect();
            let want = if triclinic { 3 } else { 2 };
            if t.len() != want {
                return Err(FileError::Malformed {
                    file: self.file.clone(),
                    line: self.line,
                    expected: format!("{want} numbers in a box bounds row, found {}", t.len()),
                });
            }
            bounds[c][0] = parse(&self.file, self.line, Some(t[0]), "a lower box bound")?;
            bounds[c][1] = parse(&self.file, self.line, Some(t[1]), "an upper box bound")?;
            if triclinic {
                tilt[c] = parse(&self.file, self.line, Some(t[2]), "a tilt factor")?;
            }
        }
        let cols_text = self.item("ATOMS")?;
        let cols: Vec<&str> = cols_text.split_whitespace().collect();
        let find = |name: &str| cols.iter().position(|&c| c == name);
        let (id, ty) = (find("id"), find("type"));
        let (pos, unwrapped) = match (find("xu"), find("yu"), find("zu")) {
            (Some(x), Some(y), Some(z)) => ([x, y, z], true),
            _ => match (find("x"), find("y"), find("z")) {
                (Some(x), Some(y), Some(z)) => ([x, y, z], false),
                _ => {
                    return Err(FileError::Malformed {
                        file: self.file.clone(),
                        line: self.line,
                        expected: "ATOMS columns with xu yu zu or x y z".into(),
                    })
                }
            },
        };
        let vel = match (find("vx"), find("vy"), find("vz")) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            _ => None,
        };
        let mut frame = DumpFrame {
            step,
            time,
            sim_box: SimBox::from_dump_bounds(bounds, tilt),
            ids: Vec::with_capacity(n),
            types: Vec::with_capacity(n),
            positions: Vec::with_capacity(3 * n),
            unwrapped,
            velocities: Vec::new(),
        };
        for a in 0..n {
            let l = self.expect_line(&format!("{n} atom rows"))?;
            let t: Vec<&str> = l.split_whitespace().collect();
            if t.len() != cols.len() {
                return Err(FileError::Malformed {
                    file: self.file.clone(),
                    line: self.line,
                    expected: format!("{} columns, found {}", cols.len(), t.len()),
                });
            }
            let (file, line) = (&self.file, self.line);
            frame.ids.push(match id {
                Some(i) => parse(file, line, Some(t[i]), "an atom id")?,
                None => a as u64 + 1,
            });
            frame.types.push(match ty {
                Some(i) => parse(file, line, Some(t[i]), "an atom type")?,
                None => 1,
            });
            for i in pos {
                frame
                    .positions
                    .push(parse(file, line, Some(t[i]), "a position")?);
            }
            if let Some(v) = vel {
                for i in v {
                    frame
                        .velocities
                        .push(parse(file, line, Some(t[i]), "a velocity")?);
                }
            }
        }
        Ok(Some(frame))
    }
}

impl<R: BufRead> Iterator for DumpReader<R> {
    type Item = Result<DumpFrame, FileError>;

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
