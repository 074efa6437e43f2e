//! What the driver asks of the thing it runs: a [`Stepper`] starts a run,
//! takes step k in place, and stores (for a lazily projecting RATTLE run,
//! projects) the states the run keeps. The driver ([`Run`](super::Run))
//! owns the stop rule, the stride, the trajectory, the observers and the
//! end of a run on error; the stepper owns the system, the step map, the
//! guard and the Kahan carry. [`Integrator`](crate::Integrator) implements
//! it (`integrator/stepper.rs`), so the driver names no facade above it.

use crate::diagnostics::Accumulator;
use crate::error::StepError;
use crate::report::StepInfo;
use crate::state::State;
use crate::trajectory::{Names, Trajectory};

use super::lane::Lane;

/// How a run's steps are projected, fixed by [`Stepper::begin_run`].
#[derive(Copy, Clone, Debug)]
pub(crate) struct Projection {
    /// Every step is RATTLE's R_h (Π after each SHAKE step).
    pub(crate) per_step: bool,
    /// A RATTLE run that steps with SHAKE and projects only the states it
    /// stores or shows (Π ∘ S_hᵏ = Π ∘ R_hᵏ).
    pub(crate) lazy: bool,
}

/// The driver's view of an integrator (module docs).
pub(crate) trait Stepper {
    /// The trajectory's layout: d, and the names of the coordinates and
    /// constraints (`None`: numbered, as for a particle system's 10⁶
    /// coordinates).
    fn layout(&self) -> (usize, Option<Names>);

    /// m, the number of constraints (the multipliers a diagnosed run keeps).
    fn constraint_count(&self) -> usize;

    /// The step size h.
    fn step_size(&self) -> f64;

    /// Whether the run keeps a diagnostics record per stored state.
    fn diagnostics(&self) -> bool;

    /// Whether a step that fails leaves (q, p) as they were, and storing a
    /// state never fails (then the driver keeps no copy of the state before
    /// each step to end a failed run with: (q, p) is that state).
    fn atomic_steps(&self) -> bool {
        false
    }

    /// Checks h, the options and the start state's dimensions.
    fn check_start(&self, z0: &State) -> Result<(), StepError>;

    /// Starts a run at (q, p), time `t0`: checks the state (finite, on M,
    /// N well conditioned), resets the guard's reference, the carry and
    /// the warm starts to it, and projects it onto M^H when every step
    /// is projected. Returns how the run projects.
    fn begin_run(&mut self, q: &mut [f64], p: &mut [f64], t0: f64)
        -> Result<Projection, StepError>;

    /// Takes the steps of `lane` in the stepper's own frame (`lane`), when
    /// it can; otherwise leaves `lane.end` at `NotEntered` and does nothing.
    fn lane<'a>(&'a mut self, q: &'a mut [f64], p: &'a mut [f64], per_step: bool, lane: Lane<'a>);

    /// Step k, to time `t`, in place; `show`: the run will show this
    /// state (a lazy step may make its Π where its numbers are). (q, p)
    /// are the driver's own buffers: a stepper that computes the new state
    /// in buffers of its own may swap them in.
    fn advance(
        &mut self,
        q: &mut Vec<f64>,
        p: &mut Vec<f64>,
        per_step: bool,
        k: u64,
        t: f64,
        show: bool,
    ) -> Result<StepInfo, StepError>;

    /// With diagnostics, after the step leaving the last stored state:
    /// that step's λ into the stored record.
    fn fill_leaving_lambda(&mut self, traj: &mut Trajectory, per_step: bool);

    /// A lazy RATTLE run failed at step k: replays the steps after the
    /// last stored one (`from`, its SHAKE state in (q, p)), projecting
    /// each. Returns the last step whose RATTLE state exists (its SHAKE
    /// state left in (q, p)) and a projection's error before step k.
    fn replay(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        from: u64,
        k: u64,
        t0: f64,
    ) -> (u64, Option<StepError>);

    /// Stores (and shows to the observer) the state (q, p) of step k.
    #[allow(clippy::too_many_arguments)]
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
    ) -> Result<(), StepError>;
}
