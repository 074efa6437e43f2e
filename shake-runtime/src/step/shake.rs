//! One substep: SHAKE of size γh from (q, p) in place, then Π if asked,
//! each result handed to the [`Guard`](crate::guard).
//!
//! Two paths compute the same map (to round-off, `tests/fast_paths.rs`):
//! the general one, a Newton iteration on λ through the base map and the
//! fibre flow (`crate::shake`), and the classical one for holonomic
//! constraints, a separable H with constant mass matrix and a
//! kick–drift–kick base map (`crate::classical`).

use crate::base_map::BaseMap;
use crate::error::StepError;
use crate::guard::Guard;
use crate::integrator::Integrator;
use crate::rattle::project_hidden;
use crate::shake::shake_step;
use crate::step::StepInfo;
use crate::system::ConstrainedSystem;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// One SHAKE step of size `h` from (q, p), in place, then (if
    /// `project`) Π, then the checks.
    pub(crate) fn substep(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        self.n_fresh = false;
        if let (Some(kdk), true) = (self.classical, self.fast_paths) {
            return self.classical_substep(q, p, h, project, step, t, kdk);
        }
        let newton = *self.guard.newton();
        // Inside a run the increment is added with Kahan's compensation
        // (its carry is kept across the run's steps).
        let carry = if self.compensated && self.carrying {
            Some(self.carry.as_mut_slice())
        } else {
            None
        };
        let report = shake_step(
            &self.system,
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
            base_iterations: report.base_iterations,
            lambda: report.lambda,
            ..StepInfo::default()
        };
        if project {
            let pr = project_hidden(&self.system, q, p, &mut self.ws, &newton)
                .map_err(|e| e.at(step, t))?;
            info.rattle_iterations = pr.iterations;
            self.guard.after_projection(&pr, h, step, t)?;
        }
        Guard::finite(q, p, "state", step, t)?;
        if self.system.constraint_count() == 0 {
            return Ok(info);
        }
        // Newton's stopping rule looks at the size of its updates, not at
        // the residual; far outside its basin (absurd h) it can stop on a
        // huge λ with g ≠ 0. Such a state is refused here: a step never
        // returns a point off M. (The tolerance's scale ‖∂g_i/∂z‖₁ is
        // measured at the new state.)
        self.system.constraints(q, p, &mut self.ws.g);
        self.system.constraint_jacobian(q, p, &mut self.ws.g_z_1);
        crate::validate::gradient_sizes(&self.ws.pattern, &self.ws.g_z_1, &mut self.ws.g_size);
        self.guard.after_shake(
            &self.system,
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

    /// [`substep`](Self::substep) on the classical path (see `classical`):
    /// SHAKE with its own Newton iteration, then one evaluation and
    /// factorisation of N at the new q for the checks and (if `project`)
    /// for Π, which is one linear solve.
    #[allow(clippy::too_many_arguments)]
    fn classical_substep(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        h: f64,
        project: bool,
        step: u64,
        t: f64,
        kdk: (f64, f64),
    ) -> Result<StepInfo, StepError> {
        let newton = *self.guard.newton();
        let carrying = self.compensated && self.carrying;
        if self.fixed_size {
            let carry = carrying.then_some(self.carry.as_mut_slice());
            let cx = crate::classical::fixed::Substep {
                q: &mut *q,
                p: &mut *p,
                h,
                kdk,
                project,
                step,
                t,
                newton,
                guard: &mut self.guard,
                ws: &mut self.ws,
                carry,
            };
            if let Some(result) = self.system.classical_fixed(cx) {
                self.n_fresh = result.is_ok();
                return result;
            }
        }
        let carry = carrying.then_some(self.carry.as_mut_slice());
        let report =
            crate::classical::shake_step(&self.system, kdk, h, q, p, &mut self.ws, &newton, carry)
                .map_err(|e| e.at(step, t))?;
        let mut info = StepInfo {
            shake_iterations: report.iterations,
            lambda: report.lambda,
            ..StepInfo::default()
        };
        Guard::finite(q, p, "state", step, t)?;
        // g at the new state was the last residual of SHAKE's iteration
        // (the state is z0 + Δ, rounded once more by the addition); the
        // tolerance's scale ‖∂g_i/∂z‖₁ is G0's, at the start of the step.
        crate::validate::gradient_sizes(
            &self.ws.classical.pattern,
            &self.ws.g_z_y,
            &mut self.ws.g_size,
        );
        self.guard.after_shake(
            &self.system,
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
        self.n_fresh = true;
        if project {
            // Linear in σ: one solve, no second root to jump to.
            crate::classical::project(&self.system, q, p, &mut self.ws);
            info.rattle_iterations = 1;
        }
        Ok(info)
    }
}
