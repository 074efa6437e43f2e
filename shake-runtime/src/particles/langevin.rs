//! Langevin dynamics on M: the BAOAB splitting with RATTLE's projections,
//! and its geodesic variant (g-BAOAB, Leimkuhler & Matthews, Proc. R. Soc.
//! A 472, 2016), as the step of a [`Rattle`] given a [`Langevin`]
//! thermostat (`thermostat.rs`).

use super::thermostat::{mix, normal_pair, Langevin};
use super::{Method, ParticleState, Rattle};
use crate::error::StepError;
use crate::report::StepInfo;

impl Rattle {
    /// Sets (or, with `None`, removes) the Langevin thermostat: with one,
    /// every [`step`](Self::step) (and so every run) is a (g-)BAOAB step.
    /// Refuses a thermostat for SHAKE (the O step's noise needs RATTLE's
    /// projection onto the cotangent space).
    pub fn set_thermostat(&mut self, thermostat: Option<Langevin>) -> Result<(), StepError> {
        if thermostat.is_some() && self.options().method != Method::Rattle {
            return Err(StepError::InvalidInput {
                what: "a Langevin thermostat needs the RATTLE method (its projection onto the cotangent space), not SHAKE",
                value: f64::NAN,
            });
        }
        if thermostat.is_some() {
            self.q0.resize(self.qn.len(), 0.0);
        }
        self.thermostat = thermostat;
        Ok(())
    }

    /// The thermostat, if any.
    pub fn thermostat(&self) -> Option<&Langevin> {
        self.thermostat.as_ref()
    }

    /// One (g-)BAOAB step into `self.qn`, `self.pn` from `state` (step
    /// k at `time`), the forces of `state.q` already in `self.force`.
    pub(super) fn langevin_step(
        &mut self,
        th: Langevin,
        state: &ParticleState,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let half = 0.5 * self.h;
        // B.
        self.qn.copy_from_slice(&state.q);
        self.pn.copy_from_slice(&state.p);
        if self.has_potential {
            for (p, f) in self.pn.iter_mut().zip(&self.force) {
                *p -= half * f;
            }
        }
        let delta = half / th.substeps() as f64;
        self.drift(delta, th.substeps(), k, time, report)?;
        // O.
        let c1 = (-th.friction() * self.h).exp();
        let c2 = (-(-2.0 * th.friction() * self.h).exp_m1() * th.kt()).sqrt();
        // Step k of the state's own count, also in a run on the driver.
        let key = mix(th.seed() ^ mix(k + self.step_offset));
        let d = self.system.dim();
        let masses = self.system.masses();
        let mut pair = (0.0, 0.0);
        for (i, p) in self.pn.iter_mut().enumerate() {
            let xi = if i % 2 == 0 {
                pair = normal_pair(key, i as u64 / 2);
                pair.0
            } else {
                pair.1
            };
            *p = c1 * *p + c2 * masses[i / d].sqrt() * xi;
        }
        self.drift(delta, th.substeps(), k, time, report)?;
        // B, at q1 (whose forces the next step reuses), and p onto the
        // cotangent space (where the last drift left it without a kick).
        if self.has_potential {
            self.closing_kick(k, time)?;
            self.velocity_stage(true, k, time, report)?;
        }
        report.rattle_iterations = 2 * th.substeps() + usize::from(self.has_potential);
        Ok(())
    }

    /// `substeps` RATTLE steps of size `delta` of the free flow on
    /// (`self.qn`, `self.pn`), each ending on the cotangent space.
    fn drift(
        &mut self,
        delta: f64,
        substeps: usize,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let d = self.system.dim();
        let mut q0 = std::mem::take(&mut self.q0);
        let mut result = Ok(());
        for _ in 0..substeps {
            q0.copy_from_slice(&self.qn);
            for (a, w) in self.system.inverse_masses().iter().enumerate() {
                for c in a * d..(a + 1) * d {
                    self.qn[c] = q0[c] + delta * w * self.pn[c];
                }
            }
            let mut sub = StepInfo::default();
            result = self.position_stage(&q0, 0, false, 1.0 / delta, k, time, &mut sub);
            // (Without a potential the position stage did it.)
            if result.is_ok() && !self.fused() {
                result = self.velocity_stage(true, k, time, &mut sub);
            }
            report.hidden = sub.hidden;
            report.shake_iterations = report.shake_iterations.max(sub.shake_iterations);
            report.shake_iterations_total += sub.shake_iterations_total;
            report.residual = match (report.residual, sub.residual) {
                (Some(a), Some(b)) => Some(a.max(b)),
                (a, b) => a.or(b),
            };
            if result.is_err() {
                break;
            }
        }
        self.q0 = q0;
        result
    }
}
