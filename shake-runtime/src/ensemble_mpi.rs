//! Ensembles over MPI ranks (feature `mpi`): many initial conditions on a
//! cluster, rayon inside each rank, nothing lost.
//!
//! [`run_ensemble_mpi`] is [`run_ensemble`](crate::run_ensemble) spread over
//! the ranks of an MPI communicator:
//!
//! - **Assignment.** The members still to do are taken in increasing order,
//!   in batches of [`MpiEnsemble::batch`]; inside a batch, the i-th member
//!   goes to rank i mod (number of ranks) (round robin, so members of
//!   neighbouring index, often of similar cost, are spread over the ranks),
//!   and each rank runs its share with rayon on its own threads.
//! - **Determinism.** Every member is computed by the same code as in
//!   `run_ensemble`: a clone of the template runs it from its initial state
//!   ([`Template::run_member`]: a dense [`Integrator`](crate::Integrator)
//!   from a [`State`](crate::State), a particle
//!   [`Rattle`](crate::particles::Rattle) from a
//!   [`ParticleState`](crate::particles::ParticleState), each run
//!   independent of the runs before it), so its outcome is bit for bit the
//!   same whatever the number of ranks, threads or the batch it fell into.
//! - **Gather.** Each rank packs its outcomes
//!   ([`pack_outcome`]: u64 words, floats as
//!   their bits, the error with its step and time, the partial trajectory of
//!   a failed member) and rank 0 gathers them with one `MPI_Gatherv` per
//!   batch. Only rank 0 gets the results.
//! - **Nothing lost.** A failed member is an outcome like any other (its
//!   typed [`StepError`](crate::StepError) and the trajectory up to the
//!   last good state). With [`MpiEnsemble::store`] set, rank 0 appends every
//!   batch to an [`EnsembleStore`] (records and manifest, flushed to disk)
//!   before the next batch starts; started again on the same directory, the
//!   job loads the finished members and computes only the missing ones. At
//!   most one batch of work is lost when a job is killed.
//!
//! MPI is called from the thread that calls [`run_ensemble_mpi`] only (the
//! rayon workers never call it), so MPI initialised with
//! `Threading::Funneled` is enough. Every rank must pass the same initial
//! states, template, stop and options.
//!
//! ```no_run
//! use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
//! use geoshake_runtime::ensemble_mpi::{run_ensemble_mpi, MpiEnsemble};
//! use geoshake_runtime::mpi::{self, Threading};
//!
//! let (universe, _) = mpi::initialize_with_threading(Threading::Funneled).unwrap();
//! let world = universe.world();
//! let rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).rattle();
//! let starts: Vec<_> = (0..1000).map(|k| Pendulum::default().state(1e-3 * k as f64, 0.0)).collect();
//! let options = MpiEnsemble { store: Some("pendulums.ensemble".into()), ..MpiEnsemble::default() };
//! let results = run_ensemble_mpi(&world, &rattle, &starts, Stop::Time(10.0), 100, &options).unwrap();
//! if let Some(results) = results {
//!     // Rank 0: every member's outcome, and the counts.
//!     println!("{}", results.summary);
//! }
//! ```

use crate::ensemble::{ensemble, pack_outcome, unpack_outcome, RecordError, Template};
use crate::ensemble_store::{EnsembleStore, StoreError};
use crate::integrator::{RunOutcome, Stop};
use mpi::datatype::PartitionMut;
use mpi::traits::{Communicator, CommunicatorCollectives, Root};
use mpi::Count;
use std::fmt;
use std::path::PathBuf;
use std::time::Instant;

/// How [`run_ensemble_mpi`] distributes and records an ensemble.
///
/// ```
/// use geoshake_runtime::ensemble_mpi::MpiEnsemble;
/// let o = MpiEnsemble { batch: 4096, ..MpiEnsemble::default() };
/// assert!(o.store.is_none() && o.collect);
/// ```
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MpiEnsemble {
    /// Members per batch (all ranks together); one gather, and one write to
    /// the store, per batch. Large enough that each rank gets many members
    /// per batch (the gather's latency is then negligible), small enough
    /// that a killed job loses little. Default 1024.
    pub batch: usize,
    /// The directory of an [`EnsembleStore`] (created, or resumed if it
    /// holds this job's manifest); `None` keeps the results in memory only.
    pub store: Option<PathBuf>,
    /// What identifies the ensemble in the store's manifest (system,
    /// method, h, stop, …): resuming a store made for another job is an
    /// error.
    pub job: String,
    /// Stop (cleanly, the store up to date) after this many batches, e.g.
    /// to end before a wall-time limit and resume in the next job.
    pub max_batches: Option<usize>,
    /// Whether rank 0 returns every outcome (loading the finished ones from
    /// the store); with `false` it returns the summary only, and the
    /// outcomes stay in the store.
    pub collect: bool,
}

impl Default for MpiEnsemble {
    fn default() -> Self {
        MpiEnsemble {
            batch: 1024,
            store: None,
            job: String::new(),
            max_batches: None,
            collect: true,
        }
    }
}

/// What a distributed ensemble did. Its `Display` is the line
/// `ensemble members=… ok=… failed=… ranks=… threads=… members_per_s=…`.
///
/// ```
/// use geoshake_runtime::ensemble_mpi::EnsembleSummary;
/// let s = EnsembleSummary { members: 10, ok: 9, failed: 1, computed: 10, resumed: 0,
///     pending: 0, ranks: 2, threads: 1, seconds: 0.5, words: 190 };
/// assert_eq!(s.members_per_second(), 20.0);
/// assert!(s.to_string().starts_with("ensemble members=10 ok=9 failed=1 ranks=2 threads=1"));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct EnsembleSummary {
    /// Members of the ensemble.
    pub members: usize,
    /// Finished without error (this job and resumed).
    pub ok: usize,
    /// Finished with an error (this job and resumed).
    pub failed: usize,
    /// Members computed by this job.
    pub computed: usize,
    /// Members found finished in the store.
    pub resumed: usize,
    /// Members not done (only when [`MpiEnsemble::max_batches`] stopped
    /// the job early).
    pub pending: usize,
    /// MPI ranks.
    pub ranks: usize,
    /// Rayon threads of rank 0.
    pub threads: usize,
    /// Wall time of this job's batches (compute, gather and store), s.
    pub seconds: f64,
    /// Words (8 bytes) gathered on rank 0 by this job: the communication
    /// volume, all ranks' records together.
    pub words: u64,
}

impl EnsembleSummary {
    /// Members computed by this job per second of wall time (0 when it
    /// computed none: everything was resumed).
    ///
    /// See [`EnsembleSummary`].
    pub fn members_per_second(&self) -> f64 {
        if self.computed == 0 {
            0.0
        } else {
            self.computed as f64 / self.seconds
        }
    }
}

impl fmt::Display for EnsembleSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "ensemble members={} ok={} failed={} ranks={} threads={} members_per_s={:.1}",
            self.members,
            self.ok,
            self.failed,
            self.ranks,
            self.threads,
            self.members_per_second()
        )
    }
}

/// Rank 0's result of [`run_ensemble_mpi`].
///
/// See [`run_ensemble_mpi`].
#[derive(Clone, Debug)]
pub struct MpiEnsembleResults {
    /// The counts.
    pub summary: EnsembleSummary,
    /// Member k's outcome at index k when [`MpiEnsemble::collect`]
    /// (`None` for a member still pending); empty otherwise.
    pub outcomes: Vec<Option<RunOutcome>>,
}

/// Why a distributed ensemble stopped. Every rank returns an error when
/// one of them meets one (rank 0 tells the others), so no rank is left
/// waiting in a collective call.
///
/// ```
/// use geoshake_runtime::ensemble_mpi::MpiEnsembleError;
/// assert!(MpiEnsembleError::OnRankZero.to_string().contains("rank 0"));
/// ```
#[derive(Debug, thiserror::Error)]
pub enum MpiEnsembleError {
    /// The store could not be opened, written or read (rank 0).
    #[error("ensemble store: {0}")]
    Store(#[from] StoreError),
    /// A gathered record did not read back (rank 0; a bug or a corrupted
    /// message, never a failed member).
    #[error("gathered record from rank {rank}: {source}")]
    Record {
        /// The rank that sent it.
        rank: usize,
        /// Why.
        #[source]
        source: RecordError,
    },
    /// A batch's records exceed what one MPI gather can count (2³¹ − 1
    /// words): use a smaller [`MpiEnsemble::batch`] or a larger stride.
    #[error("batch of {words} words is too large for one gather; use a smaller batch")]
    BatchTooLarge {
        /// Words of the batch.
        words: u64,
    },
    /// An invalid option (a batch of 0 members).
    #[error("invalid option: {0}")]
    InvalidOption(&'static str),
    /// Rank 0 failed (its error is reported there); this rank stopped.
    #[error("stopped: rank 0 reported an error")]
    OnRankZero,
}

/// Runs every initial state until `stop`, keeping every `stride`-th state,
/// over the ranks of `comm` (see the [module docs](self)): on rank 0
/// `Some` of the outcomes in the order of `initial` and the summary, on
/// the other ranks `None`.
///
/// Collective: every rank of `comm` must call it with the same arguments.
///
/// # Panics
///
/// If the ranks pass different numbers of initial states (a programming
/// error: the job could not be consistent).
///
/// ```no_run
/// # use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
/// # use geoshake_runtime::ensemble_mpi::{run_ensemble_mpi, MpiEnsemble};
/// let universe = geoshake_runtime::mpi::initialize().unwrap();
/// let rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).rattle();
/// let starts = vec![Pendulum::default().state(0.5, 0.0); 100];
/// let r = run_ensemble_mpi(&universe.world(), &rattle, &starts, Stop::Steps(100), 100,
///     &MpiEnsemble::default()).unwrap();
/// ```
pub fn run_ensemble_mpi<C, T>(
    comm: &C,
    template: &T,
    initial: &[T::Start],
    stop: Stop,
    stride: u64,
    options: &MpiEnsemble,
) -> Result<Option<MpiEnsembleResults>, MpiEnsembleError>
where
    C: Communicator + CommunicatorCollectives,
    T: Template,
{
    if options.batch == 0 {
        return Err(MpiEnsembleError::InvalidOption("batch must be at least 1"));
    }
    let rank = comm.rank() as usize;
    let ranks = comm.size() as usize;
    let root = comm.process_at_rank(0);
    let members = initial.len();

    // Rank 0 opens the store and tells every rank which members are left:
    // first their number (u64::MAX if the store failed), then the list.
    let mut store = None;
    let mut head = [0u64; 2]; // [members, pending]
    let mut pending: Vec<u64> = Vec::new();
    let mut opened = Ok(());
    if rank == 0 {
        match options
            .store
            .as_ref()
            .map(|dir| EnsembleStore::open(dir, members, &options.job))
            .transpose()
        {
            Ok(s) => {
                pending = match &s {
                    Some(s) => s.pending().into_iter().map(|k| k as u64).collect(),
                    None => (0..members as u64).collect(),
                };
                store = s;
                head = [members as u64, pending.len() as u64];
            }
            Err(e) => {
                head = [members as u64, u64::MAX];
                opened = Err(e);
            }
        }
    }
    root.broadcast_into(&mut head[..]);
    if head[1] == u64::MAX {
        return match opened {
            Err(e) => Err(e.into()),
            Ok(()) => Err(MpiEnsembleError::OnRankZero),
        };
    }
    assert_eq!(
        head[0], members as u64,
        "every rank must pass the same initial states"
    );
    pending.resize(head[1] as usize, 0);
    root.broadcast_into(&mut pending[..]);

    let resumed = store.as_ref().map_or(0, |s| s.finished());
    let mut outcomes: Vec<Option<RunOutcome>> = Vec::new();
    if rank == 0 && options.collect {
        outcomes = match &store {
            Some(s) => s.load_all()?,
            None => vec![None; members],
        };
    }
    let (mut ok, mut failed) = store
        .as_ref()
        .map_or((0, 0), |s| (s.finished() - s.failed(), s.failed()));

    let start = Instant::now();
    let mut computed = 0;
    let mut gathered = 0;
    for (b, batch) in pending.chunks(options.batch).enumerate() {
        if options.max_batches.is_some_and(|m| b >= m) {
            break;
        }
        // This rank's share, computed exactly as `run_ensemble` does.
        let mine: Vec<usize> = batch
            .iter()
            .skip(rank)
            .step_by(ranks)
            .map(|&k| k as usize)
            .collect();
        let packed: Vec<Vec<u64>> = ensemble(template, &mine, |copy, _, &k| {
            let out = copy.run_member(&initial[k], stop, stride);
            let mut words = Vec::new();
            pack_outcome(k, &out, &mut words);
            words
        });
        let words = packed.concat();
        // Every rank learns every count, so all agree on whether the batch
        // fits one gather.
        let mut counts = vec![0u64; ranks];
        comm.all_gather_into(&(words.len() as u64), &mut counts[..]);
        let total: u64 = counts.iter().sum();
        if total > Count::MAX as u64 {
            return Err(MpiEnsembleError::BatchTooLarge { words: total });
        }
        gathered += total;
        let mut status = [0u64];
        if rank == 0 {
            let counts: Vec<Count> = counts.iter().map(|&c| c as Count).collect();
            let displs: Vec<Count> = counts
                .iter()
                .scan(0, |acc, &c| {
                    let d = *acc;
                    *acc += c;
                    Some(d)
                })
                .collect();
            let mut all = vec![0u64; total as usize];
            root.gather_varcount_into_root(
                &words[..],
                &mut PartitionMut::new(&mut all[..], &counts[..], &displs[..]),
            );
            let done = receive(members, &all, &counts, &displs).and_then(|mut got| {
                got.sort_by_key(|(k, _)| *k);
                if let Some(s) = store.as_mut() {
                    let refs: Vec<_> = got.iter().map(|(k, o)| (*k, o)).collect();
                    s.append(&refs)?;
                }
                Ok(got)
            });
            match done {
                Ok(got) => {
                    computed += got.len();
                    for (k, out) in got {
                        if out.error.is_none() {
                            ok += 1;
                        } else {
                            failed += 1;
                        }
                        if options.collect {
                            outcomes[k] = Some(out);
                        }
                    }
                }
                Err(e) => {
                    status[0] = 1;
                    root.broadcast_into(&mut status[..]);
                    return Err(e);
                }
            }
        } else {
            root.gather_varcount_into(&words[..]);
        }
        root.broadcast_into(&mut status[..]);
        if status[0] != 0 {
            return Err(MpiEnsembleError::OnRankZero);
        }
    }
    if rank != 0 {
        return Ok(None);
    }
    let summary = EnsembleSummary {
        members,
        ok,
        failed,
        computed,
        resumed,
        pending: pending.len() - computed,
        ranks,
        threads: rayon::current_num_threads(),
        seconds: start.elapsed().as_secs_f64(),
        words: gathered,
    };
    Ok(Some(MpiEnsembleResults { summary, outcomes }))
}

/// Unpacks the records rank r sent in `all[displs[r]..][..counts[r]]`.
fn receive(
    members: usize,
    all: &[u64],
    counts: &[Count],
    displs: &[Count],
) -> Result<Vec<(usize, RunOutcome)>, MpiEnsembleError> {
    let mut got = Vec::new();
    for (r, (&c, &d)) in counts.iter().zip(displs).enumerate() {
        let mut part = &all[d as usize..(d + c) as usize];
        while !part.is_empty() {
            let (k, out, used) = unpack_outcome(part)
                .map_err(|source| MpiEnsembleError::Record { rank: r, source })?;
            if k >= members {
                return Err(MpiEnsembleError::Record {
                    rank: r,
                    source: RecordError::Corrupted {
                        what: "member",
                        value: k as u64,
                    },
                });
            }
            got.push((k, out));
            part = &part[used..];
        }
    }
    Ok(got)
}
