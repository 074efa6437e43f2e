//! The Langevin thermostat's parameters and its counter-based noise: what
//! a (g-)BAOAB step (`langevin.rs`) is asked to do.

use crate::error::StepError;

/// The most RATTLE substeps per drift of g-BAOAB
/// ([`Langevin::geodesic`]): beyond 2²⁰ a drift's substeps are smaller
/// than any step a simulation would take, and a run would not end.
pub const MAX_SUBSTEPS: usize = 1 << 20;

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
/// generate::set_temperature(rattle.system(), &mut state, 300.0);
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

    /// g-BAOAB: each drift A made of K ≥ 1 RATTLE substeps of h/(2K), K
    /// at most [`MAX_SUBSTEPS`].
    pub fn geodesic(mut self, substeps: usize) -> Result<Self, StepError> {
        if substeps == 0 || substeps > MAX_SUBSTEPS {
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
pub(super) fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Two independent standard normals for coordinates 2j and 2j + 1 of step
/// k (Box–Muller on two uniforms hashed from seed, k and j).
pub(super) fn normal_pair(step_key: u64, j: u64) -> (f64, f64) {
    let x = mix(step_key.wrapping_add(j.wrapping_mul(0x9e37_79b9_7f4a_7c15)));
    let unit = |z: u64| (z >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
    let u1 = 1.0 - unit(mix(x ^ 0x5851_f42d_4c95_7f2d)); // (0, 1]
    let u2 = unit(mix(x ^ 0x1405_7b7e_f767_814f));
    let r = (-2.0 * u1.ln()).sqrt();
    let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
    (r * c, r * s)
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
