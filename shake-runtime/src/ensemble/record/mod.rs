//! One member's outcome as flat words: what crosses a process boundary (an MPI
//! gather, a results file) for the distributed ensembles of `ensemble_mpi`
//! and the resumable store of `ensemble_store`.

use crate::diagnostics::DiagnosticRecord;
use crate::integrator::{RunOutcome, RunSummary, Trajectory};

mod error;

use error::{pack_error, unpack_error};

/// The first word of every packed record ("SHAKE", version 4: with the
/// multipliers λ, σ of each diagnostic record, the error variants of both
/// engines (a member's failure, a shape, a topology, a solver refused) and
/// the run's summary; a record of an older version is refused by its tag).
const RECORD_TAG: u64 = 0x5348_414b_4504;
/// Words of one packed [`DiagnosticRecord`].
const DIAGNOSTIC_WORDS: usize = 10;

/// Why a packed record could not be read back (a truncated or corrupted
/// buffer or file; a record written by this crate always reads back).
///
/// ```
/// use geoshake_runtime::ensemble::{unpack_outcome, RecordError};
/// assert!(matches!(unpack_outcome(&[1, 2, 3]), Err(RecordError::BadTag { .. })));
/// ```
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RecordError {
    /// The record does not start with the record tag.
    #[error("not a packed outcome (first word {found:#x})")]
    BadTag {
        /// The word found instead.
        found: u64,
    },
    /// The buffer ends inside the record.
    #[error("packed outcome truncated: {needed} words needed, {available} available")]
    Truncated {
        /// Words the record claims or needs.
        needed: usize,
        /// Words there are.
        available: usize,
    },
    /// A field holds a value no record can hold.
    #[error("packed outcome corrupted: {what} = {value}")]
    Corrupted {
        /// Which field.
        what: &'static str,
        /// Its value.
        value: u64,
    },
}

/// Appends member `member`'s outcome to `words` as one self-delimiting
/// record: u64 words, floats as their IEEE bits (so a record read back is
/// bit for bit the outcome, NaN payloads and signed zeros included).
///
/// Layout: tag, member, record length, d, n stored states, n diagnostics,
/// m constraints; t0, h, stride; the n steps; the n times; the n states (q
/// then p, 2d words each); the diagnostics (10 words each, then the
/// record's m multipliers λ and m multipliers σ); the error (a variant code, 0 for none, and
/// its fields; message strings as a byte count and the bytes). This is the
/// one place that knows how a [`RunOutcome`] is laid out in memory.
///
/// ```
/// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// use geoshake_runtime::ensemble::{pack_outcome, unpack_outcome};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).rattle();
/// let out = integ.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(3)).execute();
/// let mut words = Vec::new();
/// pack_outcome(7, &out, &mut words);
/// let (member, back, used) = unpack_outcome(&words).unwrap();
/// assert_eq!((member, used), (7, words.len()));
/// assert_eq!(back, out);
/// ```
pub fn pack_outcome(member: usize, out: &RunOutcome, words: &mut Vec<u64>) {
    let start = words.len();
    let traj = &out.trajectory;
    let n = traj.len();
    let (d, t0, h, stride) = traj.layout();
    words.extend([
        RECORD_TAG,
        member as u64,
        0, // the record length, filled in below
        d as u64,
        n as u64,
        traj.diagnostics.len() as u64,
        traj.constraints() as u64,
        t0.to_bits(),
        h.to_bits(),
        stride,
    ]);
    words.extend(traj.steps());
    words.extend(traj.times().iter().map(|t| t.to_bits()));
    for i in 0..n {
        words.extend(traj.q(i).iter().chain(traj.p(i)).map(|x| x.to_bits()));
    }
    let m = traj.constraints();
    let multipliers = traj.multiplier_words();
    for (i, r) in traj.diagnostics.iter().enumerate() {
        words.extend([
            r.step,
            r.t.to_bits(),
            r.energy.to_bits(),
            r.constraint.to_bits(),
            r.hidden_constraint.to_bits(),
            r.max_shake_iterations as u64,
            r.max_base_iterations as u64,
            r.rattle_iterations as u64,
            r.max_lambda.to_bits(),
            r.max_condition.to_bits(),
        ]);
        words.extend(
            multipliers[2 * m * i..2 * m * (i + 1)]
                .iter()
                .map(|x| x.to_bits()),
        );
    }
    pack_error(out.error.as_ref(), words);
    let s = &out.summary;
    let measured = |x: Option<f64>| [x.is_some() as u64, x.unwrap_or(0.0).to_bits()];
    words.extend([s.steps, s.max_newton_iterations as u64, s.newton_iterations]);
    words.extend(measured(s.max_residual));
    words.extend(measured(s.max_hidden));
    words[start + 2] = (words.len() - start) as u64;
}

/// Reads one record written by [`pack_outcome`] from the start of `words`:
/// the member index, the outcome, and the number of words used.
///
/// ```
/// use geoshake_runtime::{RunOutcome, Trajectory, StepError};
/// use geoshake_runtime::ensemble::{pack_outcome, unpack_outcome, RecordError};
/// let failed = RunOutcome {
///     trajectory: Trajectory::default(),
///     summary: Default::default(),
///     error: Some(StepError::NonFinite { what: "initial state", step: 0, t: 0.0, entry: 0 }),
/// };
/// let mut words = Vec::new();
/// pack_outcome(3, &failed, &mut words);
/// assert_eq!(unpack_outcome(&words).unwrap().1, failed);
/// // Half a record is an error, not a panic.
/// assert!(matches!(unpack_outcome(&words[..4]), Err(RecordError::Truncated { .. })));
/// ```
pub fn unpack_outcome(words: &[u64]) -> Result<(usize, RunOutcome, usize), RecordError> {
    let mut r = Reader { words, at: 0 };
    let tag = r.word()?;
    if tag != RECORD_TAG {
        return Err(RecordError::BadTag { found: tag });
    }
    let member = r.index("member")?;
    let len = r.index("record length")?;
    if len > words.len() {
        return Err(RecordError::Truncated {
            needed: len,
            available: words.len(),
        });
    }
    // From here on read only inside the record's own length.
    let mut r = Reader {
        words: &words[..len],
        at: r.at,
    };
    let d = r.index("dof")?;
    let n = r.count("stored states")?;
    let n_diag = r.count("diagnostics")?;
    if n_diag != 0 && n_diag != n {
        return Err(RecordError::Corrupted {
            what: "diagnostics",
            value: n_diag as u64,
        });
    }
    let m = r.index("constraints")?;
    // d and m are the system's, kept when no state or multiplier is stored
    // (a member that failed at its start): each is bounded by the words
    // its 2d (2m) numbers take only when the record holds some.
    for (what, size, held) in [("dof", d, n), ("constraints", m, n_diag)] {
        if held > 0 && size.checked_mul(2).is_none_or(|w| w > len) {
            return Err(RecordError::Corrupted {
                what,
                value: size as u64,
            });
        }
    }
    let t0 = f64::from_bits(r.word()?);
    let h = f64::from_bits(r.word()?);
    let stride = r.word()?;
    let steps = r.slice(n)?.to_vec();
    let times = r.slice(n)?.to_vec();
    let mut trajectory = Trajectory::new(d, t0, h, stride, n);
    for i in 0..n {
        // The steps must be those a run stores (0, s, 2s, … and at most one
        // more), or the times rebuilt from them would not be the packed ones.
        let z = r.slice(2 * d)?;
        let q: Vec<f64> = z[..d].iter().map(|&w| f64::from_bits(w)).collect();
        let p: Vec<f64> = z[d..].iter().map(|&w| f64::from_bits(w)).collect();
        let regular = steps[i] == trajectory.len() as u64 * stride.max(1);
        if !regular && i + 1 != n {
            return Err(RecordError::Corrupted {
                what: "stored steps",
                value: steps[i],
            });
        }
        trajectory.push(steps[i], &q, &p);
        if trajectory.time(i).to_bits() != times[i] {
            return Err(RecordError::Corrupted {
                what: "stored times",
                value: times[i],
            });
        }
    }
    let mut diagnostics = Vec::with_capacity(n_diag);
    let mut multipliers = Vec::new();
    for _ in 0..n_diag {
        let w = r.slice(DIAGNOSTIC_WORDS)?;
        let f = |i: usize| f64::from_bits(w[i]);
        diagnostics.push(DiagnosticRecord {
            step: w[0],
            t: f(1),
            energy: f(2),
            constraint: f(3),
            hidden_constraint: f(4),
            max_shake_iterations: w[5] as usize,
            max_base_iterations: w[6] as usize,
            rattle_iterations: w[7] as usize,
            max_lambda: f(8),
            max_condition: f(9),
        });
        let w = r.slice(2 * m)?;
        multipliers.extend(w.iter().map(|&x| f64::from_bits(x)));
    }
    let error = unpack_error(&mut r)?;
    let (steps, max_newton_iterations) = (r.word()?, r.index("iterations")?);
    let newton_iterations = r.word()?;
    let mut measured = || -> Result<Option<f64>, RecordError> {
        match (r.word()?, f64::from_bits(r.word()?)) {
            (0, _) => Ok(None),
            (1, x) => Ok(Some(x)),
            (flag, _) => Err(RecordError::Corrupted {
                what: "summary flag",
                value: flag,
            }),
        }
    };
    let summary = RunSummary {
        steps,
        max_newton_iterations,
        newton_iterations,
        max_residual: measured()?,
        max_hidden: measured()?,
    };
    if r.at != len {
        return Err(RecordError::Corrupted {
            what: "record length",
            value: len as u64,
        });
    }
    trajectory.diagnostics = diagnostics;
    trajectory.set_multipliers(m, multipliers);
    let outcome = RunOutcome {
        trajectory,
        summary,
        error,
    };
    Ok((member, outcome, len))
}

/// A cursor over the words of one record; every read is bounds-checked.
struct Reader<'a> {
    words: &'a [u64],
    at: usize,
}

impl Reader<'_> {
    fn slice(&mut self, n: usize) -> Result<&[u64], RecordError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.words.len())
            .ok_or(RecordError::Truncated {
                needed: self.at.saturating_add(n),
                available: self.words.len(),
            })?;
        let s = &self.words[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn word(&mut self) -> Result<u64, RecordError> {
        Ok(self.slice(1)?[0])
    }
    fn float(&mut self) -> Result<f64, RecordError> {
        Ok(f64::from_bits(self.word()?))
    }
    /// A count: no larger than the words there are (a corrupted count must
    /// not make the reader allocate terabytes before it finds the end).
    fn count(&mut self, what: &'static str) -> Result<usize, RecordError> {
        let w = self.word()?;
        usize::try_from(w)
            .ok()
            .filter(|&c| c <= self.words.len())
            .ok_or(RecordError::Corrupted { what, value: w })
    }
    /// An index or iteration count (any value a usize holds).
    fn index(&mut self, what: &'static str) -> Result<usize, RecordError> {
        let w = self.word()?;
        usize::try_from(w).map_err(|_| RecordError::Corrupted { what, value: w })
    }
}
