//! Single steps of an [`Integrator`] outside a run: the checks of h and of
//! a state's dimensions, the validation of a starting state, one step in
//! place or into a new state (S_h for SHAKE, R_h for RATTLE), S_h alone
//! for a RATTLE integrator, and the step a run's driver takes through the
//! same guard and Kahan carry.

use super::Integrator;
use crate::base_map::BaseMap;
use crate::error::StepError;
use crate::report::StepInfo;
use crate::state::State;
use crate::step::{Method, Within};
use crate::system::ConstrainedSystem;
use crate::validate;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    pub(crate) fn check_h(&self) -> Result<(), StepError> {
        validate::step_size(self.h)?;
        validate::options(&self.guard.options)
    }

    pub(crate) fn check_dims(&self, z: &State) -> Result<(), StepError> {
        if z.q.len() != self.system.dof() || z.p.len() != self.system.dof() {
            return Err(StepError::InvalidInput {
                what: "state dimension differs from the system's DOF",
                value: z.q.len().max(z.p.len()) as f64,
            });
        }
        Ok(())
    }

    /// Validates a starting state (finite, on M, N well conditioned) and
    /// resets the guard's reference ‖N‖ and det N and the Kahan carry to it.
    pub(crate) fn begin(
        &mut self,
        q: &[f64],
        p: &[f64],
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        self.check_h()?;
        self.carry.fill(0.0);
        // The guard and N's buffers now describe this state: a later
        // single step from the state `step_in_place` returned before must
        // start afresh, not resume from them.
        self.checked_valid = false;
        // No Π of an earlier state may be shown for this one.
        (self.steps.map.show, self.steps.map.shown_fresh) = (false, false);
        self.guard
            .start(&self.system, q, p, &mut self.steps.map.ws, step, t)?;
        if self.system.constraint_count() > 0 {
            // `start` factorised N at this q (the classical path reuses it).
            self.steps.map.n_fresh = self.steps.map.classical.is_some();
        }
        if self.steps.reverse_checked(&self.system, &self.guard) {
            self.steps.reverse_buffers(&self.system);
        }
        Ok(())
    }

    /// One step in place, allocation-free: z ← S_h(z) or R_h(z).
    ///
    /// Like [`step`](Self::step), the checks of nondegeneracy compare the new
    /// state with `z`. On error `z` is left unchanged.
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1).shake();
    /// let mut z = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
    /// integ.step_in_place(&mut z).unwrap();
    /// let mut g = [0.0];
    /// integ.system().constraints(z.q.as_slice(), z.p.as_slice(), &mut g);
    /// assert!(g[0].abs() < 1e-15);
    /// ```
    pub fn step_in_place(&mut self, z: &mut State) -> Result<StepInfo, StepError> {
        self.step_in_place_projecting(z, self.method == Method::Rattle)
    }

    /// [`step_in_place`](Self::step_in_place), with Π (R_h) or without
    /// (S_h).
    fn step_in_place_projecting(
        &mut self,
        z: &mut State,
        project: bool,
    ) -> Result<StepInfo, StepError> {
        self.check_dims(z)?;
        let d = self.system.dof();
        if self.steps.map.fast_paths
            && self.checked_valid
            && self.system.constraint_count() > 0
            && z.q.as_slice() == &self.checked[..d]
            && z.p.as_slice() == &self.checked[d..]
        {
            // The result of the last step, checked there (finite, on M,
            // N's condition relative to the step before, which bounds the
            // condition begin() would compute): take its N as this step's
            // reference instead of evaluating and factorising it again.
            // h and the options, validated once for as long as they stay.
            if self.valid_h != self.h {
                self.check_h()?;
                self.valid_h = self.h;
            }
            self.guard.resume(self.checked_norm, self.checked_det);
        } else {
            self.checked_valid = false;
            self.begin(z.q.as_slice(), z.p.as_slice(), 0, 0.0)?;
        }
        self.carrying = false;
        // One substep a step: the fixed-size classical step straight on
        // z's numbers, the same substep `advance` reaches through the
        // step's layers (`tests/suite/run_lane.rs` compares the two).
        if self.steps.composition.stages() == 1 {
            let map = &mut self.steps.map;
            let fast = crate::run::lane::single(
                map,
                &self.system,
                &mut self.guard,
                z,
                &mut self.checked,
                self.h,
                project,
            );
            if let Some(res) = fast {
                self.checked_valid = res.is_ok();
                if res.is_ok() {
                    (self.checked_norm, self.checked_det) = self.guard.last();
                }
                return res;
            }
        }
        self.out_q.copy_from_slice(z.q.as_slice());
        self.out_p.copy_from_slice(z.p.as_slice());
        let mut q = std::mem::take(&mut self.out_q);
        let mut p = std::mem::take(&mut self.out_p);
        let res = self.advance(&mut q, &mut p, project, 1, self.h);
        if res.is_ok() {
            z.q.as_mut_slice().copy_from_slice(&q);
            z.p.as_mut_slice().copy_from_slice(&p);
            self.checked[..d].copy_from_slice(&q);
            self.checked[d..].copy_from_slice(&p);
            self.checked_valid = true;
            (self.checked_norm, self.checked_det) = self.guard.last();
        } else {
            // The guard now describes the refused state: a retry from z
            // must start afresh (`begin`), not resume from it.
            self.checked_valid = false;
        }
        self.out_q = q;
        self.out_p = p;
        res
    }

    /// Takes over `other`'s record of the last state its `step_in_place`
    /// returned and checked (finite, on M, ‖N‖₁ and det N there), so that
    /// a `step_in_place` of this integrator from that state resumes instead
    /// of checking it and factorising N again. For two integrators of one
    /// system and options that differ in h alone (the sampler's steps
    /// forward and back): N = {{H,g_i},g_j} does not depend on h.
    pub(crate) fn adopt_checked(&mut self, other: &Self) {
        self.checked.copy_from_slice(&other.checked);
        self.checked_valid = other.checked_valid;
        (self.checked_norm, self.checked_det) = (other.checked_norm, other.checked_det);
        // Π of this integrator's own last state is not Π of that one.
        (self.steps.map.show, self.steps.map.shown_fresh) = (false, false);
    }

    /// S_h(z) in place, whatever this integrator's method: for RATTLE the
    /// step without its Π, with every check of the new state that R_h
    /// makes (its solve, on M, N's condition, fibre and component jumps),
    /// so it fails exactly where R_h(z) would. For a caller that reads only
    /// the new positions, which S_h and R_h share (the sampler's step
    /// back, which must return to the start of the step it checks). On
    /// error z is left unchanged.
    pub(crate) fn shake_in_place(&mut self, z: &mut State) -> Result<(), StepError> {
        let res = self.step_in_place_projecting(z, false).map(|_| ());
        // z is S_h(z), off M^H for RATTLE: no step resumes from it.
        self.checked_valid = false;
        res
    }

    /// One step: S_h(z) for SHAKE (z ∈ M), R_h(z) for RATTLE (z ∈ M^H).
    ///
    /// The input must lie on M to [`Options::constraint_tolerance`] (relative to g's scale);
    /// errors report step 1 and t = h (the step from t0 = 0).
    ///
    /// [`Options::constraint_tolerance`]: crate::guard::Options::constraint_tolerance
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, ImplicitMidpoint, State, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), ImplicitMidpoint, 0.1);
    /// let z1 = integ.step(&State::from_slices(&[0.6, -0.8], &[0.8, 0.6])).unwrap();
    /// let mut hidden = [0.0];
    /// integ.system().hidden_constraints(z1.q.as_slice(), z1.p.as_slice(), &mut hidden);
    /// assert!(hidden[0].abs() < 1e-14);
    /// ```
    pub fn step(&mut self, z: &State) -> Result<State, StepError> {
        let mut z1 = z.clone();
        self.step_in_place(&mut z1)?;
        Ok(z1)
    }
}

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// One step from (q, p), in place (the step map's `Composed::advance`), with this
    /// integrator's system, guard, h, and (inside a run) Kahan carry.
    /// `step` is the index of the new state, `t` the time t0 + k·h of the
    /// state it computes.
    pub(crate) fn advance(
        &mut self,
        q: &mut [f64],
        p: &mut [f64],
        project: bool,
        step: u64,
        t: f64,
    ) -> Result<StepInfo, StepError> {
        let at = Within {
            carry: (self.compensated && self.carrying).then_some(self.carry.as_mut_slice()),
            in_run: self.carrying,
            diagnostics: self.diagnostics,
            step,
            t,
        };
        self.steps
            .advance(&self.system, &mut self.guard, self.h, q, p, project, at)
    }
}
