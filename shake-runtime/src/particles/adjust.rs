//! The constraints of an integrator that moves the particles itself (ASE's
//! dynamics, a hand-written velocity Verlet): SHAKE's position stage and
//! RATTLE's velocity stage as two calls on arrays, on the same solvers as
//! [`Rattle::step`].

use super::rattle::particle_report;
use super::Rattle;
use crate::error::{Stage, StepError};
use crate::report::StepInfo;

impl Rattle {
    /// SHAKE's position stage for positions moved by someone else's
    /// integrator: given the old positions q0 (on M) and new, unconstrained
    /// positions x̃ in `x`, replaces `x` by
    ///
    ///   x = x̃ − M⁻¹ G(q0)ᵀ ν,  with g(x) = 0,
    ///
    /// the point where the line of constraint forces at q0 (the fibre
    /// through x̃, the paper's Section 5.1.3) meets M. This is the
    /// equation of the position stage of [`step`](Self::step), solved by
    /// the same solver (Newton on each cluster, or on the coupled graph),
    /// to [`Options::tol`](super::Options::tol): with x̃ = q0 + h M⁻¹ p̃ the
    /// result is bit for bit the q1 of a SHAKE step with the same p̃, and
    /// (x − x̃) M / h is the constrained momentum's change, as a velocity
    /// Verlet loop computes it. The momenta are not touched.
    ///
    /// Refuses q0 or x of a length other than n·D ([`StepError::Shape`]),
    /// a NaN or infinite entry ([`StepError::NonFinite`], `entry` the index
    /// in the array named), and reports a Newton failure at the member
    /// where it happened ([`StepError::AtMember`], stage SHAKE; the result
    /// is judged at its own scale, |∇g(x)| · extent(x), whatever q0's);
    /// `x` is left as it was on error. Errors name step 0 and t = 0: the
    /// call belongs to no step of this solver. The caches a step reuses (N's
    /// factor, the multipliers, the constraint forces) are forgotten.
    ///
    /// ```
    /// use geoshake_runtime::particles::{stencils::Distance, Options, ParticleSystem, Rattle, Table};
    /// let mut bonds = Table::new(2, 1);
    /// bonds.push(&[0, 1], &[1.0]).unwrap();
    /// let system = ParticleSystem::new(3, vec![1.0, 3.0])
    ///     .unwrap()
    ///     .with_constraints("bond", Distance::<3>, bonds)
    ///     .unwrap();
    /// // The step size plays no part in these calls.
    /// let mut rattle = Rattle::new(system, 1.0, Options { tol: 1e-13, ..Options::default() }).unwrap();
    /// let q0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    /// let mut x = [0.0, 0.1, 0.0, 1.2, 0.0, 0.0]; // stretched to about 1.2
    /// rattle.shake_positions(&q0, &mut x).unwrap();
    /// let r: Vec<f64> = (0..3).map(|c| x[3 + c] - x[c]).collect();
    /// assert!((r.iter().map(|r| r * r).sum::<f64>().sqrt() - 1.0).abs() < 1e-13);
    /// // Moved along q0's bond only, the light particle three times as far.
    /// assert_eq!((x[1], x[2], x[4], x[5]), (0.1, 0.0, 0.0, 0.0));
    /// assert!((x[0] + 3.0 * (x[3] - 1.2)).abs() < 1e-14);
    /// ```
    pub fn shake_positions(&mut self, q0: &[f64], x: &mut [f64]) -> Result<StepInfo, StepError> {
        self.check_lengths([("q0", q0.len()), ("x", x.len())])?;
        // The stage overwrites ν and N's factor: no state may count as
        // continued afterwards.
        self.stamp = 0;
        Self::not_finite(0, 0.0, "old positions q0", q0, 0)?;
        Self::not_finite(0, 0.0, "new positions x", x, 0)?;
        self.qn.copy_from_slice(x);
        let mut report = particle_report();
        // inv_h = 0: the momenta (`pn`) are left alone. The equation is
        // SHAKE's, whatever the stage calls it without a step.
        self.position_stage(q0, 0, false, 0.0, 0, 0.0, &mut report)
            .map_err(|mut e| {
                if let StepError::AtMember { stage, .. } = &mut e {
                    *stage = Stage::Shake;
                }
                e
            })?;
        self.confirm_positions(0, 0.0, &report)?;
        x.copy_from_slice(&self.qn);
        Ok(report)
    }

    /// RATTLE's velocity stage for momenta made by someone else's
    /// integrator: replaces `p` by
    ///
    ///   p − G(q)ᵀ μ,  with G(q) M⁻¹ p = 0 afterwards,
    ///
    /// the projection of p onto the cotangent space of M at q along the
    /// constraint forces (one linear solve with N = G M⁻¹ Gᵀ per cluster,
    /// or on the coupled graph). The same solver as the velocity stage of
    /// [`step`](Self::step): for the q1 and p′ = p½ − (h/2) ∇V(q1) of a
    /// step the result is bit for bit that step's p1. q is not required to
    /// lie on M (the projection is taken wherever q is); a force array in
    /// place of `p` gives the forces' component tangent to M in the metric
    /// M⁻¹, as ASE's `adjust_forces` asks.
    ///
    /// Refuses q or p of a length other than n·D ([`StepError::Shape`]),
    /// a NaN or infinite entry, given or in the result (velocities M⁻¹p
    /// that overflow; [`StepError::NonFinite`]; `entry` counts
    /// z = (q, p): n·D + i for p's entry i), and a singular N at q
    /// ([`StepError::AtMember`], stage RATTLE); `p` is left as it was on
    /// error. Errors name step 0 and t = 0. The caches a step reuses are
    /// forgotten.
    ///
    /// ```
    /// use geoshake_runtime::particles::{stencils::Distance, Options, ParticleSystem, Rattle, Table};
    /// let mut bonds = Table::new(2, 1);
    /// bonds.push(&[0, 1], &[1.0]).unwrap();
    /// let system = ParticleSystem::new(3, vec![1.0, 3.0])
    ///     .unwrap()
    ///     .with_constraints("bond", Distance::<3>, bonds)
    ///     .unwrap();
    /// let mut rattle = Rattle::new(system, 1.0, Options::default()).unwrap();
    /// let q = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    /// let mut p = [1.0, 0.5, 0.0, 0.0, 0.0, 0.0];
    /// rattle.project_momenta(&q, &mut p).unwrap();
    /// // Along the bond the two velocities now agree; across it, untouched.
    /// assert!((p[0] / 1.0 - p[3] / 3.0).abs() < 1e-15);
    /// assert_eq!((p[1], p[4]), (0.5, 0.0));
    /// ```
    pub fn project_momenta(&mut self, q: &[f64], p: &mut [f64]) -> Result<StepInfo, StepError> {
        self.check_shape(q, p)?;
        self.stamp = 0;
        Self::not_finite(0, 0.0, "positions q", q, 0)?;
        Self::not_finite(0, 0.0, "momenta p", p, q.len())?;
        self.qn.copy_from_slice(q);
        self.pn.copy_from_slice(p);
        let mut report = particle_report();
        self.velocity_stage(false, 0, 0.0, &mut report)?;
        report.rattle_iterations = 1;
        Self::not_finite(0, 0.0, "projected momenta p", &self.pn, q.len())?;
        p.copy_from_slice(&self.pn);
        Ok(report)
    }
}
