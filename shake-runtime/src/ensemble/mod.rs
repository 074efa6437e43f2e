//! Ensembles: many initial conditions through one integrator configuration,
//! in parallel.
//!
//! Sampling and sensitivity studies run the same system, method and step
//! size from many initial states; the runs are independent, so they are
//! spread over the cores with rayon. Each piece of work rayon hands a
//! thread (a few per thread) clones the template once (its workspace
//! included) and reuses the copy for every run in it, so an ensemble
//! allocates per thread, not per run or per step.
//! The results come back in the order of the initial states, and each run
//! is the same computation as on one thread (the same floating-point
//! operations in the same order): the results do not depend on the number
//! of threads.
//!
//! The template is anything that clones into an independent copy and can
//! be shared with the threads that clone it ([`ensemble()`] asks no more);
//! [`run_ensemble`] and the MPI ensemble also start runs from it, through
//! [`Template`]: the dense [`Integrator`] from a [`State`], the particle
//! [`Rattle`] from a [`ParticleState`]. A member's failure is its own: it
//! comes back as its outcome's error with the trajectory up to the step
//! that failed, and the other members run on.
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
use crate::particles::{ParticleState, Rattle};
use crate::state::State;
use crate::system::ConstrainedSystem;
use rayon::prelude::*;

/// What [`run_ensemble`] replicates: a solver that clones into an
/// independent copy taking the same steps, shared by reference with the
/// threads that clone it, and that runs a member from its initial state.
///
/// ```
/// use geoshake_runtime::ensemble::Template;
/// use geoshake_runtime::{Integrator, StormerVerlet, Stop, examples::Pendulum};
/// let mut rattle = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).rattle();
/// let out = rattle.run_member(&Pendulum::default().state(0.5, 0.0), Stop::Steps(10), 5);
/// assert_eq!(out.trajectory.len(), 3);
/// ```
pub trait Template: Clone + Sync {
    /// A member's initial state.
    type Start: Sync;

    /// Runs from `start` until `stop`, keeping every `stride`-th state
    /// (see [`Run::stride`](crate::Run::stride)). The run must not depend
    /// on the runs this copy took before (the ensemble hands members to
    /// copies in no fixed order).
    fn run_member(&mut self, start: &Self::Start, stop: Stop, stride: u64) -> RunOutcome;
}

/// Dense runs start from a [`State`] at time 0 (every run resets the
/// integrator's carried state).
impl<S, B> Template for Integrator<S, B>
where
    S: ConstrainedSystem + Clone + Sync,
    B: BaseMap,
{
    type Start = State;

    fn run_member(&mut self, start: &State, stop: Stop, stride: u64) -> RunOutcome {
        self.run(start.clone(), stop).stride(stride).execute()
    }
}

/// Particle runs start from a [`ParticleState`] (its time and step count
/// kept) as a new state: no cache of the steps before (forces, N's
/// factor, the multipliers' warm start) is reused, even for a state this
/// copy made, so that a member's steps do not depend on which copy runs
/// it.
impl Template for Rattle {
    type Start = ParticleState;

    fn run_member(&mut self, start: &ParticleState, stop: Stop, stride: u64) -> RunOutcome {
        self.member_run(start, stop).stride(stride).execute()
    }
}

impl Rattle {
    /// The run of an ensemble's member from `start`, as
    /// [`Template::run_member`] makes it, for a caller that configures it
    /// further ([`Run::on_step`](crate::run::Run::on_step) to stop it,
    /// say) before [`execute`](crate::run::Run::execute).
    pub fn member_run(
        &mut self,
        start: &ParticleState,
        stop: Stop,
    ) -> crate::run::Run<'_, Self, fn(u64, f64, &crate::State)> {
        self.forget_last_state();
        self.run(start, stop)
    }
}

/// `f(copy, k, &initial[k])` for every k, in parallel; the results in the
/// order of `initial`. `copy` is a clone of `template` (for an
/// [`Integrator`]: the same system, base map, h, method and options) made
/// once per piece of work rayon hands a thread and reused for every
/// member in it.
///
/// ```
/// use geoshake_runtime::{ensemble, Integrator, ImplicitMidpoint, State, examples::Pendulum};
/// let shake = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).shake();
/// let starts = vec![State::from_slices(&[0.0, -1.0], &[0.5, 0.0]); 4];
/// let ends = ensemble(&shake, &starts, |integ, _, z0| integ.step(z0).unwrap());
/// assert!(ends.iter().all(|z| z == &ends[0]));
/// ```
///
/// A particle ensemble: boxes of rigid water at four temperatures, each
/// run 20 steps on the particle [`Rattle`], with its kinetic energy at the
/// end.
///
/// ```
/// use geoshake_runtime::particles::{generate, Options, Rattle};
/// use geoshake_runtime::{ensemble, Stop};
/// let (system, mut state) = generate::water(27, 3).unwrap();
/// let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// let starts: Vec<_> = [100.0, 200.0, 300.0, 400.0]
///     .iter()
///     .map(|&kelvin| {
///         let mut s = state.clone();
///         generate::set_temperature(rattle.system(), &mut s, kelvin);
///         s
///     })
///     .collect();
/// let ends = ensemble(&rattle, &starts, |copy, _, z0| {
///     let out = copy.run(z0, Stop::Steps(20)).stride(20).execute();
///     assert!(out.error.is_none());
///     let traj = &out.trajectory;
///     copy.system().kinetic_energy(traj.p(traj.len() - 1))
/// });
/// assert!(ends.windows(2).all(|w| w[0] < w[1]));
/// ```
pub fn ensemble<T, Z, R, F>(template: &T, initial: &[Z], f: F) -> Vec<R>
where
    T: Clone + Sync,
    Z: Sync,
    R: Send,
    F: Fn(&mut T, usize, &Z) -> R + Sync,
{
    initial
        .par_iter()
        .enumerate()
        .map_init(|| template.clone(), |copy, (k, z0)| f(copy, k, z0))
        .collect()
}

/// Runs every initial state until `stop`, keeping every `stride`-th state
/// (see [`Run::stride`](crate::Run::stride)); the outcomes in the order of
/// `initial`. A member that fails has its error and its trajectory up to
/// the failure in its outcome.
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
///
/// The same for particles, from [`ParticleState`]s:
///
/// ```
/// use geoshake_runtime::particles::{generate, Options, Rattle};
/// use geoshake_runtime::{run_ensemble, Stop};
/// let (system, mut state) = generate::water(8, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// let starts: Vec<_> = (1..=4)
///     .map(|k| {
///         let mut s = state.clone();
///         generate::set_temperature(rattle.system(), &mut s, 100.0 * k as f64);
///         s
///     })
///     .collect();
/// let outs = run_ensemble(&rattle, &starts, Stop::Steps(50), 10);
/// assert!(outs.iter().all(|o| o.error.is_none() && o.trajectory.len() == 6));
/// ```
pub fn run_ensemble<T: Template>(
    template: &T,
    initial: &[T::Start],
    stop: Stop,
    stride: u64,
) -> Vec<RunOutcome> {
    ensemble(template, initial, |copy, _, z0| {
        copy.run_member(z0, stop, stride)
    })
}

mod record;
#[cfg(test)]
mod tests;

pub use record::{pack_outcome, unpack_outcome, RecordError};
