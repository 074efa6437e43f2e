//! The forces of the constraints and their virial: what a molecular-dynamics
//! code reports as the constraint contribution to the pressure.

use super::{ParticleState, ParticleSystem, Rattle};
use crate::error::StepError;

/// The constraint forces of one RATTLE or SHAKE step, filled by
/// [`Rattle::constraint_forces`].
///
/// The position stage of the step from q0 (the paper's Section 5.1.3) moves
/// the unconstrained update by the multipliers of the constraint forces:
/// p½ = p0 − (h/2) ∇V(q0) − (h/2) G(q0)ᵀ Λ, q1 = q0 + h M⁻¹ p½, so that
/// q1 = q0 + h M⁻¹ p0 + (h²/2) M⁻¹ (−∇V(q0) + f_c), the velocity-Verlet
/// form with the constraint force
///
///   f_c = −G(q0)ᵀ Λ = −Σ_k Λ_k ∇g_k(q0)
///
/// acting at the start of the step, q0, at time t0 + (k−1)·h. This is the
/// force SHAKE codes add to the atoms (LAMMPS' `fix shake` and `fix
/// rattle`), and its virial
///
///   W = Σ_a x_a ⊗ f_{c,a}   (D×D),
///
/// their constraint virial: the constraint part of the pressure tensor is
/// W / V for a box of volume V (LAMMPS' sign: P V = N k T + tr(W_total)/3
/// in 3-D). For a distance constraint g_k = |x_a − x_b|² − l_k², the bond's
/// tension is 2 Λ_k l_k (positive when it pulls the two particles together).
///
/// Allocated once for a system ([`ConstraintForces::new`]) and filled after
/// each step without allocating.
///
/// ```
/// use geoshake_runtime::particles::{generate, ConstraintForces, Options, Rattle};
/// let (system, mut state) = generate::water(8, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// generate::set_temperature(rattle.system(), &mut state, 300.0);
/// let mut fc = ConstraintForces::new(rattle.system());
/// rattle.step(&mut state).unwrap();
/// rattle.constraint_forces(&state, &mut fc).unwrap();
/// // Rigid waters only: the constraint forces balance (Newton's third law)
/// // and their virial is symmetric (they exert no torque).
/// let total: f64 = fc.forces.iter().step_by(3).sum();
/// assert!(total.abs() < 1e-9 * fc.forces.iter().map(|f| f.abs()).sum::<f64>());
/// assert!((fc.virial[1] - fc.virial[3]).abs() < 1e-9 * fc.virial[0].abs());
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ConstraintForces {
    /// Λ_k of every constraint: the families in the order they were added,
    /// each family's members in the order of its table.
    pub multipliers: Vec<f64>,
    /// f_c, D entries per particle (the layout of q).
    pub forces: Vec<f64>,
    /// W = Σ_a x_a ⊗ f_{c,a}, D×D row-major: `virial[r * D + c]` = Σ_a
    /// x_{a,r} f_{c,a,c}.
    pub virial: Vec<f64>,
    /// The step the forces belong to: the one that made the state given
    /// to [`Rattle::constraint_forces`] (k; the forces act at step k − 1).
    pub step: u64,
    /// The time of q0, where the forces act: t0 + (k−1)·h.
    pub time: f64,
}

impl ConstraintForces {
    /// Buffers for `system`: one multiplier per constraint, D per particle,
    /// D² for the virial; zero until filled.
    pub fn new(system: &ParticleSystem) -> Self {
        let d = system.dim();
        ConstraintForces {
            multipliers: vec![0.0; system.constraints()],
            forces: vec![0.0; system.particles() * d],
            virial: vec![0.0; d * d],
            step: 0,
            time: f64::NAN,
        }
    }

    /// tr(W), the constraints' part of 3·P·V in 3-D (D·P·V in D dimensions).
    pub fn virial_trace(&self) -> f64 {
        let d = (self.virial.len() as f64).sqrt() as usize;
        (0..d).map(|r| self.virial[r * d + r]).sum()
    }
}

impl Rattle {
    /// The constraint forces, their multipliers and their virial
    /// ([`ConstraintForces`]) of the RATTLE or SHAKE step that made
    /// `state`, from the multipliers that step solved for (no solve, one
    /// pass over the constraints).
    ///
    /// Refused with [`StepError::Unavailable`] when `state` is not the last
    /// state this solver made by a RATTLE or SHAKE step: the initial data,
    /// a state after [`project`](Self::project), a state changed by hand,
    /// an older state, or one made by a thermostatted step (a (g-)BAOAB
    /// step spreads the constraint forces over its drifts and projections,
    /// so it has no single f_c at q0); with [`StepError::Shape`] when `out`
    /// was made for another system; with [`StepError::NonFinite`] when a
    /// multiplier, force or virial entry overflows (h near the bottom of
    /// f64's range: Λ = 2ν/h²).
    pub fn constraint_forces(
        &self,
        state: &ParticleState,
        out: &mut ConstraintForces,
    ) -> Result<(), StepError> {
        let system = self.system();
        let d = system.dim();
        for (what, got, expected) in [
            (
                "ConstraintForces::multipliers",
                out.multipliers.len(),
                system.constraints(),
            ),
            (
                "ConstraintForces::forces",
                out.forces.len(),
                system.particles() * d,
            ),
            ("ConstraintForces::virial", out.virial.len(), d * d),
        ] {
            if got != expected {
                return Err(StepError::Shape {
                    what,
                    got,
                    expected,
                });
            }
        }
        self.check_shape(&state.q, &state.p)?;
        let Some((nu, q0)) = self.last_position_stage(state) else {
            return Err(StepError::Unavailable {
                what: "constraint forces",
                why: "the state is not the last one a RATTLE or SHAKE step of this solver made \
                      (initial data, a projection, a thermostatted step, an older state or one \
                      changed by hand)",
            });
        };
        // ν = h λ with p½ = p̃ − G(q0)ᵀ ν / h: (h/2) Λ = ν / h.
        let scale = 2.0 / (self.h * self.h);
        out.multipliers
            .iter_mut()
            .zip(nu)
            .for_each(|(l, n)| *l = scale * n);
        out.forces.fill(0.0);
        out.virial.fill(0.0);
        let mut c0 = 0;
        for fam in system.constraint_families() {
            let c1 = c0 + fam.table().len();
            fam.forces_virial(
                q0,
                &out.multipliers[c0..c1],
                1.0,
                &mut out.forces,
                &mut out.virial,
            );
            c0 = c1;
        }
        out.step = state.step;
        out.time = state.time - self.h;
        // Λ = 2ν/h² overflows for a step size near the bottom of f64's
        // range: a typed error, not forces of NaN or ∞.
        for (what, v) in [
            ("constraint multipliers", &out.multipliers),
            ("constraint forces", &out.forces),
            ("constraint virial", &out.virial),
        ] {
            Rattle::not_finite(state.step, state.time, what, v, 0)?;
        }
        Ok(())
    }
}
