//! A [`Trajectory`] as an Arrow IPC file (Feather v2) and back, with the
//! `arrow` feature: the columnar format pandas (`pd.read_feather`), pyarrow
//! (`pyarrow.feather.read_table`) and polars (`pl.read_ipc`) read without
//! parsing text, and that keeps every f64 as its 8 bytes (so a file read
//! back gives the same numbers bit for bit, NaN and ±inf included).
//!
//! The columns are those of the CSV layout (see [`io`](crate::io)), with
//! their types: `t` f64, `step` u64, `q[i]`, `p[i]` f64, and with
//! diagnostics `energy`, `constraint`, `hidden_constraint` f64,
//! `max_shake_iterations`, `max_base_iterations`, `rattle_iterations` u64,
//! `max_lambda`, `max_condition` f64, `lambda[j]`, `sigma[j]` f64 (the
//! multipliers of [`Trajectory::lambda`], [`Trajectory::sigma`]). None is
//! nullable: the last state's λ, which no step computes, is NaN as in
//! memory. What fixes every state's time is in the schema's metadata:
//! `shake.format` = `trajectory v1`, `shake.t0`, `shake.h`, `shake.stride`,
//! `shake.m` (numbers in Rust's shortest round-trip form).

use crate::diagnostics::DiagnosticRecord;
use crate::io::{column_names, parse_columns, push_checked};
use crate::trajectory::Trajectory;
use arrow_array::{Array, ArrayRef, Float64Array, RecordBatch, UInt64Array};
use arrow_schema::{ArrowError, DataType, Field, Schema};
use std::collections::HashMap;
use std::io::{Read, Seek, Write};
use std::sync::Arc;

const FORMAT_KEY: &str = "shake.format";
const FORMAT: &str = "trajectory v1";

/// Why a trajectory could not be written to or read from Arrow IPC. Rows
/// count from 0 over the whole file (across record batches).
///
/// ```
/// use geoshake_runtime::{Trajectory, io_arrow::ArrowIoError};
/// let not_arrow = std::io::Cursor::new(b"t,step\n0,0\n".to_vec());
/// assert!(matches!(Trajectory::read_arrow(not_arrow), Err(ArrowIoError::Arrow(_))));
/// ```
#[derive(Debug, thiserror::Error)]
pub enum ArrowIoError {
    /// The Arrow library refused: not an IPC file, a truncated one, or
    /// writing failed.
    #[error("Arrow IPC: {0}")]
    Arrow(#[from] ArrowError),
    /// A `shake.*` key of the schema metadata is missing or not a number.
    #[error("schema metadata: {key} is missing or malformed ({found:?})")]
    BadMetadata {
        /// The key.
        key: &'static str,
        /// The value found, if any.
        found: Option<String>,
    },
    /// The columns are not those a trajectory has, or not of its types.
    #[error("bad schema ({found}): {why}")]
    BadSchema {
        /// The column names found, comma-separated.
        found: String,
        /// What is wrong.
        why: String,
    },
    /// A declared name cannot be written as a column (writing only).
    #[error("a declared name cannot name a column: {0}")]
    BadName(String),
    /// A value is null (the layout has no nullable column).
    #[error("row {row}, column {column}: null")]
    Null {
        /// The row.
        row: usize,
        /// The column's name.
        column: String,
    },
    /// The steps or times are not those a run stores.
    #[error("row {row}: {what}")]
    Inconsistent {
        /// The row.
        row: usize,
        /// What does not fit.
        what: &'static str,
    },
}

/// The value under `key` in the schema metadata.
fn meta_value<T: std::str::FromStr>(
    meta: &HashMap<String, String>,
    key: &'static str,
) -> Result<T, ArrowIoError> {
    let found = meta.get(key);
    found
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| ArrowIoError::BadMetadata {
            key,
            found: found.cloned(),
        })
}

/// Whether a column holds u64 (the step and the iteration counts) or f64.
fn is_count(name: &str) -> bool {
    matches!(
        name,
        "step" | "max_shake_iterations" | "max_base_iterations" | "rattle_iterations"
    )
}

impl Trajectory {
    /// Writes the trajectory as an Arrow IPC file, one record batch
    /// (layout in [`io_arrow`](crate::io_arrow)).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, Trajectory, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(3)).execute().trajectory;
    /// let mut file = Vec::new();
    /// traj.write_arrow(&mut file).unwrap();
    /// assert_eq!(&file[..6], b"ARROW1");
    /// let back = Trajectory::read_arrow(std::io::Cursor::new(file)).unwrap();
    /// assert_eq!(back, traj);
    /// ```
    pub fn write_arrow<W: Write>(&self, w: W) -> Result<(), ArrowIoError> {
        let (d, t0, h, stride) = self.layout();
        let m = self.constraints();
        let n = self.len();
        // (diagnostics of a run that did not store its states have no
        // rows to go with; they are left out, as in the CSV)
        let diag = !self.diagnostics.is_empty() && self.diagnostics.len() == n;
        let names = column_names(self, diag).map_err(ArrowIoError::BadName)?;
        let f64s = |f: &dyn Fn(usize) -> f64| -> ArrayRef {
            Arc::new(Float64Array::from_iter_values((0..n).map(f)))
        };
        let u64s = |f: &dyn Fn(usize) -> u64| -> ArrayRef {
            Arc::new(UInt64Array::from_iter_values((0..n).map(f)))
        };
        let mut columns: Vec<ArrayRef> = vec![f64s(&|i| self.time(i)), u64s(&|i| self.step(i))];
        for k in 0..d {
            columns.push(f64s(&|i| self.q(i)[k]));
        }
        for k in 0..d {
            columns.push(f64s(&|i| self.p(i)[k]));
        }
        if diag {
            let r = &self.diagnostics;
            columns.push(f64s(&|i| r[i].energy));
            columns.push(f64s(&|i| r[i].constraint));
            columns.push(f64s(&|i| r[i].hidden_constraint));
            columns.push(u64s(&|i| r[i].max_shake_iterations as u64));
            columns.push(u64s(&|i| r[i].max_base_iterations as u64));
            columns.push(u64s(&|i| r[i].rattle_iterations as u64));
            columns.push(f64s(&|i| r[i].max_lambda));
            columns.push(f64s(&|i| r[i].max_condition));
            for j in 0..m {
                columns.push(f64s(&|i| self.lambda(i)[j]));
            }
            for j in 0..m {
                columns.push(f64s(&|i| self.sigma(i)[j]));
            }
        }
        let fields: Vec<Field> = names
            .iter()
            .map(|c| {
                let ty = if is_count(c) {
                    DataType::UInt64
                } else {
                    DataType::Float64
                };
                Field::new(c, ty, false)
            })
            .collect();
        let metadata = HashMap::from([
            (FORMAT_KEY.to_string(), FORMAT.to_string()),
            ("shake.t0".to_string(), t0.to_string()),
            ("shake.h".to_string(), h.to_string()),
            ("shake.stride".to_string(), stride.to_string()),
            ("shake.m".to_string(), m.to_string()),
            ("shake.d".to_string(), d.to_string()),
        ]);
        let schema = Arc::new(Schema::new_with_metadata(fields, metadata));
        let batch = RecordBatch::try_new(schema.clone(), columns)?;
        let mut writer = arrow_ipc::writer::FileWriter::try_new(w, &schema)?;
        writer.write(&batch)?;
        writer.finish()?;
        Ok(())
    }

    /// Reads a trajectory written by [`write_arrow`](Self::write_arrow)
    /// (or by pyarrow/polars from such a file, in any number of record
    /// batches, as long as the columns, types and `shake.*` metadata are
    /// kept); the same numbers bit for bit. Malformed input is an
    /// [`ArrowIoError`], never a panic.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, Stop, Trajectory, examples::Pendulum};
    /// let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = i.run(Pendulum::default().state(0.5, 0.0), Stop::Steps(5)).stride(2).execute().trajectory;
    /// let mut file = Vec::new();
    /// traj.write_arrow(&mut file).unwrap();
    /// let back = Trajectory::read_arrow(std::io::Cursor::new(file)).unwrap();
    /// assert_eq!((back.steps(), back.q(3)), (vec![0, 2, 4, 5], traj.q(3)));
    /// ```
    pub fn read_arrow<R: Read + Seek>(r: R) -> Result<Trajectory, ArrowIoError> {
        let reader = arrow_ipc::reader::FileReader::try_new(r, None)?;
        let schema = reader.schema();
        let meta = schema.metadata();
        if meta.get(FORMAT_KEY).map(String::as_str) != Some(FORMAT) {
            return Err(ArrowIoError::BadMetadata {
                key: FORMAT_KEY,
                found: meta.get(FORMAT_KEY).cloned(),
            });
        }
        let t0: f64 = meta_value(meta, "shake.t0")?;
        let h: f64 = meta_value(meta, "shake.h")?;
        let stride: u64 = meta_value(meta, "shake.stride")?;
        let m: usize = meta_value(meta, "shake.m")?;
        if stride == 0 {
            return Err(ArrowIoError::BadMetadata {
                key: "shake.stride",
                found: Some("0".into()),
            });
        }

        let names: Vec<&str> = schema.fields().iter().map(|f| f.name().as_str()).collect();
        let bad = |why: String| ArrowIoError::BadSchema {
            found: names.join(","),
            why,
        };
        // (files written before `shake.d` number their coordinates q[i])
        let d = match meta.get("shake.d") {
            Some(_) => Some(meta_value(meta, "shake.d")?),
            None => None,
        };
        let (d, diag, declared) =
            parse_columns(&names, d, m).map_err(|why| bad(why.to_string()))?;
        for f in schema.fields() {
            let want = if is_count(f.name()) {
                DataType::UInt64
            } else {
                DataType::Float64
            };
            if f.data_type() != &want {
                return Err(bad(format!(
                    "column {} is {}, not {want}",
                    f.name(),
                    f.data_type()
                )));
            }
        }

        let mut traj = Trajectory::new(d, t0, h, stride, 0);
        traj.set_names(declared);
        let mut multipliers = Vec::new();
        let mut z = vec![0.0; 2 * d];
        let mut row0 = 0;
        for batch in reader {
            let batch = batch?;
            // The types were checked against the file's schema; a batch
            // that disagrees is refused, not unwrapped.
            let mut f64_cols = Vec::with_capacity(names.len());
            let mut u64_cols = Vec::with_capacity(names.len());
            for (c, col) in batch.columns().iter().enumerate() {
                if let Some(k) = (0..col.len()).find(|&k| col.is_null(k)) {
                    return Err(ArrowIoError::Null {
                        row: row0 + k,
                        column: names[c].to_string(),
                    });
                }
                f64_cols.push(col.as_any().downcast_ref::<Float64Array>());
                u64_cols.push(col.as_any().downcast_ref::<UInt64Array>());
            }
            if batch.num_columns() != names.len()
                || (0..names.len()).any(|c| {
                    if is_count(names[c]) {
                        u64_cols[c].is_none()
                    } else {
                        f64_cols[c].is_none()
                    }
                })
            {
                return Err(bad("a record batch does not match the schema".into()));
            }
            let f = |c: usize, k: usize| f64_cols[c].map_or(f64::NAN, |a| a.value(k));
            let u = |c: usize, k: usize| u64_cols[c].map_or(0, |a| a.value(k));
            for k in 0..batch.num_rows() {
                let row = row0 + k;
                let (t, step) = (f(0, k), u(1, k));
                for (c, x) in z.iter_mut().enumerate() {
                    *x = f(2 + c, k);
                }
                push_checked(&mut traj, step, t, &z)
                    .map_err(|what| ArrowIoError::Inconsistent { row, what })?;
                if diag {
                    let b = 2 + 2 * d;
                    let count = |c| usize::try_from(u(b + c, k)).unwrap_or(usize::MAX);
                    traj.diagnostics.push(DiagnosticRecord {
                        step,
                        t,
                        energy: f(b, k),
                        constraint: f(b + 1, k),
                        hidden_constraint: f(b + 2, k),
                        max_shake_iterations: count(3),
                        max_base_iterations: count(4),
                        rattle_iterations: count(5),
                        max_lambda: f(b + 6, k),
                        max_condition: f(b + 7, k),
                    });
                    multipliers.extend((b + 8..names.len()).map(|c| f(c, k)));
                }
            }
            row0 += batch.num_rows();
        }
        traj.set_multipliers(m, multipliers);
        Ok(traj)
    }
}

#[cfg(test)]
mod tests {
    //! What a file written by another program can get wrong, built here
    //! with the arrow crates themselves: types, nulls, steps and times.
    use super::*;
    use crate::{examples::Pendulum, Integrator, Stop, StormerVerlet};
    use std::io::Cursor;

    /// The columns and metadata of a real run's file, to be damaged.
    fn parts() -> (Vec<Field>, HashMap<String, String>, Vec<ArrayRef>) {
        let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
        let traj = i
            .run(Pendulum::default().state(0.5, 0.0), Stop::Steps(4))
            .execute()
            .trajectory;
        let mut file = Vec::new();
        traj.write_arrow(&mut file).unwrap();
        let reader = arrow_ipc::reader::FileReader::try_new(Cursor::new(file), None).unwrap();
        let schema = reader.schema();
        let batches: Vec<RecordBatch> = reader.map(Result::unwrap).collect();
        assert_eq!(batches.len(), 1);
        let fields = schema.fields().iter().map(|f| f.as_ref().clone()).collect();
        (
            fields,
            schema.metadata().clone(),
            batches[0].columns().to_vec(),
        )
    }

    fn write(
        fields: Vec<Field>,
        meta: HashMap<String, String>,
        batches: &[Vec<ArrayRef>],
    ) -> Vec<u8> {
        let schema = Arc::new(Schema::new_with_metadata(fields, meta));
        let mut file = Vec::new();
        let mut w = arrow_ipc::writer::FileWriter::try_new(&mut file, &schema).unwrap();
        for cols in batches {
            w.write(&RecordBatch::try_new(schema.clone(), cols.clone()).unwrap())
                .unwrap();
        }
        w.finish().unwrap();
        drop(w);
        file
    }

    fn read(file: Vec<u8>) -> Result<Trajectory, ArrowIoError> {
        Trajectory::read_arrow(Cursor::new(file))
    }

    #[test]
    fn the_columns_are_the_csv_header_in_order() {
        let mut i = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).with_diagnostics();
        let traj = i
            .run(Pendulum::default().state(0.5, 0.0), Stop::Steps(2))
            .execute()
            .trajectory;
        let (mut arrow, mut csv) = (Vec::new(), Vec::new());
        traj.write_arrow(&mut arrow).unwrap();
        traj.write_csv(&mut csv).unwrap();
        let reader = arrow_ipc::reader::FileReader::try_new(Cursor::new(arrow), None).unwrap();
        let names: Vec<String> = reader
            .schema()
            .fields()
            .iter()
            .map(|f| f.name().clone())
            .collect();
        let csv = String::from_utf8(csv).unwrap();
        assert_eq!(names.join(","), csv.lines().nth(1).unwrap());
        assert!(names.contains(&"lambda[rod]".to_string()));
    }

    #[test]
    fn several_record_batches_read_as_one_trajectory() {
        let (fields, meta, cols) = parts();
        let whole = read(write(
            fields.clone(),
            meta.clone(),
            std::slice::from_ref(&cols),
        ))
        .unwrap();
        let head: Vec<ArrayRef> = cols.iter().map(|c| c.slice(0, 2)).collect();
        let tail: Vec<ArrayRef> = cols.iter().map(|c| c.slice(2, 3)).collect();
        assert_eq!(read(write(fields, meta, &[head, tail])).unwrap(), whole);
    }

    #[test]
    fn a_wrong_type_is_a_schema_error() {
        let (mut fields, meta, mut cols) = parts();
        // step as f64
        fields[1] = Field::new("step", DataType::Float64, false);
        cols[1] = Arc::new(Float64Array::from(vec![0.0, 1.0, 2.0, 3.0, 4.0]));
        let err = read(write(fields, meta, &[cols])).unwrap_err();
        assert!(matches!(err, ArrowIoError::BadSchema { ref why, .. } if why.contains("step")));
    }

    #[test]
    fn a_null_is_refused_with_its_row() {
        let (mut fields, meta, mut cols) = parts();
        fields[2] = Field::new("q[0]", DataType::Float64, true);
        cols[2] = Arc::new(Float64Array::from(vec![
            Some(0.0),
            Some(1.0),
            None,
            Some(0.0),
            Some(0.0),
        ]));
        let err = read(write(fields, meta, &[cols])).unwrap_err();
        assert!(matches!(err, ArrowIoError::Null { row: 2, ref column } if column == "q[0]"));
    }

    #[test]
    fn steps_and_times_off_the_run_are_inconsistent() {
        let (fields, meta, mut cols) = parts();
        let mut skipped = cols.clone();
        skipped[1] = Arc::new(UInt64Array::from(vec![0, 1, 3, 4, 5]));
        assert!(matches!(
            read(write(fields.clone(), meta.clone(), &[skipped])),
            Err(ArrowIoError::Inconsistent { row: 2, .. })
        ));
        cols[0] = Arc::new(Float64Array::from(vec![
            0.0,
            0.1,
            0.2,
            0.30000000000000004,
            0.5,
        ]));
        assert!(matches!(
            read(write(fields, meta, &[cols])),
            Err(ArrowIoError::Inconsistent { row: 4, .. })
        ));
    }
}
