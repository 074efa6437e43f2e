//! The integrator as the driver's [`Stepper`]: how a run starts, steps,
//! and enters the fixed-size lane, and the entry points of a run
//! ([`Integrator::run`], [`Integrator::run_observed`]). Storing a state is
//! in `record`.

use std::ops::ControlFlow;

use crate::base_map::BaseMap;
use crate::diagnostics::Accumulator;
use crate::error::StepError;
use crate::rattle::project_hidden;
use crate::report::StepInfo;
use crate::run::lane::{self, Lane};
use crate::run::stepper::{Projection, Stepper};
use crate::run::{Run, RunOutcome, StepEvent, Stop};
use crate::state::State;
use crate::step::Method;
use crate::system::ConstrainedSystem;
use crate::trajectory::{Names, Trajectory};

use super::Integrator;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// A run from `z0` until `stop`; configure it with
    /// [`Run::stride`], [`Run::observe`], … and start it with
    /// [`Run::execute`].
    ///
    /// A RATTLE run steps with SHAKE and applies Π only to the states it
    /// stores or observes: since Π ∘ S_hᵏ = Π ∘ R_hᵏ (the paper's equation
    /// after Proposition 4.2; see [`rattle`](crate::rattle)) these are the
    /// RATTLE states, at a fraction of the cost.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, ImplicitMidpoint, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.01);
    /// let mut energies = Vec::new();
    /// let out = integ
    ///     .run(State::from_slices(&[0.0, -1.0], &[1.0, 0.0]), Stop::Time(2.0))
    ///     .stride(50)
    ///     .observe(|_step, _t, z| energies.push(0.5 * z.p.norm_squared() + z.q[1]))
    ///     .execute();
    /// assert!(out.error.is_none());
    /// assert_eq!(energies.len(), 5);
    /// assert!(energies.iter().all(|e| (e - energies[0]).abs() < 1e-4));
    /// ```
    pub fn run(&mut self, z0: State, stop: Stop) -> Run<'_, Self, fn(u64, f64, &State)> {
        Run::new(self, z0, stop)
    }

    /// [`run`](Self::run) with default settings and `on_step` called after
    /// every step (see [`Run::on_step`]): the hook a progress indicator
    /// uses. `ControlFlow::Break(())` ends the run early, without error.
    ///
    /// ```
    /// use std::ops::ControlFlow;
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, Stop, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// let mut done = 0.0;
    /// let out = integ.run_observed(
    ///     State::from_slices(&[0.0, -1.0], &[0.5, 0.0]),
    ///     Stop::Steps(20),
    ///     &mut |e| {
    ///         done = e.step as f64 / e.steps as f64;
    ///         ControlFlow::Continue(())
    ///     },
    /// );
    /// assert!(out.error.is_none() && done == 1.0);
    /// ```
    pub fn run_observed(
        &mut self,
        z0: State,
        stop: Stop,
        on_step: &mut impl FnMut(&StepEvent) -> ControlFlow<()>,
    ) -> RunOutcome {
        self.run(z0, stop).on_step(on_step).execute()
    }
}

impl<S: ConstrainedSystem, B: BaseMap> Stepper for Integrator<S, B> {
    fn layout(&self) -> (usize, Option<Names>) {
        (self.system.dof(), Some(Names::of(&self.system)))
    }

    fn constraint_count(&self) -> usize {
        self.system.constraint_count()
    }

    fn step_size(&self) -> f64 {
        self.h
    }

    fn diagnostics(&self) -> bool {
        self.diagnostics
    }

    fn check_start(&self, z0: &State) -> Result<(), StepError> {
        self.check_h()?;
        self.check_dims(z0)
    }

    fn begin_run(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        t0: f64,
    ) -> Result<Projection, StepError> {
        // SHAKE's difference quotients take their scale from the first state
        // they meet: this run's, not whatever an earlier run on this
        // integrator started from (an ensemble reuses one integrator per
        // thread; a member's result must not depend on its neighbours).
        self.steps.map.ws.probe.lambda_scale = 0.0;
        self.begin(q, p, 0, t0)?;
        self.carrying = true;
        let rattle = self.method == Method::Rattle;
        let per_step = rattle && self.guard.options.project_every_step;
        // The initial state: projected for RATTLE, as given for SHAKE.
        if per_step {
            project_hidden(
                &self.system,
                q,
                p,
                &mut self.steps.map.ws,
                self.guard.newton(),
            )
            .map_err(|e| e.at(0, t0))?;
        }
        Ok(Projection {
            per_step,
            lazy: rattle && !per_step,
        })
    }

    fn lane<'a>(&'a mut self, q: &'a mut [f64], p: &'a mut [f64], per_step: bool, lane: Lane<'a>) {
        // One substep a step and no record per state: the lane's case.
        if self.diagnostics || self.steps.composition.stages() != 1 {
            return;
        }
        let carry = (self.compensated && self.carrying).then_some(self.carry.as_mut_slice());
        // (The driver reads what the lane did from `lane.end`, not from
        // this answer: a hand-written `with_sizes` could change that.)
        let _ = lane::enter(
            &mut self.steps.map,
            &self.system,
            &mut self.guard,
            q,
            p,
            self.h,
            per_step,
            carry,
            lane,
        );
    }

    #[inline]
    fn advance(
        &mut self,
        q: &mut Vec<f64>,
        p: &mut Vec<f64>,
        per_step: bool,
        k: u64,
        t: f64,
        show: bool,
    ) -> Result<StepInfo, StepError> {
        self.steps.map.show = show;
        Integrator::advance(self, q, p, per_step, k, t)
    }

    fn fill_leaving_lambda(&mut self, traj: &mut Trajectory, per_step: bool) {
        Integrator::fill_leaving_lambda(self, traj, per_step)
    }

    fn replay(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        from: u64,
        k: u64,
        t0: f64,
    ) -> (u64, Option<StepError>) {
        self.replay_lazy(q, p, from, k, t0)
    }

    #[inline]
    fn record<F: FnMut(u64, f64, &State)>(
        &mut self,
        q: &[f64],
        p: &[f64],
        projected: bool,
        k: u64,
        t: f64,
        acc: &mut Accumulator,
        traj: &mut Trajectory,
        store: bool,
        observer: &mut F,
        scratch: &mut State,
    ) -> Result<(), StepError> {
        Integrator::record(
            self, q, p, projected, k, t, acc, traj, store, observer, scratch,
        )
    }
}
