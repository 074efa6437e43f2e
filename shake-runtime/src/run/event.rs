//! What an observer of every step sees (see [`Run::on_step`](crate::Run::on_step)).

use std::ops::ControlFlow;

use crate::report::StepInfo;

/// An observer of every step: `ControlFlow::Break(())` ends the run.
pub type StepObserver<'a> = dyn FnMut(&StepEvent) -> ControlFlow<()> + 'a;

/// One step of a run has been taken: step `step` of `steps`, reaching time
/// `t` = t0 + step·h.
///
/// ```
/// use geoshake_runtime::{StepEvent, StepInfo};
/// let e = StepEvent { step: 3, steps: 10, t: 0.3, info: StepInfo::default() };
/// assert_eq!(e.fraction(), 0.3);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct StepEvent {
    /// The index of the state just computed (1 for the first step).
    pub step: u64,
    /// The number of steps the run will take if nothing stops it.
    pub steps: u64,
    /// Its time t0 + step·h.
    pub t: f64,
    /// What the step did.
    pub info: StepInfo,
}

impl StepEvent {
    /// step / steps, in [0, 1] (1 for a run of no steps).
    ///
    /// ```
    /// use geoshake_runtime::{StepEvent, StepInfo};
    /// let e = StepEvent { step: 5, steps: 5, t: 1.0, info: StepInfo::default() };
    /// assert_eq!(e.fraction(), 1.0);
    /// ```
    pub fn fraction(&self) -> f64 {
        if self.steps == 0 {
            1.0
        } else {
            self.step as f64 / self.steps as f64
        }
    }
}
