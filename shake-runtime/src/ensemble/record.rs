//! One member's outcome as flat words: what crosses a process boundary (an MPI
//! gather, a results file) for the distributed ensembles of `ensemble_mpi`
//! and the resumable store of `ensemble_store`.

use crate::diagnostics::DiagnosticRecord;
use crate::error::{SolveError, Stage, StepError};
use crate::integrator::{RunOutcome, Trajectory};

/// The first word of every packed record ("SHAKE", version 3: with the
/// multipliers λ, σ of each diagnostic record, and the error variants of
/// version 3: entry of a non-finite value, singular SHAKE Jacobian, singular
/// N, the constraint and cause of a state off M).
const RECORD_TAG: u64 = 0x5348_414b_4503;
/// Words of one packed [`DiagnosticRecord`].
const DIAGNOSTIC_WORDS: usize = 10;

/// Why a packed record could not be read back (a truncated or corrupted
/// buffer or file; a record written by this crate always reads back).
///
/// ```
/// use shake_runtime::ensemble::{unpack_outcome, RecordError};
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
/// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// use shake_runtime::ensemble::{pack_outcome, unpack_outcome};
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
    words[start + 2] = (words.len() - start) as u64;
}

/// Reads one record written by [`pack_outcome`] from the start of `words`:
/// the member index, the outcome, and the number of words used.
///
/// ```
/// use shake_runtime::{RunOutcome, Trajectory, StepError};
/// use shake_runtime::ensemble::{pack_outcome, unpack_outcome, RecordError};
/// let failed = RunOutcome {
///     trajectory: Trajectory::default(),
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
    let d = r.count("dof")?;
    let n = r.count("stored states")?;
    let n_diag = r.count("diagnostics")?;
    if n_diag != 0 && n_diag != n {
        return Err(RecordError::Corrupted {
            what: "diagnostics",
            value: n_diag as u64,
        });
    }
    let m = r.count("constraints")?;
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
    if r.at != len {
        return Err(RecordError::Corrupted {
            what: "record length",
            value: len as u64,
        });
    }
    trajectory.diagnostics = diagnostics;
    trajectory.set_multipliers(m, multipliers);
    Ok((member, RunOutcome { trajectory, error }, len))
}

fn pack_error(e: Option<&StepError>, w: &mut Vec<u64>) {
    let b = f64::to_bits;
    let Some(e) = e else {
        w.push(0);
        return;
    };
    match *e {
        StepError::InvalidInput { what, value } => {
            w.extend([1, b(value)]);
            pack_str(what, w);
        }
        StepError::NonFinite {
            what,
            step,
            t,
            entry,
        } => {
            w.extend([2, step, b(t), entry as u64]);
            pack_str(what, w);
        }
        StepError::NewtonNotConverged {
            stage,
            step,
            t,
            source,
        } => {
            w.extend([3, stage_code(stage), step, b(t)]);
            pack_solve(Some(source), w);
        }
        StepError::SingularShakeJacobian {
            step,
            t,
            iterations,
        } => w.extend([8, step, b(t), iterations as u64]),
        StepError::SingularNondegeneracyMatrix { stage, step, t } => {
            w.extend([9, stage_code(stage), step, b(t)])
        }
        StepError::NondegeneracyLost {
            stage,
            step,
            t,
            condition,
            limit,
        } => w.extend([4, stage_code(stage), step, b(t), b(condition), b(limit)]),
        StepError::ComponentJump {
            step,
            t,
            det_before,
            det_after,
        } => w.extend([5, step, b(t), b(det_before), b(det_after)]),
        StepError::FibreJump {
            stage,
            step,
            t,
            lambda,
            predicted,
        } => w.extend([6, stage_code(stage), step, b(t), b(lambda), b(predicted)]),
        StepError::NotOnConstraint {
            step,
            t,
            residual,
            tolerance,
            ref constraint,
            cause,
        } => {
            w.extend([7, step, b(t), b(residual), b(tolerance)]);
            pack_str(constraint, w);
            pack_solve(cause, w);
        }
        StepError::BranchJump {
            step,
            t,
            miss,
            tolerance,
            ref cause,
        } => {
            // The step back's own error, if any, follows (it is never a
            // branch jump itself: the step back is not checked by stepping
            // back).
            let (has, miss) = miss.map_or((0, 0.0), |m| (1, m));
            w.extend([10, step, b(t), has, b(miss), b(tolerance)]);
            pack_error(cause.as_deref(), w);
        }
    }
}

/// A solver error as (kind, iterations, residual); kind 3 is none.
fn pack_solve(e: Option<SolveError>, w: &mut Vec<u64>) {
    let (kind, iterations, residual) = match e {
        Some(SolveError::NotConverged {
            iterations,
            residual,
        }) => (0, iterations, residual),
        Some(SolveError::Singular { iterations }) => (1, iterations, 0.0),
        Some(SolveError::NonFinite { iterations }) => (2, iterations, 0.0),
        None => (3, 0, 0.0),
    };
    w.extend([kind, iterations as u64, residual.to_bits()]);
}

fn unpack_solve(r: &mut Reader) -> Result<Option<SolveError>, RecordError> {
    let (kind, iterations, residual) = (r.word()?, r.index("iterations")?, r.float()?);
    Ok(Some(match kind {
        0 => SolveError::NotConverged {
            iterations,
            residual,
        },
        1 => SolveError::Singular { iterations },
        2 => SolveError::NonFinite { iterations },
        3 => return Ok(None),
        k => {
            return Err(RecordError::Corrupted {
                what: "solve error",
                value: k,
            })
        }
    }))
}

fn unpack_error(r: &mut Reader) -> Result<Option<StepError>, RecordError> {
    unpack_error_in(r, false)
}

/// `in_cause`: this error is a branch jump's cause, which is never a
/// branch jump itself (the step back is not stepped back); refusing one
/// there keeps a corrupt record from recursing without end.
fn unpack_error_in(r: &mut Reader, in_cause: bool) -> Result<Option<StepError>, RecordError> {
    let e = match r.word()? {
        0 => return Ok(None),
        10 if in_cause => {
            return Err(RecordError::Corrupted {
                what: "branch jump's cause",
                value: 10,
            })
        }
        1 => {
            let value = r.float()?;
            StepError::InvalidInput {
                what: r.string()?,
                value,
            }
        }
        2 => {
            let (step, t, entry) = (r.word()?, r.float()?, r.index("entry")?);
            StepError::NonFinite {
                what: r.string()?,
                step,
                t,
                entry,
            }
        }
        3 => {
            let (stage, step, t) = (r.stage()?, r.word()?, r.float()?);
            let source = unpack_solve(r)?.ok_or(RecordError::Corrupted {
                what: "solve error",
                value: 3,
            })?;
            StepError::NewtonNotConverged {
                stage,
                step,
                t,
                source,
            }
        }
        8 => StepError::SingularShakeJacobian {
            step: r.word()?,
            t: r.float()?,
            iterations: r.index("iterations")?,
        },
        9 => StepError::SingularNondegeneracyMatrix {
            stage: r.stage()?,
            step: r.word()?,
            t: r.float()?,
        },
        4 => StepError::NondegeneracyLost {
            stage: r.stage()?,
            step: r.word()?,
            t: r.float()?,
            condition: r.float()?,
            limit: r.float()?,
        },
        5 => StepError::ComponentJump {
            step: r.word()?,
            t: r.float()?,
            det_before: r.float()?,
            det_after: r.float()?,
        },
        6 => StepError::FibreJump {
            stage: r.stage()?,
            step: r.word()?,
            t: r.float()?,
            lambda: r.float()?,
            predicted: r.float()?,
        },
        7 => StepError::NotOnConstraint {
            step: r.word()?,
            t: r.float()?,
            residual: r.float()?,
            tolerance: r.float()?,
            constraint: r.string()?.to_string(),
            cause: unpack_solve(r)?,
        },
        10 => {
            let (step, t, has, miss, tolerance) =
                (r.word()?, r.float()?, r.word()?, r.float()?, r.float()?);
            if has > 1 {
                return Err(RecordError::Corrupted {
                    what: "branch jump's miss flag",
                    value: has,
                });
            }
            let cause = unpack_error_in(r, true)?;
            StepError::BranchJump {
                step,
                t,
                miss: (has == 1).then_some(miss),
                tolerance,
                cause: cause.map(Box::new),
            }
        }
        k => {
            return Err(RecordError::Corrupted {
                what: "error variant",
                value: k,
            })
        }
    };
    Ok(Some(e))
}

const STAGES: [Stage; 5] = [
    Stage::BaseMap,
    Stage::Shake,
    Stage::Rattle,
    Stage::Fibre,
    Stage::ProjectionOntoM,
];

fn stage_code(s: Stage) -> u64 {
    STAGES.iter().position(|&x| x == s).unwrap_or(0) as u64
}

fn pack_str(s: &str, w: &mut Vec<u64>) {
    w.push(s.len() as u64);
    w.extend(s.as_bytes().chunks(8).map(|c| {
        let mut b = [0u8; 8];
        b[..c.len()].copy_from_slice(c);
        u64::from_le_bytes(b)
    }));
}

/// The error messages of [`StepError`] are `&'static str`; one read back
/// from a record is interned: leaked once per distinct text, so a job that
/// reads a million failures of a few kinds keeps a few strings. A corrupted
/// file cannot make this grow without bound: past 256 distinct texts the
/// message is replaced by a fixed one.
fn intern(s: String) -> &'static str {
    use std::collections::HashSet;
    use std::sync::{Mutex, OnceLock};
    static SEEN: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut seen = SEEN
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(&known) = seen.get(s.as_str()) {
        return known;
    }
    if seen.len() >= 256 {
        return "(message not kept: too many distinct messages read back)";
    }
    let leaked: &'static str = Box::leak(s.into_boxed_str());
    seen.insert(leaked);
    leaked
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
    fn stage(&mut self) -> Result<Stage, RecordError> {
        let w = self.word()?;
        STAGES
            .get(w as usize)
            .copied()
            .ok_or(RecordError::Corrupted {
                what: "stage",
                value: w,
            })
    }
    fn string(&mut self) -> Result<&'static str, RecordError> {
        let len = self.index("message length")?;
        let bytes: Vec<u8> = self
            .slice(len.div_ceil(8))?
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .take(len)
            .collect();
        let s = String::from_utf8(bytes).map_err(|_| RecordError::Corrupted {
            what: "message",
            value: len as u64,
        })?;
        Ok(intern(s))
    }
}
