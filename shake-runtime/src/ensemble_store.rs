//! A resumable record of a long ensemble: which members are finished, and
//! their outcomes, on disk.
//!
//! A job of 10⁶ members on a cluster gets interrupted (a wall-time limit, a
//! node failure). An [`EnsembleStore`] is a directory with two files:
//!
//! - `results.bin`: the outcomes, one record per member in the format of
//!   [`pack_outcome`] (little-endian u64
//!   words; floats as their IEEE bits, so an outcome read back is bit for bit
//!   the one computed);
//! - `manifest.txt`: a header line naming the job, then one line per finished
//!   member, `<member> ok <offset> <words>` or
//!   `<member> failed <offset> <words> step=<step> | <error message>`
//!   (offset and length of its record in words), readable with grep.
//!
//! A batch is appended in that order — records, flushed to the disk, then
//! the manifest lines, flushed — so a manifest line always points to a
//! complete record. Opening an existing store resumes it: a torn last line
//! (the job died while writing it), or a line pointing past the end of
//! `results.bin`, ends the valid part; both files are cut back to it, and
//! every member not in the manifest is still to do. The header records the
//! number of members and a caller-chosen job description; resuming with
//! other values is an error, not a silent mix of two ensembles.
//!
//! ```
//! use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
//! use geoshake_runtime::ensemble_store::EnsembleStore;
//! let dir = std::env::temp_dir().join(format!("shake-store-doc-{}", std::process::id()));
//! let _ = std::fs::remove_dir_all(&dir);
//! let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).rattle();
//! let out = integ.run(Pendulum::default().state(0.3, 0.0), Stop::Steps(5)).execute();
//!
//! let mut store = EnsembleStore::open(&dir, 3, "pendulums h=0.1").unwrap();
//! store.append(&[(1, &out)]).unwrap();
//! drop(store); // the job is interrupted
//!
//! let store = EnsembleStore::open(&dir, 3, "pendulums h=0.1").unwrap();
//! assert_eq!(store.pending(), vec![0, 2]);
//! assert_eq!(store.load(1).unwrap(), Some(out));
//! // Another job in the same directory is refused.
//! assert!(EnsembleStore::open(&dir, 3, "pendulums h=0.05").is_err());
//! std::fs::remove_dir_all(&dir).unwrap();
//! ```

use crate::ensemble::{pack_outcome, unpack_outcome, RecordError};
use crate::integrator::RunOutcome;
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

const HEADER: &str = "# shake ensemble manifest v1";

/// Why a store could not be opened, written or read.
///
/// ```
/// use geoshake_runtime::ensemble_store::{EnsembleStore, StoreError};
/// // A directory inside a file cannot be created.
/// let file = std::env::temp_dir().join(format!("shake-store-doc0-{}", std::process::id()));
/// std::fs::write(&file, b"").unwrap();
/// let e = EnsembleStore::open(&file.join("store"), 1, "job");
/// assert!(matches!(e, Err(StoreError::Io { .. })));
/// std::fs::remove_file(&file).unwrap();
/// ```
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// A file could not be created, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The directory holds another job's manifest.
    #[error("{path} belongs to another ensemble: it has `{found}`, this job is `{expected}`")]
    OtherJob {
        /// The manifest.
        path: PathBuf,
        /// This job's header line.
        expected: String,
        /// The header line found.
        found: String,
    },
    /// A record the manifest points to does not read back (the file was
    /// changed behind the store's back).
    #[error("member {member}: {source}")]
    Record {
        /// The member.
        member: usize,
        /// Why.
        #[source]
        source: RecordError,
    },
}

/// Where a finished member's record lies in `results.bin`, in words.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
struct Entry {
    offset: u64,
    words: u64,
    ok: bool,
}

/// A directory recording the finished members of one ensemble (see the
/// [module docs](self)).
///
/// ```
/// use geoshake_runtime::ensemble_store::EnsembleStore;
/// let dir = std::env::temp_dir().join(format!("shake-store-doc2-{}", std::process::id()));
/// let _ = std::fs::remove_dir_all(&dir);
/// let store = EnsembleStore::open(&dir, 4, "job").unwrap();
/// assert_eq!((store.members(), store.finished(), store.pending().len()), (4, 0, 4));
/// std::fs::remove_dir_all(&dir).unwrap();
/// ```
#[derive(Debug)]
pub struct EnsembleStore {
    dir: PathBuf,
    manifest: File,
    results: File,
    /// Length of `results.bin` in words.
    results_words: u64,
    entries: Vec<Option<Entry>>,
}

impl EnsembleStore {
    /// Opens the store in `dir` for an ensemble of `members` members
    /// described by `job` (one line; the caller's choice of what identifies
    /// the ensemble: system, method, h, stop, …), creating it if there is
    /// none and resuming it otherwise.
    ///
    /// ```
    /// use geoshake_runtime::ensemble_store::EnsembleStore;
    /// let dir = std::env::temp_dir().join(format!("shake-store-doc3-{}", std::process::id()));
    /// let _ = std::fs::remove_dir_all(&dir);
    /// drop(EnsembleStore::open(&dir, 4, "job").unwrap());
    /// // Four members of this job, not five.
    /// assert!(EnsembleStore::open(&dir, 5, "job").is_err());
    /// std::fs::remove_dir_all(&dir).unwrap();
    /// ```
    pub fn open(dir: &Path, members: usize, job: &str) -> Result<Self, StoreError> {
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let manifest_path = dir.join("manifest.txt");
        let results_path = dir.join("results.bin");
        let header = format!(
            "{HEADER} members={members} job={}",
            job.replace(['\n', '\r'], " ")
        );
        let mut manifest = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&manifest_path)
            .map_err(io(&manifest_path))?;
        let results = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&results_path)
            .map_err(io(&results_path))?;
        let mut text = Vec::new();
        manifest
            .read_to_end(&mut text)
            .map_err(io(&manifest_path))?;
        let results_bytes = results.metadata().map_err(io(&results_path))?.len();
        let mut entries = vec![None; members];
        let (keep_manifest, keep_words) = if text.is_empty() {
            // A new store (or one that died before its header was written).
            manifest
                .write_all(format!("{header}\n").as_bytes())
                .map_err(io(&manifest_path))?;
            (header.len() as u64 + 1, 0)
        } else {
            let first = text.split(|&b| b == b'\n').next().unwrap_or_default();
            let found = String::from_utf8_lossy(first).into_owned();
            if found != header || text.len() == first.len() {
                return Err(StoreError::OtherJob {
                    path: manifest_path,
                    expected: header,
                    found,
                });
            }
            valid_prefix(&text, first.len() + 1, results_bytes / 8, &mut entries)
        };
        // Cut both files back to their valid parts, so that what is appended
        // next follows complete lines and records.
        manifest
            .set_len(keep_manifest)
            .map_err(io(&manifest_path))?;
        manifest
            .seek(SeekFrom::End(0))
            .map_err(io(&manifest_path))?;
        results.set_len(keep_words * 8).map_err(io(&results_path))?;
        manifest.sync_all().map_err(io(&manifest_path))?;
        results.sync_all().map_err(io(&results_path))?;
        Ok(EnsembleStore {
            dir: dir.to_path_buf(),
            manifest,
            results,
            results_words: keep_words,
            entries,
        })
    }

    /// The number of members of the ensemble.
    ///
    /// See [`EnsembleStore`].
    pub fn members(&self) -> usize {
        self.entries.len()
    }

    /// The number of finished members (ok or failed).
    ///
    /// See [`EnsembleStore::append`].
    pub fn finished(&self) -> usize {
        self.entries.iter().flatten().count()
    }

    /// The number of finished members that failed (their error and partial
    /// trajectory are in the store).
    ///
    /// See [`EnsembleStore::append`].
    pub fn failed(&self) -> usize {
        self.entries.iter().flatten().filter(|e| !e.ok).count()
    }

    /// The members still to do, in increasing order.
    ///
    /// See [`EnsembleStore`].
    pub fn pending(&self) -> Vec<usize> {
        (0..self.entries.len())
            .filter(|&k| self.entries[k].is_none())
            .collect()
    }

    /// Records finished members: their records, flushed to the disk, then
    /// their manifest lines, flushed. A member recorded twice keeps its
    /// last outcome.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// use geoshake_runtime::ensemble_store::EnsembleStore;
    /// let dir = std::env::temp_dir().join(format!("shake-store-doc4-{}", std::process::id()));
    /// let _ = std::fs::remove_dir_all(&dir);
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let good = integ.run(Pendulum::default().state(0.3, 0.0), Stop::Steps(2)).execute();
    /// let bad = integ.run(State::from_slices(&[f64::NAN, 0.0], &[0.0, 0.0]), Stop::Steps(2)).execute();
    /// let mut store = EnsembleStore::open(&dir, 2, "job").unwrap();
    /// store.append(&[(0, &good), (1, &bad)]).unwrap();
    /// assert_eq!((store.finished(), store.failed()), (2, 1));
    /// std::fs::remove_dir_all(&dir).unwrap();
    /// ```
    ///
    /// # Panics
    ///
    /// If a member index is not below [`members`](Self::members) (a
    /// programming error of the caller).
    pub fn append(&mut self, batch: &[(usize, &RunOutcome)]) -> Result<(), StoreError> {
        let mut words = Vec::new();
        let mut lines = String::new();
        let mut new = Vec::with_capacity(batch.len());
        for &(k, out) in batch {
            assert!(k < self.entries.len(), "member {k} out of range");
            let start = words.len();
            pack_outcome(k, out, &mut words);
            let entry = Entry {
                offset: self.results_words + start as u64,
                words: (words.len() - start) as u64,
                ok: out.error.is_none(),
            };
            lines.push_str(&manifest_line(k, &entry, out));
            new.push((k, entry));
        }
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
        let results_path = self.dir.join("results.bin");
        let manifest_path = self.dir.join("manifest.txt");
        self.results
            .seek(SeekFrom::Start(self.results_words * 8))
            .and_then(|_| self.results.write_all(&bytes))
            .and_then(|_| self.results.sync_data())
            .map_err(io(&results_path))?;
        self.results_words += words.len() as u64;
        self.manifest
            .write_all(lines.as_bytes())
            .and_then(|_| self.manifest.sync_data())
            .map_err(io(&manifest_path))?;
        for (k, e) in new {
            self.entries[k] = Some(e);
        }
        Ok(())
    }

    /// Member k's outcome, if it is finished.
    ///
    /// See the [module docs](self).
    pub fn load(&self, k: usize) -> Result<Option<RunOutcome>, StoreError> {
        let Some(e) = self.entries.get(k).copied().flatten() else {
            return Ok(None);
        };
        let path = self.dir.join("results.bin");
        let mut bytes = vec![0u8; e.words as usize * 8];
        let mut file = &self.results;
        file.seek(SeekFrom::Start(e.offset * 8))
            .and_then(|_| file.read_exact(&mut bytes))
            .map_err(io(&path))?;
        read_record(k, &bytes).map(Some)
    }

    /// Every member's outcome, `None` for those not finished (one pass over
    /// `results.bin`).
    ///
    /// See [`EnsembleStore::load`].
    pub fn load_all(&self) -> Result<Vec<Option<RunOutcome>>, StoreError> {
        let path = self.dir.join("results.bin");
        let mut bytes = Vec::new();
        let mut file = &self.results;
        file.seek(SeekFrom::Start(0))
            .and_then(|_| file.read_to_end(&mut bytes))
            .map_err(io(&path))?;
        self.entries
            .iter()
            .enumerate()
            .map(|(k, e)| {
                e.map(|e| {
                    let (a, b) = (e.offset as usize * 8, (e.offset + e.words) as usize * 8);
                    read_record(k, &bytes[a..b])
                })
                .transpose()
            })
            .collect()
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> StoreError + '_ {
    move |source| StoreError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn manifest_line(k: usize, e: &Entry, out: &RunOutcome) -> String {
    let mut line = format!(
        "{k} {} {} {}",
        if e.ok { "ok" } else { "failed" },
        e.offset,
        e.words
    );
    if let Some(err) = &out.error {
        let msg = err.to_string().replace(['\n', '\r'], " ");
        line.push_str(&format!(" step={} | {msg}", err.step()));
    }
    line.push('\n');
    line
}

/// Reads the manifest lines after the header (from byte `from`) while they
/// are complete, well formed and point inside the `words` words of
/// `results.bin`; fills `entries`; returns the byte length of the valid
/// manifest and the word length of `results.bin` it needs.
fn valid_prefix(text: &[u8], from: usize, words: u64, entries: &mut [Option<Entry>]) -> (u64, u64) {
    let (mut keep, mut used) = (from, 0u64);
    let mut rest = &text[from..];
    while let Some(end) = rest.iter().position(|&b| b == b'\n') {
        let Some((k, e)) = parse_line(&rest[..end])
            .filter(|&(k, e)| k < entries.len() && e.offset.saturating_add(e.words) <= words)
        else {
            break;
        };
        entries[k] = Some(e);
        used = used.max(e.offset + e.words);
        keep += end + 1;
        rest = &rest[end + 1..];
    }
    (keep as u64, used)
}

fn parse_line(line: &[u8]) -> Option<(usize, Entry)> {
    let line = std::str::from_utf8(line).ok()?;
    let mut f = line.split_whitespace();
    let k = f.next()?.parse().ok()?;
    let ok = match f.next()? {
        "ok" => true,
        "failed" => false,
        _ => return None,
    };
    let offset = f.next()?.parse().ok()?;
    let words = f.next()?.parse().ok()?;
    Some((k, Entry { offset, words, ok }))
}

fn read_record(k: usize, bytes: &[u8]) -> Result<RunOutcome, StoreError> {
    let words: Vec<u64> = bytes
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let record = |source| StoreError::Record { member: k, source };
    let (member, out, used) = unpack_outcome(&words).map_err(record)?;
    if member != k || used != words.len() {
        return Err(record(RecordError::Corrupted {
            what: "member",
            value: member as u64,
        }));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::examples::Pendulum;
    use crate::{Integrator, State, Stop, StormerVerlet};

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("shake-store-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    fn outcomes() -> Vec<RunOutcome> {
        let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.05)
            .rattle()
            .with_diagnostics();
        (0..6)
            .map(|k| {
                let z0 = if k == 4 {
                    State::from_slices(&[f64::NAN, -1.0], &[0.0, 0.0])
                } else {
                    Pendulum::default().state(0.2 * k as f64, 0.1)
                };
                integ.run(z0, Stop::Steps(7)).stride(3).execute()
            })
            .collect()
    }

    /// A job killed while writing: a torn manifest line and half a record
    /// at the end of results.bin. Resuming keeps the complete members,
    /// drops the torn one, and appends after the valid part.
    #[test]
    fn resume_after_torn_write() {
        let dir = scratch("torn");
        let outs = outcomes();
        let mut store = EnsembleStore::open(&dir, 6, "job").unwrap();
        store.append(&[(0, &outs[0]), (4, &outs[4])]).unwrap();
        store.append(&[(2, &outs[2])]).unwrap();
        drop(store);
        let manifest = dir.join("manifest.txt");
        let text = std::fs::read_to_string(&manifest).unwrap();
        let last = text.lines().last().unwrap().to_string();
        assert!(last.starts_with("2 ok "), "{text}");
        // Tear member 2's line and record: the line loses its newline and
        // the record its end.
        std::fs::write(&manifest, &text[..text.len() - 1]).unwrap();
        let results = dir.join("results.bin");
        let len = std::fs::metadata(&results).unwrap().len();
        OpenOptions::new()
            .write(true)
            .open(&results)
            .unwrap()
            .set_len(len - 16)
            .unwrap();

        let mut store = EnsembleStore::open(&dir, 6, "job").unwrap();
        assert_eq!(store.pending(), vec![1, 2, 3, 5]);
        assert_eq!((store.finished(), store.failed()), (2, 1));
        store
            .append(&[(1, &outs[1]), (2, &outs[2]), (3, &outs[3]), (5, &outs[5])])
            .unwrap();
        drop(store);
        let store = EnsembleStore::open(&dir, 6, "job").unwrap();
        assert!(store.pending().is_empty());
        let all = store.load_all().unwrap();
        for (k, out) in outs.iter().enumerate() {
            assert_eq!(all[k].as_ref(), Some(out), "member {k}");
            assert_eq!(store.load(k).unwrap().as_ref(), Some(out));
        }
        assert!(all[4].as_ref().unwrap().error.is_some());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A manifest line pointing past the end of results.bin (the records
    /// never reached the disk) is not trusted.
    #[test]
    fn line_without_record_is_pending() {
        let dir = scratch("dangling");
        let outs = outcomes();
        let mut store = EnsembleStore::open(&dir, 6, "job").unwrap();
        store.append(&[(3, &outs[3])]).unwrap();
        drop(store);
        std::fs::write(dir.join("results.bin"), []).unwrap();
        let store = EnsembleStore::open(&dir, 6, "job").unwrap();
        assert_eq!(store.finished(), 0);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn failed_member_line_names_its_error() {
        let dir = scratch("line");
        let outs = outcomes();
        let mut store = EnsembleStore::open(&dir, 6, "job").unwrap();
        store.append(&[(4, &outs[4])]).unwrap();
        let text = std::fs::read_to_string(dir.join("manifest.txt")).unwrap();
        let line = text.lines().nth(1).unwrap();
        assert!(line.starts_with("4 failed 0 "), "{line}");
        assert!(line.contains("step=0") && line.contains("non-finite value in the initial state"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
