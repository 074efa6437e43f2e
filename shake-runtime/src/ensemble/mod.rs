//! Ensembles: many initial conditions through one integrator configuration,
//! in parallel.
//!
//! Sampling and sensitivity studies run the same system, method and step
//! size from many initial states; the runs are independent, so they are
//! spread over the cores with rayon. Each worker thread clones the
//! template [`Integrator`] once (its workspace included) and reuses it for
//! every run it takes, so an ensemble allocates per thread, not per run or
//! per step. The results come back in the order of the initial states, and
//! each run is the same computation as on one thread (the same floating-
//! point operations in the same order): the results do not depend on the
//! number of threads.
//!
//! The pool is rayon's global one (one thread per core, or
//! `RAYON_NUM_THREADS`); to choose the number of threads, call inside
//! `geoshake_runtime::rayon::ThreadPoolBuilder::new().num_threads(n).build()?.install(..)`.
//!
//! ```
//! use geoshake_runtime::{ensemble, Integrator, StormerVerlet, State, Stop, examples::Pendulum};
//!
//! let rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.01).rattle();
//! // Pendulums released at rest from angles 0.1, 0.2, …, 1.0.
//! let starts: Vec<State> = (1..=10)
//!     .map(|k| {
//!         let a = 0.1 * k as f64;
//!         State::from_slices(&[a.sin(), -a.cos()], &[0.0, 0.0])
//!     })
//!     .collect();
//! // The largest |q₁| over one second of each run.
//! let reach = ensemble(&rattle, &starts, |integ, _k, z0| {
//!     let mut max = 0.0f64;
//!     let out = integ
//!         .run(z0.clone(), Stop::Time(1.0))
//!         .store(false)
//!         .observe(|_, _, z| max = max.max(z.q[0].abs()))
//!         .execute();
//!     assert!(out.error.is_none());
//!     max
//! });
//! assert_eq!(reach.len(), 10);
//! assert!(reach.windows(2).all(|w| w[0] < w[1]));
//! ```

use crate::base_map::BaseMap;
use crate::integrator::{Integrator, RunOutcome, Stop};
use crate::state::State;
use crate::system::ConstrainedSystem;
use rayon::prelude::*;

/// `f(integrator, k, &initial[k])` for every k, in parallel; the results in
/// the order of `initial`. `integrator` is a per-thread clone of
/// `template` (same system, base map, h, method and options).
///
/// ```
/// use geoshake_runtime::{ensemble, Integrator, ImplicitMidpoint, State, examples::Pendulum};
/// let shake = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).shake();
/// let starts = vec![State::from_slices(&[0.0, -1.0], &[0.5, 0.0]); 4];
/// let ends = ensemble(&shake, &starts, |integ, _, z0| integ.step(z0).unwrap());
/// assert!(ends.iter().all(|z| z == &ends[0]));
/// ```
pub fn ensemble<S, B, T, F>(template: &Integrator<S, B>, initial: &[State], f: F) -> Vec<T>
where
    S: ConstrainedSystem + Clone + Sync,
    B: BaseMap,
    T: Send,
    F: Fn(&mut Integrator<S, B>, usize, &State) -> T + Sync,
{
    initial
        .par_iter()
        .enumerate()
        .map_init(|| template.clone(), |integ, (k, z0)| f(integ, k, z0))
        .collect()
}

/// Runs every initial state until `stop`, keeping every `stride`-th state
/// (see [`Run::stride`](crate::Run::stride)); the outcomes in the order of
/// `initial`.
///
/// ```
/// use geoshake_runtime::{run_ensemble, Integrator, StormerVerlet, State, Stop, examples::Pendulum};
/// let rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.05).rattle();
/// let starts: Vec<State> = (0..8)
///     .map(|k| State::from_slices(&[0.0, -1.0], &[0.1 * k as f64, 0.0]))
///     .collect();
/// let outs = run_ensemble(&rattle, &starts, Stop::Time(1.0), 10);
/// assert!(outs.iter().all(|o| o.error.is_none() && o.trajectory.len() == 3));
/// ```
pub fn run_ensemble<S, B>(
    template: &Integrator<S, B>,
    initial: &[State],
    stop: Stop,
    stride: u64,
) -> Vec<RunOutcome>
where
    S: ConstrainedSystem + Clone + Sync,
    B: BaseMap,
{
    ensemble(template, initial, |integ, _, z0| {
        integ.run(z0.clone(), stop).stride(stride).execute()
    })
}

mod record;
#[cfg(test)]
mod tests;

pub use record::{pack_outcome, unpack_outcome, RecordError};
