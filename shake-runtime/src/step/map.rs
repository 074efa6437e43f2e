//! The substep map: SHAKE S_{γh} from (q, p) in place, then Π if asked
//! (R_{γh} = Π ∘ S_{γh}), each result handed to the
//! [`Guard`](crate::guard). [`StepMap`] holds the base map and every
//! buffer the map needs, so that a second one (the reverse check's) runs
//! beside the first without touching it.
//!
//! Two paths compute the same map (to round-off, `tests/suite/fast_paths.rs`):
//! the general one, a Newton iteration on λ through the base map and the
//! fibre flow (`crate::shake`), and the classical one for holonomic
//! constraints, a separable H with constant mass matrix and a
//! kick–drift–kick base map (`crate::shake::classical`).

use crate::base_map::BaseMap;
use crate::error::StepError;
use crate::guard::Guard;
use crate::rattle::project_hidden;
use crate::report::StepInfo;
use crate::shake::{shake_step, Workspace};
use crate::state::State;
use crate::system::ConstrainedSystem;

/// SHAKE (and Π) over the base map `B`, with its own workspaces.
#[derive(Clone, Debug)]
pub(crate) struct StepMap<B: BaseMap> {
    pub(crate) base: B,
    /// SHAKE's and Π's buffers, and N at the last checked state.
    pub(crate) ws: Workspace,
    /// The base map's own buffers.
    pub(crate) base_ws: B::Workspace,
    /// The kick fractions of the base map when the classical path applies
    /// (see `classical`), and whether it is used.
    pub(crate) classical: Option<(f64, f64)>,
    pub(crate) fast_paths: bool,
    /// Whether the fast classical path may use the system's fixed-size
    /// step (`geoshake::classical::fixed`, `geoshake::classical::fixed_m`) when it has one.
    pub(crate) fixed_size: bool,
    /// `ws.jac`/`ws.piv` hold the factors of N at the current state's q
    /// (set by the classical step's check and by `Integrator::begin`).
    pub(crate) n_fresh: bool,
    /// A request, for the next [`apply`](Self::apply) only (it resets it):
    /// when that substep is not projected, also write Π of its result
    /// into `shown` if the path can do so where its numbers are (the
    /// fixed-size classical step), for a lazily projecting run to show
    /// (`run::record`, which otherwise projects a copy itself).
    pub(crate) show: bool,
    /// Π of the last substep's result, valid when `shown_fresh`: the same
    /// operations on the same numbers as `geoshake::classical::project`.
    pub(crate) shown: State,
    pub(crate) shown_fresh: bool,
}

impl<B: BaseMap> StepMap<B> {
    /// The map for `sys` over `base`, its buffers allocated.
    pub(crate) fn new<S: ConstrainedSystem>(sys: &S, base: B) -> Self {
        let classical = crate::shake::classical::classical(sys, &base);
        StepMap {
            ws: Workspace::new(sys, classical.is_some()),
            base_ws: base.workspace(sys.dof()),
            classical,
            base,
            fast_paths: true,
            fixed_size: true,
            n_fresh: false,
            show: false,
            shown: State::zeros(sys.dof()),
            shown_fresh: false,
        }
    }

    /// One SHAKE step of size `h` from (q, p), in place, then (if
    /// `project`) Π, then `guard`'s checks. `carry` is Kahan's carry of
    /// the state inside a run (the increment is added with it), `step`
    /// and `t` the index and time of the state computed.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn apply<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        guard: &mut Guard,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        carry: Option<&mut [f64]>,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        self.n_fresh = false;
        self.shown_fresh = false;
        let show = std::mem::take(&mut self.show) && !project;
        if let (Some(kdk), true) = (self.classical, self.fast_paths) {
            return self.classical_step(sys, guard, q, p, h, project, carry, step, t, kdk, show);
        }
        let newton = *guard.newton();
        let report = shake_step(
            sys,
            &self.base,
            h,
            q,
            p,
            &mut self.ws,
            &mut self.base_ws,
            &newton,
            carry,
        )
        .map_err(|e| e.at(step, t))?;
        let mut info = StepInfo {
            shake_iterations: report.iterations,
            shake_iterations_total: report.iterations as u64,
            base_iterations: report.base_iterations,
            lambda: report.lambda,
            ..StepInfo::default()
        };
        if project {
            let pr = project_hidden(sys, q, p, &mut self.ws, &newton).map_err(|e| e.at(step, t))?;
            info.rattle_iterations = pr.iterations;
            guard.after_projection(&pr, h, step, t)?;
        }
        Guard::finite(q, p, "state", step, t)?;
        if sys.constraint_count() == 0 {
            return Ok(info);
        }
        // Newton's stopping rule looks at the size of its updates, not at
        // the residual; far outside its basin (absurd h) it can stop on a
        // huge λ with g ≠ 0. Such a state is refused here: a step never
        // returns a point off M. (The tolerance's scale ‖∂g_i/∂z‖₁ is
        // measured at the new state.)
        sys.constraints(q, p, &mut self.ws.g);
        sys.constraint_jacobian(q, p, &mut self.ws.g_z_1);
        crate::tolerance::gradient_sizes(&self.ws.pattern, &self.ws.g_z_1, &mut self.ws.g_size);
        guard.after_shake(
            sys,
            q,
            p,
            &mut self.ws,
            &report,
            &mut info,
            project,
            h,
            step,
            t,
        )?;
        Ok(info)
    }

    /// [`apply`](Self::apply) on the classical path (see `classical`):
    /// SHAKE with its own Newton iteration, then one evaluation and
    /// factorisation of N at the new q for the checks and (if `project`)
    /// for Π, which is one linear solve. `show`: write Π of the result
    /// into `shown` where the fixed-size step runs (see `show`).
    #[allow(clippy::too_many_arguments)]
    fn classical_step<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        guard: &mut Guard,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        mut carry: Option<&mut [f64]>,
        step: u64,
        t: f64,
        kdk: (f64, f64),
        show: bool,
    ) -> Result<StepInfo, StepError> {
        let newton = *guard.newton();
        if self.fixed_size {
            let cx = super::classical::Substep {
                q: &mut *q,
                p: &mut *p,
                h,
                kdk,
                project,
                step,
                t,
                newton,
                guard: &mut *guard,
                ws: &mut self.ws,
                carry: carry.as_deref_mut(),
                show: show.then_some(&mut self.shown),
            };
            if let Some(result) = sys.with_sizes(cx) {
                self.n_fresh = result.is_ok();
                // (A fixed-size substep that succeeds has written Π there.)
                self.shown_fresh = show && result.is_ok();
                return result;
            }
        }
        let report =
            crate::shake::classical::shake_step(sys, kdk, h, q, p, &mut self.ws, &newton, carry)
                .map_err(|e| e.at(step, t))?;
        let info = super::classical::check_and_project(
            sys,
            q,
            p,
            &mut self.ws,
            guard,
            &report,
            project,
            h,
            step,
            t,
        )?;
        // N at this q is factorised (the lazy Π of a stored state uses it).
        self.n_fresh = true;
        Ok(info)
    }
}
