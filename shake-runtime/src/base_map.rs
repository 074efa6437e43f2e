//! Base maps φ_h: symplectic one-step maps of R^{2d} approximating the
//! unconstrained flow exp(h X_H).
//!
//! SHAKE and RATTLE are built on top of any of them (the paper's Definitions
//! 1.1 and 1.2). Each base map also provides its *tangent map* Dφ_h(y),
//! obtained by linearising its stage equations; SHAKE's Newton matrix needs
//! it (see SHAKE in the crate docs).
//!
//! - [`ImplicitMidpoint`]: z1 = z0 + h X_H((z0 + z1)/2), for any H;
//!   symmetric, order 2.
//! - [`StormerVerlet`]: the form of the paper's Section 5.1.3,
//!   p½ = p0 − (h/2) H_q(q0, p½),
//!   q1 = q0 + (h/2)(H_p(q0, p½) + H_p(q1, p½)),
//!   p1 = p½ − (h/2) H_q(q1, p½);
//!   explicit when H is separable ([`Hamiltonian::separable`]), implicit otherwise;
//!   symmetric, order 2.
//! - [`SymplecticEuler`]: p1 = p0 − h H_q(q0, p1), q1 = q0 + h H_p(q0, p1)
//!   (the paper's Section 5.1.3 variant); explicit when separable; order 1.
//!
//! Implicit stage equations are solved by Newton's method with the Hessian
//! of H, to round-off (see [`newton`](crate::newton)). Within one SHAKE step
//! the base map is applied to a sequence of nearby points; each solve starts
//! from the previous solution shifted by the change of the input point.

use crate::linalg::{lu_factor, lu_solve, norm_inf};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::system::Hamiltonian;
use crate::SolveError;

/// Buffers for a base map: the stage values of the last application (kept
/// for its tangent map and for warm starts), gradient and Hessian outputs
/// (zeroed once here, written only by the system), and Newton matrices.
///
/// ```
/// use shake_runtime::BaseMapWorkspace;
/// let ws = BaseMapWorkspace::new(2);
/// assert_eq!(ws.dof(), 2);
/// ```
#[derive(Clone, Debug)]
pub struct BaseMapWorkspace {
    d: usize,
    /// The input point y = (q0, p0) of the last application.
    y: Vec<f64>,
    /// The input point of the application before (for warm starts).
    y_prev: Vec<f64>,
    /// Stage unknowns: midpoint m (2d); SV p½ then q1; Euler p1.
    stage: Vec<f64>,
    warm: bool,
    /// Whether the prepared tangent map is that of a separable H (no stage
    /// matrices to solve with).
    tangent_separable: bool,
    // Outputs of the system, one buffer per use, written only by it.
    h_q: Vec<f64>,
    h_p: Vec<f64>,
    h_p_a: Vec<f64>,
    hess_a: Vec<f64>,
    hess_b: Vec<f64>,
    // Our own matrices and vectors (fully overwritten before each use).
    mat: Vec<f64>,
    piv: Vec<usize>,
    mat_b: Vec<f64>,
    piv_b: Vec<usize>,
    res: Vec<f64>,
    tmp: Vec<f64>,
}

impl BaseMapWorkspace {
    /// Buffers for a system with `d` degrees of freedom.
    ///
    /// ```
    /// let ws = shake_runtime::BaseMapWorkspace::new(3);
    /// assert_eq!(ws.dof(), 3);
    /// ```
    pub fn new(d: usize) -> Self {
        let n = 2 * d;
        BaseMapWorkspace {
            d,
            y: vec![0.0; n],
            y_prev: vec![0.0; n],
            stage: vec![0.0; n],
            warm: false,
            tangent_separable: false,
            h_q: vec![0.0; d],
            h_p: vec![0.0; d],
            h_p_a: vec![0.0; d],
            hess_a: vec![0.0; n * n],
            hess_b: vec![0.0; n * n],
            mat: vec![0.0; n * n],
            piv: vec![0; n],
            mat_b: vec![0.0; n * n],
            piv_b: vec![0; n],
            res: vec![0.0; n],
            tmp: vec![0.0; n],
        }
    }

    /// The number d of degrees of freedom these buffers are for.
    ///
    /// ```
    /// assert_eq!(shake_runtime::BaseMapWorkspace::new(4).dof(), 4);
    /// ```
    pub fn dof(&self) -> usize {
        self.d
    }

    /// Forget the last stage values: the next application starts its
    /// Newton iteration from an explicit predictor instead.
    ///
    /// ```
    /// let mut ws = shake_runtime::BaseMapWorkspace::new(2);
    /// ws.reset_warm_start();
    /// ```
    pub fn reset_warm_start(&mut self) {
        self.warm = false;
    }

    /// Records the new input point and says whether the stored stage can be
    /// shifted to it as the initial guess.
    fn begin(&mut self, q: &[f64], p: &[f64]) -> bool {
        let d = self.d;
        std::mem::swap(&mut self.y, &mut self.y_prev);
        self.y[..d].copy_from_slice(q);
        self.y[d..].copy_from_slice(p);
        self.warm
    }
}

/// A symplectic map φ_h of R^{2d} approximating exp(h X_H), with its
/// tangent map. Implemented by [`ImplicitMidpoint`], [`StormerVerlet`] and
/// [`SymplecticEuler`].
///
/// ```
/// use shake_runtime::{BaseMap, BaseMapWorkspace, ImplicitMidpoint, NewtonOptions};
/// use shake_runtime::examples::HarmonicOscillator;
/// // One midpoint step of q'' = −q conserves the quadratic energy exactly.
/// let sys = HarmonicOscillator;
/// let mut ws = BaseMapWorkspace::new(1);
/// let (mut q, mut p) = ([1.0], [0.0]);
/// ImplicitMidpoint.apply(&sys, 0.1, &mut q, &mut p, &mut ws, &NewtonOptions::default()).unwrap();
/// assert!((q[0] * q[0] + p[0] * p[0] - 1.0).abs() < 1e-15);
/// ```
pub trait BaseMap: Copy + Clone + std::fmt::Debug + Send + Sync + 'static {
    /// A short name for reports ("midpoint", ...).
    const NAME: &'static str;
    /// φ_{−h} = φ_h⁻¹: RATTLE on top of it is symmetric (Section 4).
    const SYMMETRIC: bool;
    /// The order of φ_h as an approximation of exp(h X_H).
    const ORDER: u32;

    /// Whether φ_h is explicit for this H (no stage equations to solve):
    /// Störmer–Verlet and symplectic Euler when H is separable. SHAKE then
    /// forms its Jacobian from difference quotients of its cheap residual
    /// (see `shake`). A structural fact, not a count of iterations: an
    /// implicit map whose first guess happens to be exact is still implicit.
    ///
    /// ```
    /// use shake_runtime::{BaseMap, ImplicitMidpoint, StormerVerlet, examples::Pendulum};
    /// assert!(StormerVerlet.explicit_for(&Pendulum::default()));
    /// assert!(!ImplicitMidpoint.explicit_for(&Pendulum::default()));
    /// ```
    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        let _ = sys;
        false
    }

    /// For a separable H = T(p) + V(q), this map as a kick–drift–kick
    /// p* = p0 − a h ∇V(q0), q1 = q0 + h ∇T(p*), p1 = p* − b h ∇V(q1):
    /// `Some((a, b))`, or `None` when it is not of that form. SHAKE and
    /// RATTLE then take the classical path for holonomic constraints and a
    /// quadratic T (see `classical`): one equation in the positions, no
    /// base-map or fibre-flow call in its Newton iteration.
    ///
    /// ```
    /// use shake_runtime::{BaseMap, ImplicitMidpoint, StormerVerlet, SymplecticEuler};
    /// assert_eq!(StormerVerlet.kick_drift_kick(), Some((0.5, 0.5)));
    /// assert_eq!(SymplecticEuler.kick_drift_kick(), Some((1.0, 0.0)));
    /// assert_eq!(ImplicitMidpoint.kick_drift_kick(), None);
    /// ```
    fn kick_drift_kick(&self) -> Option<(f64, f64)> {
        None
    }

    /// z ← φ_h(z) in place; returns the number of Newton iterations of its
    /// stage equations (0 when explicit).
    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError>;

    /// Evaluates and factorises the linearised stage equations at the stage
    /// values of the last [`apply`](BaseMap::apply), so that
    /// [`apply_tangent`](BaseMap::apply_tangent) gives Dφ_h at its input.
    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError>;

    /// v ← Dφ_h(y) v for v = (δq, δp) of length 2d, y the input of the last
    /// [`apply`](BaseMap::apply), after [`prepare_tangent`](BaseMap::prepare_tangent).
    fn apply_tangent(&self, h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]);

    /// The increment (δq, δp) = φ_h(z) − z, without changing z, computed as
    /// a small quantity in its own right (not as a difference of two
    /// rounded states), so that its rounding error is O(ε h) rather than
    /// O(ε |z|): what compensated summation of the state needs (see
    /// [`compensated`](crate::compensated)). Leaves the workspace as
    /// [`apply`](BaseMap::apply) does, so the tangent map is available.
    ///
    /// The provided implementation applies the map to a copy and subtracts
    /// (rounding O(ε|z|)); the midpoint rule and explicit Störmer–Verlet
    /// override it with increment forms of their stage equations.
    ///
    /// ```
    /// use shake_runtime::{BaseMap, BaseMapWorkspace, ImplicitMidpoint, NewtonOptions};
    /// use shake_runtime::examples::HarmonicOscillator;
    /// let mut ws = BaseMapWorkspace::new(1);
    /// let (mut dq, mut dp) = ([0.0], [0.0]);
    /// ImplicitMidpoint
    ///     .increment(&HarmonicOscillator, 1e-3, &[1.0], &[0.0], &mut dq, &mut dp, &mut ws, &NewtonOptions::default())
    ///     .unwrap();
    /// // q1 − q0 = −h²/2 /(1 + h²/4) for the midpoint rule on q'' = −q.
    /// assert!((dq[0] + 0.5e-6 / (1.0 + 0.25e-6)).abs() < 1e-21);
    /// ```
    #[allow(clippy::too_many_arguments)]
    fn increment<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        dq.copy_from_slice(q);
        dp.copy_from_slice(p);
        let it = self.apply(sys, h, dq, dp, ws, opts)?;
        for (d, x) in dq.iter_mut().zip(q) {
            *d -= x;
        }
        for (d, x) in dp.iter_mut().zip(p) {
            *d -= x;
        }
        Ok(it)
    }
}

/// The implicit midpoint rule z1 = z0 + h X_H((z0 + z1)/2): symplectic and
/// symmetric for any H, order 2.
///
/// ```
/// use shake_runtime::{BaseMap, ImplicitMidpoint};
/// assert!(ImplicitMidpoint::SYMMETRIC);
/// assert_eq!(ImplicitMidpoint::ORDER, 2);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct ImplicitMidpoint;

/// Störmer–Verlet in the form of the paper's Section 5.1.3 (half kick,
/// drift, half kick), explicit for separable H and the generalised implicit
/// method otherwise; symplectic, symmetric, order 2. With holonomic
/// constraints, SHAKE/RATTLE over it are the classical methods.
///
/// ```
/// use shake_runtime::{BaseMap, StormerVerlet};
/// assert!(StormerVerlet::SYMMETRIC);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct StormerVerlet;

/// Symplectic Euler p1 = p0 − h H_q(q0, p1), q1 = q0 + h H_p(q0, p1):
/// symplectic, not symmetric, order 1; explicit for separable H.
///
/// ```
/// use shake_runtime::{BaseMap, SymplecticEuler};
/// assert!(!SymplecticEuler::SYMMETRIC);
/// assert_eq!(SymplecticEuler::ORDER, 1);
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct SymplecticEuler;

/// out += alpha · B x, where B is the d×d block of the 2d×2d column-major
/// Hessian `hz` starting at row `r0`, column `c0`.
#[inline]
fn block_mul_add(
    hz: &[f64],
    d: usize,
    r0: usize,
    c0: usize,
    x: &[f64],
    alpha: f64,
    out: &mut [f64],
) {
    let n = 2 * d;
    for (j, xj) in x.iter().enumerate().take(d) {
        let s = alpha * xj;
        if s != 0.0 {
            let col = &hz[(c0 + j) * n + r0..(c0 + j) * n + r0 + d];
            for (o, b) in out.iter_mut().zip(col) {
                *o += b * s;
            }
        }
    }
}

/// mat (d×d) = I + alpha · B, B the block at (r0, c0) of the Hessian.
fn identity_plus_block(mat: &mut [f64], hz: &[f64], d: usize, r0: usize, c0: usize, alpha: f64) {
    let n = 2 * d;
    for j in 0..d {
        for i in 0..d {
            mat[i + j * d] = alpha * hz[(r0 + i) + (c0 + j) * n] + if i == j { 1.0 } else { 0.0 };
        }
    }
}

fn check_finite(v: &[f64], iterations: usize) -> Result<(), SolveError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(SolveError::NonFinite { iterations })
    }
}

/// The implicit momentum stage x = p0 − c H_q(q0, x) (Störmer–Verlet's
/// first half kick with c = h/2, symplectic Euler's kick with c = h), by
/// Newton's method with the matrix I + c H_qp (∂H_q/∂p). It
/// starts from the previous stage shifted by the change of p0 when
/// `prev_p0` is given (warm start), else from the explicit kick.
#[allow(clippy::too_many_arguments)]
fn momentum_stage<S: Hamiltonian>(
    sys: &S,
    q0: &[f64],
    p0: &[f64],
    c: f64,
    prev_p0: Option<&[f64]>,
    x: &mut [f64],
    res: &mut [f64],
    mat: &mut [f64],
    piv: &mut [usize],
    h_q: &mut [f64],
    hess_a: &mut [f64],
    opts: &NewtonOptions,
) -> Result<usize, SolveError> {
    let d = q0.len();
    match prev_p0 {
        Some(prev) => {
            for i in 0..d {
                x[i] += p0[i] - prev[i];
            }
        }
        None => {
            sys.grad_q(q0, p0, h_q);
            for i in 0..d {
                x[i] = p0[i] - c * h_q[i];
            }
        }
    }
    solve_stage(
        x,
        res,
        mat,
        piv,
        opts,
        |x, r| {
            sys.grad_q(q0, x, h_q);
            for i in 0..d {
                r[i] = x[i] - p0[i] + c * h_q[i];
            }
        },
        |x, a| {
            sys.hessian(q0, x, hess_a);
            identity_plus_block(a, hess_a, d, 0, d, c);
        },
    )
}

/// Newton's method for a d-dimensional stage equation R(x) = 0 where
/// `residual(x, res)` writes R and `matrix(x, mat)` writes dR/dx (d×d).
fn solve_stage(
    x: &mut [f64],
    res: &mut [f64],
    mat: &mut [f64],
    piv: &mut [usize],
    opts: &NewtonOptions,
    mut residual: impl FnMut(&[f64], &mut [f64]),
    mut matrix: impl FnMut(&[f64], &mut [f64]),
) -> Result<usize, SolveError> {
    let n = x.len();
    let mut mon = Monitor::new(*opts);
    loop {
        residual(x, res);
        let r = norm_inf(res);
        if !r.is_finite() {
            return Err(SolveError::NonFinite {
                iterations: mon.iterations,
            });
        }
        if r == 0.0 {
            return Ok(mon.iterations);
        }
        if mon.exhausted() {
            return Err(SolveError::NotConverged {
                iterations: mon.iterations,
                residual: r,
            });
        }
        matrix(x, mat);
        lu_factor(mat, n, piv).map_err(|_| SolveError::Singular {
            iterations: mon.iterations,
        })?;
        lu_solve(mat, n, piv, res);
        for (xi, di) in x.iter_mut().zip(res.iter()) {
            *xi -= di;
        }
        if mon.update(norm_inf(res), norm_inf(x)) == Verdict::Converged {
            check_finite(x, mon.iterations)?;
            return Ok(mon.iterations);
        }
    }
}

impl BaseMap for ImplicitMidpoint {
    const NAME: &'static str = "implicit midpoint";
    const SYMMETRIC: bool = true;
    const ORDER: u32 = 2;

    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let d = ws.d;
        let n = 2 * d;
        let warm = ws.begin(q, p);
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        // The unknown is the midpoint m = (z0 + z1)/2: m = y + (h/2) X_H(m).
        if warm {
            for i in 0..n {
                stage[i] += y[i] - y_prev[i];
            }
        } else {
            sys.gradient(&y[..d], &y[d..], h_q, h_p);
            for i in 0..d {
                stage[i] = y[i] + 0.5 * h * h_p[i];
                stage[d + i] = y[d + i] - 0.5 * h * h_q[i];
            }
        }
        let y: &[f64] = y;
        let iters = solve_stage(
            stage,
            res,
            mat,
            piv,
            opts,
            |m, r| {
                sys.gradient(&m[..d], &m[d..], h_q, h_p);
                for i in 0..d {
                    r[i] = m[i] - y[i] - 0.5 * h * h_p[i];
                    r[d + i] = m[d + i] - y[d + i] + 0.5 * h * h_q[i];
                }
            },
            |m, a| {
                sys.hessian(&m[..d], &m[d..], hess_a);
                midpoint_matrix(a, hess_a, d, -0.5 * h);
            },
        );
        ws.warm = iters.is_ok();
        let iters = iters?;
        for i in 0..d {
            q[i] = 2.0 * ws.stage[i] - ws.y[i];
            p[i] = 2.0 * ws.stage[d + i] - ws.y[d + i];
        }
        Ok(iters)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        sys.hessian(&ws.stage[..d], &ws.stage[d..], &mut ws.hess_a);
        midpoint_matrix(&mut ws.mat, &ws.hess_a, d, -0.5 * h);
        lu_factor(&mut ws.mat, 2 * d, &mut ws.piv)
            .map_err(|_| SolveError::Singular { iterations: 0 })
    }

    fn apply_tangent(&self, _h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        // δz1 = δz0 + h J H_zz(m) δm with δm = (δz0 + δz1)/2, i.e.
        // (I − (h/2) J H_zz) δm = δz0 and δz1 = 2 δm − δz0.
        let n = 2 * ws.d;
        ws.tmp.copy_from_slice(&v[..n]);
        lu_solve(&ws.mat, n, &ws.piv, &mut ws.tmp);
        for (vi, mi) in v.iter_mut().zip(&ws.tmp) {
            *vi = 2.0 * mi - *vi;
        }
    }

    /// The unknown is k = m − y, the half increment: k = (h/2) X_H(y + k),
    /// solved by Newton to stagnation; z1 − z0 = 2k.
    fn increment<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let d = ws.d;
        let n = 2 * d;
        let warm = ws.begin(q, p);
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            hess_a,
            mat,
            piv,
            res,
            tmp,
            ..
        } = ws;
        // tmp holds k (stage holds m = y + k for the tangent map).
        if warm {
            for i in 0..n {
                tmp[i] = stage[i] - y_prev[i];
            }
        } else {
            sys.gradient(&y[..d], &y[d..], h_q, h_p);
            for i in 0..d {
                tmp[i] = 0.5 * h * h_p[i];
                tmp[d + i] = -0.5 * h * h_q[i];
            }
        }
        let y: &[f64] = y;
        let iters = solve_stage(
            tmp,
            res,
            mat,
            piv,
            opts,
            |k, r| {
                for i in 0..n {
                    stage[i] = y[i] + k[i];
                }
                sys.gradient(&stage[..d], &stage[d..], h_q, h_p);
                for i in 0..d {
                    r[i] = k[i] - 0.5 * h * h_p[i];
                    r[d + i] = k[d + i] + 0.5 * h * h_q[i];
                }
            },
            |k, a| {
                // y_prev is free once the warm start has been read.
                for i in 0..n {
                    y_prev[i] = y[i] + k[i];
                }
                sys.hessian(&y_prev[..d], &y_prev[d..], hess_a);
                midpoint_matrix(a, hess_a, d, -0.5 * h);
            },
        );
        ws.warm = iters.is_ok();
        let iters = iters?;
        for i in 0..n {
            ws.stage[i] = ws.y[i] + ws.tmp[i];
        }
        for i in 0..d {
            dq[i] = 2.0 * ws.tmp[i];
            dp[i] = 2.0 * ws.tmp[d + i];
        }
        Ok(iters)
    }
}

/// a = I + alpha · J H_zz (2d×2d), J = [[0, I], [−I, 0]].
fn midpoint_matrix(a: &mut [f64], hz: &[f64], d: usize, alpha: f64) {
    let n = 2 * d;
    for j in 0..n {
        for i in 0..d {
            // (J H)[i, j] = H[d+i, j]; (J H)[d+i, j] = −H[i, j].
            a[i + j * n] = alpha * hz[(d + i) + j * n];
            a[(d + i) + j * n] = -alpha * hz[i + j * n];
        }
        a[j + j * n] += 1.0;
    }
}

impl BaseMap for StormerVerlet {
    const NAME: &'static str = "Störmer–Verlet";
    const SYMMETRIC: bool = true;
    const ORDER: u32 = 2;

    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        sys.separable()
    }

    fn kick_drift_kick(&self) -> Option<(f64, f64)> {
        Some((0.5, 0.5))
    }

    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let d = ws.d;
        let hh = 0.5 * h;
        let warm = ws.begin(q, p);
        if sys.separable() {
            // Explicit: kick, drift, kick. The stage keeps p½ and q1.
            let BaseMapWorkspace {
                stage, h_q, h_p, ..
            } = ws;
            let (p_half, q1) = stage.split_at_mut(d);
            sys.grad_q(q, p, h_q);
            for i in 0..d {
                p_half[i] = p[i] - hh * h_q[i];
            }
            sys.grad_p(q, p_half, h_p);
            for i in 0..d {
                q1[i] = q[i] + h * h_p[i];
            }
            sys.grad_q(q1, p_half, h_q);
            for i in 0..d {
                q[i] = q1[i];
                p[i] = p_half[i] - hh * h_q[i];
            }
            ws.warm = true;
            return Ok(0);
        }
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            h_p,
            h_p_a,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        let (p_half, q1) = stage.split_at_mut(d);
        let (q0, p0) = y.split_at(d);
        // p½ = p0 − (h/2) H_q(q0, p½).
        let it1 = momentum_stage(
            sys,
            q0,
            p0,
            hh,
            if warm { Some(&y_prev[d..]) } else { None },
            p_half,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            h_q,
            hess_a,
            opts,
        );
        let it1 = match it1 {
            Ok(it) => it,
            Err(e) => {
                ws.warm = false;
                return Err(e);
            }
        };
        // q1 = q0 + (h/2)(H_p(q0, p½) + H_p(q1, p½)).
        sys.grad_p(q0, p_half, h_p_a);
        if warm {
            for i in 0..d {
                q1[i] += q0[i] - y_prev[i];
            }
        } else {
            for i in 0..d {
                q1[i] = q0[i] + h * h_p_a[i];
            }
        }
        let p_half: &[f64] = p_half;
        let h_p_a: &[f64] = h_p_a;
        let it2 = solve_stage(
            q1,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            opts,
            |x, r| {
                sys.grad_p(x, p_half, h_p);
                for i in 0..d {
                    r[i] = x[i] - q0[i] - hh * (h_p_a[i] + h_p[i]);
                }
            },
            |x, a| {
                sys.hessian(x, p_half, hess_a);
                identity_plus_block(a, hess_a, d, d, 0, -hh);
            },
        );
        let it2 = match it2 {
            Ok(it) => it,
            Err(e) => {
                ws.warm = false;
                return Err(e);
            }
        };
        // p1 = p½ − (h/2) H_q(q1, p½).
        sys.grad_q(q1, p_half, h_q);
        for i in 0..d {
            q[i] = q1[i];
            p[i] = p_half[i] - hh * h_q[i];
        }
        ws.warm = true;
        Ok(it1 + it2)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        let hh = 0.5 * h;
        let (p_half, q1) = ws.stage.split_at(d);
        sys.hessian(&ws.y[..d], p_half, &mut ws.hess_a);
        sys.hessian(q1, p_half, &mut ws.hess_b);
        if !sys.separable() {
            identity_plus_block(&mut ws.mat, &ws.hess_a, d, 0, d, hh);
            lu_factor(&mut ws.mat[..d * d], d, &mut ws.piv)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
            identity_plus_block(&mut ws.mat_b, &ws.hess_b, d, d, 0, -hh);
            lu_factor(&mut ws.mat_b[..d * d], d, &mut ws.piv_b)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
        }
        ws.tangent_separable = sys.separable();
        Ok(())
    }

    fn apply_tangent(&self, h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        let d = ws.d;
        let hh = 0.5 * h;
        let separable = ws.tangent_separable;
        let (dq, dp) = v.split_at_mut(d);
        let (dp_half, dq1) = ws.tmp.split_at_mut(d);
        // (I + (h/2) H_qp^a) δp½ = δp0 − (h/2) H_qq^a δq0.
        dp_half.copy_from_slice(dp);
        block_mul_add(&ws.hess_a, d, 0, 0, dq, -hh, dp_half);
        if !separable {
            lu_solve(&ws.mat[..d * d], d, &ws.piv, dp_half);
        }
        // (I − (h/2) H_pq^b) δq1 = δq0 + (h/2)(H_pq^a δq0 + (H_pp^a + H_pp^b) δp½).
        dq1.copy_from_slice(dq);
        block_mul_add(&ws.hess_a, d, d, 0, dq, hh, dq1);
        block_mul_add(&ws.hess_a, d, d, d, dp_half, hh, dq1);
        block_mul_add(&ws.hess_b, d, d, d, dp_half, hh, dq1);
        if !separable {
            lu_solve(&ws.mat_b[..d * d], d, &ws.piv_b, dq1);
        }
        // δp1 = δp½ − (h/2)(H_qq^b δq1 + H_qp^b δp½).
        dp.copy_from_slice(dp_half);
        block_mul_add(&ws.hess_b, d, 0, 0, dq1, -hh, dp);
        block_mul_add(&ws.hess_b, d, 0, d, dp_half, -hh, dp);
        dq.copy_from_slice(dq1);
    }

    /// Separable H: δq = h H_p(p½), δp = −(h/2)(H_q(q0) + H_q(q1)), each a
    /// small quantity computed directly. Non-separable H: the provided
    /// difference form.
    fn increment<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        if !sys.separable() {
            dq.copy_from_slice(q);
            dp.copy_from_slice(p);
            let it = self.apply(sys, h, dq, dp, ws, opts)?;
            for (x, x0) in dq.iter_mut().zip(q) {
                *x -= x0;
            }
            for (x, x0) in dp.iter_mut().zip(p) {
                *x -= x0;
            }
            return Ok(it);
        }
        let d = ws.d;
        let hh = 0.5 * h;
        ws.begin(q, p);
        let BaseMapWorkspace {
            stage,
            h_q,
            h_p,
            res,
            ..
        } = ws;
        let (p_half, q1) = stage.split_at_mut(d);
        let hq0 = &mut res[..d];
        sys.grad_q(q, p, hq0);
        for i in 0..d {
            p_half[i] = p[i] - hh * hq0[i];
        }
        sys.grad_p(q, p_half, h_p);
        for i in 0..d {
            dq[i] = h * h_p[i];
            q1[i] = q[i] + dq[i];
        }
        sys.grad_q(q1, p_half, h_q);
        for i in 0..d {
            // Two half kicks, as in `apply` (a sum first could overflow).
            dp[i] = -hh * hq0[i] - hh * h_q[i];
        }
        ws.warm = true;
        Ok(0)
    }
}

impl BaseMap for SymplecticEuler {
    const NAME: &'static str = "symplectic Euler";
    const SYMMETRIC: bool = false;
    const ORDER: u32 = 1;

    fn explicit_for<S: Hamiltonian>(&self, sys: &S) -> bool {
        sys.separable()
    }

    fn kick_drift_kick(&self) -> Option<(f64, f64)> {
        Some((1.0, 0.0))
    }

    fn apply<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        q: &mut [f64],
        p: &mut [f64],
        ws: &mut BaseMapWorkspace,
        opts: &NewtonOptions,
    ) -> Result<usize, SolveError> {
        let d = ws.d;
        let warm = ws.begin(q, p);
        if sys.separable() {
            let BaseMapWorkspace {
                stage, h_q, h_p, ..
            } = ws;
            let p1 = &mut stage[..d];
            sys.grad_q(q, p, h_q);
            for i in 0..d {
                p1[i] = p[i] - h * h_q[i];
            }
            sys.grad_p(q, p1, h_p);
            for i in 0..d {
                q[i] += h * h_p[i];
            }
            p.copy_from_slice(p1);
            ws.warm = true;
            return Ok(0);
        }
        let BaseMapWorkspace {
            y,
            y_prev,
            stage,
            h_q,
            hess_a,
            mat,
            piv,
            res,
            ..
        } = ws;
        let p1 = &mut stage[..d];
        let (q0, p0) = y.split_at(d);
        // p1 = p0 − h H_q(q0, p1).
        let it = momentum_stage(
            sys,
            q0,
            p0,
            h,
            if warm { Some(&y_prev[d..]) } else { None },
            p1,
            &mut res[..d],
            &mut mat[..d * d],
            piv,
            h_q,
            hess_a,
            opts,
        );
        ws.warm = it.is_ok();
        let it = it?;
        let (q0, p1) = (&ws.y[..d], &ws.stage[..d]);
        sys.grad_p(q0, p1, &mut ws.h_p);
        for i in 0..d {
            q[i] = q0[i] + h * ws.h_p[i];
            p[i] = p1[i];
        }
        Ok(it)
    }

    fn prepare_tangent<S: Hamiltonian>(
        &self,
        sys: &S,
        h: f64,
        ws: &mut BaseMapWorkspace,
    ) -> Result<(), SolveError> {
        let d = ws.d;
        sys.hessian(&ws.y[..d], &ws.stage[..d], &mut ws.hess_a);
        if !sys.separable() {
            identity_plus_block(&mut ws.mat, &ws.hess_a, d, 0, d, h);
            lu_factor(&mut ws.mat[..d * d], d, &mut ws.piv)
                .map_err(|_| SolveError::Singular { iterations: 0 })?;
        }
        ws.tangent_separable = sys.separable();
        Ok(())
    }

    fn apply_tangent(&self, h: f64, ws: &mut BaseMapWorkspace, v: &mut [f64]) {
        let d = ws.d;
        let separable = ws.tangent_separable;
        let (dq, dp) = v.split_at_mut(d);
        let dp1 = &mut ws.tmp[..d];
        // (I + h H_qp) δp1 = δp0 − h H_qq δq0.
        dp1.copy_from_slice(dp);
        block_mul_add(&ws.hess_a, d, 0, 0, dq, -h, dp1);
        if !separable {
            lu_solve(&ws.mat[..d * d], d, &ws.piv, dp1);
        }
        // δq1 = δq0 + h (H_pq δq0 + H_pp δp1).
        ws.res[..d].copy_from_slice(dq);
        block_mul_add(&ws.hess_a, d, d, 0, dq, h, &mut ws.res[..d]);
        block_mul_add(&ws.hess_a, d, d, d, dp1, h, &mut ws.res[..d]);
        dq.copy_from_slice(&ws.res[..d]);
        dp.copy_from_slice(dp1);
    }
}
