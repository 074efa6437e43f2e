//! A [`StepError`] as words and back: every variant, its step, time and
//! numbers, its stage and message, and a branch jump's cause (one level
//! deep: a cause read back never has a cause of its own).

use super::{Reader, RecordError};
use crate::error::{SolveError, Stage, StepError};
use crate::particles::TopologyError;

pub(super) fn pack_error(e: Option<&StepError>, w: &mut Vec<u64>) {
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
        StepError::Storage { step, states, dof } => w.extend([11, step, states, dof as u64]),
        StepError::Shape {
            what,
            got,
            expected,
        } => {
            w.extend([12, got as u64, expected as u64]);
            pack_str(what, w);
        }
        StepError::AtMember {
            stage,
            step,
            t,
            ref family,
            member,
            source,
        } => {
            w.extend([13, stage_code(stage), step, b(t), member as u64]);
            pack_str(family, w);
            pack_solve(Some(source), w);
        }
        StepError::Solver { solver, ref why } => {
            w.push(14);
            pack_str(solver, w);
            pack_str(why, w);
        }
        StepError::Unavailable { what, why } => {
            w.push(16);
            pack_str(what, w);
            pack_str(why, w);
        }
        StepError::Topology(ref e) => {
            w.push(15);
            pack_topology(e, w);
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

pub(super) fn unpack_error(r: &mut Reader) -> Result<Option<StepError>, RecordError> {
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
        12 => {
            let (got, expected) = (r.index("got")?, r.index("expected")?);
            StepError::Shape {
                what: r.string()?,
                got,
                expected,
            }
        }
        13 => {
            let (stage, step, t) = (r.stage()?, r.word()?, r.float()?);
            let member = r.index("member")?;
            let family = r.text()?;
            let source = unpack_solve(r)?.ok_or(RecordError::Corrupted {
                what: "solve error",
                value: 13,
            })?;
            StepError::AtMember {
                stage,
                step,
                t,
                family,
                member,
                source,
            }
        }
        14 => StepError::Solver {
            solver: r.string()?,
            why: r.text()?,
        },
        15 => StepError::Topology(unpack_topology(r)?),
        16 => StepError::Unavailable {
            what: r.string()?,
            why: r.string()?,
        },
        11 => StepError::Storage {
            step: r.word()?,
            states: r.word()?,
            dof: r.index("dof")?,
        },
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
            constraint: r.text()?,
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

/// A topology error as its kind, its numbers and its texts (family first).
fn pack_topology(e: &TopologyError, w: &mut Vec<u64>) {
    let family = match e {
        TopologyError::RowShape {
            family,
            member,
            what,
            got,
            expected,
        } => {
            w.extend([0, *member as u64, *got as u64, *expected as u64]);
            pack_str(what, w);
            family
        }
        TopologyError::RepeatedParticle {
            family,
            member,
            particle,
        } => {
            w.extend([1, *member as u64, *particle as u64]);
            family
        }
        TopologyError::DanglingParticle {
            family,
            member,
            particle,
            particles,
        } => {
            w.extend([2, *member as u64, *particle as u64, *particles as u64]);
            family
        }
        TopologyError::DuplicateMember {
            family,
            first,
            second,
        } => {
            w.extend([3, *first as u64, *second as u64]);
            family
        }
        TopologyError::BadValue {
            family,
            member,
            value,
            why,
        } => {
            w.extend([4, *member as u64, value.to_bits()]);
            pack_str(why, w);
            family
        }
        TopologyError::TooManyConstraints {
            family,
            member,
            constraints,
            coordinates,
        } => {
            w.extend([5, *member as u64, *constraints as u64, *coordinates as u64]);
            family
        }
        TopologyError::Dimension {
            family,
            stencil,
            system,
        } => {
            w.extend([6, *stencil as u64, *system as u64]);
            family
        }
    };
    pack_str(family, w);
}

fn unpack_topology(r: &mut Reader) -> Result<TopologyError, RecordError> {
    let kind = r.word()?;
    let mut e = match kind {
        0 => {
            let (member, got, expected) =
                (r.index("member")?, r.index("got")?, r.index("expected")?);
            TopologyError::RowShape {
                what: r.string()?,
                family: String::new(),
                member,
                got,
                expected,
            }
        }
        1 => TopologyError::RepeatedParticle {
            member: r.index("member")?,
            particle: r.index("particle")?,
            family: String::new(),
        },
        2 => TopologyError::DanglingParticle {
            member: r.index("member")?,
            particle: r.index("particle")?,
            particles: r.index("particles")?,
            family: String::new(),
        },
        3 => TopologyError::DuplicateMember {
            first: r.index("first")?,
            second: r.index("second")?,
            family: String::new(),
        },
        4 => {
            let (member, value) = (r.index("member")?, r.float()?);
            TopologyError::BadValue {
                why: r.string()?,
                family: String::new(),
                member,
                value,
            }
        }
        5 => TopologyError::TooManyConstraints {
            member: r.index("member")?,
            constraints: r.index("constraints")?,
            coordinates: r.index("coordinates")?,
            family: String::new(),
        },
        6 => TopologyError::Dimension {
            stencil: r.index("stencil")?,
            system: r.index("system")?,
            family: String::new(),
        },
        k => {
            return Err(RecordError::Corrupted {
                what: "topology error",
                value: k,
            })
        }
    };
    // The family's name comes last (its length is known only there).
    let name = r.text()?;
    match &mut e {
        TopologyError::RowShape { family, .. }
        | TopologyError::RepeatedParticle { family, .. }
        | TopologyError::DanglingParticle { family, .. }
        | TopologyError::DuplicateMember { family, .. }
        | TopologyError::BadValue { family, .. }
        | TopologyError::TooManyConstraints { family, .. }
        | TopologyError::Dimension { family, .. } => *family = name,
    }
    Ok(e)
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

/// What only errors hold: a stage and a message.
impl Reader<'_> {
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
        self.text().map(intern)
    }
    /// An owned text (a name or a formatted reason: not interned, so that
    /// any number of distinct ones read back whole).
    fn text(&mut self) -> Result<String, RecordError> {
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
        Ok(s)
    }
}
