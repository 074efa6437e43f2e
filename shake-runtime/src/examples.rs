//! Small hand-written systems for the documentation examples.
//!
//! They implement the traits of [`system`](crate::system) the way
//! `constrained_system!` does: straight-line code that writes only the
//! structurally nonzero entries.

use crate::system::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian};

/// The harmonic oscillator H = (q² + p²)/2 on R², no constraints (wrap it in
/// [`Unconstrained`](crate::Unconstrained) to integrate it).
///
/// ```
/// use geoshake_runtime::{Hamiltonian, examples::HarmonicOscillator};
/// assert_eq!(HarmonicOscillator.hamiltonian(&[1.0], &[1.0]), 1.0);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct HarmonicOscillator;

impl Hamiltonian for HarmonicOscillator {
    fn dof(&self) -> usize {
        1
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * (q[0] * q[0] + p[0] * p[0])
    }
    fn grad_q(&self, q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        h_q[0] = q[0];
    }
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[0] = 1.0;
        h_zz[3] = 1.0;
    }
}

/// The planar pendulum of the paper's Example 1.3: H = |p|²/2 + γ q₂ on R⁴,
/// g(q) = |q|² − ℓ².
///
/// ```
/// use geoshake_runtime::{ConstrainedSystem, examples::Pendulum};
/// let sys = Pendulum::default();
/// let mut g = [0.0];
/// sys.constraints(&[0.6, -0.8], &[1.0, 0.0], &mut g);
/// assert!(g[0].abs() < 1e-15);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Pendulum {
    /// Gravity γ.
    pub gravity: f64,
    /// Rod length ℓ.
    pub length: f64,
}

impl Default for Pendulum {
    /// γ = 1, ℓ = 1.
    fn default() -> Self {
        Pendulum {
            gravity: 1.0,
            length: 1.0,
        }
    }
}

impl Pendulum {
    /// The point of M^H at angle θ from the downward vertical with angular
    /// velocity ω: q = ℓ(sin θ, −cos θ), p = ℓω(cos θ, sin θ).
    ///
    /// ```
    /// use geoshake_runtime::examples::Pendulum;
    /// let z = Pendulum::default().state(0.3, 0.5);
    /// assert!((z.q.norm() - 1.0).abs() < 1e-15 && z.q.dot(&z.p).abs() < 1e-15);
    /// ```
    pub fn state(&self, theta: f64, omega: f64) -> crate::State {
        let l = self.length;
        crate::State::from_slices(
            &[l * theta.sin(), -l * theta.cos()],
            &[l * omega * theta.cos(), l * omega * theta.sin()],
        )
    }
}

impl Hamiltonian for Pendulum {
    fn dof(&self) -> usize {
        2
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * (p[0] * p[0] + p[1] * p[1]) + self.gravity * q[1]
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        h_q[1] = self.gravity;
    }
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
        h_p[1] = p[1];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[2 + 2 * 4] = 1.0;
        h_zz[3 + 3 * 4] = 1.0;
    }
}

impl ConstrainedSystem for Pendulum {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn quadratic_constraints(&self) -> bool {
        // |q|² − ℓ²: SHAKE's root in closed form (`geoshake::classical::fixed`).
        true
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["rod"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[0] * q[0] + q[1] * q[1] - self.length * self.length;
    }
    fn constraint_jacobian(&self, q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        g_z[0] = 2.0 * q[0];
        g_z[1] = 2.0 * q[1];
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], lambda: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * lambda[0];
        out[1 + 4] = 2.0 * lambda[0];
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * (q[0] * p[0] + q[1] * p[1]);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * p[0];
        out[1] = 2.0 * p[1];
        out[2] = 2.0 * q[0];
        out[3] = 2.0 * q[1];
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        n[0] = 4.0 * (q[0] * q[0] + q[1] * q[1]);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        p[0] -= 2.0 * lambda[0] * q[0];
        p[1] -= 2.0 * lambda[0] * q[1];
        ClosedForm::Applied
    }
    fn with_sizes<V: crate::SizeVisitor<Self>>(&self, v: V) -> V::Output {
        v.fixed::<2, 1>(self)
    }
}

/// The harmonic (Hopf) constraint of the paper's Section 5.4 with
/// H = |p|²/2: g = |q|² + |p|² − r² on R⁴. Its fibre flow is left to the
/// runtime's linear-flow exponential (no closed form is given here).
///
/// ```
/// use geoshake_runtime::{ConstrainedSystem, examples::HopfHarmonic};
/// let mut n = [0.0];
/// HopfHarmonic::unit().nondegeneracy_matrix(&[0.8, 0.0], &[0.0, 0.6], &mut n);
/// assert!((n[0] - 4.0 * (0.64 - 0.36)).abs() < 1e-15);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct HopfHarmonic {
    /// The radius r² of the sphere M = {|q|² + |p|² = r²}.
    pub radius2: f64,
}

impl HopfHarmonic {
    /// The unit sphere, r² = 1.
    ///
    /// ```
    /// assert_eq!(geoshake_runtime::examples::HopfHarmonic::unit().radius2, 1.0);
    /// ```
    pub fn unit() -> Self {
        HopfHarmonic { radius2: 1.0 }
    }
}

impl Hamiltonian for HopfHarmonic {
    fn dof(&self) -> usize {
        2
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, _q: &[f64], p: &[f64]) -> f64 {
        0.5 * (p[0] * p[0] + p[1] * p[1])
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], _h_q: &mut [f64]) {}
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
        h_p[1] = p[1];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[2 + 2 * 4] = 1.0;
        h_zz[3 + 3 * 4] = 1.0;
    }
}

impl ConstrainedSystem for HopfHarmonic {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Quadratic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1), (0, 2), (0, 3)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["sphere"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
        g[0] = q[0] * q[0] + q[1] * q[1] + p[0] * p[0] + p[1] * p[1] - self.radius2;
    }
    fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
        g_z[0] = 2.0 * q[0];
        g_z[1] = 2.0 * q[1];
        g_z[2] = 2.0 * p[0];
        g_z[3] = 2.0 * p[1];
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], lambda: &[f64], out: &mut [f64]) {
        for k in 0..4 {
            out[k + 4 * k] = 2.0 * lambda[0];
        }
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * (q[0] * p[0] + q[1] * p[1]);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * p[0];
        out[1] = 2.0 * p[1];
        out[2] = 2.0 * q[0];
        out[3] = 2.0 * q[1];
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        n[0] = 4.0 * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0] - p[1] * p[1]);
    }
}
