//! A progress bar for long runs (the `progress` feature): an
//! [`indicatif`] bar driven by the run's per-step hook
//! ([`Run::on_step`](crate::Run::on_step)).
//!
//! The bar is drawn on standard error when that is a terminal and hidden
//! otherwise (CI logs, pipes), at most about 20 times a second. It is moved
//! every `steps/1000` steps only, so a step costs a dynamic call and one
//! integer comparison more: on 5·10⁶ pendulum steps the difference was
//! within the timing noise of the shared machine (`shake-bench/benches/stress.rs`
//! runs 10⁷ steps with the bar on).
//!
//! ```
//! use geoshake_runtime::{progress::Progress, Integrator, StormerVerlet, Stop, examples::Pendulum};
//! let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.01);
//! let mut progress = Progress::new("pendulum");
//! let out = integ
//!     .run(Pendulum::default().state(0.5, 0.0), Stop::Steps(10_000))
//!     .stride(100)
//!     .on_step(progress.hook())
//!     .execute();
//! assert!(out.error.is_none());
//! assert_eq!((progress.bar().position(), progress.bar().is_finished()), (10_000, true));
//! ```

use crate::run::StepEvent;
use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;

/// The hook a [`Progress`] lends to [`Run::on_step`](crate::Run::on_step).
pub type StepHook = dyn FnMut(&StepEvent) -> ControlFlow<()> + Send;

/// A progress bar for one run at a time: label, elapsed time, bar,
/// percentage, steps per second and the time left.
pub struct Progress {
    bar: ProgressBar,
    hook: Box<StepHook>,
}

impl Progress {
    /// A bar labelled `label`, on standard error (hidden when that is not
    /// a terminal).
    ///
    /// ```
    /// let p = geoshake_runtime::progress::Progress::new("run");
    /// assert_eq!(p.bar().message(), "run");
    /// ```
    pub fn new(label: &str) -> Self {
        Self::with_bar(ProgressBar::new(0), label)
    }

    /// A bar that is never drawn (tests, or to keep the code path the same
    /// when the output is not wanted).
    ///
    /// ```
    /// assert!(geoshake_runtime::progress::Progress::hidden("run").bar().is_hidden());
    /// ```
    pub fn hidden(label: &str) -> Self {
        Self::with_bar(ProgressBar::hidden(), label)
    }

    fn with_bar(bar: ProgressBar, label: &str) -> Self {
        // The template is a constant: it parses, and a failure would only
        // lose the style, never the run.
        if let Ok(style) = ProgressStyle::with_template(
            "{msg:<24} [{elapsed_precise}] {wide_bar} {percent:>3}% {per_sec:>12} eta {eta}",
        ) {
            bar.set_style(style);
        }
        bar.set_message(label.to_string());
        let shown = bar.clone();
        // Moves the bar every `every` steps (at `next`), set at each run's
        // first step, when its length is known (so one Progress serves runs
        // in turn).
        let (mut every, mut next) = (1u64, 0u64);
        let hook = move |e: &StepEvent| {
            if e.step <= 1 {
                shown.reset();
                shown.set_length(e.steps);
                every = (e.steps / 1000).max(1);
                next = 0;
            }
            if e.step >= next || e.step >= e.steps {
                shown.set_position(e.step);
                next = e.step + every;
                if e.step >= e.steps {
                    shown.finish();
                }
            }
            ControlFlow::Continue(())
        };
        Progress {
            bar,
            hook: Box::new(hook),
        }
    }

    /// The hook to hand to [`Run::on_step`](crate::Run::on_step).
    pub fn hook(&mut self) -> &mut StepHook {
        &mut *self.hook
    }

    /// The indicatif bar itself (to restyle it, or read its position).
    pub fn bar(&self) -> &ProgressBar {
        &self.bar
    }
}
