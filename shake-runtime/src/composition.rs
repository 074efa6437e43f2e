//! Symmetric compositions of RATTLE: higher order on M^H.
//!
//! RATTLE over a symmetric base map (midpoint, Störmer–Verlet) is a
//! symmetric, symplectic map of M^H of order 2 (the paper's Section 4). A
//! symmetric composition
//!
//! Ψ_h = R_{γ_s h} ∘ … ∘ R_{γ_2 h} ∘ R_{γ_1 h},   γ_k = γ_{s+1−k},  Σ γ_k = 1,
//!
//! is then again symmetric and symplectic on M^H, and the coefficients below
//! raise its order to 4, 6 or 8 (Yoshida 1990; Hairer, Lubich, Wanner,
//! *Geometric Numerical Integration*, Section V.3). The order conditions of a
//! composition only use that the composed map is a symmetric one-step method
//! of order 2 on a manifold, so they hold on M^H exactly as on R^{2d}.
//!
//! # How a composed step is taken
//!
//! Each substep is a full RATTLE step R_{γ_k h}: SHAKE from a point of M^H,
//! then the projection Π back onto M^H. So every intermediate state is on
//! M^H and every substep's SHAKE starts from a point where its Newton
//! iteration is well conditioned, whatever the sign of γ_k. (Projecting is
//! not needed for the *result*: SHAKE's result does not depend on where on
//! the fibre it starts, so Π ∘ S_{γ_s h} ∘ … ∘ S_{γ_1 h} = Ψ_h. It is for
//! Newton's sake.) The last substep is projected only when the integrator's
//! method is RATTLE and the state is needed (see
//! [`Integrator::run`](crate::Integrator::run)).
//!
//! # Negative substeps
//!
//! Every scheme of order ≥ 4 has negative coefficients (Sheng 1989,
//! Suzuki 1991): the triple jump steps back by 1.70 h. SHAKE at a negative
//! step is SHAKE of the reversed flow: its Newton iteration starts from the
//! fibre at −|γ_k| h, and its first iterate is again the O(h) linear
//! prediction, so the fibre-jump and component checks of
//! [`Options`](crate::Options) apply to each substep with its own γ_k h.
//! What does change is the size of the substeps: the largest |γ_k| (1.70 for
//! the triple jump, 1.18 for Yoshida's order 6, 0.80 for the order-8
//! schemes) sets the largest step SHAKE's Newton must take, and the stability
//! limit of the composed method in h is roughly the base method's divided by
//! it. The step is the composed step h; errors report the time at its start.
//!
//! # The schemes and their sources
//!
//! | scheme | order | stages | max γ | source |
//! |---|---|---|---|---|
//! | [`Composition::SINGLE`] | base | 1 | 1 | — |
//! | [`Composition::TRIPLE_JUMP`] | 4 | 3 | 1.70 | Yoshida 1990, Creutz & Gocksch 1989, Suzuki 1990 |
//! | [`Composition::SUZUKI_5`] | 4 | 5 | 0.66 | Suzuki 1990 |
//! | [`Composition::YOSHIDA_6`] | 6 | 7 | 1.32 | Yoshida 1990, solution A (digits: HLW (V.3.11)) |
//! | [`Composition::KAHAN_LI_6`] | 6 | 9 | 0.80 | Kahan & Li 1997, s9odr6a (HLW (V.3.11)) |
//! | [`Composition::MCLACHLAN_8`] | 8 | 15 | 0.80 | McLachlan 1995, s15odr8 (also Suzuki & Umeno 1993) |
//! | [`Composition::KAHAN_LI_8`] | 8 | 17 | 0.61 | Kahan & Li 1997, s17odr8a (HLW (V.3.12)) |
//!
//! - H. Yoshida, Construction of higher order symplectic integrators,
//!   Phys. Lett. A 150 (1990) 262–268.
//! - M. Suzuki, Fractal decomposition of exponential operators with
//!   applications to many-body theories and Monte Carlo simulations,
//!   Phys. Lett. A 146 (1990) 319–323.
//! - W. Kahan, R.-C. Li, Composition constants for raising the orders of
//!   unconventional schemes for ordinary differential equations, Math.
//!   Comp. 66 (1997) 1089–1099.
//! - R. I. McLachlan, On the numerical integration of ordinary differential
//!   equations by symmetric composition methods, SIAM J. Sci. Comput. 16
//!   (1995) 151–168.
//!
//! The coefficients are written with the digits of their sources (26
//! significant digits where published so; Yoshida's order-6 solution A with
//! the 26-digit values of Hairer, Lubich and Wanner); the tests check that
//! each scheme is symmetric, sums to 1 and satisfies the power-sum
//! conditions Σγ³ = 0 (order ≥ 4), Σγ⁵ = 0 (order ≥ 6), Σγ⁷ = 0 (order 8) to
//! round-off, and measure the orders against independent references.
//!
//! ```
//! use geoshake_runtime::{Composition, Integrator, StormerVerlet, State, examples::Pendulum};
//! let mut rattle4 = Integrator::new(Pendulum::default(), StormerVerlet, 0.1)
//!     .composed(Composition::TRIPLE_JUMP);
//! assert_eq!(rattle4.order(), 4);
//! let z0 = State::from_slices(&[0.6, -0.8], &[0.8, 0.6]);
//! let z1 = rattle4.step(&z0).unwrap();
//! // Symmetric: the composed step at −h undoes it.
//! let back = rattle4.with_step_size(-0.1).step(&z1).unwrap();
//! assert!(back.distance(&z0) < 1e-14);
//! ```

/// A symmetric composition scheme: the substeps γ_1 h, …, γ_s h of one step.
///
/// ```
/// use geoshake_runtime::Composition;
/// let c = Composition::TRIPLE_JUMP;
/// assert_eq!((c.order(), c.stages()), (4, 3));
/// assert!((c.coefficients().iter().sum::<f64>() - 1.0).abs() < 1e-15);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Composition {
    name: &'static str,
    order: u32,
    coefficients: &'static [f64],
}

/// Triple jump: γ1 = γ3 = 1/(2 − 2^{1/3}), γ2 = −2^{1/3}/(2 − 2^{1/3}).
const TRIPLE_JUMP: [f64; 3] = [
    1.351_207_191_959_657_8,
    -1.702_414_383_919_315_3,
    1.351_207_191_959_657_8,
];

/// Suzuki: p = 1/(4 − 4^{1/3}); (p, p, 1 − 4p, p, p).
const SUZUKI_5: [f64; 5] = [
    0.414_490_771_794_375_7,
    0.414_490_771_794_375_7,
    -0.657_963_087_177_502_9,
    0.414_490_771_794_375_7,
    0.414_490_771_794_375_7,
];

#[allow(clippy::excessive_precision)] // the digits of the source
const YOSHIDA_6: [f64; 7] = [
    0.78451361047755726381949763,
    0.23557321335935813368479318,
    -1.17767998417887100694641568,
    1.31518632068391121888424973,
    -1.17767998417887100694641568,
    0.23557321335935813368479318,
    0.78451361047755726381949763,
];

#[allow(clippy::excessive_precision)]
const KAHAN_LI_6: [f64; 9] = [
    0.39216144400731413927925056,
    0.33259913678935943859974864,
    -0.70624617255763935980996482,
    0.08221359629355080023149045,
    0.79854399093482996339895035,
    0.08221359629355080023149045,
    -0.70624617255763935980996482,
    0.33259913678935943859974864,
    0.39216144400731413927925056,
];

#[allow(clippy::excessive_precision)]
const MCLACHLAN_8: [f64; 15] = [
    0.74167036435061295344822780,
    -0.40910082580003159399730010,
    0.19075471029623837995387626,
    -0.57386247111608226665638773,
    0.29906418130365592384446354,
    0.33462491824529818378495798,
    0.31529309239676659663205666,
    -0.79688793935291635401978884,
    0.31529309239676659663205666,
    0.33462491824529818378495798,
    0.29906418130365592384446354,
    -0.57386247111608226665638773,
    0.19075471029623837995387626,
    -0.40910082580003159399730010,
    0.74167036435061295344822780,
];

#[allow(clippy::excessive_precision)]
const KAHAN_LI_8: [f64; 17] = [
    0.13020248308889008087881763,
    0.56116298177510838456196441,
    -0.38947496264484728640807860,
    0.15884190655515560089621075,
    -0.39590389413323757733623154,
    0.18453964097831570709183254,
    0.25837438768632204729397911,
    0.29501172360931029887096624,
    -0.60550853383003451169892108,
    0.29501172360931029887096624,
    0.25837438768632204729397911,
    0.18453964097831570709183254,
    -0.39590389413323757733623154,
    0.15884190655515560089621075,
    -0.38947496264484728640807860,
    0.56116298177510838456196441,
    0.13020248308889008087881763,
];

impl Composition {
    /// No composition: one step of the method itself (the default).
    pub const SINGLE: Composition = Composition {
        name: "single step",
        order: 2,
        coefficients: &[1.0],
    };
    /// Yoshida's triple jump, order 4, 3 stages (Yoshida 1990).
    pub const TRIPLE_JUMP: Composition = Composition {
        name: "triple jump (order 4)",
        order: 4,
        coefficients: &TRIPLE_JUMP,
    };
    /// Suzuki's 5-stage fractal, order 4: (p, p, 1 − 4p, p, p) with
    /// p = 1/(4 − 4^{1/3}) (Suzuki 1990). Smaller substeps and error
    /// constant than the triple jump.
    pub const SUZUKI_5: Composition = Composition {
        name: "Suzuki 5-stage (order 4)",
        order: 4,
        coefficients: &SUZUKI_5,
    };
    /// Yoshida's order-6 solution A, 7 stages (Yoshida 1990).
    pub const YOSHIDA_6: Composition = Composition {
        name: "Yoshida 6A (order 6)",
        order: 6,
        coefficients: &YOSHIDA_6,
    };
    /// Kahan and Li's s9odr6a, order 6, 9 stages (Kahan & Li 1997).
    pub const KAHAN_LI_6: Composition = Composition {
        name: "Kahan–Li s9odr6a (order 6)",
        order: 6,
        coefficients: &KAHAN_LI_6,
    };
    /// McLachlan's s15odr8, order 8, 15 stages (McLachlan 1995).
    pub const MCLACHLAN_8: Composition = Composition {
        name: "McLachlan s15odr8 (order 8)",
        order: 8,
        coefficients: &MCLACHLAN_8,
    };
    /// Kahan and Li's s17odr8a, order 8, 17 stages (Kahan & Li 1997).
    pub const KAHAN_LI_8: Composition = Composition {
        name: "Kahan–Li s17odr8a (order 8)",
        order: 8,
        coefficients: &KAHAN_LI_8,
    };

    /// Every scheme of this module, in order of increasing order.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::Composition::ALL.len(), 7);
    /// ```
    pub const ALL: [Composition; 7] = [
        Composition::SINGLE,
        Composition::TRIPLE_JUMP,
        Composition::SUZUKI_5,
        Composition::YOSHIDA_6,
        Composition::KAHAN_LI_6,
        Composition::MCLACHLAN_8,
        Composition::KAHAN_LI_8,
    ];

    /// A name for reports.
    ///
    /// ```
    /// assert!(geoshake_runtime::Composition::KAHAN_LI_8.name().contains("s17odr8a"));
    /// ```
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The order of the composition of a symmetric method of order 2
    /// (2 for [`Composition::SINGLE`]). Over a non-symmetric base map the
    /// order is not raised; see [`Integrator::order`](crate::Integrator::order).
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::Composition::MCLACHLAN_8.order(), 8);
    /// ```
    pub fn order(&self) -> u32 {
        self.order
    }

    /// The number s of substeps.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::Composition::SUZUKI_5.stages(), 5);
    /// ```
    pub fn stages(&self) -> usize {
        self.coefficients.len()
    }

    /// γ_1, …, γ_s: substep k has size γ_k h.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::Composition::SINGLE.coefficients(), &[1.0]);
    /// ```
    pub fn coefficients(&self) -> &'static [f64] {
        self.coefficients
    }

    /// max_k |γ_k|: the largest substep, in units of h.
    ///
    /// ```
    /// let g = geoshake_runtime::Composition::TRIPLE_JUMP.max_substep();
    /// assert!((g - 1.7024143839193153).abs() < 1e-15);
    /// ```
    pub fn max_substep(&self) -> f64 {
        self.coefficients.iter().fold(0.0f64, |a, g| a.max(g.abs()))
    }
}

impl Default for Composition {
    /// [`Composition::SINGLE`].
    fn default() -> Self {
        Composition::SINGLE
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Σ_k γ_k^j, summed in the order that keeps the rounding small.
    fn power_sum(c: &Composition, j: i32) -> f64 {
        c.coefficients().iter().map(|g| g.powi(j)).sum()
    }

    #[test]
    fn coefficients_are_symmetric_consistent_and_satisfy_the_power_sum_conditions() {
        for c in Composition::ALL {
            let g = c.coefficients();
            let s = g.len();
            for k in 0..s {
                assert_eq!(g[k], g[s - 1 - k], "{}: not symmetric at {k}", c.name());
            }
            let sum = power_sum(&c, 1);
            assert!(
                (sum - 1.0).abs() <= 4e-16 * s as f64,
                "{}: Σγ = {sum}",
                c.name()
            );
            // Σγ^j = 0 for odd 3 ≤ j < order: the conditions on the pure
            // powers of one vector field (E_3, E_5, E_7 in the error
            // expansion). The scale is Σ|γ|^j, the size of the terms.
            for j in (3..c.order() as i32).step_by(2) {
                let scale: f64 = g.iter().map(|x| x.abs().powi(j)).sum();
                let v = power_sum(&c, j);
                assert!(
                    v.abs() <= 1e-15 * scale,
                    "{}: Σγ^{j} = {v:e} (scale {scale})",
                    c.name()
                );
            }
        }
    }

    #[test]
    fn closed_forms_match_the_digits() {
        let c = 2f64.cbrt();
        let g1 = 1.0 / (2.0 - c);
        assert!((TRIPLE_JUMP[0] - g1).abs() < 2e-16 * g1);
        assert!((TRIPLE_JUMP[1] + c / (2.0 - c)).abs() < 4e-16);
        let p = 1.0 / (4.0 - 4f64.cbrt());
        assert!((SUZUKI_5[0] - p).abs() < 2e-16);
        assert!((SUZUKI_5[2] - (1.0 - 4.0 * p)).abs() < 1e-15);
        // Yoshida's middle coefficient is w0 = 1 − 2(w1 + w2 + w3).
        let w0 = 1.0 - 2.0 * (YOSHIDA_6[0] + YOSHIDA_6[1] + YOSHIDA_6[2]);
        assert!((YOSHIDA_6[3] - w0).abs() < 1e-15);
    }
}
