//! Langevin dynamics on M: the BAOAB splitting with RATTLE's projections,
//! and its geodesic variant (g-BAOAB, Leimkuhler & Matthews, Proc. R. Soc.
//! A 472, 2016), as the step of a [`Rattle`] given a [`Langevin`]
//! thermostat.

use super::{Method, ParticleState, Rattle};
use crate::error::StepError;
use crate::report::StepInfo;

/// A Langevin thermostat: dp = −∇V dt − γ p dt + √(2 γ k_B T) M^{1/2} dW
/// on T*M, integrated by (g-)BAOAB with the constraints kept by RATTLE.
///
/// One step of size h, with K = [`substeps`](Self::substeps):
///
/// - B: p ← p − (h/2) ∇V(q);
/// - A, K times: q ← q + (h/2K) M⁻¹ p, then q onto M along M⁻¹ G(q)ᵀ (the
///   position stage) and p onto the cotangent space (the velocity stage):
///   a RATTLE step of the free flow, the geodesic drift of g-BAOAB (K = 1
///   is BAOAB with constrained drifts);
/// - O: p ← e^{−γh} p + √((1 − e^{−2γh}) k_B T) M^{1/2} ξ, ξ ~ N(0, I);
/// - A, K times, as above;
/// - B: p ← p − (h/2) ∇V(q), then p onto the cotangent space.
///
/// The cotangent projections after the first B and after O that the
/// algorithm as published makes are left out: the next drift's position
/// stage moves p by G(q)ᵀλ at the same q, which absorbs any G(q)ᵀμ they
/// would remove, so the step is the same map.
///
/// The noise of step k is a function of the seed, k and the coordinate
/// only (counter-based), so a run is reproducible bit for bit, whatever
/// the chunks it is run in, and independent of how work is shared.
///
/// `kt` is k_B T in the units of H (mass · length² / time² of the
/// momenta's units; in LAMMPS `real` units, Å, fs, g/mol:
/// k_B T = [`KB`](super::generate::KB) · T / [`MVV2E`](super::generate::MVV2E)).
///
/// ```
/// use geoshake_runtime::particles::{generate, Langevin, Options, Rattle};
/// let (system, mut state) = generate::water(8, 1).unwrap();
/// let mut rattle = Rattle::new(system, 2.0, Options::default()).unwrap();
/// rattle.project(&mut state).unwrap();
/// // 300 K, γ = 1/ps, two geodesic drift substeps.
/// let kt = generate::KB * 300.0 / generate::MVV2E;
/// rattle.set_thermostat(Some(Langevin::new(1e-3, kt, 42).unwrap().geodesic(2).unwrap())).unwrap();
/// assert!(rattle.run_in_place(&mut state, 50).error.is_none());
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Langevin {
    gamma: f64,
    kt: f64,
    seed: u64,
    substeps: usize,
}

impl Langevin {
    /// Friction γ ≥ 0 (per unit of time; γ = 0 is the Hamiltonian flow
    /// split into drifts and kicks), k_B T ≥ 0 and the noise's seed; BAOAB
    /// (one drift substep). Refuses γ or k_B T negative or not finite.
    pub fn new(gamma: f64, kt: f64, seed: u64) -> Result<Self, StepError> {
        if !(gamma.is_finite() && gamma >= 0.0) {
            return Err(StepError::InvalidInput {
                what: "the friction γ must be finite and ≥ 0",
                value: gamma,
            });
        }
        if !(kt.is_finite() && kt >= 0.0) {
            return Err(StepError::InvalidInput {
                what: "k_B T must be finite and ≥ 0",
                value: kt,
            });
        }
        Ok(Langevin {
            gamma,
            kt,
            seed,
            substeps: 1,
        })
    }

    /// g-BAOAB: each drift A made of K ≥ 1 RATTLE substeps of h/(2K).
    pub fn geodesic(mut self, substeps: usize) -> Result<Self, StepError> {
        if substeps == 0 || substeps > 1 << 20 {
            return Err(StepError::InvalidInput {
                what: "the drift substeps K of g-BAOAB must be in 1..=2^20",
                value: substeps as f64,
            });
        }
        self.substeps = substeps;
        Ok(self)
    }

    /// The friction γ.
    pub fn friction(&self) -> f64 {
        self.gamma
    }

    /// k_B T.
    pub fn kt(&self) -> f64 {
        self.kt
    }

    /// The noise's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// K, the RATTLE substeps of each drift.
    pub fn substeps(&self) -> usize {
        self.substeps
    }
}

/// SplitMix64's finaliser: a bijection of u64 that mixes every bit.
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Two independent standard normals for coordinates 2j and 2j + 1 of step
/// k (Box–Muller on two uniforms hashed from seed, k and j).
fn normal_pair(step_key: u64, j: u64) -> (f64, f64) {
    let x = mix(step_key.wrapping_add(j.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
    let unit = |z: u64| (z >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    let u1 = 1.0 - unit(mix(x ^ 0x5851_f42d_4c95_7f2d)); // (0, 1]
    let u2 = unit(mix(x ^ 0x1405_7b7e_f767_814f));
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
    (r * c, r * s)
}

impl Rattle {
    /// Sets (or, with `None`, removes) the Langevin thermostat: with one,
    /// every [`step`](Self::step) (and so every run) is a (g-)BAOAB step.
    /// Refuses a thermostat for SHAKE (the O step's noise needs RATTLE's
    /// projection onto the cotangent space).
    pub fn set_thermostat(&mut self, thermostat: Option<Langevin>) -> Result<(), StepError> {
        if thermostat.is_some() && self.options().method != Method::Rattle {
            return Err(StepError::InvalidInput {
                what: "a Langevin thermostat needs Method::Rattle (its projection onto the cotangent space)",
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
        let delta = half / th.substeps as f64;
        self.drift(delta, th.substeps, k, time, report)?;
        // O.
        let c1 = (-th.gamma * self.h).exp();
        let c2 = (-(-2.0 * th.gamma * self.h).exp_m1() * th.kt).sqrt();
        // Step k of the state's own count, also in a run on the driver.
        let key = mix(th.seed ^ mix(k + self.step_offset));
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
        self.drift(delta, th.substeps, k, time, report)?;
        // B, at q1 (whose forces the next step reuses), and p onto the
        // cotangent space (where the last drift left it without a kick).
        if self.has_potential {
            let q1 = std::mem::take(&mut self.qn);
            let r = self.forces(&q1, k, time);
            self.qn = q1;
            r?;
            for (p, f) in self.pn.iter_mut().zip(&self.force) {
                *p -= half * f;
            }
            self.velocity_stage(k, time, report)?;
        }
        report.rattle_iterations = 2 * th.substeps + usize::from(self.has_potential);
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
                result = self.velocity_stage(k, time, &mut sub);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The noise is standard normal: mean 0, variance 1, fourth moment 3,
    /// to a few standard errors over 10⁵ draws, and uncorrelated between
    /// the two of a pair and between neighbouring steps.
    #[test]
    fn the_noise_is_standard_normal_and_uncorrelated() {
        let n = 50_000u64;
        let (mut m1, mut m2, mut m4, mut c12, mut ck) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for j in 0..n {
            let (a, b) = normal_pair(mix(7 ^ mix(3)), j);
            let (c, _) = normal_pair(mix(7 ^ mix(4)), j);
            m1 += a + b;
            m2 += a * a + b * b;
            m4 += a.powi(4) + b.powi(4);
            c12 += a * b;
            ck += a * c;
        }
        let draws = 2.0 * n as f64;
        // Standard errors: 1/√draws for the mean, √2/√draws for the
        // variance, √96/√draws for the fourth moment, 1/√n for products.
        let se = 1.0 / draws.sqrt();
        assert!((m1 / draws).abs() < 5.0 * se);
        assert!((m2 / draws - 1.0).abs() < 5.0 * 2f64.sqrt() * se);
        assert!((m4 / draws - 3.0).abs() < 5.0 * 96f64.sqrt() * se);
        let se_pair = 1.0 / (n as f64).sqrt();
        assert!((c12 / n as f64).abs() < 5.0 * se_pair);
        assert!((ck / n as f64).abs() < 5.0 * se_pair);
    }

    #[test]
    fn bad_parameters_are_refused() {
        for (g, kt) in [
            (-1.0, 1.0),
            (f64::NAN, 1.0),
            (1.0, -1e-300),
            (1.0, f64::INFINITY),
        ] {
            assert!(matches!(
                Langevin::new(g, kt, 0),
                Err(StepError::InvalidInput { .. })
            ));
        }
        let l = Langevin::new(0.0, 0.0, 0).unwrap();
        assert!(l.geodesic(0).is_err() && l.geodesic(usize::MAX).is_err());
        assert_eq!(l.geodesic(3).unwrap().substeps(), 3);
    }
}
