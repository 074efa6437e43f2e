//! Fibre flows z ↦ exp(Σ λ_i X_{g_i})(z).
//!
//! Under coisotropy the fibre of M through z is parametrised by λ ∈ R^m
//! through the flow of Σ λ_i X_{g_i} for unit time (the paper's Corollary
//! 3.2). A SHAKE or RATTLE step may move the state only along fibres and by
//! φ_h; this is what makes SHAKE presymplectic (Proposition 4.4), so these
//! flows are computed exactly to round-off, by [`ConstraintKind`]:
//!
//! - **Holonomic** g(q): X_{g_i} = (0, −∇_q g_i) is constant along its own
//!   flow, so the flow is the momentum kick p ↦ p − g_q(q)ᵀλ. The system's
//!   closed form ([`ConstrainedSystem::fibre_flow`]) is used when it has one;
//!   otherwise the kick is formed from the constraint Jacobian.
//! - **Quadratic** g (every g_i of degree ≤ 2 in z): Σ λ_i X_{g_i}(z) = A z + b
//!   with constant A = J Σ λ_i ∇²g_i and b = J Σ λ_i ∇g_i(0), so the flow is
//!   z ↦ exp(A) z + φ₁(A) b, computed as the exponential of the augmented
//!   (2d+1)×(2d+1) matrix [[A, b], [0, 0]] (scaling and squaring with a Taylor
//!   series summed to round-off). The system's closed form is preferred when
//!   it has one. One constraint with no linear part whose generator
//!   L = J∇²g squares to −ω²I (detected once, in [`FibreFlow::new`]) has the
//!   closed form exp(λL) = cos(ωλ) I + sin(ωλ)/ω · L, used instead of the
//!   exponential: for the Hopf constraint |q|² + |p|² − r² (L = 2J, ω = 2)
//!   it is the rotation z_k = q_k + i p_k ↦ e^{−2iλ} z_k.
//! - **General** g: the flow is integrated numerically over unit time by
//!   Gragg–Bulirsch–Stoer extrapolation (modified midpoint rule with 2, 4,
//!   6, … substeps, polynomial extrapolation in the squared step size).
//!   A row of the extrapolation table is accepted when it agrees with the
//!   previous row to 8 ulps of the state (‖T_jj − T_j,j−1‖∞ ≤ 8ε‖T_jj‖∞),
//!   or when that difference stops decreasing while already below 64 ulps
//!   (round-off dominates). The unit interval is first cut into 2^k pieces
//!   so that ‖f(z0)‖/‖z0‖ ≤ 1/8 per piece (f the fibre field), which keeps
//!   the number of substeps, and so the rounding, small. If a piece does not
//!   converge within 10 rows, the number of pieces is doubled (step
//!   doubling), up to 2¹⁰ pieces.

use crate::system::{ConstrainedSystem, ConstraintKind};
use crate::SolveError;

mod integrated;
mod quadratic;

use integrated::GBS_ROWS;
use quadratic::rotation_generator;

/// The fibre flow of a system together with its buffers.
///
/// ```
/// use geoshake_runtime::{FibreFlow, examples::Pendulum};
/// // The pendulum's fibre flow is the kick p ↦ p − λ ∇g(q) = p − 2λq.
/// let sys = Pendulum::default();
/// let mut flow = FibreFlow::new(&sys);
/// let (mut q, mut p) = ([0.6, -0.8], [1.0, 0.0]);
/// flow.apply(&sys, &[0.5], &mut q, &mut p).unwrap();
/// assert_eq!(p, [1.0 - 0.6, 0.8]);
/// assert_eq!(q, [0.6, -0.8]);
/// ```
#[derive(Clone, Debug)]
pub struct FibreFlow {
    d: usize,
    m: usize,
    /// g_z output at the current point (written only by the system).
    g_z: Vec<f64>,
    /// Quadratic kind: ∇²g_i, one 2d×2d buffer per constraint, and g_z(0).
    hess_i: Vec<Vec<f64>>,
    g_z0: Vec<f64>,
    aug: Vec<f64>,
    t1: Vec<f64>,
    t2: Vec<f64>,
    t3: Vec<f64>,
    /// Quadratic kind, one constraint without linear part whose generator
    /// L = J∇²g squares to −ω²I: (ω, L), so that exp(λL) is a rotation.
    rotation: Option<(f64, Vec<f64>)>,
    /// General kind: extrapolation rows and state vectors.
    row: Vec<f64>,
    row_prev: Vec<f64>,
    za: Vec<f64>,
    zb: Vec<f64>,
    zc: Vec<f64>,
    f: Vec<f64>,
    start: Vec<f64>,
}

impl FibreFlow {
    /// Buffers for the fibre flow of `sys`; for a quadratic system this also
    /// evaluates the (constant) Hessians ∇²g_i and the Jacobian g_z at 0.
    ///
    /// ```
    /// use geoshake_runtime::{FibreFlow, examples::Pendulum};
    /// let flow = FibreFlow::new(&Pendulum::default());
    /// ```
    pub fn new<S: ConstrainedSystem>(sys: &S) -> Self {
        let d = sys.dof();
        let m = sys.constraint_count();
        let n = 2 * d;
        let quadratic = sys.kind() == ConstraintKind::Quadratic;
        let general = sys.kind() == ConstraintKind::General;
        let mut flow = FibreFlow {
            d,
            m,
            g_z: vec![0.0; m * n],
            hess_i: Vec::new(),
            g_z0: vec![0.0; if quadratic { m * n } else { 0 }],
            aug: Vec::new(),
            t1: Vec::new(),
            t2: Vec::new(),
            t3: Vec::new(),
            row: vec![0.0; if general { GBS_ROWS * n } else { 0 }],
            row_prev: vec![0.0; if general { GBS_ROWS * n } else { 0 }],
            za: vec![0.0; n],
            zb: vec![0.0; n],
            zc: vec![0.0; n],
            f: vec![0.0; n],
            start: vec![0.0; n],
            rotation: None,
        };
        if quadratic {
            let zero = vec![0.0; d];
            let mut e = vec![0.0; m];
            for i in 0..m {
                e.fill(0.0);
                e[i] = 1.0;
                let mut hi = vec![0.0; n * n];
                sys.constraint_hessian(&zero, &zero, &e, &mut hi);
                flow.hess_i.push(hi);
            }
            sys.constraint_jacobian(&zero, &zero, &mut flow.g_z0);
            let n1 = n + 1;
            flow.aug = vec![0.0; n1 * n1];
            flow.t1 = vec![0.0; n1 * n1];
            flow.t2 = vec![0.0; n1 * n1];
            flow.t3 = vec![0.0; n1 * n1];
            flow.rotation = rotation_generator(&flow.hess_i, &flow.g_z0, d);
        }
        flow
    }

    /// (q, p) ← exp(Σ λ_i X_{g_i})(q, p), exact to round-off (see the module
    /// docs for the method used for each kind of constraint).
    ///
    /// ```
    /// use geoshake_runtime::{FibreFlow, examples::HopfHarmonic};
    /// // The Hopf fibre flow is the rotation z_k ↦ e^{−2iλ} z_k.
    /// let sys = HopfHarmonic::unit();
    /// let mut flow = FibreFlow::new(&sys);
    /// let (mut q, mut p) = ([1.0, 0.0], [0.0, 0.0]);
    /// let lambda = 0.3;
    /// flow.apply(&sys, &[lambda], &mut q, &mut p).unwrap();
    /// assert!((q[0] - (2.0 * lambda).cos()).abs() < 1e-15);
    /// assert!((p[0] + (2.0 * lambda).sin()).abs() < 1e-15);
    /// ```
    pub fn apply<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        lambda: &[f64],
        q: &mut [f64],
        p: &mut [f64],
    ) -> Result<(), SolveError> {
        match sys.kind() {
            ConstraintKind::None => Ok(()),
            ConstraintKind::Holonomic => {
                if !sys.fibre_flow(lambda, q, p).applied() {
                    self.kick(sys, lambda, q, p);
                }
                Ok(())
            }
            ConstraintKind::Quadratic => {
                if !sys.fibre_flow(lambda, q, p).applied() {
                    self.linear_flow(lambda, q, p);
                }
                Ok(())
            }
            ConstraintKind::General => {
                if sys.fibre_flow(lambda, q, p).applied() {
                    Ok(())
                } else {
                    self.integrate(sys, lambda, q, p)
                }
            }
        }
    }

    /// The increment (δq, δp) = exp(Σ λ_i X_{g_i})(z) − z without changing
    /// z, computed as a small quantity (rounding O(ε‖λ‖ |z|), not O(ε|z|)),
    /// for compensated summation (see [`compensated`](crate::compensated)):
    ///
    /// - holonomic: δq = 0, δp = −g_q(q)ᵀλ;
    /// - quadratic: with the affine field A z + b, the increment is
    ///   φ₁(A)(A z + b), the last column of exp([[A, A z + b], [0, 0]]);
    /// - general: the flow minus the start (no better form is known here).
    ///
    /// ```
    /// use geoshake_runtime::{FibreFlow, examples::HopfHarmonic};
    /// let sys = HopfHarmonic::unit();
    /// let mut flow = FibreFlow::new(&sys);
    /// let (mut dq, mut dp) = ([0.0; 2], [0.0; 2]);
    /// flow.increment(&sys, &[1e-9], &[1.0, 0.0], &[0.0, 0.0], &mut dq, &mut dp).unwrap();
    /// // e^{−2iλ} − 1 = (cos 2λ − 1) − i sin 2λ.
    /// assert!((dq[0] + 2e-18).abs() < 1e-30 && (dp[0] + 2e-9).abs() < 1e-24);
    /// ```
    pub fn increment<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        lambda: &[f64],
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
    ) -> Result<(), SolveError> {
        let (d, m) = (self.d, self.m);
        match sys.kind() {
            ConstraintKind::None => {
                dq.fill(0.0);
                dp.fill(0.0);
                Ok(())
            }
            ConstraintKind::Holonomic => {
                // The kick −g_q(q)ᵀλ does not depend on p: the closed-form
                // flow applied to p = 0 gives the increment itself, through
                // the generated (sparse) code.
                dq.copy_from_slice(q);
                dp.fill(0.0);
                let closed = sys.fibre_flow(lambda, dq, dp).applied();
                dq.fill(0.0);
                if !closed {
                    sys.constraint_jacobian(q, p, &mut self.g_z);
                    for k in 0..d {
                        let col = &self.g_z[k * m..(k + 1) * m];
                        dp[k] = -col.iter().zip(lambda).map(|(a, l)| a * l).sum::<f64>();
                    }
                }
                Ok(())
            }
            ConstraintKind::Quadratic => {
                self.linear_increment(lambda, q, p, dq, dp);
                Ok(())
            }
            ConstraintKind::General => {
                dq.copy_from_slice(q);
                dp.copy_from_slice(p);
                self.apply(sys, lambda, dq, dp)?;
                for (x, x0) in dq.iter_mut().zip(q) {
                    *x -= x0;
                }
                for (x, x0) in dp.iter_mut().zip(p) {
                    *x -= x0;
                }
                Ok(())
            }
        }
    }

    /// p ← p − g_q(q)ᵀλ.
    fn kick<S: ConstrainedSystem>(&mut self, sys: &S, lambda: &[f64], q: &[f64], p: &mut [f64]) {
        let (d, m) = (self.d, self.m);
        sys.constraint_jacobian(q, p, &mut self.g_z);
        for k in 0..d {
            let col = &self.g_z[k * m..(k + 1) * m];
            p[k] -= col.iter().zip(lambda).map(|(a, l)| a * l).sum::<f64>();
        }
    }
}
