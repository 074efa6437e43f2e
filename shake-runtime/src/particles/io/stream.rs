//! Writing while a run runs: [`FrameSink`], the writers' adaptor to the
//! driver's observer ([`Run::observe`](crate::Run::observe)).

use super::FileError;
use crate::State;

/// A writer of states, one frame a call ([`ExtXyzWriter`](super::ExtXyzWriter),
/// [`DumpWriter`](super::DumpWriter)), and the observers that write a run's
/// states as it runs.
///
/// An observer cannot stop a run or return an error: the first I/O error
/// is kept in the writer, nothing more is written after it (the frames
/// written before it stay whole and readable: each frame is one write and
/// a flush), and the writer's `finish` returns it. Check it right after the
/// run.
///
/// ```
/// use geoshake_runtime::particles::io::{DumpReader, DumpWriter, FrameSink, SimBox};
/// use geoshake_runtime::particles::{generate, Options, Rattle};
/// use geoshake_runtime::Stop;
/// let (system, mut state) = generate::water(4, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// generate::set_temperature(rattle.system(), &mut state, 300.0);
/// let n = rattle.system().particles();
/// let types = (0..n).map(|a| if a % 3 == 0 { 1 } else { 2 }).collect();
/// let mut dump = DumpWriter::new(Vec::new(), SimBox::default(), types, rattle.system().masses().to_vec());
/// // Observe every 5th state, write every 10th: steps 0, 10, 20.
/// let out = rattle.run(&state, Stop::Steps(25)).stride(5).store(false).observe(dump.every(10)).execute();
/// assert!(out.error.is_none(), "{:?}", out.error);
/// let text = dump.finish().unwrap();
/// let steps: Vec<u64> = DumpReader::new(&text[..], "mem").map(|f| f.unwrap().step).collect();
/// assert_eq!(steps, [0, 10, 20]);
/// ```
pub trait FrameSink {
    /// Writes one frame: positions q and momenta p (3 per atom) at `step`
    /// and `time`.
    fn write_state(&mut self, step: u64, time: f64, q: &[f64], p: &[f64]) -> Result<(), FileError>;

    /// Where an observer keeps the first error until `finish`.
    fn deferred_error(&mut self) -> &mut Option<FileError>;

    /// An observer that writes every state the run observes (every
    /// `stride`-th, the first and the last).
    fn observer(&mut self) -> impl FnMut(u64, f64, &State) + '_
    where
        Self: Sized,
    {
        self.every(1)
    }

    /// An observer that writes the observed states whose step is a multiple
    /// of `k` (steps counted from the run's start; `k` = 0 is taken as 1).
    /// With `.stride(k)` the run observes exactly those and its last state;
    /// the last is written only when its step is a multiple of `k`.
    fn every(&mut self, k: u64) -> impl FnMut(u64, f64, &State) + '_
    where
        Self: Sized,
    {
        let k = k.max(1);
        move |step, t, z| {
            if step % k != 0 || self.deferred_error().is_some() {
                return;
            }
            if let Err(e) = self.write_state(step, t, z.q.as_slice(), z.p.as_slice()) {
                *self.deferred_error() = Some(e);
            }
        }
    }

    /// Whether an observer met an error (then nothing more is written).
    fn failed(&mut self) -> bool {
        self.deferred_error().is_some()
    }
}
