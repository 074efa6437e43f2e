//! Initial data onto M^H moving the momenta only: for a user whose
//! positions are exact (measured, or built by hand on the constraint) and
//! whose momenta are only a guess.
//!
//! [`Integrator::project_to_hidden`] first brings z onto M by Gauss–Newton
//! orthogonal to M, which moves q whenever g(q) ≠ 0 in floating point,
//! then applies RATTLE's projection Π. For holonomic constraints g(q) the
//! fibre flow exp(Σ σ_i X_{g_i}) is p ↦ p − g_q(q)ᵀσ (the paper's Section
//! 5.1): Π keeps q exactly and moves p along the constraint forces, the
//! physically right correction (M⁻¹-orthogonal for H = ½ pᵀM⁻¹p + V).
//! So [`Integrator::project_momenta_to_hidden`] checks that q is on M to
//! [`Options::constraint_tolerance`](crate::Options) and applies Π alone.
//! For constraints that depend on p the fibres move q too, and keeping q
//! would be another projection than the paper's: refused with a typed
//! error rather than done some other way.

use crate::base_map::BaseMap;
use crate::error::StepError;
use crate::guard::Guard;
use crate::integrator::Integrator;
use crate::state::State;
use crate::system::ConstrainedSystem;

impl<S: ConstrainedSystem, B: BaseMap> Integrator<S, B> {
    /// Moves p only, along the fibre (Π), onto M^H = {g = 0, {g,H} = 0};
    /// q is returned bit for bit. Errors: `NotOnConstraint` when
    /// ‖g(q)‖∞ exceeds the tolerance (q would have to move: use
    /// [`project_to_hidden`](Self::project_to_hidden)), `InvalidInput`
    /// for constraints that depend on p (their fibres move q), and those of
    /// [`project`](Self::project).
    ///
    /// ```
    /// use geoshake_runtime::{Integrator, StormerVerlet, State, StepError, ConstrainedSystem, examples::Pendulum};
    /// let mut integ = Integrator::new(Pendulum::default(), StormerVerlet, 0.1);
    /// // On the rod (an exact Pythagorean point), with a guessed velocity.
    /// let z = integ.project_momenta_to_hidden(&State::from_slices(&[0.6, -0.8], &[1.0, 1.0])).unwrap();
    /// assert_eq!(z.q.as_slice(), &[0.6, -0.8]);
    /// let mut gh = [0.0];
    /// integ.system().hidden_constraints(z.q.as_slice(), z.p.as_slice(), &mut gh);
    /// assert!(gh[0].abs() < 1e-15);
    /// // Off the rod: q would have to move.
    /// let off = State::from_slices(&[0.6, -0.81], &[1.0, 1.0]);
    /// assert!(matches!(integ.project_momenta_to_hidden(&off), Err(StepError::NotOnConstraint { .. })));
    /// ```
    pub fn project_momenta_to_hidden(&mut self, z: &State) -> Result<State, StepError> {
        let sys = self.system();
        let m = sys.constraint_count();
        if z.q.len() != sys.dof() || z.p.len() != sys.dof() {
            return Err(StepError::InvalidInput {
                what: "state dimension differs from the system's dof",
                value: z.q.len() as f64,
            });
        }
        if !sys.kind().is_holonomic() {
            return Err(StepError::InvalidInput {
                what: "keeping q needs holonomic constraints (the fibres of p-dependent ones move q); \
                       use project_to_hidden",
                value: m as f64,
            });
        }
        Guard::finite(z.q.as_slice(), z.p.as_slice(), "initial state", 0, 0.0)?;
        // (`project` refuses a state off M, relative to g's scale.)
        let out = self.project(z)?;
        // X_g of a holonomic g has no q component, so even a numerically
        // integrated fibre flow adds exact zeros to q.
        debug_assert_eq!(out.q, z.q, "Π moved q for holonomic constraints");
        Ok(out)
    }
}
