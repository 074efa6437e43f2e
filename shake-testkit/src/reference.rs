//! Independent reference implementations ("oracles") for the tests and the
//! paper scenes.
//!
//! Project rule: accuracy claims are checked against something independent.
//! Nothing in this module uses `geoshake-runtime` or `geoshake-macros`: it is plain
//! Rust, `nalgebra` and `num-dual`. All derivatives are computed by forward-mode
//! automatic differentiation (`num-dual`) of the *same* H and g written once,
//! generically over the scalar type, so no code is shared with the macro's
//! symbolic derivatives.
//!
//! Conventions are MISSION.md's: z = (q, p), X_F = (F_p, −F_q),
//! {F,G} = F_q·G_p − F_p·G_q, and the constrained equations
//! q' = H_p + g_pᵀλ, p' = −H_q − g_qᵀλ, 0 = g(q,p).
//!
//! Contents (sections of the paper "Geometric generalisations of SHAKE and
//! RATTLE" in brackets):
//! 0. systems, derivatives by num-dual, brackets;
//! 1. classical SHAKE / RATTLE, Störmer–Verlet and symplectic Euler (§5.1.3);
//! 2. the exact solution of the Hopf system with H = |p|²/2 (§5.4.1);
//! 3. a high-accuracy reference integrator for the DAE (index reduction to an
//!    ODE on M^H, Gragg–Bulirsch–Stoer extrapolation);
//! 4. the formulas behind the Hopf figures (§5.4.2);
//! 5. the midpoint rule applied directly to an index-1 system (§5.3).
#![allow(dead_code)]

use nalgebra::{DMatrix, DVector};
use num_dual::{Dual64, DualNum, HyperDual64};
use std::f64::consts::PI;

// ===========================================================================
// 0. Systems and derivatives
// ===========================================================================

/// The scalar types H and g are written for: `f64` and the `num-dual` numbers.
pub trait Scalar: DualNum<Primitive = f64> + Copy {}
impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

/// A constrained Hamiltonian system on R^{2d}: H(q,p) and g_i(q,p), i < m,
/// written once, generically, so that num-dual can differentiate them.
pub trait System {
    /// d, the number of positions.
    fn dof(&self) -> usize;
    /// m, the number of constraints.
    fn n_constraints(&self) -> usize;
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T;
    fn constraint<T: Scalar>(&self, i: usize, q: &[T], p: &[T]) -> T;
}

/// Which function of a [`System`]: H or g_i.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fun {
    H,
    G(usize),
}

fn eval_fun<S: System, T: Scalar>(s: &S, f: Fun, z: &[T]) -> T {
    let (q, p) = z.split_at(s.dof());
    match f {
        Fun::H => s.hamiltonian(q, p),
        Fun::G(i) => s.constraint(i, q, p),
    }
}

/// ∇f(x) of a function of n variables, by n forward passes with dual numbers.
pub fn gradient_with(x: &[f64], f: impl Fn(&[Dual64]) -> Dual64) -> DVector<f64> {
    let mut xd: Vec<Dual64> = x.iter().map(|&v| Dual64::from(v)).collect();
    DVector::from_fn(x.len(), |i, _| {
        xd[i].eps = 1.0;
        let r = f(&xd).eps;
        xd[i].eps = 0.0;
        r
    })
}

/// (∇f(x), ∇²f(x)) by n(n+1)/2 passes with hyper-dual numbers (exact to
/// round-off, no finite differences).
pub fn hessian_with(
    x: &[f64],
    f: impl Fn(&[HyperDual64]) -> HyperDual64,
) -> (DVector<f64>, DMatrix<f64>) {
    let n = x.len();
    let mut xd: Vec<HyperDual64> = x.iter().map(|&v| HyperDual64::from(v)).collect();
    let mut grad = DVector::zeros(n);
    let mut hess = DMatrix::zeros(n, n);
    for i in 0..n {
        for j in i..n {
            xd[i].eps1 = 1.0;
            xd[j].eps2 = 1.0;
            let r = f(&xd);
            xd[i].eps1 = 0.0;
            xd[j].eps2 = 0.0;
            hess[(i, j)] = r.eps1eps2;
            hess[(j, i)] = r.eps1eps2;
            if i == j {
                grad[i] = r.eps1;
            }
        }
    }
    (grad, hess)
}

/// f(z) for f = H or g_i.
pub fn value<S: System>(s: &S, f: Fun, z: &[f64]) -> f64 {
    eval_fun(s, f, z)
}

/// ∇f(z) = (f_q, f_p).
pub fn gradient<S: System>(s: &S, f: Fun, z: &[f64]) -> DVector<f64> {
    gradient_with(z, |x| eval_fun(s, f, x))
}

/// (∇f(z), ∇²f(z)).
pub fn hessian<S: System>(s: &S, f: Fun, z: &[f64]) -> (DVector<f64>, DMatrix<f64>) {
    hessian_with(z, |x| eval_fun(s, f, x))
}

/// J∇F = (F_p, −F_q): the Hamiltonian vector field X_F from the gradient of F.
pub fn j_grad(grad: &DVector<f64>) -> DVector<f64> {
    let d = grad.len() / 2;
    DVector::from_fn(2 * d, |k, _| if k < d { grad[d + k] } else { -grad[k - d] })
}

/// {F,G} = F_q·G_p − F_p·G_q = ∇F·J∇G from the two gradients.
pub fn bracket(grad_f: &DVector<f64>, grad_g: &DVector<f64>) -> f64 {
    grad_f.dot(&j_grad(grad_g))
}

/// z = (q, p) as one vector.
pub fn join(q: &DVector<f64>, p: &DVector<f64>) -> DVector<f64> {
    DVector::from_iterator(q.len() + p.len(), q.iter().chain(p.iter()).copied())
}

/// (q, p) from z.
pub fn split(z: &DVector<f64>) -> (DVector<f64>, DVector<f64>) {
    let d = z.len() / 2;
    (z.rows(0, d).into_owned(), z.rows(d, d).into_owned())
}

pub fn energy<S: System>(s: &S, z: &DVector<f64>) -> f64 {
    value(s, Fun::H, z.as_slice())
}

/// g(z) ∈ R^m.
pub fn constraints<S: System>(s: &S, z: &DVector<f64>) -> DVector<f64> {
    DVector::from_fn(s.n_constraints(), |i, _| value(s, Fun::G(i), z.as_slice()))
}

/// The hidden constraints {g_i, H}(z) (zero exactly on M^H).
pub fn hidden_constraints<S: System>(s: &S, z: &DVector<f64>) -> DVector<f64> {
    let gh = gradient(s, Fun::H, z.as_slice());
    DVector::from_fn(s.n_constraints(), |i, _| {
        bracket(&gradient(s, Fun::G(i), z.as_slice()), &gh)
    })
}

// ---------------------------------------------------------------------------
// Newton's method to round-off (shared by the implicit solves below)
// ---------------------------------------------------------------------------

/// Newton's method with the exact Jacobian: iterate until the correction is
/// below 1e-13 relative, then one more (polishing) iteration, so the result is
/// at round-off. Panics (with `what`) on a singular Jacobian or no convergence:
/// an oracle must never return a silently wrong answer.
pub fn newton(
    mut x: DVector<f64>,
    what: &str,
    mut residual_and_jacobian: impl FnMut(&DVector<f64>) -> (DVector<f64>, DMatrix<f64>),
) -> DVector<f64> {
    let mut small = 0;
    for _ in 0..100 {
        let (r, jac) = residual_and_jacobian(&x);
        let dx = jac
            .lu()
            .solve(&r)
            .unwrap_or_else(|| panic!("{what}: singular Jacobian in Newton's method"));
        x -= &dx;
        if !x.iter().all(|v| v.is_finite()) {
            panic!("{what}: Newton's method diverged");
        }
        if dx.norm() <= 1e-13 * (1.0 + x.norm()) {
            small += 1;
            if small == 2 {
                return x;
            }
        }
    }
    panic!("{what}: Newton's method did not converge in 100 iterations")
}

// ===========================================================================
// 1. Classical SHAKE and RATTLE (§5.1.3), holonomic g(q), general H(q,p)
// ===========================================================================

/// The unconstrained symplectic map underneath the classical methods.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClassicalBase {
    /// Generalised Störmer–Verlet: classical SHAKE/RATTLE, order 2.
    StormerVerlet,
    /// Symplectic Euler (HLW VII.1.3): order 1.
    SymplecticEuler,
}

/// One classical SHAKE (and, if asked, RATTLE) step.
#[derive(Clone, Debug)]
pub struct ClassicalStep {
    pub q1: DVector<f64>,
    /// SHAKE's momentum p1⁻ (z1⁻ = (q1, p1⁻) ∈ M).
    pub p1_minus: DVector<f64>,
    /// RATTLE's momentum p1 ((q1, p1) ∈ M^H); equals p1⁻ after a SHAKE step.
    pub p1: DVector<f64>,
    /// The paper's λ (classical scaling, see [`classical_shake`]).
    pub lambda: DVector<f64>,
    /// The paper's μ of the RATTLE projection (empty after a SHAKE step).
    pub mu: DVector<f64>,
}

/// Jacobian g_q(q) (m × d) of holonomic constraints.
fn g_q<S: System>(s: &S, q: &DVector<f64>) -> DMatrix<f64> {
    let d = s.dof();
    let z = join(q, &DVector::zeros(d));
    let mut jac = DMatrix::zeros(s.n_constraints(), d);
    for i in 0..s.n_constraints() {
        let gr = gradient(s, Fun::G(i), z.as_slice());
        jac.row_mut(i).copy_from(&gr.rows(0, d).transpose());
    }
    jac
}

fn g_of_q<S: System>(s: &S, q: &DVector<f64>) -> DVector<f64> {
    constraints(s, &join(q, &DVector::zeros(s.dof())))
}

fn assert_holonomic<S: System>(s: &S, q: &DVector<f64>, p: &DVector<f64>) {
    let d = s.dof();
    let z = join(q, p);
    for i in 0..s.n_constraints() {
        let gr = gradient(s, Fun::G(i), z.as_slice());
        assert!(
            gr.rows(d, d).norm() == 0.0,
            "classical SHAKE/RATTLE (§5.1.3) needs holonomic constraints g(q); g_{i} depends on p"
        );
    }
}

/// (H_q, H_p, H_qq, H_qp, H_pq, H_pp) at (q, p).
struct HDerivs {
    hq: DVector<f64>,
    hp: DVector<f64>,
    hqp: DMatrix<f64>,
    hpq: DMatrix<f64>,
    hpp: DMatrix<f64>,
}

fn h_derivs<S: System>(s: &S, q: &DVector<f64>, p: &DVector<f64>) -> HDerivs {
    let d = s.dof();
    let (g, h) = hessian(s, Fun::H, join(q, p).as_slice());
    HDerivs {
        hq: g.rows(0, d).into_owned(),
        hp: g.rows(d, d).into_owned(),
        hqp: h.view((0, d), (d, d)).into_owned(),
        hpq: h.view((d, 0), (d, d)).into_owned(),
        hpp: h.view((d, d), (d, d)).into_owned(),
    }
}

/// Classical SHAKE (§5.1.3), written straight from the paper's formulas.
///
/// Störmer–Verlet version, (q0, p0) ↦ (q1, p1⁻):
/// ```text
/// p0⁺    = p0 − (h/2) g_q(q0)ᵀ λ
/// p_1/2  = p0⁺ − (h/2) H_q(q0, p_1/2)                       (implicit)
/// q1     = q0 + (h/2) (H_p(q0, p_1/2) + H_p(q1, p_1/2))      (implicit)
/// p1⁻    = p_1/2 − (h/2) H_q(q1, p_1/2)
/// 0      = g(q1)
/// ```
/// Symplectic-Euler version (HLW VII.1.3):
/// ```text
/// p0⁺ = p0 − h g_q(q0)ᵀ λ,  p1⁻ = p0⁺ − h H_q(q0, p1⁻),  q1 = q0 + h H_p(q0, p1⁻),  0 = g(q1).
/// ```
/// The unknowns (λ, p_1/2 or p1⁻, q1) are solved together by Newton's method
/// with the exact Jacobian (Hessian of H and g_q from num-dual), to round-off.
///
/// λ scaling: the geometric fibre parameter of MISSION.md (the kick
/// p ↦ p − g_q(q)ᵀλ_geo of exp(Σλ_i X_{g_i})) is λ_geo = (h/2)·λ for
/// Störmer–Verlet and λ_geo = h·λ for symplectic Euler.
pub fn classical_shake<S: System>(
    s: &S,
    base: ClassicalBase,
    q0: &DVector<f64>,
    p0: &DVector<f64>,
    h: f64,
) -> ClassicalStep {
    assert_holonomic(s, q0, p0);
    let (d, m) = (s.dof(), s.n_constraints());
    let gq0 = g_q(s, q0);
    // c: coefficient of the kick and of the first half step (h/2 or h).
    let c = match base {
        ClassicalBase::StormerVerlet => 0.5 * h,
        ClassicalBase::SymplecticEuler => h,
    };
    let d0 = h_derivs(s, q0, p0);
    let mut x0 = DVector::zeros(m + 2 * d);
    x0.rows_mut(m, d).copy_from(&(p0 - c * &d0.hq));
    x0.rows_mut(m + d, d).copy_from(&(q0 + h * &d0.hp));
    let x = newton(x0, "classical SHAKE", |x| {
        let lam = x.rows(0, m).into_owned();
        let pm = x.rows(m, d).into_owned(); // p_1/2 (SV) or p1⁻ (SE)
        let q1 = x.rows(m + d, d).into_owned();
        let a = h_derivs(s, q0, &pm);
        let gq1 = g_q(s, &q1);
        let mut r = DVector::zeros(m + 2 * d);
        let mut jac = DMatrix::zeros(m + 2 * d, m + 2 * d);
        let eye = DMatrix::<f64>::identity(d, d);
        // R1 = pm − p0 + c g_q(q0)ᵀλ + c H_q(q0, pm)
        r.rows_mut(0, d)
            .copy_from(&(&pm - p0 + c * gq0.transpose() * &lam + c * &a.hq));
        jac.view_mut((0, 0), (d, m))
            .copy_from(&(c * gq0.transpose()));
        jac.view_mut((0, m), (d, d)).copy_from(&(&eye + c * &a.hqp));
        match base {
            ClassicalBase::StormerVerlet => {
                // R2 = q1 − q0 − (h/2)(H_p(q0, p½) + H_p(q1, p½))
                let b = h_derivs(s, &q1, &pm);
                r.rows_mut(d, d)
                    .copy_from(&(&q1 - q0 - 0.5 * h * (&a.hp + &b.hp)));
                jac.view_mut((d, m), (d, d))
                    .copy_from(&(-0.5 * h * (&a.hpp + &b.hpp)));
                jac.view_mut((d, m + d), (d, d))
                    .copy_from(&(&eye - 0.5 * h * &b.hpq));
            }
            ClassicalBase::SymplecticEuler => {
                // R2 = q1 − q0 − h H_p(q0, p1⁻)
                r.rows_mut(d, d).copy_from(&(&q1 - q0 - h * &a.hp));
                jac.view_mut((d, m), (d, d)).copy_from(&(-h * &a.hpp));
                jac.view_mut((d, m + d), (d, d)).copy_from(&eye);
            }
        }
        // R3 = g(q1)
        r.rows_mut(2 * d, m).copy_from(&g_of_q(s, &q1));
        jac.view_mut((2 * d, m + d), (m, d)).copy_from(&gq1);
        (r, jac)
    });
    let lambda = x.rows(0, m).into_owned();
    let pm = x.rows(m, d).into_owned();
    let q1 = x.rows(m + d, d).into_owned();
    let p1_minus = match base {
        ClassicalBase::StormerVerlet => &pm - 0.5 * h * h_derivs(s, &q1, &pm).hq,
        ClassicalBase::SymplecticEuler => pm,
    };
    ClassicalStep {
        q1,
        p1: p1_minus.clone(),
        p1_minus,
        lambda,
        mu: DVector::zeros(0),
    }
}

/// Classical RATTLE (§5.1.3): SHAKE, then the projection onto M^H
/// ```text
/// Störmer–Verlet:    p1 = p1⁻ + g_q(q1)ᵀ μ,      0 = g_q(q1) H_p(q1, p1)
/// symplectic Euler:  p1 = p1⁻ − h g_q(q1)ᵀ μ,    0 = g_q(q1) H_p(q1, p1)
/// ```
/// (signs and scalings exactly as printed). The geometric parameter σ of
/// exp(Σσ_i X_{g_i}) (p ↦ p − g_qᵀσ) is σ = −μ (SV) and σ = h·μ (SE).
pub fn classical_rattle<S: System>(
    s: &S,
    base: ClassicalBase,
    q0: &DVector<f64>,
    p0: &DVector<f64>,
    h: f64,
) -> ClassicalStep {
    let mut step = classical_shake(s, base, q0, p0, h);
    let m = s.n_constraints();
    let gq1 = g_q(s, &step.q1);
    let c = match base {
        ClassicalBase::StormerVerlet => 1.0,
        ClassicalBase::SymplecticEuler => -h,
    };
    let (q1, p1m) = (step.q1.clone(), step.p1_minus.clone());
    let mu = newton(DVector::zeros(m), "classical RATTLE projection", |mu| {
        let p1 = &p1m + c * gq1.transpose() * mu;
        let a = h_derivs(s, &q1, &p1);
        (&gq1 * &a.hp, c * &gq1 * &a.hpp * gq1.transpose())
    });
    step.p1 = &p1m + c * gq1.transpose() * &mu;
    step.mu = mu;
    step
}

/// SHAKE on z = (q, p): returns z1⁻ = (q1, p1⁻).
pub fn classical_shake_z<S: System>(
    s: &S,
    base: ClassicalBase,
    z: &DVector<f64>,
    h: f64,
) -> DVector<f64> {
    let (q, p) = split(z);
    let st = classical_shake(s, base, &q, &p, h);
    join(&st.q1, &st.p1_minus)
}

/// RATTLE on z = (q, p): returns z1 = (q1, p1).
pub fn classical_rattle_z<S: System>(
    s: &S,
    base: ClassicalBase,
    z: &DVector<f64>,
    h: f64,
) -> DVector<f64> {
    let (q, p) = split(z);
    let st = classical_rattle(s, base, &q, &p, h);
    join(&st.q1, &st.p1)
}

// ---------------------------------------------------------------------------
// Ready-made holonomic systems (mass 1 unless stated; gravity along −y or −z)
// ---------------------------------------------------------------------------

fn dot<T: Scalar>(a: &[T], b: &[T]) -> T {
    a.iter()
        .zip(b)
        .fold(T::from(0.0), |acc, (&x, &y)| acc + x * y)
}

/// Planar pendulum (Example 1.3 with g read as |q|² − ℓ²):
/// H = |p|²/2 + G q_2,  g = |q|² − ℓ²  (d = 2, m = 1).
#[derive(Clone, Copy, Debug)]
pub struct PlanarPendulum {
    pub length: f64,
    pub gravity: f64,
}

impl Default for PlanarPendulum {
    fn default() -> Self {
        Self {
            length: 1.0,
            gravity: 1.0,
        }
    }
}

impl PlanarPendulum {
    /// The state at angle θ from the downward vertical with angular velocity
    /// ω: q = ℓ(sin θ, −cos θ), p = ℓω(cos θ, sin θ); it lies on M^H.
    pub fn state(&self, theta: f64, omega: f64) -> DVector<f64> {
        let l = self.length;
        DVector::from_vec(vec![
            l * theta.sin(),
            -l * theta.cos(),
            l * omega * theta.cos(),
            l * omega * theta.sin(),
        ])
    }
}

impl System for PlanarPendulum {
    fn dof(&self) -> usize {
        2
    }
    fn n_constraints(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        dot(p, p) * 0.5 + q[1] * self.gravity
    }
    fn constraint<T: Scalar>(&self, _i: usize, q: &[T], _p: &[T]) -> T {
        dot(q, q) - self.length * self.length
    }
}

/// Spherical pendulum: H = |p|²/2 + G q_3, g = |q|² − ℓ² (d = 3, m = 1).
#[derive(Clone, Copy, Debug)]
pub struct SphericalPendulum {
    pub length: f64,
    pub gravity: f64,
}

impl Default for SphericalPendulum {
    fn default() -> Self {
        Self {
            length: 1.0,
            gravity: 1.0,
        }
    }
}

impl SphericalPendulum {
    /// q = ℓ(sin θ cos φ, sin θ sin φ, −cos θ) with velocity
    /// θ' ∂q/∂θ + φ' ∂q/∂φ; the state lies on M^H.
    pub fn state(&self, theta: f64, phi: f64, theta_dot: f64, phi_dot: f64) -> DVector<f64> {
        let l = self.length;
        let (st, ct, sp, cp) = (theta.sin(), theta.cos(), phi.sin(), phi.cos());
        let q = [l * st * cp, l * st * sp, -l * ct];
        let dq_dtheta = [l * ct * cp, l * ct * sp, l * st];
        let dq_dphi = [-l * st * sp, l * st * cp, 0.0];
        DVector::from_fn(6, |k, _| {
            if k < 3 {
                q[k]
            } else {
                theta_dot * dq_dtheta[k - 3] + phi_dot * dq_dphi[k - 3]
            }
        })
    }
}

impl System for SphericalPendulum {
    fn dof(&self) -> usize {
        3
    }
    fn n_constraints(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        dot(p, p) * 0.5 + q[2] * self.gravity
    }
    fn constraint<T: Scalar>(&self, _i: usize, q: &[T], _p: &[T]) -> T {
        dot(q, q) - self.length * self.length
    }
}

/// Double pendulum in the plane, two links (d = 4, m = 2):
/// q = (x1, y1, x2, y2),
/// H = |p1|²/(2 m1) + |p2|²/(2 m2) + G (m1 y1 + m2 y2),
/// g_1 = |x1|² − ℓ1², g_2 = |x2 − x1|² − ℓ2².
#[derive(Clone, Copy, Debug)]
pub struct DoublePendulum {
    pub l1: f64,
    pub l2: f64,
    pub m1: f64,
    pub m2: f64,
    pub gravity: f64,
}

impl Default for DoublePendulum {
    fn default() -> Self {
        Self {
            l1: 1.0,
            l2: 1.0,
            m1: 1.0,
            m2: 1.0,
            gravity: 1.0,
        }
    }
}

impl DoublePendulum {
    /// The state at link angles θ1, θ2 (from the downward vertical) with
    /// angular velocities ω1, ω2; it lies on M^H.
    pub fn state(&self, th1: f64, th2: f64, w1: f64, w2: f64) -> DVector<f64> {
        let (x1, y1) = (self.l1 * th1.sin(), -self.l1 * th1.cos());
        let (x2, y2) = (x1 + self.l2 * th2.sin(), y1 - self.l2 * th2.cos());
        let (u1, v1) = (self.l1 * w1 * th1.cos(), self.l1 * w1 * th1.sin());
        let (u2, v2) = (u1 + self.l2 * w2 * th2.cos(), v1 + self.l2 * w2 * th2.sin());
        DVector::from_vec(vec![
            x1,
            y1,
            x2,
            y2,
            self.m1 * u1,
            self.m1 * v1,
            self.m2 * u2,
            self.m2 * v2,
        ])
    }
}

impl System for DoublePendulum {
    fn dof(&self) -> usize {
        4
    }
    fn n_constraints(&self) -> usize {
        2
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        dot(&p[0..2], &p[0..2]) * (0.5 / self.m1)
            + dot(&p[2..4], &p[2..4]) * (0.5 / self.m2)
            + (q[1] * self.m1 + q[3] * self.m2) * self.gravity
    }
    fn constraint<T: Scalar>(&self, i: usize, q: &[T], _p: &[T]) -> T {
        match i {
            0 => dot(&q[0..2], &q[0..2]) - self.l1 * self.l1,
            _ => {
                let (dx, dy) = (q[2] - q[0], q[3] - q[1]);
                dx * dx + dy * dy - self.l2 * self.l2
            }
        }
    }
}

/// A planar pendulum with a position-dependent mass, so that the classical
/// methods are genuinely implicit (H_qp ≠ 0, H_pp not constant):
/// H = (1 + ε q_1²)|p|²/2 + G q_2, g = |q|² − 1 (d = 2, m = 1).
#[derive(Clone, Copy, Debug)]
pub struct NonSeparablePendulum {
    pub eps: f64,
    pub gravity: f64,
}

impl System for NonSeparablePendulum {
    fn dof(&self) -> usize {
        2
    }
    fn n_constraints(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        (q[0] * q[0] * self.eps + 1.0) * dot(p, p) * 0.5 + q[1] * self.gravity
    }
    fn constraint<T: Scalar>(&self, _i: usize, q: &[T], _p: &[T]) -> T {
        dot(q, q) - 1.0
    }
}

// ===========================================================================
// 2. Exact solution of the Hopf system with H = |p|²/2 (§5.4.1)
// ===========================================================================

/// The 2-d cross product q ∧ p = q_0 p_1 − q_1 p_0 (angular momentum).
pub fn wedge(q: [f64; 2], p: [f64; 2]) -> f64 {
    q[0] * p[1] - q[1] * p[0]
}

/// The multiplier λ(z) of the Hopf system in MISSION.md's convention.
///
/// With g = |q|² + |p|² − r², H = |p|²/2: q' = H_p + g_pᵀλ = (1 + 2λ)p,
/// p' = −H_q − g_qᵀλ = −2λq. The paper (eq_hopf_dae) writes (1 + λ)p and −λq,
/// so **λ_paper = 2 λ_MISSION**. Differentiating the hidden constraint
/// q·p = 0 gives λ_paper = |p|²/(|q|² − |p|²) (eq hopf_lambda), hence
/// λ = |p|² / (2(|q|² − |p|²)). Valid for any radius r.
pub fn hopf_lambda(q: [f64; 2], p: [f64; 2]) -> f64 {
    let (qq, pp) = (q[0] * q[0] + q[1] * q[1], p[0] * p[0] + p[1] * p[1]);
    pp / (2.0 * (qq - pp))
}

/// The paper's λ (eq hopf_lambda): twice [`hopf_lambda`].
pub fn hopf_lambda_paper(q: [f64; 2], p: [f64; 2]) -> f64 {
    2.0 * hopf_lambda(q, p)
}

/// The α of eq hopf_dea_exact_solution *with the sign that makes the formula
/// right*: α = −(q0 ∧ p0)/|q0|², i.e. α = −sign(q0 ∧ p0)·|p0|/|q0|.
///
/// The paper says the sign "depends on which connected component" of M^H the
/// point is on. That is not so: each component (|q| > |p| and |q| < |p|)
/// contains points of both orientations q0 ∧ p0 ≷ 0, and on both components
/// the correct sign is the opposite of the sign of q0 ∧ p0.
pub fn hopf_alpha_paper(q0: [f64; 2], p0: [f64; 2]) -> f64 {
    -wedge(q0, p0) / (q0[0] * q0[0] + q0[1] * q0[1])
}

/// Rotation R(θ) applied to v.
pub fn rot(theta: f64, v: [f64; 2]) -> [f64; 2] {
    let (s, c) = theta.sin_cos();
    [c * v[0] - s * v[1], s * v[0] + c * v[1]]
}

/// The exact solution of the Hopf system with H = |p|²/2 (eq
/// hopf_dea_exact_solution): q(t) = R(ωt) q0, p(t) = R(ωt) p0 with
///
///     ω = 1/(α − 1/α) = (q0 ∧ p0) / (|q0|² − |p0|²),   α as in [`hopf_alpha_paper`].
///
/// This form has no branch: it is right on both components of M^H and for
/// both orientations, and it gives rest (ω = 0) at p0 = 0 and at q0 = 0.
/// Derivation: |q|, |p|, λ are constant; q'' = −λ_p(1 + λ_p) q with
/// λ_p(1+λ_p) = |q|²|p|²/(|q|²−|p|²)², and since q0 ⊥ p0 in the plane the
/// solution is a rotation at speed ω with the sign of the initial turn of q.
///
/// Requires (q0, p0) ∈ M^H, i.e. q0·p0 = 0 (any radius), and |q0| ≠ |p0|
/// (the exceptional fibres); panics otherwise.
pub fn hopf_exact(q0: [f64; 2], p0: [f64; 2], t: f64) -> ([f64; 2], [f64; 2]) {
    let (qq, pp) = (q0[0] * q0[0] + q0[1] * q0[1], p0[0] * p0[0] + p0[1] * p0[1]);
    let qp = q0[0] * p0[0] + q0[1] * p0[1];
    assert!(
        qp.abs() <= 1e-12 * (qq + pp),
        "hopf_exact needs a point of M^H (q·p = 0), got q·p = {qp:e}"
    );
    assert!(
        (qq - pp).abs() > 1e-12 * (qq + pp),
        "hopf_exact: |q| = |p| is an exceptional fibre (nondegeneracy fails)"
    );
    let omega = wedge(q0, p0) / (qq - pp);
    (rot(omega * t, q0), rot(omega * t, p0))
}

/// [`hopf_exact`] on z = (q0, q1, p0, p1).
pub fn hopf_exact_z(z: &[f64], t: f64) -> [f64; 4] {
    let (q, p) = hopf_exact([z[0], z[1]], [z[2], z[3]], t);
    [q[0], q[1], p[0], p[1]]
}

// ===========================================================================
// 3. High-accuracy reference integrator for the constrained DAE
// ===========================================================================

/// The multipliers λ(z) on M^H.
///
/// Along a solution the hidden constraints h_i = {g_i, H} stay zero:
/// 0 = d/dt h_i = dh_i·(X_H + Σ_j λ_j X_{g_j}) = {h_i, H} + Σ_j λ_j {h_i, g_j}.
/// With N_ij = {{H, g_i}, g_j} = −{h_i, g_j} this is
///
///     N λ = b,   b_i = {{g_i, H}, H}.
///
/// Brackets of h_i need ∇h_i; with h_i = ∇g_iᵀ J ∇H,
/// ∇h_i = ∇²g_i J∇H − ∇²H J∇g_i (all from num-dual). Panics if N is singular
/// (nondegeneracy fails).
pub fn multipliers<S: System>(s: &S, z: &DVector<f64>) -> DVector<f64> {
    let m = s.n_constraints();
    let (gh, hh) = hessian(s, Fun::H, z.as_slice());
    let xh = j_grad(&gh);
    let mut grads = Vec::with_capacity(m);
    let mut grad_h = Vec::with_capacity(m);
    for i in 0..m {
        let (gg, hg) = hessian(s, Fun::G(i), z.as_slice());
        grad_h.push(&hg * &xh - &hh * j_grad(&gg));
        grads.push(gg);
    }
    let n = DMatrix::from_fn(m, m, |i, j| -bracket(&grad_h[i], &grads[j]));
    let b = DVector::from_fn(m, |i, _| bracket(&grad_h[i], &gh));
    n.lu()
        .solve(&b)
        .expect("reference: N = {{H,g_i},g_j} is singular (nondegeneracy fails)")
}

/// The index-reduced vector field ż = X_H(z) + Σ λ_i(z) X_{g_i}(z) whose flow
/// on M^H is the solution of the DAE (its invariants: g and {g,H}).
pub fn dae_vector_field<S: System>(s: &S, z: &DVector<f64>) -> DVector<f64> {
    let lam = multipliers(s, z);
    let mut f = j_grad(&gradient(s, Fun::H, z.as_slice()));
    for (i, l) in lam.iter().enumerate() {
        f += *l * j_grad(&gradient(s, Fun::G(i), z.as_slice()));
    }
    f
}

/// Default number of extrapolation levels: order 2·6 = 12.
pub const DEFAULT_LEVELS: usize = 6;

/// One Gragg–Bulirsch–Stoer step (HNW I, §II.9): the modified midpoint rule
/// with n_j = 2j substeps, j = 1..levels, extrapolated in h² by
/// Aitken–Neville. Order 2·levels.
pub fn gbs_step(
    f: &mut impl FnMut(&DVector<f64>) -> DVector<f64>,
    z: &DVector<f64>,
    h: f64,
    levels: usize,
) -> DVector<f64> {
    assert!(levels >= 1);
    let f0 = f(z);
    let mut prev_row: Vec<DVector<f64>> = Vec::new();
    let mut ns: Vec<f64> = Vec::new();
    for j in 1..=levels {
        let n = 2 * j;
        let hs = h / n as f64;
        let mut zm = z.clone();
        let mut zc = z + hs * &f0;
        for _ in 1..n {
            let zn = &zm + 2.0 * hs * f(&zc);
            zm = zc;
            zc = zn;
        }
        ns.push(n as f64);
        // row[k-1] = T_{j,k};  T_{j,k+1} = T_{j,k} + (T_{j,k} − T_{j−1,k})/((n_j/n_{j−k})² − 1)
        let mut row = vec![zc];
        for k in 1..j {
            let ratio = (ns[j - 1] / ns[j - 1 - k]).powi(2);
            let next = &row[k - 1] + (&row[k - 1] - &prev_row[k - 1]) / (ratio - 1.0);
            row.push(next);
        }
        prev_row = row;
    }
    prev_row.pop().unwrap()
}

/// z(t_end) from z0 ∈ M^H: `n_steps` GBS steps of order 2·`levels` on
/// [`dae_vector_field`].
pub fn reference_solution_levels<S: System>(
    s: &S,
    z0: &DVector<f64>,
    t_end: f64,
    n_steps: usize,
    levels: usize,
) -> DVector<f64> {
    let h = t_end / n_steps as f64;
    let mut f = |z: &DVector<f64>| dae_vector_field(s, z);
    let mut z = z0.clone();
    for _ in 0..n_steps {
        z = gbs_step(&mut f, &z, h, levels);
    }
    z
}

/// z(t_end) from z0 ∈ M^H with the default order 12. For the pendulums at
/// O(1) energies, steps of 0.05 are at the round-off floor (~1e-13 per unit
/// time); with large multipliers use [`reference_solution_auto`].
pub fn reference_solution<S: System>(
    s: &S,
    z0: &DVector<f64>,
    t_end: f64,
    n_steps: usize,
) -> DVector<f64> {
    reference_solution_levels(s, z0, t_end, n_steps, DEFAULT_LEVELS)
}

/// z(t_end) with the step chosen automatically: n = ⌈|t_end|/0.05⌉ steps,
/// doubled until two successive results differ by at most `tol` (or stop
/// improving: the round-off floor, ~1e-13 per unit time). Returns the finer
/// result and the last difference, a conservative error estimate (the finer
/// result is 2¹² times more accurate than the difference in the asymptotic
/// regime). Needed when the multipliers are large (fast motion along the
/// fibres, e.g. the Hopf scenes), where h = 0.05 is not enough.
pub fn reference_solution_auto<S: System>(
    s: &S,
    z0: &DVector<f64>,
    t_end: f64,
    tol: f64,
) -> (DVector<f64>, f64) {
    let mut n = ((t_end.abs() / 0.05).ceil() as usize).max(1);
    let mut a = reference_solution(s, z0, t_end, n);
    let mut last = f64::INFINITY;
    for _ in 0..8 {
        n *= 2;
        let b = reference_solution(s, z0, t_end, n);
        let diff = (&b - &a).amax();
        if diff <= tol || diff >= 0.5 * last {
            return (b, diff);
        }
        (a, last) = (b, diff);
    }
    (a, last)
}

/// z(t_k) at the sample times `times` (nondecreasing, from t = 0), each
/// interval by [`reference_solution_auto`] with tolerance 1e-13. Panics if an
/// interval's error estimate exceeds 1e-11.
pub fn reference_trajectory<S: System>(
    s: &S,
    z0: &DVector<f64>,
    times: &[f64],
) -> Vec<DVector<f64>> {
    let mut out = Vec::with_capacity(times.len());
    let (mut t, mut z) = (0.0, z0.clone());
    for &tk in times {
        assert!(
            tk >= t,
            "reference_trajectory: times must be nondecreasing from 0"
        );
        if tk > t {
            let (zn, err) = reference_solution_auto(s, &z, tk - t, 1e-13);
            assert!(
                err <= 1e-11,
                "reference_trajectory: error estimate {err:e} on [{t}, {tk}]"
            );
            z = zn;
            t = tk;
        }
        out.push(z.clone());
    }
    out
}

/// Classical RK4 step (for the selftests' independent ODEs).
pub fn rk4_step(
    f: &mut impl FnMut(&DVector<f64>) -> DVector<f64>,
    z: &DVector<f64>,
    h: f64,
) -> DVector<f64> {
    let k1 = f(z);
    let k2 = f(&(z + 0.5 * h * &k1));
    let k3 = f(&(z + 0.5 * h * &k2));
    let k4 = f(&(z + h * &k3));
    z + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
}

/// Hopf constraint with H = |p|²/2 (§5.4.1): g = |q|² + |p|² − r² on R⁴.
#[derive(Clone, Copy, Debug)]
pub struct HopfFree {
    pub radius2: f64,
}

impl Default for HopfFree {
    fn default() -> Self {
        Self { radius2: 1.0 }
    }
}

impl System for HopfFree {
    fn dof(&self) -> usize {
        2
    }
    fn n_constraints(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, _q: &[T], p: &[T]) -> T {
        dot(p, p) * 0.5
    }
    fn constraint<T: Scalar>(&self, _i: usize, q: &[T], p: &[T]) -> T {
        dot(q, q) + dot(p, p) - self.radius2
    }
}

/// The radius² of the paper's table of initial data (see [`PAPER_Z_A`]).
pub const PAPER_RADIUS2: f64 = 0.98;

/// Hopf constraint with the linear potential of §5.4.2:
/// H = |p|²/2 − gv·q, g = |q|² + |p|² − r². Then
/// {g, H} = 2(q·p + gv·p).
#[derive(Clone, Copy, Debug)]
pub struct HopfGravity {
    pub radius2: f64,
    pub gvec: [f64; 2],
}

impl Default for HopfGravity {
    /// The paper's scene: gv = (0, −1), radius² 1.
    fn default() -> Self {
        Self {
            radius2: 1.0,
            gvec: [0.0, -1.0],
        }
    }
}

impl HopfGravity {
    /// gv = (0, −1) on the sphere of the given radius².
    pub fn with_radius2(radius2: f64) -> Self {
        Self {
            radius2,
            ..Self::default()
        }
    }
    /// gv = (0, −1) on the sphere through z (radius² = |z|²): the paper's
    /// table points lie on M of this system exactly (|z|² = 0.98000000636,
    /// not 0.98 to round-off).
    pub fn through(z: &[f64]) -> Self {
        Self::with_radius2(z.iter().map(|v| v * v).sum())
    }
}

impl System for HopfGravity {
    fn dof(&self) -> usize {
        2
    }
    fn n_constraints(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        dot(p, p) * 0.5 - (q[0] * self.gvec[0] + q[1] * self.gvec[1])
    }
    fn constraint<T: Scalar>(&self, _i: usize, q: &[T], p: &[T]) -> T {
        dot(q, q) + dot(p, p) - self.radius2
    }
}

// ===========================================================================
// 4. Formulas for the Hopf figures (§5.4.2)
// ===========================================================================

/// Table of initial data (table_initialconditions), verbatim, as
/// z = (q_0, q_1, p_0, p_1). They satisfy the hidden constraint of
/// H = |p|²/2 − gv·q, gv = (0,−1), to ~3e-16, but |z|² = 0.9800000063625813,
/// not 1 (and 0.98 only to 6.4e-9).
#[allow(clippy::excessive_precision)] // verbatim from the paper
pub const PAPER_Z_A: [f64; 4] = [
    -0.7865261200000000,
    -0.4043988000000000,
    -0.3880746864163783,
    0.2173391755798215,
];
#[allow(clippy::excessive_precision)] // verbatim from the paper
pub const PAPER_Z_B: [f64; 4] = [
    -0.4963624948824013,
    -0.7319740436366664,
    -0.4275775933953260,
    0.1225384882604160,
];
#[allow(clippy::excessive_precision)] // verbatim from the paper
pub const PAPER_Z_C: [f64; 4] = [
    0.3477491188213400,
    -0.8131619010029159,
    -0.4368285559113795,
    -0.0837800227934176,
];

/// The Hopf map (eq_hopf) with z_k = q_k + i p_k:
/// (z0, z1) ↦ (ζ, ρ) = (2 z0 z̄1, |z0|² − |z1|²), ζ returned as (re, im).
/// Maps the sphere |z|² = r² onto the 2-sphere of radius r².
pub fn hopf_map(z: &[f64]) -> ([f64; 2], f64) {
    let (a0, b0, a1, b1) = (z[0], z[2], z[1], z[3]); // z0 = a0 + i b0, z1 = a1 + i b1
    let zeta = [2.0 * (a0 * a1 + b0 * b1), 2.0 * (b0 * a1 - a0 * b1)];
    (zeta, a0 * a0 + b0 * b0 - a1 * a1 - b1 * b1)
}

/// The stereographic projection of the caption of fig_numtests_grav:
/// (ζ, ρ) ↦ ζ/(sqrt(|ζ|² + ρ²) − ρ), returned as (re, im). Homogeneous of
/// degree 0, so the radius of the sphere does not matter; the "north pole"
/// ζ = 0, ρ > 0 goes to infinity.
pub fn stereographic(zeta: [f64; 2], rho: f64) -> [f64; 2] {
    let den = (zeta[0] * zeta[0] + zeta[1] * zeta[1] + rho * rho).sqrt() - rho;
    [zeta[0] / den, zeta[1] / den]
}

/// Stereographic projection of the Hopf image of z (the plotted point).
pub fn hopf_plane_point(z: &[f64]) -> [f64; 2] {
    let (zeta, rho) = hopf_map(z);
    stereographic(zeta, rho)
}

/// The point at fibre angle θ, as printed in §5.4.2:
/// (q cos θ + p sin θ, −q sin θ + p cos θ). In MISSION's conventions this is
/// exp((θ/2) X_g)(z) for g = |q|² + |p|² − r² (X_g = (2p, −2q)), i.e.
/// z_k ↦ e^{−iθ} z_k. The Hopf map is invariant along it.
pub fn fibre_point(z: &[f64], theta: f64) -> [f64; 4] {
    let (s, c) = theta.sin_cos();
    [
        z[0] * c + z[2] * s,
        z[1] * c + z[3] * s,
        -z[0] * s + z[2] * c,
        -z[1] * s + z[3] * c,
    ]
}

/// Hr(θ) = H(fibre_point(z, θ)) for H = |p|²/2 − gv·q.
pub fn hr(z: &[f64], gv: [f64; 2], theta: f64) -> f64 {
    let y = fibre_point(z, theta);
    0.5 * (y[2] * y[2] + y[3] * y[3]) - gv[0] * y[0] - gv[1] * y[1]
}

/// Coefficients (A, B, C, D) = (½(|q|² − |p|²), q·p, gv·q, gv·p).
fn hr_coeffs(z: &[f64], gv: [f64; 2]) -> (f64, f64, f64, f64) {
    let (qq, pp) = (z[0] * z[0] + z[1] * z[1], z[2] * z[2] + z[3] * z[3]);
    (
        0.5 * (qq - pp),
        z[0] * z[2] + z[1] * z[3],
        gv[0] * z[0] + gv[1] * z[1],
        gv[0] * z[2] + gv[1] * z[3],
    )
}

/// Hr'(θ) = d/dθ H(fibre_point(z, θ)) for H = |p|²/2 − gv·q (derived here,
/// checked against finite differences in the selftest):
///
///     Hr'(θ) = ½(|q|² − |p|²) sin 2θ − q·p cos 2θ + gv·q sin θ − gv·p cos θ.
///
/// Hr'(0) = −(q·p + gv·p) = −{g,H}/2: zero exactly on M^H.
///
/// The paper's eq_Hprime2 ([`hr_prime_paper`]) differs: it is the derivative
/// along the opposite orientation z_k ↦ e^{+iθ} z_k (which matches the
/// paper's printed Hr(θ) and its fibre flow e^{it}z) except that the term
/// −gv·q sin θ there has the wrong sign; with gv = 0 (eq_Hprime) the paper's
/// formula is exactly −Hr'(−θ) of this one. Both vanish at θ = 0 exactly on
/// M^H, but the other roots of eq_Hprime2 are not critical points of H on
/// the fibre. Use this function for the fibre plots.
pub fn hr_prime(z: &[f64], gv: [f64; 2], theta: f64) -> f64 {
    let (a, b, c, d) = hr_coeffs(z, gv);
    a * (2.0 * theta).sin() - b * (2.0 * theta).cos() + c * theta.sin() - d * theta.cos()
}

/// Hr''(θ) = (|q|² − |p|²) cos 2θ + 2 q·p sin 2θ + gv·q cos θ + gv·p sin θ.
pub fn hr_second(z: &[f64], gv: [f64; 2], theta: f64) -> f64 {
    let (a, b, c, d) = hr_coeffs(z, gv);
    2.0 * a * (2.0 * theta).cos()
        + 2.0 * b * (2.0 * theta).sin()
        + c * theta.cos()
        + d * theta.sin()
}

/// The paper's eq_Hprime2 verbatim (eq_Hprime when gv = 0):
/// ½(|q|² − |p|²) sin 2θ + q·p cos 2θ − gv·q sin θ + gv·p cos θ.
/// See [`hr_prime`] for how it relates to the true derivative.
pub fn hr_prime_paper(z: &[f64], gv: [f64; 2], theta: f64) -> f64 {
    let (a, b, c, d) = hr_coeffs(z, gv);
    a * (2.0 * theta).sin() + b * (2.0 * theta).cos() - c * theta.sin() + d * theta.cos()
}

/// A critical point of H on the fibre (a point of fibre ∩ M^H).
#[derive(Clone, Copy, Debug)]
pub struct FibreCriticalPoint {
    /// Fibre angle in [0, 2π).
    pub theta: f64,
    /// Hr''(θ): nonzero for a nondegenerate critical point.
    pub second: f64,
    pub degenerate: bool,
}

/// All roots of Hr' on [0, 2π) (see [`hr_prime`]), i.e. the points where the
/// fibre through z crosses M^H, classified as nondegenerate or degenerate
/// (|Hr''| ≤ 1e-6·scale, scale = |A|+|B|+|C|+|D| of the coefficients).
///
/// Method: 4096 samples; sign changes are refined by bisection and Newton;
/// extrema of Hr' (sign changes of Hr'') are located too, which finds two
/// simple roots closer than the sample spacing and roots of even multiplicity
/// (touching zero: |Hr'| ≤ 1e-9·scale at the extremum). Hr' is a trigonometric
/// polynomial of degree 2, so there are at most 4 roots counted with
/// multiplicity: cases (i) four nondegenerate, (ii) two nondegenerate,
/// (iii) two nondegenerate and one degenerate.
pub fn fibre_critical_points(z: &[f64], gv: [f64; 2]) -> Vec<FibreCriticalPoint> {
    let (a, b, c, d) = hr_coeffs(z, gv);
    let scale = a.abs() + b.abs() + c.abs() + d.abs();
    let f1 = |t: f64| hr_prime(z, gv, t);
    let f2 = |t: f64| hr_second(z, gv, t);
    let f3 =
        |t: f64| -4.0 * a * (2.0 * t).sin() + 4.0 * b * (2.0 * t).cos() - c * t.sin() + d * t.cos();
    // Root of `f` in [lo, hi] with f(lo)·f(hi) ≤ 0: bisection, then Newton.
    let refine = |f: &dyn Fn(f64) -> f64, df: &dyn Fn(f64) -> f64, mut lo: f64, mut hi: f64| {
        let flo = f(lo);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if (f(mid) > 0.0) == (flo > 0.0) && f(mid) != 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let mut t = 0.5 * (lo + hi);
        for _ in 0..3 {
            let dd = df(t);
            if dd != 0.0 {
                let step = f(t) / dd;
                if step.abs() < 1e-9 {
                    t -= step;
                }
            }
        }
        t
    };
    // Cells are centred on multiples of 2π/n, so a root at θ = 0 (a point
    // of M^H) is interior to a cell, not on its boundary.
    let n = 4096;
    let grid = |k: usize| 2.0 * PI * (k as f64 - 0.5) / n as f64;
    let mut roots: Vec<f64> = Vec::new();
    for k in 0..n {
        let (t0, t1) = (grid(k), grid(k + 1));
        let (v0, v1) = (f1(t0), f1(t1));
        if v0 == 0.0 {
            roots.push(t0);
        } else if v0 * v1 < 0.0 {
            roots.push(refine(&f1, &f2, t0, t1));
        }
    }
    // Touching roots: extrema of Hr' where Hr' vanishes.
    let near = |rs: &[f64], t: f64| {
        rs.iter().any(|&r| {
            let dd = (r - t).rem_euclid(2.0 * PI);
            dd.min(2.0 * PI - dd) < 1e-5
        })
    };
    for k in 0..n {
        let (t0, t1) = (grid(k), grid(k + 1));
        if f2(t0) * f2(t1) < 0.0 {
            let t = refine(&f2, &f3, t0, t1);
            let v = f1(t);
            if f1(t0) * f1(t1) > 0.0 && v * f1(t0) < 0.0 {
                // Two close simple roots inside one cell, either side of the extremum.
                roots.push(refine(&f1, &f2, t0, t));
                roots.push(refine(&f1, &f2, t, t1));
            } else if v.abs() <= 1e-9 * scale && !near(&roots, t) {
                roots.push(t);
            }
        }
    }
    let mut out: Vec<FibreCriticalPoint> = roots
        .into_iter()
        .map(|t| {
            let mut theta = t.rem_euclid(2.0 * PI);
            if theta >= 2.0 * PI {
                theta -= 2.0 * PI;
            }
            let second = f2(theta);
            FibreCriticalPoint {
                theta,
                second,
                degenerate: second.abs() <= 1e-6 * scale,
            }
        })
        .collect();
    out.sort_by(|x, y| x.theta.partial_cmp(&y.theta).unwrap());
    out
}

/// The classification of §5.4.2 from the output of [`fibre_critical_points`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FibreCase {
    /// (i) four nondegenerate critical points.
    FourNondegenerate,
    /// (ii) two nondegenerate critical points.
    TwoNondegenerate,
    /// (iii) two nondegenerate and one degenerate critical point.
    TwoPlusDegenerate,
    /// Anything else (e.g. gv = 0 and |q| = |p|: Hr' ≡ 0 on an exceptional fibre).
    Other {
        nondegenerate: usize,
        degenerate: usize,
    },
}

pub fn fibre_case(points: &[FibreCriticalPoint]) -> FibreCase {
    let deg = points.iter().filter(|c| c.degenerate).count();
    let nondeg = points.len() - deg;
    match (nondeg, deg) {
        (4, 0) => FibreCase::FourNondegenerate,
        (2, 0) => FibreCase::TwoNondegenerate,
        (2, 1) => FibreCase::TwoPlusDegenerate,
        _ => FibreCase::Other {
            nondegenerate: nondeg,
            degenerate: deg,
        },
    }
}

/// Brings z onto M^H of H = |p|²/2 − gv·q on the sphere |z|² = `radius2`:
/// 1. radially: z ↦ k z, k = sqrt(radius2/|z|²) (onto M). This maps fibres
///    to fibres and multiplies the Hopf image by k², so the plotted point
///    [`hopf_plane_point`] (degree-0 homogeneous) does not change;
/// 2. along the fibre (which preserves |z| and the Hopf image) to the
///    nondegenerate critical point of Hr nearest to θ = 0 (smallest |θ| on the
///    circle), polished by Newton on Hr'.
///
/// A point already on M^H comes back unchanged (θ = 0 is a root). Note that
/// step 1 alone does not keep M^H: {g,H} = 2(q·p + gv·p) is not homogeneous.
/// Panics if the fibre has no nondegenerate critical point.
pub fn hopf_onto_mh(z: &[f64], gv: [f64; 2], radius2: f64) -> [f64; 4] {
    let r2: f64 = z.iter().map(|v| v * v).sum();
    let k = (radius2 / r2).sqrt();
    let zs = [k * z[0], k * z[1], k * z[2], k * z[3]];
    let crit = fibre_critical_points(&zs, gv);
    let dist = |t: f64| t.min(2.0 * PI - t);
    let best = crit
        .iter()
        .filter(|c| !c.degenerate)
        .min_by(|x, y| dist(x.theta).partial_cmp(&dist(y.theta)).unwrap())
        .expect("hopf_onto_mh: no nondegenerate critical point on the fibre");
    let mut t = if best.theta > PI {
        best.theta - 2.0 * PI
    } else {
        best.theta
    };
    for _ in 0..3 {
        t -= hr_prime(&zs, gv, t) / hr_second(&zs, gv, t);
    }
    fibre_point(&zs, t)
}

// ===========================================================================
// 5. Index-1 constraints (§5.3): the midpoint rule on the index-1 system
// ===========================================================================

/// H(q, p, β) with q, p ∈ R^n, β ∈ R^k, H_ββ invertible.
pub trait Index1System {
    fn n(&self) -> usize;
    fn k(&self) -> usize;
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T], beta: &[T]) -> T;
}

fn eval_i1<S: Index1System, T: Scalar>(s: &S, y: &[T]) -> T {
    let n = s.n();
    s.hamiltonian(&y[..n], &y[n..2 * n], &y[2 * n..])
}

/// The chosen example (n = k = 1), genuinely coupled and non-separable:
///
///     H(q, p, β) = (q² + p²)/2 + β²/2 + β⁴/12 − c β p sin q,
///
/// so H_β = β + β³/3 − c p sin q and H_ββ = 1 + β² ≥ 1: B(q,p) is unique and
/// global, and the reduced Hamiltonian H(q, p, B(q,p)) is not quadratic.
/// Since β²/2 − cβs ≥ −c²s²/2, the reduced Hamiltonian is
/// ≥ q²/2 + (1 − c²)p²/2, so for |c| < 1 every orbit is bounded. (A coupling
/// like −cβqp would not do: its reduced Hamiltonian is unbounded below and
/// orbits escape to infinity in finite time.)
#[derive(Clone, Copy, Debug)]
pub struct Index1Example {
    pub coupling: f64,
}

impl Default for Index1Example {
    fn default() -> Self {
        Self { coupling: 0.8 }
    }
}

impl Index1System for Index1Example {
    fn n(&self) -> usize {
        1
    }
    fn k(&self) -> usize {
        1
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T], beta: &[T]) -> T {
        let (q, p, b) = (q[0], p[0], beta[0]);
        (q * q + p * p) * 0.5 + b * b * 0.5 + b.powi(4) * (1.0 / 12.0)
            - b * p * q.sin() * self.coupling
    }
}

/// The same problem on the extended space R^{2n+2k} (§5.3): positions (q, α),
/// momenta (p, β), H(q, p, β), holonomic constraints g_i = α_i. Its state
/// vector is z = (q, α, p, β). Here N = {{H,g},g} = H_ββ.
#[derive(Clone, Copy, Debug)]
pub struct Index1Extended<S>(pub S);

impl<S: Index1System> System for Index1Extended<S> {
    fn dof(&self) -> usize {
        self.0.n() + self.0.k()
    }
    fn n_constraints(&self) -> usize {
        self.0.k()
    }
    fn hamiltonian<T: Scalar>(&self, q: &[T], p: &[T]) -> T {
        let n = self.0.n();
        self.0.hamiltonian(&q[..n], &p[..n], &p[n..])
    }
    fn constraint<T: Scalar>(&self, i: usize, q: &[T], _p: &[T]) -> T {
        q[self.0.n() + i]
    }
}

/// β = B(q, p): the solution of H_β(q, p, β) = 0 near `guess` (Newton).
pub fn index1_beta<S: Index1System>(
    s: &S,
    q: &DVector<f64>,
    p: &DVector<f64>,
    guess: &DVector<f64>,
) -> DVector<f64> {
    let (n, k) = (s.n(), s.k());
    newton(guess.clone(), "index-1 B(q,p)", |b| {
        let y: Vec<f64> = q.iter().chain(p.iter()).chain(b.iter()).copied().collect();
        let (g, h) = hessian_with(&y, |x| eval_i1(s, x));
        (
            g.rows(2 * n, k).into_owned(),
            h.view((2 * n, 2 * n), (k, k)).into_owned(),
        )
    })
}

/// The midpoint rule applied directly to the index-1 system (eq indexone)
/// (the method of McLachlan–Modin–Verdier–Wilkins' index-1 paper, §5.3):
/// ```text
/// (q1 − q0)/h =  H_p(q̄, p̄, β̄)
/// (p1 − p0)/h = −H_q(q̄, p̄, β̄)
///           0 =  H_β(q̄, p̄, β̄),      q̄ = (q0+q1)/2, p̄ = (p0+p1)/2
/// ```
/// solved for (q1, p1, β̄) by Newton with the exact Jacobian (Hessian of H by
/// num-dual), to round-off. Returns (q1, p1, β̄). β̄ is the value of β used in
/// the step; on the extended space it is the β-component of midpoint SHAKE's
/// z1⁻ (the fibre flow shifts β, the midpoint map keeps it). `beta_guess` only
/// selects the branch.
pub fn index1_midpoint_step<S: Index1System>(
    s: &S,
    q0: &DVector<f64>,
    p0: &DVector<f64>,
    beta_guess: &DVector<f64>,
    h: f64,
) -> (DVector<f64>, DVector<f64>, DVector<f64>) {
    let (n, k) = (s.n(), s.k());
    let dim = 2 * n + k;
    let x0 = DVector::from_iterator(
        dim,
        q0.iter().chain(p0.iter()).chain(beta_guess.iter()).copied(),
    );
    let x = newton(x0, "index-1 midpoint rule", |x| {
        let q1 = x.rows(0, n);
        let p1 = x.rows(n, n);
        let b = x.rows(2 * n, k);
        let y: Vec<f64> = (0..n)
            .map(|i| 0.5 * (q0[i] + q1[i]))
            .chain((0..n).map(|i| 0.5 * (p0[i] + p1[i])))
            .chain(b.iter().copied())
            .collect();
        let (g, hs) = hessian_with(&y, |v| eval_i1(s, v));
        // dy/dx = diag(½ I, ½ I, I)
        let mut hsd = hs.clone();
        for j in 0..2 * n {
            hsd.column_mut(j).scale_mut(0.5);
        }
        let mut r = DVector::zeros(dim);
        r.rows_mut(0, n).copy_from(&(q1 - q0 - h * g.rows(n, n)));
        r.rows_mut(n, n).copy_from(&(p1 - p0 + h * g.rows(0, n)));
        r.rows_mut(2 * n, k).copy_from(&g.rows(2 * n, k));
        let mut jac = DMatrix::zeros(dim, dim);
        jac.rows_mut(0, n).copy_from(&(-h * hsd.rows(n, n)));
        jac.rows_mut(n, n).copy_from(&(h * hsd.rows(0, n)));
        jac.rows_mut(2 * n, k).copy_from(&hsd.rows(2 * n, k));
        for i in 0..2 * n {
            jac[(i, i)] += 1.0;
        }
        (r, jac)
    });
    (
        x.rows(0, n).into_owned(),
        x.rows(n, n).into_owned(),
        x.rows(2 * n, k).into_owned(),
    )
}

/// H_β at the midpoint of a step (the residual of the algebraic equation).
pub fn index1_midpoint_residual<S: Index1System>(
    s: &S,
    q0: &DVector<f64>,
    p0: &DVector<f64>,
    q1: &DVector<f64>,
    p1: &DVector<f64>,
    beta: &DVector<f64>,
) -> DVector<f64> {
    let (n, k) = (s.n(), s.k());
    let y: Vec<f64> = (0..n)
        .map(|i| 0.5 * (q0[i] + q1[i]))
        .chain((0..n).map(|i| 0.5 * (p0[i] + p1[i])))
        .chain(beta.iter().copied())
        .collect();
    gradient_with(&y, |v| eval_i1(s, v))
        .rows(2 * n, k)
        .into_owned()
}

/// The planar pendulum's angle θ'' = −(γ/ℓ) sin θ by classical RK4 with
/// 100 000 steps: an independent reference (global error ~1e-15 at T = 1).
pub fn pendulum_reference(gravity: f64, length: f64, theta: f64, omega: f64, t: f64) -> (f64, f64) {
    let f = |th: f64, om: f64| (om, -(gravity / length) * th.sin());
    let n = 100_000;
    let dt = t / n as f64;
    let (mut th, mut om) = (theta, omega);
    for _ in 0..n {
        let k1 = f(th, om);
        let k2 = f(th + 0.5 * dt * k1.0, om + 0.5 * dt * k1.1);
        let k3 = f(th + 0.5 * dt * k2.0, om + 0.5 * dt * k2.1);
        let k4 = f(th + dt * k3.0, om + dt * k3.1);
        th += dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        om += dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
    }
    (th, om)
}

/// The pendulum state (q, p) at angle θ from the downward vertical and
/// angular velocity ω (unit mass).
pub fn pendulum_state(length: f64, theta: f64, omega: f64) -> geoshake::State {
    let (s, c) = theta.sin_cos();
    geoshake::State::from_slices(
        &[length * s, -length * c],
        &[length * omega * c, length * omega * s],
    )
}
