//! One step of a [`Rattle`]: RATTLE (or SHAKE) with Störmer–Verlet (the
//! paper's Section 5.1.3), or with a thermostat a (g-)BAOAB step
//! (`langevin.rs`): the drift and the kicks around the position and
//! velocity stages, and the stamping of the state it makes.

use rayon::prelude::*;

use super::{parallel, particle_report, Path, Rattle, PARALLEL_PARTICLES};
use crate::error::StepError;
use crate::particles::options::Method;
use crate::particles::ParticleState;
use crate::report::StepInfo;

impl Rattle {
    /// One step of the method from `state` (step k − 1 at t0 + (k−1)h) to
    /// step k at t0 + k·h, in place: RATTLE (or SHAKE), or with a
    /// [`Langevin`] thermostat ([`set_thermostat`](Self::set_thermostat))
    /// a (g-)BAOAB step. On failure the state is left as it was and the
    /// error names step k and time t0 + k·h.
    ///
    /// [`Langevin`]: crate::particles::Langevin
    pub fn step(&mut self, state: &mut ParticleState) -> Result<StepInfo, StepError> {
        self.check_shape(&state.q, &state.p)?;
        let k = state.step + 1;
        let time = state.t0 + k as f64 * self.h;
        // A NaN or infinite t0, or t0 + k·h past f64's range, would be
        // stamped on the state and on every error from here on.
        if !time.is_finite() {
            return Err(StepError::InvalidInput {
                what: "the step's time t0 + k·h must be finite",
                value: time,
            });
        }
        let continued = state.stamp != 0 && state.stamp == self.stamp;
        // The caches (N's factor, ν, forces) are about to be overwritten: a
        // step that fails half-way must not leave them claiming a state.
        self.stamp = 0;
        if !continued {
            Self::not_finite(k, time, "initial state", &state.q, 0)?;
            Self::not_finite(k, time, "initial state", &state.p, state.q.len())?;
        }
        if self.has_potential && !(continued && self.force_stamp == state.stamp) {
            self.forces(&state.q, k, time)?;
        }
        let mut report = particle_report();
        match self.thermostat {
            Some(th) => self.langevin_step(th, state, k, time, &mut report)?,
            None => self.rattle_step(state, continued, k, time, &mut report)?,
        }
        Self::not_finite(k, time, "state", &self.qn, 0)?;
        Self::not_finite(k, time, "state", &self.pn, self.qn.len())?;
        std::mem::swap(&mut state.q, &mut self.qn);
        std::mem::swap(&mut state.p, &mut self.pn);
        state.step = k;
        state.time = time;
        let s = self.new_stamp();
        state.stamp = s;
        self.force_stamp = if self.has_potential { s } else { 0 };
        let projected = self.options.method == Method::Rattle;
        let langevin = self.thermostat.is_some();
        self.multipliers_stamp = if langevin { 0 } else { s };
        match &mut self.path {
            // RATTLE factorised N(q1): the next step's N(q0).
            Path::Global(g) => g.factor_stamp = if projected { s } else { 0 },
            // ν of a full step's position stage (not of a drift's), the
            // next step's first guess.
            Path::Clusters { nu_stamp, .. } => *nu_stamp = if langevin { 0 } else { s },
        }
        Ok(report)
    }

    /// One RATTLE (or SHAKE) step into `self.qn`, `self.pn` from `state`,
    /// the forces of `state.q` already in `self.force`:
    /// p̃ = p0 − (h/2) ∇V(q0), q̃ = q0 + h M⁻¹ p̃, the position stage,
    /// p′ = p½ − (h/2) ∇V(q1), the velocity stage.
    fn rattle_step(
        &mut self,
        state: &ParticleState,
        continued: bool,
        k: u64,
        time: f64,
        report: &mut StepInfo,
    ) -> Result<(), StepError> {
        let (h, half) = (self.h, 0.5 * self.h);
        let d = self.system.dim();
        let inv_m = self.system.inverse_masses();
        let kick = self.has_potential;
        // p̃ and q̃ particle by particle, in chunks on threads when large.
        // (Each particle's d entries sliced once and zipped: indexed one
        // by one, every access was bounds-checked.)
        let drift = |(((qn, pn), (q, p)), (f, w)): Chunk<'_>| {
            // p̃ first over the whole chunk, one flat loop the compiler
            // vectorises; then q̃ particle by particle (each particle's
            // h/m_a), with R³'s rows of a fixed length, unrolled.
            if kick {
                for ((pn, p), f) in pn.iter_mut().zip(p).zip(f) {
                    *pn = p - half * f;
                }
            } else {
                pn.copy_from_slice(p);
            }
            let row = |qn: &mut [f64], q: &[f64], pn: &[f64], wa: f64| {
                let w = h * wa;
                for ((qn, q), pt) in qn.iter_mut().zip(q).zip(pn) {
                    *qn = q + w * pt;
                }
            };
            if d == 3 {
                let (qn, q, pn) = (
                    qn.as_chunks_mut::<3>().0,
                    q.as_chunks::<3>().0,
                    pn.as_chunks::<3>().0,
                );
                for (((qn, q), pn), &wa) in qn.iter_mut().zip(q).zip(pn).zip(w) {
                    row(qn, q, pn, wa);
                }
            } else {
                let (qn, q, pn) = (
                    qn.chunks_exact_mut(d),
                    q.chunks_exact(d),
                    pn.chunks_exact(d),
                );
                for (((qn, q), pn), &wa) in qn.zip(q).zip(pn).zip(w) {
                    row(qn, q, pn, wa);
                }
            }
        };
        let n = PARALLEL_PARTICLES;
        // (Without a potential the drift reads no force: p stands in.)
        let force: &[f64] = if kick { &self.force } else { &state.p };
        if parallel(inv_m.len()) {
            let (qn, pn) = (self.qn.par_chunks_mut(n * d), self.pn.par_chunks_mut(n * d));
            let (q, p) = (state.q.par_chunks(n * d), state.p.par_chunks(n * d));
            let (f, w) = (force.par_chunks(n * d), inv_m.par_chunks(n));
            qn.zip(pn).zip(q.zip(p)).zip(f.zip(w)).for_each(drift);
        } else {
            drift((
                ((&mut self.qn, &mut self.pn), (&state.q, &state.p)),
                (force, inv_m),
            ));
        }
        self.position_stage(&state.q, state.stamp, continued, 1.0 / h, k, time, report)?;
        if self.options.method == Method::Shake {
            // RATTLE's velocity stage judges q1 at its own scale; without
            // it, the coupled solvers' test at q0's scale is all there is.
            self.confirm_positions(k, time, report)?;
        }
        if self.has_potential {
            self.closing_kick(k, time)?;
        }
        if self.options.method == Method::Rattle {
            if !self.fused() {
                self.velocity_stage(true, k, time, report)?;
            }
            // One linear solve with N = G M⁻¹ Gᵀ.
            report.rattle_iterations = 1;
        }
        Ok(())
    }

    /// p′ = p½ − (h/2) ∇V(q1) on (`self.qn`, `self.pn`): the step's last
    /// kick, with the forces at the new positions, which the next step's
    /// first kick reuses.
    pub(in crate::particles) fn closing_kick(
        &mut self,
        k: u64,
        time: f64,
    ) -> Result<(), StepError> {
        let half = 0.5 * self.h;
        let q1 = std::mem::take(&mut self.qn);
        let r = self.forces(&q1, k, time);
        self.qn = q1;
        r?;
        if parallel(self.force.len()) {
            let kick = |(p, f): (&mut f64, &f64)| *p -= half * f;
            self.pn.par_iter_mut().zip(&self.force).for_each(kick);
        } else {
            for (p, f) in self.pn.iter_mut().zip(&self.force) {
                *p -= half * f;
            }
        }
        Ok(())
    }
}

/// One chunk of the drift: (q̃, p̃) out, (q0, p0) and (force, 1/m) in.
type Chunk<'a> = (
    ((&'a mut [f64], &'a mut [f64]), (&'a [f64], &'a [f64])),
    (&'a [f64], &'a [f64]),
);
