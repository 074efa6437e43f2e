//! The stored states of a run, in one contiguous buffer.
//!
//! A run stores the states at steps 0, s, 2s, … (s the stride) and at most
//! one more at the end (the last step when it is off the stride, or the
//! last good state of a run that failed). So the step indices and the times
//! t0 + k h need not be stored: they are computed from t0, h, s and that
//! one extra index, exactly as the driver computes them. What is stored per
//! state is z = (q, p) itself, 2d numbers back to back in one `Vec<f64>`:
//! 16·2d bytes and nothing else (a pendulum state, d = 2, takes 32 bytes;
//! as separate heap vectors it took about 140).

use crate::diagnostics::DiagnosticRecord;
use crate::state::State;

/// The stored states of a run: state `i` at step [`step(i)`](Self::step),
/// time [`time(i)`](Self::time), with `diagnostics[i]` when diagnostics are
/// on.
///
/// ```
/// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
/// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
/// let traj = integ.run(z0, Stop::Steps(4)).execute().trajectory;
/// assert_eq!(traj.steps(), vec![0, 1, 2, 3, 4]);
/// assert_eq!(traj.len(), 5);
/// assert_eq!(traj.q(0), &[0.0, -1.0]);
/// assert_eq!(traj.state(0).p[0], 0.5);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// d: each state is 2d numbers, q then p.
    dof: usize,
    /// The states, back to back.
    data: Vec<f64>,
    t0: f64,
    h: f64,
    stride: u64,
    /// States at steps 0, s, 2s, …
    regular: usize,
    /// One last state off the stride, at this step.
    extra: Option<u64>,
    /// Diagnostics, one per state, when enabled (empty otherwise).
    pub diagnostics: Vec<DiagnosticRecord>,
}

/// No state, d = 0, t0 = 0, h = 0, stride 1 (the stride a run clamps to).
impl Default for Trajectory {
    fn default() -> Self {
        Trajectory::new(0, 0.0, 0.0, 1, 0)
    }
}

impl Trajectory {
    /// An empty trajectory of a run with d degrees of freedom, start time
    /// t0, step size h and stride s, with room for `capacity` states.
    pub(crate) fn new(dof: usize, t0: f64, h: f64, stride: u64, capacity: usize) -> Self {
        Trajectory {
            dof,
            data: Vec::with_capacity(2 * dof * capacity),
            t0,
            h,
            stride: stride.max(1),
            regular: 0,
            extra: None,
            diagnostics: Vec::new(),
        }
    }

    /// (d, t0, h, stride): what, with the stored step indices, fixes every
    /// state's place and time (for packing a trajectory into flat words and
    /// back).
    pub(crate) fn layout(&self) -> (usize, f64, f64, u64) {
        (self.dof, self.t0, self.h, self.stride)
    }

    /// Appends the state (q, p) at step k: the next multiple of the stride,
    /// or the one last state off it.
    pub(crate) fn push(&mut self, k: u64, q: &[f64], p: &[f64]) {
        debug_assert!(
            self.extra.is_none(),
            "nothing is stored after the extra state"
        );
        if k == self.regular as u64 * self.stride {
            self.regular += 1;
        } else {
            self.extra = Some(k);
        }
        self.data.extend_from_slice(q);
        self.data.extend_from_slice(p);
    }

    /// Number of stored states.
    ///
    /// ```
    /// assert_eq!(shake_runtime::Trajectory::default().len(), 0);
    /// ```
    pub fn len(&self) -> usize {
        self.regular + usize::from(self.extra.is_some())
    }

    /// True when nothing was stored.
    ///
    /// ```
    /// assert!(shake_runtime::Trajectory::default().is_empty());
    /// ```
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The step index of state `i` (panics when `i ≥ len()`).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0, Stop::Steps(7)).stride(3).execute().trajectory;
    /// assert_eq!(traj.step(3), 7);
    /// ```
    pub fn step(&self, i: usize) -> u64 {
        assert!(i < self.len(), "state {i} of {}", self.len());
        if i < self.regular {
            i as u64 * self.stride
        } else {
            self.extra.expect("the extra state")
        }
    }

    /// The step indices of all stored states.
    ///
    /// ```
    /// assert!(shake_runtime::Trajectory::default().steps().is_empty());
    /// ```
    pub fn steps(&self) -> Vec<u64> {
        (0..self.len()).map(|i| self.step(i)).collect()
    }

    /// The time t0 + k h of state `i`, k its step index.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.5);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0, Stop::Steps(2)).start_time(1.0).execute().trajectory;
    /// assert_eq!(traj.time(2), 2.0);
    /// ```
    pub fn time(&self, i: usize) -> f64 {
        self.t0 + self.step(i) as f64 * self.h
    }

    /// The times of all stored states.
    ///
    /// ```
    /// assert!(shake_runtime::Trajectory::default().times().is_empty());
    /// ```
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|i| self.time(i)).collect()
    }

    /// The positions q of state `i`, a view into the buffer.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.q(0), &[0.0, -1.0]);
    /// ```
    pub fn q(&self, i: usize) -> &[f64] {
        assert!(i < self.len(), "state {i} of {}", self.len());
        let n = 2 * self.dof;
        &self.data[i * n..i * n + self.dof]
    }

    /// The momenta p of state `i`, a view into the buffer.
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.p(0), &[0.5, 0.0]);
    /// ```
    pub fn p(&self, i: usize) -> &[f64] {
        assert!(i < self.len(), "state {i} of {}", self.len());
        let n = 2 * self.dof;
        &self.data[i * n + self.dof..(i + 1) * n]
    }

    /// State `i` as an owned [`State`] (a copy).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let z0 = State::from_slices(&[0.0, -1.0], &[0.5, 0.0]);
    /// let traj = integ.run(z0.clone(), Stop::Steps(1)).execute().trajectory;
    /// assert_eq!(traj.state(0), z0);
    /// ```
    pub fn state(&self, i: usize) -> State {
        State::from_slices(self.q(i), self.p(i))
    }

    /// The last stored state (a copy).
    ///
    /// ```
    /// assert!(shake_runtime::Trajectory::default().last().is_none());
    /// ```
    pub fn last(&self) -> Option<State> {
        self.len().checked_sub(1).map(|i| self.state(i))
    }

    /// Every stored state in order (copies).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(3)).execute().trajectory;
    /// assert_eq!(traj.states().count(), 4);
    /// ```
    pub fn states(&self) -> impl ExactSizeIterator<Item = State> + '_ {
        (0..self.len()).map(|i| self.state(i))
    }

    /// The bytes the stored states hold (the buffer's capacity; step
    /// indices and times take none).
    ///
    /// ```
    /// use shake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let traj = integ.run(State::from_slices(&[0.0, -1.0], &[0.5, 0.0]), Stop::Steps(9)).execute().trajectory;
    /// assert_eq!(traj.state_bytes(), 10 * 32);
    /// ```
    pub fn state_bytes(&self) -> usize {
        self.data.capacity() * std::mem::size_of::<f64>()
    }
}
