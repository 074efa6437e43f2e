//! The forces and the potential energy of a [`Rattle`]'s system: ∇V(q) and
//! V(q) evaluated into the solver's cache, which a step from the state
//! they belong to reuses.

use super::Rattle;
use crate::error::StepError;
use crate::particles::ParticleState;

impl Rattle {
    /// ∇V(q) into `self.force` and V(q) into `self.potential`; a
    /// non-finite force is reported at the entry of p it would change.
    pub(super) fn forces(&mut self, q: &[f64], step: u64, time: f64) -> Result<(), StepError> {
        // Until the caller says whose they are, the forces are nobody's.
        self.force_stamp = 0;
        self.potential = self.system.potential_gradient(q, &mut self.force);
        Self::not_finite(step, time, "forces ∇V(q)", &self.force, q.len())
    }

    /// The potential energy V(q) = Σ_fam V_fam(q) + V_ext(q) of `state`
    /// (0 without a potential): read from the last step when `state` is
    /// the one it made, else one evaluation of the forces, which the next
    /// step from `state` then reuses. With
    /// [`ParticleSystem::kinetic_energy`] this gives H along a run at no
    /// extra cost.
    ///
    /// [`ParticleSystem::kinetic_energy`]: crate::particles::ParticleSystem::kinetic_energy
    ///
    /// ```
    /// use geoshake_runtime::particles::{generate, Options, Rattle};
    /// let (system, mut state) = generate::water(8, 1).unwrap();
    /// // A weak harmonic tether of every atom to the origin, brought as forces.
    /// let system = system.with_forces(|q: &[f64], f: &mut [f64]| {
    ///     f.iter_mut().zip(q).for_each(|(f, q)| *f -= 1e-3 * q);
    ///     0.5e-3 * q.iter().map(|q| q * q).sum::<f64>()
    /// });
    /// let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    /// rattle.project(&mut state).unwrap();
    /// generate::set_temperature(rattle.system(), &mut state, 300.0);
    /// let energy = |r: &mut Rattle, s: &_| {
    ///     r.potential_energy(s).unwrap() + r.system().kinetic_energy(s.p())
    /// };
    /// let h0 = energy(&mut rattle, &state);
    /// assert!(rattle.run_in_place(&mut state, 100).error.is_none());
    /// assert!(((energy(&mut rattle, &state) - h0) / h0).abs() < 1e-3);
    /// ```
    pub fn potential_energy(&mut self, state: &ParticleState) -> Result<f64, StepError> {
        self.check_shape(&state.q, &state.p)?;
        if !self.has_potential {
            return Ok(0.0);
        }
        if state.stamp == 0 || self.force_stamp != state.stamp {
            self.forces(&state.q, state.step, state.time)?;
            // The forces now held are this state's (a state changed by hand
            // has stamp 0 and ties to nothing).
            self.force_stamp = state.stamp;
        }
        // Finite forces do not make V finite (a field of 1e300 times a
        // coordinate of 1e10).
        if !self.potential.is_finite() {
            return Err(StepError::NonFinite {
                what: "potential energy V(q)",
                step: state.step,
                t: state.time,
                entry: 0,
            });
        }
        Ok(self.potential)
    }
}
