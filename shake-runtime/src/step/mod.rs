//! Step maps: SHAKE S_h (Definition 1.1), RATTLE R_h = Π ∘ S_h
//! (Definition 1.2) and their symmetric compositions (Section 4), each a
//! map z ↦ z′ over a base map φ_h.
//!
//! - `map`: one substep, SHAKE on the general path (the Newton iteration
//!   on λ of `crate::shake`) or the classical one (`crate::shake::classical`),
//!   followed by Π for RATTLE: `StepMap`, which owns its workspaces;
//! - `reverse`: the check of a composed step by stepping back with −h;
//! - this file: `Composed`, the composition of substeps γ_k h that makes
//!   one step.
//!
//! A step map only computes; every check on its result is the
//! [`guard`](crate::guard)'s, and the run around it (stride, storage,
//! observers) is the [`run`](crate::run) driver's.

pub(crate) mod classical;
pub(crate) mod map;
mod reverse;

pub(crate) use map::StepMap;
pub(crate) use reverse::Reverse;

use crate::base_map::BaseMap;
use crate::composition::Composition;
use crate::error::StepError;
use crate::guard::Guard;
pub use crate::report::StepInfo;
use crate::system::ConstrainedSystem;

/// Which map a step is: SHAKE S_h (onto M) or RATTLE R_h = Π ∘ S_h (onto M^H).
///
/// ```
/// use geoshake_runtime::{Integrator, ImplicitMidpoint, Method, examples::Pendulum};
/// let integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1).shake();
/// assert_eq!(integ.method(), Method::Shake);
/// ```
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Default)]
pub enum Method {
    /// Geometric SHAKE (Definition 1.1): states stay on M, the hidden
    /// constraint residual is O(h).
    Shake,
    /// Geometric RATTLE (Definition 1.2): states on M^H.
    #[default]
    Rattle,
}

/// One step of the integrator: the substeps γ_k h of a composition (one
/// substep of size h without one) on a [`StepMap`], and the reverse check
/// of composed steps (`reverse`) on a second one.
#[derive(Clone, Debug)]
pub(crate) struct Composed<B: BaseMap> {
    pub(crate) composition: Composition,
    pub(crate) map: StepMap<B>,
    /// The buffers of a composed step's reverse check, made before the
    /// first composed step that needs them.
    pub(crate) reverse: Option<Reverse<B>>,
    /// λ of the first substep of the last composed step (kept only with
    /// diagnostics): the multiplier of the step leaving the state.
    pub(crate) lead_lambda: Vec<f64>,
}

/// Where a step runs: inside a run (`carry`, Kahan's carry of the state,
/// when the run is compensated), with diagnostics or not, and the index
/// and time of the state it computes.
pub(crate) struct Within<'a> {
    pub(crate) carry: Option<&'a mut [f64]>,
    pub(crate) in_run: bool,
    pub(crate) diagnostics: bool,
    pub(crate) step: u64,
    pub(crate) t: f64,
}

impl<B: BaseMap> Composed<B> {
    /// The single step over `map` for a system of m constraints.
    pub(crate) fn new(map: StepMap<B>, m: usize) -> Self {
        Composed {
            composition: Composition::SINGLE,
            map,
            reverse: None,
            lead_lambda: vec![0.0; m],
        }
    }

    /// One step of size `h` from (q, p), in place: the substeps γ_k h of
    /// the composition, each a SHAKE step, projected onto M^H unless it is
    /// the last one and `project` is false, and each checked by `guard`.
    /// Iteration counts are summed over the substeps, ‖λ‖ and the
    /// condition of N are the largest.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn advance<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        guard: &mut Guard,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        project: bool,
        mut at: Within<'_>,
    ) -> Result<StepInfo, StepError> {
        let (step, t) = (at.step, at.t);
        let gammas = self.composition.coefficients();
        if gammas.len() == 1 {
            return self
                .map
                .apply(sys, guard, q, p, h, project, at.carry, step, t);
        }
        let last = gammas.len() - 1;
        // Π of a composed step's result is the run's to make: a request
        // (`StepMap::show`) is for one substep's.
        self.map.show = false;
        let reverse = self.reverse_checked(sys, guard);
        if reverse {
            self.keep_start(sys, q, p);
        }
        let mut total = StepInfo::default();
        for (k, &gamma) in gammas.iter().enumerate() {
            let project_k = project || k < last;
            let carry = at.carry.as_deref_mut();
            let info = self
                .map
                .apply(sys, guard, q, p, gamma * h, project_k, carry, step, t)?;
            if k == 0 && at.diagnostics {
                self.lead_lambda.copy_from_slice(&self.map.ws.lambda);
            }
            total.shake_iterations += info.shake_iterations;
            total.shake_iterations_total += info.shake_iterations_total;
            total.base_iterations += info.base_iterations;
            total.rattle_iterations += info.rattle_iterations;
            total.lambda = total.lambda.max(info.lambda);
            total.condition = total.condition.max(info.condition);
            total.fold = total.fold.max(info.fold);
            total.det_n = info.det_n;
        }
        if reverse {
            // Inside a run with every step projected the start is on M^H;
            // elsewhere (a lazy run, SHAKE, a single step from a state of
            // the caller's) the step back returns Π of it.
            let start_on_mh = project && at.in_run;
            self.reverse(sys, guard, h, q, p, project, start_on_mh, step, t)?;
        }
        Ok(total)
    }
}
