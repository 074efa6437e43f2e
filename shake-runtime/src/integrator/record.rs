//! Storing one state of a run: its projection onto M^H when the run
//! projects lazily (Π ∘ S_hᵏ = Π ∘ R_hᵏ, see [`rattle`](crate::rattle)),
//! its diagnostics record, the observer call and the trajectory push.

use crate::base_map::BaseMap;
use crate::diagnostics::{Accumulator, DiagnosticRecord};
use crate::error::StepError;
use crate::integrator::Integrator;
use crate::linalg::norm_inf;
use crate::rattle::project_hidden;
use crate::state::State;
use crate::step::Method;
use crate::system::ConstrainedSystem;
use crate::trajectory::Trajectory;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// With diagnostics, after the step leaving the last recorded state:
    /// writes that step's λ (of its first substep) into the record. A
    /// RATTLE run that projects only the states it records stepped from
    /// the SHAKE state z⁻, so its λ also carries the projection's σ (same
    /// fibre, same point: the parameters add); σ is taken off so that the
    /// record's λ is RATTLE's, from the state on M^H.
    pub(crate) fn fill_leaving_lambda(&mut self, traj: &mut Trajectory, per_step: bool) {
        let m = self.system.constraint_count();
        let lead = if self.steps.composition.stages() == 1 {
            &self.steps.map.ws.lambda
        } else {
            &self.steps.lead_lambda
        };
        let subtract = self.method == Method::Rattle && !per_step;
        if let Some((lambda, sigma)) = traj.last_multipliers_mut() {
            for j in 0..m {
                lambda[j] = lead[j] - if subtract { sigma[j] } else { 0.0 };
            }
        }
    }

    /// A lazily projecting RATTLE run failed at step k, and the SHAKE states
    /// after its last stored one (step `from`, SHAKE state (q, p)) were
    /// never projected: replays them, projecting each as a stored state
    /// would be, so that the run can end at the last step whose RATTLE state
    /// exists. Returns that step (its SHAKE state left in (q, p)) and the
    /// projection's error where one failed before step k. Runs only on
    /// failure; the replayed steps equal the original ones to round-off.
    pub(crate) fn replay_lazy(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        from: u64,
        k: u64,
        t0: f64,
    ) -> (u64, Option<StepError>) {
        let h = self.h;
        let mut scratch = State::from_slices(q, p);
        let (mut acc, mut unused) = (Accumulator::default(), Trajectory::default());
        let (mut good_q, mut good_p) = (q.to_vec(), p.to_vec());
        let mut good = from;
        // The compensated sum's carry is that of the failed step (NaN, for
        // a step that overflowed): the replay starts without one.
        self.carry.fill(0.0);
        for j in from + 1..k {
            let t = t0 + j as f64 * h;
            // Round-off can make a replayed step fail where the original
            // passed: then that step is the failing one.
            if let Err(e) = self.advance(q, p, false, j, t) {
                q.copy_from_slice(&good_q);
                p.copy_from_slice(&good_p);
                return (good, Some(e.at(j, t)));
            }
            let shown = &mut |_: u64, _: f64, _: &State| {};
            let r = self.record(
                q,
                p,
                false,
                j,
                t,
                &mut acc,
                &mut unused,
                false,
                shown,
                &mut scratch,
            );
            if let Err(e) = r {
                q.copy_from_slice(&good_q);
                p.copy_from_slice(&good_p);
                return (good, Some(e.at(j, t)));
            }
            good = j;
            good_q.copy_from_slice(q);
            good_p.copy_from_slice(p);
        }
        q.copy_from_slice(&good_q);
        p.copy_from_slice(&good_p);
        (good, None)
    }

    /// Π of a copy of step k's SHAKE state, in place in `z`, for a lazily
    /// projecting RATTLE run; returns Π's Newton iterations.
    fn project_shown(&mut self, z: &mut State, k: u64, t: f64) -> Result<usize, StepError> {
        if self.steps.map.n_fresh && self.steps.map.fast_paths {
            // The classical path: N at this q is factorised and checked.
            crate::shake::classical::project(
                &self.system,
                z.q.as_slice(),
                z.p.as_mut_slice(),
                &mut self.steps.map.ws,
            );
            return Ok(1);
        }
        let pr = project_hidden(
            &self.system,
            z.q.as_mut_slice(),
            z.p.as_mut_slice(),
            &mut self.steps.map.ws,
            self.guard.newton(),
        )
        .map_err(|e| e.at(k, t))?;
        // The stored state is the projection of the SHAKE state z⁻ of
        // this step: it must be the nearby crossing of the fibre with
        // M^H, on the component the run is on.
        self.guard.after_lazy_projection(
            &self.system,
            z.q.as_slice(),
            z.p.as_slice(),
            &mut self.steps.map.ws,
            &pr,
            self.h,
            k,
            t,
        )?;
        Ok(pr.iterations)
    }

    /// Stores (and shows to the observer) the state (q, p) at step k.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn record<F: FnMut(u64, f64, &State)>(
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
        let lazy = self.method == Method::Rattle && !projected;
        let rattle_iterations = if lazy && self.steps.map.shown_fresh {
            // The step that made (q, p) also made its Π (`StepMap::show`),
            // with the operations of `geoshake::classical::project`.
            std::mem::swap(scratch, &mut self.steps.map.shown);
            self.steps.map.shown_fresh = false;
            1
        } else {
            scratch.q.as_mut_slice().copy_from_slice(q);
            scratch.p.as_mut_slice().copy_from_slice(p);
            if lazy {
                self.project_shown(scratch, k, t)?
            } else {
                0
            }
        };
        // NaN or ∞ (a parameter that overflows the projection) is an error
        // at this step, never a stored state.
        crate::guard::Guard::finite(
            scratch.q.as_slice(),
            scratch.p.as_slice(),
            "projected state",
            k,
            t,
        )?;
        if self.diagnostics {
            let (sq, sp) = (scratch.q.as_slice(), scratch.p.as_slice());
            let (mut constraint, mut hidden) = (0.0, 0.0);
            if self.system.constraint_count() > 0 {
                self.system.constraints(sq, sp, &mut self.steps.map.ws.g);
                self.system
                    .hidden_constraints(sq, sp, &mut self.steps.map.ws.hidden);
                constraint = norm_inf(&self.steps.map.ws.g);
                hidden = norm_inf(&self.steps.map.ws.hidden);
            }
            traj.diagnostics.push(DiagnosticRecord {
                step: k,
                t,
                energy: self.system.hamiltonian(sq, sp),
                constraint,
                hidden_constraint: hidden,
                max_shake_iterations: acc.shake,
                max_base_iterations: acc.base,
                rattle_iterations,
                max_lambda: acc.lambda,
                max_condition: acc.condition,
            });
            // σ: the projection that gave this state, done just now or
            // (projected) by the last substep; λ is known only once the
            // step leaving the state is taken (`execute` fills it in).
            traj.push_multipliers(
                (self.method == Method::Rattle).then_some(self.steps.map.ws.sigma.as_slice()),
            );
            *acc = Accumulator::default();
        }
        observer(k, t, scratch);
        if store {
            traj.push(k, scratch.q.as_slice(), scratch.p.as_slice());
        }
        Ok(())
    }
}
