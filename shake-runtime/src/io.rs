//! A [`Trajectory`] as CSV and back: one row per stored state, named
//! columns, every number in Rust's shortest round-trip form (so a file read
//! back gives the same f64 bit for bit, NaN and ±inf included).
//!
//! Hand-written rather than with the `csv` crate: the format is numbers
//! only (no quoting, no embedded commas), and writing it directly keeps the
//! runtime's dependencies as they are.
//!
//! Layout: a first line `# shake trajectory v1 t0=… h=… stride=…` (what
//! fixes every state's time, as in the trajectory itself; CSV readers skip
//! it with their comment option, e.g. pandas' `comment="#"`), a header, then
//! the rows. Columns: `t`, `step`, `q[0]` … `q[d-1]`, `p[0]` … `p[d-1]`, and
//! with diagnostics `energy`, `constraint`, `hidden_constraint`,
//! `max_shake_iterations`, `max_base_iterations`, `rattle_iterations`,
//! `max_lambda`, `max_condition`, `lambda[0]` … `lambda[m-1]`, `sigma[0]` …
//! `sigma[m-1]` (see [`Trajectory::lambda`], [`Trajectory::sigma`]).
//! The state and multiplier columns carry the names the system declared
//! ([`Trajectory::variable_name`], [`Trajectory::constraint_name`]):
//! `t,step,theta,p_theta,…,lambda[rod],sigma[rod]`; the numbered names
//! above are what a system that declares none gets. The first line also
//! records d (`d=…`); files written before it was, with numbered columns,
//! still read.

use crate::diagnostics::DiagnosticRecord;
use crate::trajectory::{Names, Trajectory};
use std::io::{BufRead, Write};

const MAGIC: &str = "# shake trajectory v1";
pub(crate) const DIAG_COLUMNS: [&str; 8] = [
    "energy",
    "constraint",
    "hidden_constraint",
    "max_shake_iterations",
    "max_base_iterations",
    "rattle_iterations",
    "max_lambda",
    "max_condition",
];

/// Why a CSV file could not be read as a trajectory. Lines count from 1.
///
/// ```
/// use geoshake_runtime::{Trajectory, io::CsvError};
/// let bad = "# shake trajectory v1 t0=0 h=0.1 stride=1 m=0\nt,step,q[0],p[0]\n0,0,1.0,zero\n";
/// assert!(matches!(Trajectory::read_csv(bad.as_bytes()), Err(CsvError::BadNumber { line: 3, .. })));
/// ```
#[derive(Debug, thiserror::Error)]
pub enum CsvError {
    /// Reading failed.
    #[error("reading the CSV failed: {0}")]
    Io(#[from] std::io::Error),
    /// The first line is not `# shake trajectory v1 t0=… h=… stride=…`.
    #[error("line 1: not a shake trajectory ({found:?})")]
    BadMetadata {
        /// The line found.
        found: String,
    },
    /// The header does not name the columns a trajectory has.
    #[error("line 2: bad header ({found:?}): {why}")]
    BadHeader {
        /// The header found.
        found: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// A row has another number of fields than the header.
    #[error("line {line}: {found} fields, the header has {expected}")]
    WrongColumnCount {
        /// The line.
        line: usize,
        /// Fields in the header.
        expected: usize,
        /// Fields in the row.
        found: usize,
    },
    /// A field is not a number (or not an integer where one is needed).
    #[error("line {line}, column {column}: {text:?} is not a number of that kind")]
    BadNumber {
        /// The line.
        line: usize,
        /// The column's name.
        column: String,
        /// The field.
        text: String,
    },
    /// The steps or times are not those a run stores (0, s, 2s, … and at
    /// most one more, at t0 + k h).
    #[error("line {line}: {what}")]
    Inconsistent {
        /// The line.
        line: usize,
        /// What does not fit.
        what: &'static str,
    },
}

impl Trajectory {
    /// Writes the trajectory as CSV (layout in [`io`](crate::io)).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, Trajectory, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(3)).execute().trajectory;
    /// let mut csv = Vec::new();
    /// traj.write_csv(&mut csv).unwrap();
    /// let text = String::from_utf8(csv).unwrap();
    /// assert!(text.lines().nth(1).unwrap().starts_with("t,step,q[0],q[1],p[0],p[1],energy"));
    /// assert_eq!(Trajectory::read_csv(text.as_bytes()).unwrap(), traj);
    /// ```
    pub fn write_csv<W: Write>(&self, mut w: W) -> std::io::Result<()> {
        let (d, t0, h, stride) = self.layout();
        let m = self.constraints();
        // (diagnostics of a run that did not store its states have no
        // rows to go with; they are left out)
        let diag = !self.diagnostics.is_empty() && self.diagnostics.len() == self.len();
        let names = column_names(self, diag)
            .map_err(|why| std::io::Error::new(std::io::ErrorKind::InvalidInput, why))?;
        writeln!(w, "{MAGIC} t0={t0} h={h} stride={stride} m={m} d={d}")?;
        write!(w, "{}", names.join(","))?;
        writeln!(w)?;
        for i in 0..self.len() {
            write!(w, "{},{}", self.time(i), self.step(i))?;
            for x in self.q(i).iter().chain(self.p(i)) {
                write!(w, ",{x}")?;
            }
            if let Some(r) = self.diagnostics.get(i).filter(|_| diag) {
                write!(
                    w,
                    ",{},{},{},{},{},{},{},{}",
                    r.energy,
                    r.constraint,
                    r.hidden_constraint,
                    r.max_shake_iterations,
                    r.max_base_iterations,
                    r.rattle_iterations,
                    r.max_lambda,
                    r.max_condition
                )?;
                for x in self.lambda(i).iter().chain(self.sigma(i)) {
                    write!(w, ",{x}")?;
                }
            }
            writeln!(w)?;
        }
        Ok(())
    }

    /// Reads a trajectory written by [`write_csv`](Self::write_csv); the
    /// same numbers bit for bit. Every malformed input is a [`CsvError`]
    /// carrying the line, never a panic.
    ///
    /// ```
    /// use geoshake_runtime::{Trajectory, io::CsvError};
    /// let text = "# shake trajectory v1 t0=0 h=0.5 stride=1 m=0\nt,step,q[0],p[0]\n0,0,1,0\n0.5,1,0.9,-0.4\n";
    /// let traj = Trajectory::read_csv(text.as_bytes()).unwrap();
    /// assert_eq!((traj.len(), traj.time(1), traj.p(1)[0]), (2, 0.5, -0.4));
    /// let short = "# shake trajectory v1 t0=0 h=0.5 stride=1 m=0\nt,step,q[0],p[0]\n0,0,1\n";
    /// assert!(matches!(Trajectory::read_csv(short.as_bytes()), Err(CsvError::WrongColumnCount { line: 3, .. })));
    /// ```
    pub fn read_csv<R: BufRead>(r: R) -> Result<Trajectory, CsvError> {
        let mut lines = r.lines();
        let first = lines.next().transpose()?.unwrap_or_default();
        let meta = parse_metadata(&first).ok_or(CsvError::BadMetadata {
            found: first.clone(),
        })?;
        let (t0, h, stride, m, d) = meta;
        let header = lines.next().transpose()?.unwrap_or_default();
        let names: Vec<&str> = header.split(',').collect();
        let bad = |why| CsvError::BadHeader {
            found: header.clone(),
            why,
        };
        if names.len() < 2 || names[0] != "t" || names[1] != "step" {
            return Err(bad("it must start with t,step"));
        }
        let (d, diag, declared) = parse_columns(&names, d, m).map_err(bad)?;
        let mut traj = Trajectory::new(d, t0, h, stride, 0);
        traj.set_names(declared);
        let mut multipliers = Vec::new();
        let mut z = vec![0.0; 2 * d];
        for (k, line) in lines.enumerate() {
            let line_no = k + 3;
            let line = line?;
            if line.is_empty() {
                continue;
            }
            let fields: Vec<&str> = line.split(',').collect();
            if fields.len() != names.len() {
                return Err(CsvError::WrongColumnCount {
                    line: line_no,
                    expected: names.len(),
                    found: fields.len(),
                });
            }
            let num = |c: usize| -> Result<f64, CsvError> {
                fields[c].parse::<f64>().map_err(|_| CsvError::BadNumber {
                    line: line_no,
                    column: names[c].to_string(),
                    text: fields[c].to_string(),
                })
            };
            let int = |c: usize| -> Result<u64, CsvError> {
                fields[c].parse::<u64>().map_err(|_| CsvError::BadNumber {
                    line: line_no,
                    column: names[c].to_string(),
                    text: fields[c].to_string(),
                })
            };
            let t = num(0)?;
            let step = int(1)?;
            for (c, x) in z.iter_mut().enumerate() {
                *x = num(2 + c)?;
            }
            push_checked(&mut traj, step, t, &z).map_err(|what| CsvError::Inconsistent {
                line: line_no,
                what,
            })?;
            if diag {
                let b = 2 + 2 * d;
                let f = |i| num(b + i);
                let u = |i| int(b + i).map(|x| x as usize);
                traj.diagnostics.push(DiagnosticRecord {
                    step,
                    t,
                    energy: f(0)?,
                    constraint: f(1)?,
                    hidden_constraint: f(2)?,
                    max_shake_iterations: u(3)?,
                    max_base_iterations: u(4)?,
                    rattle_iterations: u(5)?,
                    max_lambda: f(6)?,
                    max_condition: f(7)?,
                });
                for c in b + 8..names.len() {
                    multipliers.push(num(c)?);
                }
            }
        }
        traj.set_multipliers(m, multipliers);
        Ok(traj)
    }
}

/// The fixed columns, which a declared name must not shadow.
fn is_fixed(name: &str) -> bool {
    name == "t" || name == "step" || DIAG_COLUMNS.contains(&name)
}

/// The columns of `traj` in file order (shared by the CSV and the Arrow
/// layout): `t`, `step`, the 2d declared names of z = (q, p), and with
/// diagnostics the diagnostic columns, `lambda[c]` and `sigma[c]` for each
/// constraint c by its declared name. A declared name that is one of the
/// fixed columns (a coordinate called `t`, as in a system made autonomous
/// with time as a coordinate) is written with its half as a prefix, `q:t`.
/// A name that would break the format (empty, with a comma, a quote or a
/// line break) or that two entries share is an error.
pub(crate) fn column_names(traj: &Trajectory, diag: bool) -> Result<Vec<String>, String> {
    let (d, ..) = traj.layout();
    let m = traj.constraints();
    let mut names: Vec<String> = vec!["t".into(), "step".into()];
    for k in 0..2 * d {
        let name = traj.variable_name(k);
        if name.is_empty() || name.contains([',', '"', '\n', '\r']) {
            return Err(format!(
                "the name {name:?} of z[{k}] is empty or holds a comma, quote or line break"
            ));
        }
        names.push(if is_fixed(&name) {
            format!("{}:{name}", if k < d { "q" } else { "p" })
        } else {
            name.into_owned()
        });
    }
    if let Some(k) = (3..names.len()).find(|&k| names[2..k].contains(&names[k])) {
        return Err(format!("two entries of z are named {}", names[k]));
    }
    if diag {
        names.extend(DIAG_COLUMNS.iter().map(|c| c.to_string()));
        for half in ["lambda", "sigma"] {
            for j in 0..m {
                let c = traj.constraint_name(j);
                if c.contains([',', '"', '\n', '\r']) {
                    return Err(format!(
                        "the constraint name {c:?} holds a comma, quote or line break"
                    ));
                }
                names.push(format!("{half}[{c}]"));
            }
        }
    }
    Ok(names)
}

/// (d, whether there are diagnostics, the declared names) from a file's
/// columns, checked against the layout of [`column_names`]. `d` is the
/// metadata's; files written before it was recorded number their
/// coordinates `q[i]`, which gives d.
pub(crate) fn parse_columns(
    names: &[&str],
    d: Option<usize>,
    m: usize,
) -> Result<(usize, bool, Names), &'static str> {
    let layout = "the columns are not t, step, the 2d entries of z, and the diagnostics";
    let d = d.unwrap_or_else(|| names.iter().filter(|n| n.starts_with("q[")).count());
    let state_end = 2usize
        .checked_add(d.checked_mul(2).ok_or(layout)?)
        .ok_or(layout)?;
    if names.len() < state_end || names[..2] != ["t", "step"] {
        return Err(layout);
    }
    let strip = |name: &str| {
        name.strip_prefix("q:")
            .or_else(|| name.strip_prefix("p:"))
            .filter(|n| is_fixed(n))
            .unwrap_or(name)
            .to_owned()
    };
    let variables: Vec<String> = names[2..state_end].iter().map(|n| strip(n)).collect();
    if variables.iter().any(String::is_empty) {
        return Err(layout);
    }
    let diag = names.len() > state_end;
    let mut constraints = Vec::new();
    if diag {
        let rest = &names[state_end..];
        if rest.len() != DIAG_COLUMNS.len() + 2 * m || rest[..DIAG_COLUMNS.len()] != DIAG_COLUMNS {
            return Err(layout);
        }
        let mult = &rest[DIAG_COLUMNS.len()..];
        for j in 0..m {
            let lambda = mult[j]
                .strip_prefix("lambda[")
                .and_then(|c| c.strip_suffix(']'));
            let sigma = mult[m + j]
                .strip_prefix("sigma[")
                .and_then(|c| c.strip_suffix(']'));
            match (lambda, sigma) {
                (Some(a), Some(b)) if a == b => constraints.push(a.to_owned()),
                _ => {
                    return Err(
                        "the multipliers are not lambda[c] then sigma[c] for each constraint c",
                    )
                }
            }
        }
    }
    Ok((
        d,
        diag,
        Names {
            variables,
            constraints,
        },
    ))
}

/// Appends the state z = (q, p) read at `step`, time `t`, after checking
/// that a run could have stored it there: the steps a run stores are
/// 0, s, 2s, … and at most one more before the next multiple of s (which
/// [`Trajectory::push`] relies on), and t must be t0 + step·h to the bit.
pub(crate) fn push_checked(
    traj: &mut Trajectory,
    step: u64,
    t: f64,
    z: &[f64],
) -> Result<(), &'static str> {
    let (d, _, _, stride) = traj.layout();
    let n = traj.len() as u64;
    let after_extra = n > 0 && traj.step(n as usize - 1) != (n - 1) * stride;
    let regular = step == n * stride;
    let extra = n > 0 && step > (n - 1) * stride && step < n * stride;
    if after_extra || !(regular || extra) {
        return Err("steps must be 0, s, 2s, … and at most one more");
    }
    traj.push(step, &z[..d], &z[d..]);
    if traj.time(n as usize).to_bits() != t.to_bits() {
        return Err("t is not t0 + step·h");
    }
    Ok(())
}

/// (t0, h, stride, m, d) from the first line (d is absent in files
/// written before the coordinates had names).
fn parse_metadata(line: &str) -> Option<(f64, f64, u64, usize, Option<usize>)> {
    let rest = line.strip_prefix(MAGIC)?;
    let mut it = rest.split_whitespace();
    let mut field = |key: &str| it.next()?.strip_prefix(key).map(str::to_owned);
    let t0 = field("t0=")?.parse().ok()?;
    let h = field("h=")?.parse().ok()?;
    let stride: u64 = field("stride=")?.parse().ok()?;
    let m = field("m=")?.parse().ok()?;
    let d = match field("d=") {
        Some(d) => Some(d.parse().ok()?),
        None => None,
    };
    (stride >= 1).then_some((t0, h, stride, m, d))
}
