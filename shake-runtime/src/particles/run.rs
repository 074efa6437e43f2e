//! A particle system's run on the engine's one driver: [`Rattle`] is a
//! [`Stepper`], so a particle run has the dense path's [`Run`] builder
//! (stride, start time, observers, `on_step`), its [`Trajectory`], its
//! [`RunOutcome`] with the partial trajectory on failure, and everything
//! built on them (CSV and Arrow files, plots, progress bars).

use super::{Method, ParticleState, Rattle};
use crate::diagnostics::Accumulator;
use crate::error::StepError;
use crate::report::StepInfo;
use crate::run::lane::Lane;
use crate::run::stepper::{Projection, Stepper};
use crate::run::{Run, RunOutcome, Stop};
use crate::state::State;
use crate::trajectory::{Names, Trajectory};

impl Rattle {
    /// A run from `state` until `stop`, starting at the state's time;
    /// configure it with [`Run::stride`], [`Run::observe`], … and start it
    /// with [`Run::execute`]. The state is copied: the run leaves it as it
    /// was, and its last state is the trajectory's last.
    ///
    /// Every step is the method's own (RATTLE's velocity stage is part of
    /// the step); the start state is taken as given, so bring initial data
    /// onto M and M^H first with [`project`](Self::project). Before the
    /// first step the request is checked as a whole (the start time, the
    /// number of steps and the last time t0 + n·h, the stride, the states
    /// to store: [`StepError::InvalidInput`], [`StepError::Storage`]) and
    /// the state's shape and entries ([`StepError::Shape`],
    /// [`StepError::NonFinite`]). A step that fails at k ends the run with
    /// the states up to k − 1 stored, the last one always.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// use geoshake_runtime::{Stop, StepError};
    /// let (system, mut state) = generate::chain(20, 7).unwrap();
    /// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// let out = rattle.run(&state, Stop::Steps(100)).stride(10).execute();
    /// assert!(out.error.is_none());
    /// let traj = &out.trajectory;
    /// assert_eq!((traj.len(), traj.step(10)), (11, 100));
    /// assert!(out.summary.max_residual.unwrap() <= 1e-10);
    /// // More steps than f64 can count exactly: refused before the first.
    /// let out = rattle.run(&state, Stop::Steps(u64::MAX)).execute();
    /// assert!(matches!(out.error, Some(StepError::InvalidInput { .. })));
    /// ```
    pub fn run(
        &mut self,
        state: &ParticleState,
        stop: Stop,
    ) -> Run<'_, Self, fn(u64, f64, &State)> {
        // (q and p of different lengths are not a `State`: refused here,
        // with the step's own error.)
        if let Err(e) = self.check_shape(&state.q, &state.p) {
            return Run::refused(self, stop, e);
        }
        let z0 = State::from_slices(&state.q, &state.p);
        self.start_stamp = state.stamp;
        self.start_step = state.step;
        Run::new(self, z0, stop).start_time(state.time)
    }

    /// `steps` steps from `state`, leaving `state` at the last good state:
    /// step n, or step k − 1 of a run whose step k failed (then the error
    /// is in the outcome): the molecular-dynamics loop's call. It is a
    /// [`run`](Self::run) that stores nothing (the outcome's trajectory is
    /// empty; its summary is the call's steps); the state's step count
    /// goes up by the steps taken, its time is t0 + k·h again (its start
    /// time t0 kept), and an error's step counts the state's steps, as
    /// [`step`](Self::step)'s does. Beside the state it holds two copies
    /// of it while it runs (the driver's, and the one it shows), none per
    /// step; a run continued from where the last one stopped keeps the
    /// caches and takes the same steps as one run.
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, mut state) = generate::water(8, 1).unwrap();
    /// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// for _ in 0..3 {
    ///     let out = rattle.run_in_place(&mut state, 10);
    ///     assert!(out.error.is_none() && out.summary.max_residual.unwrap() <= 1e-10);
    /// }
    /// assert_eq!((state.step(), state.time()), (30, 60.0));
    /// ```
    pub fn run_in_place(&mut self, state: &mut ParticleState, steps: u64) -> RunOutcome {
        let first = state.step;
        let mut last = 0;
        let run = self.run(state, Stop::Steps(steps));
        // The observer sees the start, the end and, on failure, the last
        // good state: the latest one seen is where the state ends.
        let mut out = run
            .stride(steps.max(1))
            .store(false)
            .observe(|k, _, z| {
                if k > 0 {
                    state.q.copy_from_slice(z.q.as_slice());
                    state.p.copy_from_slice(z.p.as_slice());
                    last = k;
                }
            })
            .execute();
        if last > 0 {
            state.step = first + last;
            state.time = state.t0 + state.step as f64 * self.step_size();
            // The state is the one the last step made, unless the run
            // failed: then the caches are not its own.
            state.stamp = if out.error.is_none() {
                self.last_stamp()
            } else {
                0
            };
        }
        if let Some(e) = out.error.take() {
            let (k, t) = (first + e.step(), e.time().unwrap_or(f64::NAN));
            out.error = Some(e.at(k, t));
        }
        out
    }
}

impl Stepper for Rattle {
    fn layout(&self) -> (usize, Option<Names>) {
        // Numbered columns: names for 10⁶ coordinates would outweigh a
        // stored state.
        (self.system().particles() * self.system().dim(), None)
    }

    fn constraint_count(&self) -> usize {
        self.system().constraints()
    }

    fn step_size(&self) -> f64 {
        Rattle::step_size(self)
    }

    fn diagnostics(&self) -> bool {
        false
    }

    fn atomic_steps(&self) -> bool {
        // `Rattle::step` works in its own buffers and swaps them in only
        // on success.
        true
    }

    fn check_start(&self, z0: &State) -> Result<(), StepError> {
        self.check_shape(z0.q.as_slice(), z0.p.as_slice())
    }

    fn begin_run(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        t0: f64,
    ) -> Result<Projection, StepError> {
        // A new state: no cache (forces, factor of N, ν) belongs to it.
        self.run_from(t0);
        Rattle::not_finite(0, t0, "initial state", q, 0)?;
        Rattle::not_finite(0, t0, "initial state", p, q.len())?;
        Ok(Projection {
            per_step: self.options().method == Method::Rattle,
            lazy: false,
        })
    }

    fn lane<'a>(&'a mut self, _: &'a mut [f64], _: &'a mut [f64], _: bool, _: Lane<'a>) {
        // No fixed-size lane: the particle step loops over its own
        // clusters or solves the whole graph.
    }

    #[inline]
    fn advance(
        &mut self,
        q: &mut Vec<f64>,
        p: &mut Vec<f64>,
        _per_step: bool,
        k: u64,
        _t: f64,
        _show: bool,
    ) -> Result<StepInfo, StepError> {
        // The step works on a state that owns its buffers (and swaps its
        // own in on success): the driver's are lent to it, not copied.
        let mut state = ParticleState {
            q: std::mem::take(q),
            p: std::mem::take(p),
            t0: self.run_t0,
            time: 0.0,
            step: k - 1,
            stamp: self.run_stamp,
        };
        self.step_offset = self.run_step0;
        let result = self.step(&mut state);
        self.step_offset = 0;
        *q = state.q;
        *p = state.p;
        // (On failure the step left the state and the caches' stamp as
        // they were: a new stamp of 0 makes nothing count as continued.)
        self.run_stamp = if result.is_ok() { state.stamp } else { 0 };
        result
    }

    fn fill_leaving_lambda(&mut self, _: &mut Trajectory, _: bool) {}

    fn replay(
        &mut self,
        _: &mut [f64],
        _: &mut [f64],
        from: u64,
        _: u64,
        _: f64,
    ) -> (u64, Option<StepError>) {
        // Never called: a particle run projects in every step (not lazy).
        (from, None)
    }

    #[inline]
    fn record<F: FnMut(u64, f64, &State)>(
        &mut self,
        q: &[f64],
        p: &[f64],
        _projected: bool,
        k: u64,
        t: f64,
        _acc: &mut Accumulator,
        traj: &mut Trajectory,
        store: bool,
        observer: &mut F,
        scratch: &mut State,
    ) -> Result<(), StepError> {
        scratch.q.as_mut_slice().copy_from_slice(q);
        scratch.p.as_mut_slice().copy_from_slice(p);
        observer(k, t, scratch);
        if store {
            traj.push(k, q, p);
        }
        Ok(())
    }
}
