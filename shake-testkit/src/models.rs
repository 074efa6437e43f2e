//! Hand-written systems implementing the runtime's traits: the test models
//! of the runtime and the "hand-written analytic" baseline of the
//! benchmarks.
//!
//! Each is straight-line code without allocation that writes only the
//! structurally nonzero entries of its outputs (the contract of
//! `geoshake_runtime::system`: column-major, q-columns first). Their
//! derivatives are checked against finite differences in
//! `tests/suite/runtime_models.rs`.
//!
//! Conventions (MISSION.md): X_F = (F_p, −F_q), {F,G} = F_q·G_p − F_p·G_q,
//! hidden constraints {g_i, H}, N_ij = {{H,g_i},g_j}.
#![allow(dead_code)]

use geoshake::{ClosedForm, ConstrainedSystem, ConstraintKind, Hamiltonian};

// ---------------------------------------------------------------------------
// Pendulum (Example 1.3)
// ---------------------------------------------------------------------------

/// Planar pendulum: H = |p|²/2 + γ q₂, g = |q|² − ℓ² (d = 2, m = 1). The
/// runtime ships this hand-written model for its own doc examples; the tests
/// and benchmarks use the same one.
// Not every test crate that includes `common` uses every model.
#[allow(unused_imports)]
pub use geoshake::runtime::examples::Pendulum;

// ---------------------------------------------------------------------------
// Pendulum with a position-dependent mass (non-separable H)
// ---------------------------------------------------------------------------

/// H = (1 + ε q₁²)|p|²/2 + γ q₂, g = |q|² − 1 (d = 2, m = 1): H_qp ≠ 0, so
/// Störmer–Verlet and symplectic Euler are implicit.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct NonSeparablePendulum {
    pub eps: f64,
    pub gravity: f64,
}

impl Default for NonSeparablePendulum {
    fn default() -> Self {
        NonSeparablePendulum {
            eps: 0.5,
            gravity: 1.0,
        }
    }
}

impl NonSeparablePendulum {
    /// q = (sin θ, −cos θ), p = ω(cos θ, sin θ): q·p = 0, a point of M^H.
    pub fn state_on_mh(&self, theta: f64, omega: f64) -> geoshake::State {
        geoshake::State::from_slices(
            &[theta.sin(), -theta.cos()],
            &[omega * theta.cos(), omega * theta.sin()],
        )
    }
}

impl Hamiltonian for NonSeparablePendulum {
    fn dof(&self) -> usize {
        2
    }
    fn separable(&self) -> bool {
        false
    }
    fn quadratic_kinetic(&self) -> bool {
        false
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * (1.0 + self.eps * q[0] * q[0]) * (p[0] * p[0] + p[1] * p[1]) + self.gravity * q[1]
    }
    fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
        h_q[0] = self.eps * q[0] * (p[0] * p[0] + p[1] * p[1]);
        h_q[1] = self.gravity;
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        let a = 1.0 + self.eps * q[0] * q[0];
        h_p[0] = a * p[0];
        h_p[1] = a * p[1];
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        let a = 1.0 + self.eps * q[0] * q[0];
        let b0 = 2.0 * self.eps * q[0] * p[0];
        let b1 = 2.0 * self.eps * q[0] * p[1];
        h_zz[0] = self.eps * (p[0] * p[0] + p[1] * p[1]);
        h_zz[2] = b0;
        h_zz[3] = b1;
        h_zz[2 * 4] = b0;
        h_zz[3 * 4] = b1;
        h_zz[2 + 2 * 4] = a;
        h_zz[3 + 3 * 4] = a;
    }
}

impl ConstrainedSystem for NonSeparablePendulum {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["rod"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[0] * q[0] + q[1] * q[1] - 1.0;
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
        let a = 1.0 + self.eps * q[0] * q[0];
        out[0] = 2.0 * a * (q[0] * p[0] + q[1] * p[1]);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let a = 1.0 + self.eps * q[0] * q[0];
        let qp = q[0] * p[0] + q[1] * p[1];
        out[0] = 2.0 * a * p[0] + 4.0 * self.eps * q[0] * qp;
        out[1] = 2.0 * a * p[1];
        out[2] = 2.0 * a * q[0];
        out[3] = 2.0 * a * q[1];
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        let a = 1.0 + self.eps * q[0] * q[0];
        n[0] = 4.0 * a * (q[0] * q[0] + q[1] * q[1]);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        let l2 = 2.0 * lambda[0];
        p[0] -= l2 * q[0];
        p[1] -= l2 * q[1];
        ClosedForm::Applied
    }
}

// ---------------------------------------------------------------------------
// Spherical pendulum
// ---------------------------------------------------------------------------

/// Spherical pendulum: H = |p|²/2 + γ q₃, g = |q|² − ℓ² (d = 3, m = 1).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct SphericalPendulum {
    pub gravity: f64,
    pub length: f64,
}

impl Default for SphericalPendulum {
    fn default() -> Self {
        SphericalPendulum {
            gravity: 1.0,
            length: 1.0,
        }
    }
}

impl SphericalPendulum {
    /// q = ℓ(sin θ cos φ, sin θ sin φ, −cos θ), p = θ' ∂q/∂θ + φ' ∂q/∂φ: on M^H.
    pub fn state(&self, theta: f64, phi: f64, theta_dot: f64, phi_dot: f64) -> geoshake::State {
        let l = self.length;
        let (st, ct, sp, cp) = (theta.sin(), theta.cos(), phi.sin(), phi.cos());
        geoshake::State::from_slices(
            &[l * st * cp, l * st * sp, -l * ct],
            &[
                theta_dot * l * ct * cp - phi_dot * l * st * sp,
                theta_dot * l * ct * sp + phi_dot * l * st * cp,
                theta_dot * l * st,
            ],
        )
    }
}

impl Hamiltonian for SphericalPendulum {
    fn dof(&self) -> usize {
        3
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) + self.gravity * q[2]
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        h_q[2] = self.gravity;
    }
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
        h_p[1] = p[1];
        h_p[2] = p[2];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[3 + 3 * 6] = 1.0;
        h_zz[4 + 4 * 6] = 1.0;
        h_zz[5 + 5 * 6] = 1.0;
    }
}

impl ConstrainedSystem for SphericalPendulum {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1), (0, 2)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["rod"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] - self.length * self.length;
    }
    fn constraint_jacobian(&self, q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        g_z[0] = 2.0 * q[0];
        g_z[1] = 2.0 * q[1];
        g_z[2] = 2.0 * q[2];
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], lambda: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * lambda[0];
        out[1 + 6] = 2.0 * lambda[0];
        out[2 + 2 * 6] = 2.0 * lambda[0];
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * (q[0] * p[0] + q[1] * p[1] + q[2] * p[2]);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * p[0];
        out[1] = 2.0 * p[1];
        out[2] = 2.0 * p[2];
        out[3] = 2.0 * q[0];
        out[4] = 2.0 * q[1];
        out[5] = 2.0 * q[2];
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        n[0] = 4.0 * (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        let l2 = 2.0 * lambda[0];
        p[0] -= l2 * q[0];
        p[1] -= l2 * q[1];
        p[2] -= l2 * q[2];
        ClosedForm::Applied
    }
}

// ---------------------------------------------------------------------------
// Double pendulum
// ---------------------------------------------------------------------------

/// Planar double pendulum, q = (x₁, y₁, x₂, y₂) (d = 4, m = 2):
/// H = |p₁|²/(2m₁) + |p₂|²/(2m₂) + γ(m₁y₁ + m₂y₂),
/// g₁ = |q₁|² − ℓ₁², g₂ = |q₂ − q₁|² − ℓ₂².
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct DoublePendulum {
    pub l1: f64,
    pub l2: f64,
    pub m1: f64,
    pub m2: f64,
    pub gravity: f64,
}

impl Default for DoublePendulum {
    fn default() -> Self {
        DoublePendulum {
            l1: 1.0,
            l2: 1.0,
            m1: 1.0,
            m2: 1.0,
            gravity: 1.0,
        }
    }
}

impl DoublePendulum {
    /// The point of M^H at link angles θ₁, θ₂ (from the downward vertical)
    /// with angular velocities ω₁, ω₂.
    pub fn state(&self, th1: f64, th2: f64, w1: f64, w2: f64) -> geoshake::State {
        let (x1, y1) = (self.l1 * th1.sin(), -self.l1 * th1.cos());
        let (x2, y2) = (x1 + self.l2 * th2.sin(), y1 - self.l2 * th2.cos());
        let (u1, v1) = (self.l1 * w1 * th1.cos(), self.l1 * w1 * th1.sin());
        let (u2, v2) = (u1 + self.l2 * w2 * th2.cos(), v1 + self.l2 * w2 * th2.sin());
        geoshake::State::from_slices(
            &[x1, y1, x2, y2],
            &[self.m1 * u1, self.m1 * v1, self.m2 * u2, self.m2 * v2],
        )
    }
}

impl Hamiltonian for DoublePendulum {
    fn dof(&self) -> usize {
        4
    }
    fn separable(&self) -> bool {
        true
    }
    fn quadratic_kinetic(&self) -> bool {
        true
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        (p[0] * p[0] + p[1] * p[1]) * (0.5 / self.m1)
            + (p[2] * p[2] + p[3] * p[3]) * (0.5 / self.m2)
            + self.gravity * (self.m1 * q[1] + self.m2 * q[3])
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        h_q[1] = self.gravity * self.m1;
        h_q[3] = self.gravity * self.m2;
    }
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0] / self.m1;
        h_p[1] = p[1] / self.m1;
        h_p[2] = p[2] / self.m2;
        h_p[3] = p[3] / self.m2;
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[4 + 4 * 8] = 1.0 / self.m1;
        h_zz[5 + 5 * 8] = 1.0 / self.m1;
        h_zz[6 + 6 * 8] = 1.0 / self.m2;
        h_zz[7 + 7 * 8] = 1.0 / self.m2;
    }
}

impl ConstrainedSystem for DoublePendulum {
    fn constraint_count(&self) -> usize {
        2
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (1, 3)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["upper rod", "lower rod"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        g[0] = q[0] * q[0] + q[1] * q[1] - self.l1 * self.l1;
        g[1] = ux * ux + uy * uy - self.l2 * self.l2;
    }
    fn constraint_jacobian(&self, q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        // (i, k) at i + 2k.
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        g_z[0] = 2.0 * q[0];
        g_z[2] = 2.0 * q[1];
        g_z[1] = -2.0 * ux;
        g_z[3] = -2.0 * uy;
        g_z[5] = 2.0 * ux;
        g_z[7] = 2.0 * uy;
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], lambda: &[f64], out: &mut [f64]) {
        let (a, b) = (2.0 * lambda[0], 2.0 * lambda[1]);
        out[0] = a + b;
        out[1 + 8] = a + b;
        out[2 + 2 * 8] = b;
        out[3 + 3 * 8] = b;
        out[2 * 8] = -b;
        out[2] = -b;
        out[1 + 3 * 8] = -b;
        out[3 + 8] = -b;
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        let (vx, vy) = (
            p[2] / self.m2 - p[0] / self.m1,
            p[3] / self.m2 - p[1] / self.m1,
        );
        out[0] = 2.0 * (q[0] * p[0] + q[1] * p[1]) / self.m1;
        out[1] = 2.0 * (ux * vx + uy * vy);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        let (vx, vy) = (
            p[2] / self.m2 - p[0] / self.m1,
            p[3] / self.m2 - p[1] / self.m1,
        );
        // Row 0: d(2 q₁·p₁/m₁).
        out[0] = 2.0 * p[0] / self.m1;
        out[2] = 2.0 * p[1] / self.m1;
        out[2 * 4] = 2.0 * q[0] / self.m1;
        out[2 * 5] = 2.0 * q[1] / self.m1;
        // Row 1: d(2 u·v), u = q₂ − q₁, v = p₂/m₂ − p₁/m₁.
        out[1] = -2.0 * vx;
        out[1 + 2] = -2.0 * vy;
        out[1 + 2 * 2] = 2.0 * vx;
        out[1 + 2 * 3] = 2.0 * vy;
        out[1 + 2 * 4] = -2.0 * ux / self.m1;
        out[1 + 2 * 5] = -2.0 * uy / self.m1;
        out[1 + 2 * 6] = 2.0 * ux / self.m2;
        out[1 + 2 * 7] = 2.0 * uy / self.m2;
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        // N = g_q M⁻¹ g_qᵀ.
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        let uu = ux * ux + uy * uy;
        let qu = q[0] * ux + q[1] * uy;
        n[0] = 4.0 * (q[0] * q[0] + q[1] * q[1]) / self.m1;
        n[1] = -4.0 * qu / self.m1;
        n[2] = -4.0 * qu / self.m1;
        n[3] = 4.0 * uu * (1.0 / self.m1 + 1.0 / self.m2);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        let (ux, uy) = (q[2] - q[0], q[3] - q[1]);
        let (a, b) = (2.0 * lambda[0], 2.0 * lambda[1]);
        p[0] -= a * q[0] - b * ux;
        p[1] -= a * q[1] - b * uy;
        p[2] -= b * ux;
        p[3] -= b * uy;
        ClosedForm::Applied
    }
}

// ---------------------------------------------------------------------------
// Hopf (harmonic) constraint, Section 5.4
// ---------------------------------------------------------------------------

/// g = |q|² + |p|² − r² on R⁴ with H = |p|²/2 − γ·q (γ = (0, 0) gives the
/// Hamiltonian without potential of 5.4.1, γ = (0, −1) the one of 5.4.2).
/// The fibre flow is the closed-form rotation z_k = q_k + i p_k ↦ e^{−2iλ} z_k.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Hopf {
    /// r² (the paper's table lies on r² = 0.98).
    pub radius2: f64,
    /// The vector γ of the potential −γ·q.
    pub gravity: [f64; 2],
}

impl Hopf {
    /// H = |p|²/2 on the unit sphere (Section 5.4.1).
    pub fn free() -> Self {
        Hopf {
            radius2: 1.0,
            gravity: [0.0, 0.0],
        }
    }

    /// H = |p|²/2 − γ·q with γ = (0, −1) on the unit sphere (Section 5.4.2).
    pub fn gravity() -> Self {
        Hopf {
            radius2: 1.0,
            gravity: [0.0, -1.0],
        }
    }
}

impl Hamiltonian for Hopf {
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
        0.5 * (p[0] * p[0] + p[1] * p[1]) - self.gravity[0] * q[0] - self.gravity[1] * q[1]
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], h_q: &mut [f64]) {
        h_q[0] = -self.gravity[0];
        h_q[1] = -self.gravity[1];
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

impl ConstrainedSystem for Hopf {
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
        let a = 2.0 * lambda[0];
        out[0] = a;
        out[1 + 4] = a;
        out[2 + 2 * 4] = a;
        out[3 + 3 * 4] = a;
    }
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        // {g,H} = g_q·H_p − g_p·H_q = 2q·p + 2γ·p.
        out[0] =
            2.0 * (q[0] * p[0] + q[1] * p[1] + self.gravity[0] * p[0] + self.gravity[1] * p[1]);
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = 2.0 * p[0];
        out[1] = 2.0 * p[1];
        out[2] = 2.0 * (q[0] + self.gravity[0]);
        out[3] = 2.0 * (q[1] + self.gravity[1]);
    }
    fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
        // N = {{H,g},g} = 4(|q|² − |p|² + γ·q).
        n[0] = 4.0
            * (q[0] * q[0] + q[1] * q[1] - p[0] * p[0] - p[1] * p[1]
                + self.gravity[0] * q[0]
                + self.gravity[1] * q[1]);
    }
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        let (s, c) = (2.0 * lambda[0]).sin_cos();
        for k in 0..2 {
            let (qk, pk) = (q[k], p[k]);
            q[k] = c * qk + s * pk;
            p[k] = -s * qk + c * pk;
        }
        ClosedForm::Applied
    }
}

// ---------------------------------------------------------------------------
// Section 5.2: failing nondegeneracy
// ---------------------------------------------------------------------------

/// R⁴ with coordinates q = (q, q̄), p = (p, p̄), g = q̄, H = p²/2 + p̄ q:
/// N = {{H,g},g} ≡ 0 and the problem has index 5 (Section 5.2).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct IndexFive;

impl Hamiltonian for IndexFive {
    fn dof(&self) -> usize {
        2
    }
    fn separable(&self) -> bool {
        false
    }
    fn quadratic_kinetic(&self) -> bool {
        false
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * p[0] * p[0] + p[1] * q[0]
    }
    fn grad_q(&self, _q: &[f64], p: &[f64], h_q: &mut [f64]) {
        h_q[0] = p[1];
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
        h_p[1] = q[0];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[2 + 2 * 4] = 1.0;
        h_zz[3 * 4] = 1.0;
        h_zz[3] = 1.0;
    }
}

impl ConstrainedSystem for IndexFive {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 1)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["q̄"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[1];
    }
    fn constraint_jacobian(&self, _q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        g_z[1] = 1.0;
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], _lambda: &[f64], _out: &mut [f64]) {}
    fn hidden_constraints(&self, q: &[f64], _p: &[f64], out: &mut [f64]) {
        out[0] = q[0];
    }
    fn hidden_constraint_jacobian(&self, _q: &[f64], _p: &[f64], out: &mut [f64]) {
        out[0] = 1.0;
    }
    fn nondegeneracy_matrix(&self, _q: &[f64], _p: &[f64], n: &mut [f64]) {
        n[0] = 0.0;
    }
    fn fibre_flow(&self, lambda: &[f64], _q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        p[1] -= lambda[0];
        ClosedForm::Applied
    }
}

/// The other example of Section 5.2: g = q̄, H = p²/2. H is constant on the
/// fibres, M^H = M and solutions are not unique.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct FlatFibres;

impl Hamiltonian for FlatFibres {
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
        0.5 * p[0] * p[0]
    }
    fn grad_q(&self, _q: &[f64], _p: &[f64], _h_q: &mut [f64]) {}
    fn grad_p(&self, _q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
    }
    fn hessian(&self, _q: &[f64], _p: &[f64], h_zz: &mut [f64]) {
        h_zz[2 + 2 * 4] = 1.0;
    }
}

impl ConstrainedSystem for FlatFibres {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 1)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["q̄"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[1];
    }
    fn constraint_jacobian(&self, _q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        g_z[1] = 1.0;
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], _lambda: &[f64], _out: &mut [f64]) {}
    fn hidden_constraints(&self, _q: &[f64], _p: &[f64], out: &mut [f64]) {
        out[0] = 0.0;
    }
    fn hidden_constraint_jacobian(&self, _q: &[f64], _p: &[f64], _out: &mut [f64]) {}
    fn nondegeneracy_matrix(&self, _q: &[f64], _p: &[f64], n: &mut [f64]) {
        n[0] = 0.0;
    }
    fn fibre_flow(&self, lambda: &[f64], _q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        p[1] -= lambda[0];
        ClosedForm::Applied
    }
}

/// g = q̄ with H = p²/2 + q p̄²/2 on R⁴: N = {{H,g},g} = q changes sign at
/// q = 0, where M^H = {q̄ = 0, q p̄ = 0} splits into the components q < 0 and
/// q > 0 (with p̄ = 0). Moving with p > 0 from q < 0 crosses it.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct SignChange;

impl Hamiltonian for SignChange {
    fn dof(&self) -> usize {
        2
    }
    fn separable(&self) -> bool {
        false
    }
    fn quadratic_kinetic(&self) -> bool {
        false
    }
    fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
        0.5 * p[0] * p[0] + 0.5 * q[0] * p[1] * p[1]
    }
    fn grad_q(&self, _q: &[f64], p: &[f64], h_q: &mut [f64]) {
        h_q[0] = 0.5 * p[1] * p[1];
    }
    fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
        h_p[0] = p[0];
        h_p[1] = q[0] * p[1];
    }
    fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
        h_zz[3 * 4] = p[1];
        h_zz[3] = p[1];
        h_zz[2 + 2 * 4] = 1.0;
        h_zz[3 + 3 * 4] = q[0];
    }
}

impl ConstrainedSystem for SignChange {
    fn constraint_count(&self) -> usize {
        1
    }
    fn kind(&self) -> ConstraintKind {
        ConstraintKind::Holonomic
    }
    fn jacobian_pattern(&self) -> &[(usize, usize)] {
        &[(0, 1)]
    }
    fn constraint_name(&self, i: usize) -> &str {
        const NAMES: &[&str] = &["q̄"];
        NAMES[i]
    }
    fn constraints(&self, q: &[f64], _p: &[f64], g: &mut [f64]) {
        g[0] = q[1];
    }
    fn constraint_jacobian(&self, _q: &[f64], _p: &[f64], g_z: &mut [f64]) {
        g_z[1] = 1.0;
    }
    fn constraint_hessian(&self, _q: &[f64], _p: &[f64], _lambda: &[f64], _out: &mut [f64]) {}
    fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = q[0] * p[1];
    }
    fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
        out[0] = p[1];
        out[3] = q[0];
    }
    fn nondegeneracy_matrix(&self, q: &[f64], _p: &[f64], n: &mut [f64]) {
        n[0] = q[0];
    }
    fn fibre_flow(&self, lambda: &[f64], _q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        p[1] -= lambda[0];
        ClosedForm::Applied
    }
}

// ---------------------------------------------------------------------------
// Wrappers that hide a closed form
// ---------------------------------------------------------------------------

/// Delegates everything to `S` but has no closed-form fibre flow, so the
/// runtime uses its own (the kick from g_q for holonomic g, the matrix
/// exponential for quadratic g).
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct NoClosedForm<S>(pub S);

/// Delegates everything to `S` but declares `ConstraintKind::General`, so the
/// runtime integrates the fibre flow numerically.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct AsGeneral<S>(pub S);

/// Delegates everything to `S`, its closed-form fibre flow included, but
/// the packed values of g_z
/// ([`ConstrainedSystem::constraint_jacobian_values`]) and the fixed-size
/// step, so the runtime reads G out of the dense g_z on its slice path.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub struct DenseJacobian<S>(pub S);

macro_rules! delegate {
    ($wrapper:ident, $kind:expr $(, { $($more:tt)* })?) => {
        impl<S: ConstrainedSystem> Hamiltonian for $wrapper<S> {
            fn dof(&self) -> usize {
                self.0.dof()
            }
            fn separable(&self) -> bool {
                self.0.separable()
            }
            fn quadratic_kinetic(&self) -> bool {
                self.0.quadratic_kinetic()
            }
            fn hamiltonian(&self, q: &[f64], p: &[f64]) -> f64 {
                self.0.hamiltonian(q, p)
            }
            fn grad_q(&self, q: &[f64], p: &[f64], h_q: &mut [f64]) {
                self.0.grad_q(q, p, h_q)
            }
            fn grad_p(&self, q: &[f64], p: &[f64], h_p: &mut [f64]) {
                self.0.grad_p(q, p, h_p)
            }
            fn hessian(&self, q: &[f64], p: &[f64], h_zz: &mut [f64]) {
                self.0.hessian(q, p, h_zz)
            }
        }
        impl<S: ConstrainedSystem> ConstrainedSystem for $wrapper<S> {
            fn constraint_count(&self) -> usize {
                self.0.constraint_count()
            }
            fn kind(&self) -> ConstraintKind {
                let kind: Option<ConstraintKind> = $kind;
                kind.unwrap_or_else(|| self.0.kind())
            }
            fn jacobian_pattern(&self) -> &[(usize, usize)] {
                self.0.jacobian_pattern()
            }
            fn constraint_name(&self, i: usize) -> &str {
                self.0.constraint_name(i)
            }
            fn constraints(&self, q: &[f64], p: &[f64], g: &mut [f64]) {
                self.0.constraints(q, p, g)
            }
            fn constraint_jacobian(&self, q: &[f64], p: &[f64], g_z: &mut [f64]) {
                self.0.constraint_jacobian(q, p, g_z)
            }
            fn constraint_hessian(&self, q: &[f64], p: &[f64], lambda: &[f64], out: &mut [f64]) {
                self.0.constraint_hessian(q, p, lambda, out)
            }
            fn hidden_constraints(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
                self.0.hidden_constraints(q, p, out)
            }
            fn hidden_constraint_jacobian(&self, q: &[f64], p: &[f64], out: &mut [f64]) {
                self.0.hidden_constraint_jacobian(q, p, out)
            }
            fn nondegeneracy_matrix(&self, q: &[f64], p: &[f64], n: &mut [f64]) {
                self.0.nondegeneracy_matrix(q, p, n)
            }
            fn interpreted(&self) -> bool {
                self.0.interpreted()
            }
            $($($more)*)?
        }
    };
}

delegate!(NoClosedForm, None);
delegate!(AsGeneral, Some(ConstraintKind::General));
delegate!(DenseJacobian, None, {
    fn fibre_flow(&self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) -> ClosedForm {
        self.0.fibre_flow(lambda, q, p)
    }
});
