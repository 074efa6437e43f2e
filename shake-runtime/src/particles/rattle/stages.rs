//! The stages of a [`Rattle`] step on its path (independent clusters or the
//! coupled solver): the position stage (SHAKE's solve for q1 with
//! g(q1) = 0), the velocity stage (RATTLE's projection onto M^H), and the
//! projection of initial data, which is the two stages alone (the paper's
//! Section 5.1.3). Also the position stage's multipliers ν a step leaves,
//! and a cluster kernel's failure as a [`StepError`].

use super::{particle_report, Path, Rattle};
use crate::error::{SolveError, Stage, StepError};
use crate::particles::graph::Numbering;
use crate::particles::plan::{ClusterArgs, ClusterFailure, ClusterReport, FailureKind};
use crate::particles::ParticleState;
use crate::report::StepInfo;

impl Rattle {
    /// Brings initial data onto M and then onto M^H: q ← the point of M
    /// reached by Newton along M⁻¹ G(q)ᵀ (the fibre direction), then
    /// p ← p − G(q)ᵀ μ with G(q) M⁻¹ p = 0. p is projected even for SHAKE.
    /// Errors report step 0 and the state's time.
    pub fn project(&mut self, state: &mut ParticleState) -> Result<StepInfo, StepError> {
        self.check_shape(&state.q, &state.p)?;
        // The projection overwrites N's factor, G and ν: no state may count
        // as "continued" afterwards (a step of another state would reuse
        // this one's factor: found by the hostile review).
        self.stamp = 0;
        let (k, time) = (state.step, state.time);
        Self::not_finite(k, time, "initial state", &state.q, 0)?;
        Self::not_finite(k, time, "initial state", &state.p, state.q.len())?;
        self.qn.copy_from_slice(&state.q);
        self.pn.copy_from_slice(&state.p);
        let mut report = particle_report();
        self.position_stage(&state.q, 0, false, 0.0, k, time, &mut report)?;
        self.velocity_stage(true, k, time, &mut report)?;
        report.rattle_iterations = 1;
        // As after a step: velocities that overflow (momenta of 1e300 on a
        // mass of 1e-300) make the projection NaN without a failed solve.
        Self::not_finite(k, time, "projected state", &self.qn, 0)?;
        Self::not_finite(k, time, "projected state", &self.pn, self.qn.len())?;
        std::mem::swap(&mut state.q, &mut self.qn);
        std::mem::swap(&mut state.p, &mut self.pn);
        state.stamp = 0;
        Ok(report)
    }

    /// qn: q̃ → q1 with g(q1) = 0; pn: p̃ → p½ (unless inv_h = 0).
    #[allow(clippy::too_many_arguments)]
    pub(in crate::particles) fn position_stage(
        &mut self,
        q0: &[f64],
        stamp: u64,
        continued: bool,
        inv_h: f64,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let stage = if inv_h != 0.0 {
            Stage::Shake
        } else {
            Stage::ProjectionOntoM
        };
        let args = ClusterArgs {
            q0,
            inv_mass: self.system.inverse_masses(),
            inv_h,
            tol: self.options.tol,
            max_iter: self.options.max_iter,
        };
        let fuse = self.fused() && inv_h != 0.0;
        match &mut self.path {
            Path::Clusters {
                plans,
                nu,
                nu_stamp,
            } => {
                let mut rep = ClusterReport::default();
                // Warm start only along a trajectory (not for projections).
                let warm = inv_h != 0.0 && continued && *nu_stamp == stamp && stamp != 0;
                for (f, fam) in self.system.constraint_families().iter().enumerate() {
                    let (c0, c1) = (self.num.offsets[f], self.num.offsets[f + 1]);
                    let store = if inv_h != 0.0 {
                        Some(&mut nu[c0..c1])
                    } else {
                        None
                    };
                    if let Err(e) = fam.shake_clusters(
                        &plans[f],
                        &args,
                        fuse,
                        store,
                        warm,
                        &mut self.qn,
                        &mut self.pn,
                        &mut rep,
                    ) {
                        return Err(self.cluster_error(f, e, stage, k, time));
                    }
                }
                report.residual = Some(rep.max_rel);
                // (Measured here when the velocity stage ran inside.)
                report.hidden = fuse.then_some(rep.max_hidden);
                report.shake_iterations = rep.max_iter;
                report.shake_iterations_total = rep.iterations;
                Ok(())
            }
            Path::Global(g) => {
                let reuse = continued && g.factor_stamp == stamp && stamp != 0;
                g.position_stage(
                    &self.system,
                    &self.num,
                    &args,
                    reuse,
                    &mut self.qn,
                    &mut self.pn,
                    k,
                    time,
                    report,
                )
            }
        }
    }

    /// On the coupled path, the position stage's result in `qn` judged at
    /// its own scale (the clusters judge every iterate at its own).
    pub(in crate::particles) fn confirm_positions(
        &mut self,
        k: u64,
        time: f64,
        report: &StepInfo,
    ) -> Result<(), StepError> {
        match &mut self.path {
            Path::Clusters { .. } => Ok(()),
            Path::Global(g) => g.confirm_positions(
                &self.system,
                &self.num,
                &self.qn,
                self.options.tol,
                report.shake_iterations,
                k,
                time,
            ),
        }
    }

    /// pn ← pn − G(qn)ᵀ μ with G(qn) M⁻¹ pn = 0. With
    /// `after_position_stage` (qn was just solved for by a position stage)
    /// the coupled path also confirms g(qn) at qn's own scale, from the
    /// gradients it evaluates there anyway; momenta projected at positions
    /// someone else made are projected wherever those positions are.
    pub(in crate::particles) fn velocity_stage(
        &mut self,
        after_position_stage: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        // The projection is linear in p: it is solved for p scaled by a
        // power of two (exact) to a largest entry near 1, so that the
        // velocities M⁻¹p it solves with and judges by cannot underflow
        // where p itself is representable (momenta of 1e-283 on masses of
        // 1e91 read as velocities of 0, "on M^H" whatever their direction).
        // Momenta whose largest entry lies within 2^±16 are left as they
        // are: a velocity underflows there only for masses beyond 1e303,
        // near where they overflow themselves, and the scaling, exact
        // either way, would cost two more passes over p every step.
        let largest = crate::linalg::norm_inf(&self.pn);
        let scale = if (SCALE_FREE_LOW..=SCALE_FREE_HIGH).contains(&largest) {
            1.0
        } else {
            power_of_two_near(largest)
        };
        if scale != 1.0 {
            self.pn.iter_mut().for_each(|p| *p /= scale);
        }
        let r = self.velocity_stage_scaled(after_position_stage, k, time, report);
        if scale != 1.0 {
            self.pn.iter_mut().for_each(|p| *p *= scale);
        }
        r
    }

    /// [`velocity_stage`](Self::velocity_stage) on momenta already scaled.
    fn velocity_stage_scaled(
        &mut self,
        after_position_stage: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        match &mut self.path {
            Path::Clusters { plans, .. } => {
                let mut rep = ClusterReport::default();
                for (f, fam) in self.system.constraint_families().iter().enumerate() {
                    if let Err(e) = fam.project_clusters(
                        &plans[f],
                        self.system.inverse_masses(),
                        &self.qn,
                        &mut self.pn,
                        &mut rep,
                    ) {
                        return Err(self.cluster_error(f, e, Stage::Rattle, k, time));
                    }
                }
                report.hidden = Some(rep.max_hidden);
                Ok(())
            }
            Path::Global(g) => g.velocity_stage(
                &self.system,
                &self.num,
                &self.qn,
                &mut self.pn,
                after_position_stage.then_some(self.options.tol),
                k,
                time,
                report,
            ),
        }
    }

    /// The position stage's multipliers ν (one per constraint, in the
    /// families' order) of the RATTLE or SHAKE step that made `state`, and
    /// that step's start positions q0; `None` when `state` is not the last
    /// state this solver made by such a step (a thermostatted step, a
    /// projection or another step since, a state changed by hand).
    pub(in crate::particles) fn last_position_stage(
        &self,
        state: &ParticleState,
    ) -> Option<(&[f64], &[f64])> {
        let made = state.stamp != 0 && state.stamp == self.stamp;
        if !(made && self.multipliers_stamp == state.stamp) {
            return None;
        }
        // The step swapped its buffers: `qn` holds the state it started from.
        let nu = match &self.path {
            Path::Clusters { nu, .. } => nu.as_slice(),
            Path::Global(g) => g.nu.as_slice(),
        };
        Some((nu, &self.qn))
    }

    /// A cluster kernel's failure in `stage`, at its family's member.
    fn cluster_error(
        &self,
        f: usize,
        e: ClusterFailure,
        stage: Stage,
        step: u64,
        time: f64,
    ) -> StepError {
        let iterations = e.iterations;
        let (stage, source) = match e.kind {
            FailureKind::NotConverged => (
                stage,
                SolveError::NotConverged {
                    iterations,
                    residual: e.residual,
                },
            ),
            // G(q1) M⁻¹ G(q0)ᵀ, the Newton matrix of the position stage.
            FailureKind::SingularNewton => (stage, SolveError::Singular { iterations }),
            // N = G M⁻¹ Gᵀ: the matrix of the projection onto M^H.
            FailureKind::SingularN => (Stage::Rattle, SolveError::Singular { iterations }),
            FailureKind::NotFinite => (stage, SolveError::NonFinite { iterations }),
        };
        Numbering::member_error(&self.system, f, e.member, stage, step, time, source)
    }
}

/// The range of a largest momentum left unscaled by the velocity stage.
const SCALE_FREE_LOW: f64 = 1.0 / 65536.0; // 2^-16
const SCALE_FREE_HIGH: f64 = 65536.0; // 2^16

/// 2^e with 2^e ≤ x < 2^(e+1) for a positive normal x, so that x / 2^e
/// lies in [1, 2) and dividing or multiplying by it is exact; 1 for 0, a
/// subnormal, ∞ or NaN (nothing to gain, or nothing to scale).
fn power_of_two_near(x: f64) -> f64 {
    if !x.is_normal() {
        return 1.0;
    }
    // The exponent bits alone: the power of two at or below x.
    f64::from_bits(x.to_bits() & 0x7ff0_0000_0000_0000)
}
