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

use crate::linalg::{expm, norm_inf};
use crate::system::{ConstrainedSystem, ConstraintKind};
use crate::SolveError;

const GBS_ROWS: usize = 10;
const GBS_MAX_SPLITS: u32 = 10;

/// The fibre flow of a system together with its buffers.
///
/// ```
/// use shake_runtime::{FibreFlow, examples::Pendulum};
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
    /// use shake_runtime::{FibreFlow, examples::Pendulum};
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
    /// use shake_runtime::{FibreFlow, examples::HopfHarmonic};
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
    /// use shake_runtime::{FibreFlow, examples::HopfHarmonic};
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

    /// (δq, δp) = φ₁(A)(A z + b) for the affine field A z + b of λ.
    fn linear_increment(
        &mut self,
        lambda: &[f64],
        q: &[f64],
        p: &[f64],
        dq: &mut [f64],
        dp: &mut [f64],
    ) {
        if let Some((omega, l)) = &self.rotation {
            // cos θ − 1 = −2 sin²(θ/2): no cancellation for small λ.
            let half = (0.5 * omega * lambda[0]).sin();
            let s = (omega * lambda[0]).sin() / omega;
            rotate(l, -2.0 * half * half, s, q, p, &mut self.za, &mut self.zb);
            let d = self.d;
            dq.copy_from_slice(&self.zb[..d]);
            dp.copy_from_slice(&self.zb[d..]);
            return;
        }
        let (d, m) = (self.d, self.m);
        let n = 2 * d;
        let n1 = n + 1;
        let aug = &mut self.aug;
        aug.fill(0.0);
        for (l, hi) in lambda.iter().zip(&self.hess_i) {
            if *l == 0.0 {
                continue;
            }
            for j in 0..n {
                for r in 0..d {
                    aug[r + j * n1] += l * hi[(d + r) + j * n];
                    aug[(d + r) + j * n1] -= l * hi[r + j * n];
                }
            }
        }
        let z = &mut self.za;
        z[..d].copy_from_slice(q);
        z[d..].copy_from_slice(p);
        // Last column: A z + b.
        for r in 0..n {
            let mut s = 0.0;
            for (i, l) in lambda.iter().enumerate().take(m) {
                s += if r < d {
                    l * self.g_z0[i + (d + r) * m]
                } else {
                    -l * self.g_z0[i + (r - d) * m]
                };
            }
            for j in 0..n {
                s += aug[r + j * n1] * z[j];
            }
            aug[r + n * n1] = s;
        }
        expm(aug, n1, &mut self.t1, &mut self.t2, &mut self.t3);
        for r in 0..d {
            dq[r] = aug[r + n * n1];
            dp[r] = aug[(d + r) + n * n1];
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

    /// z ← exp(A) z + φ₁(A) b for the affine field A z + b.
    fn linear_flow(&mut self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) {
        if let Some((omega, l)) = &self.rotation {
            let (c, s) = ((omega * lambda[0]).cos(), (omega * lambda[0]).sin() / omega);
            rotate(l, c - 1.0, s, q, p, &mut self.za, &mut self.zb);
            for (x, dx) in q.iter_mut().chain(p.iter_mut()).zip(&self.zb) {
                *x += dx;
            }
            return;
        }
        let (d, m) = (self.d, self.m);
        let n = 2 * d;
        let n1 = n + 1;
        let aug = &mut self.aug;
        aug.fill(0.0);
        for (i, (l, hi)) in lambda.iter().zip(&self.hess_i).enumerate() {
            let _ = i;
            if *l == 0.0 {
                continue;
            }
            for j in 0..n {
                for r in 0..d {
                    // (J M)[r, j] = M[d+r, j]; (J M)[d+r, j] = −M[r, j].
                    aug[r + j * n1] += l * hi[(d + r) + j * n];
                    aug[(d + r) + j * n1] -= l * hi[r + j * n];
                }
            }
        }
        for r in 0..d {
            let (mut bq, mut bp) = (0.0, 0.0);
            for (i, l) in lambda.iter().enumerate().take(m) {
                bq += l * self.g_z0[i + (d + r) * m];
                bp -= l * self.g_z0[i + r * m];
            }
            aug[r + n * n1] = bq;
            aug[(d + r) + n * n1] = bp;
        }
        expm(aug, n1, &mut self.t1, &mut self.t2, &mut self.t3);
        let z = &mut self.za;
        z[..d].copy_from_slice(q);
        z[d..].copy_from_slice(p);
        for r in 0..n {
            let mut s = aug[r + n * n1];
            for j in 0..n {
                s += aug[r + j * n1] * z[j];
            }
            if r < d {
                q[r] = s;
            } else {
                p[r - d] = s;
            }
        }
    }

    /// f ← Σ λ_i X_{g_i}(z) = (g_pᵀλ, −g_qᵀλ).
    fn field<S: ConstrainedSystem>(
        sys: &S,
        g_z: &mut [f64],
        d: usize,
        m: usize,
        lambda: &[f64],
        z: &[f64],
        f: &mut [f64],
    ) {
        sys.constraint_jacobian(&z[..d], &z[d..], g_z);
        for k in 0..d {
            let (mut fq, mut fp) = (0.0, 0.0);
            for (i, l) in lambda.iter().enumerate().take(m) {
                fq += l * g_z[i + (d + k) * m];
                fp -= l * g_z[i + k * m];
            }
            f[k] = fq;
            f[d + k] = fp;
        }
    }

    /// Gragg–Bulirsch–Stoer over unit time, with step doubling.
    fn integrate<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        lambda: &[f64],
        q: &mut [f64],
        p: &mut [f64],
    ) -> Result<(), SolveError> {
        let d = self.d;
        self.start[..d].copy_from_slice(q);
        self.start[d..].copy_from_slice(p);
        // Start with pieces short enough that the field turns the state by
        // at most about 1/8 per piece: fewer substeps, less rounding.
        Self::field(
            sys,
            &mut self.g_z,
            d,
            self.m,
            lambda,
            &self.start,
            &mut self.f,
        );
        let rate = norm_inf(&self.f) / norm_inf(&self.start).max(f64::MIN_POSITIVE);
        let mut first = 0;
        while first < GBS_MAX_SPLITS && rate / (1u64 << first) as f64 > 0.125 {
            first += 1;
        }
        for split in first..=GBS_MAX_SPLITS {
            let pieces = 1usize << split;
            let width = 1.0 / pieces as f64;
            self.zc.copy_from_slice(&self.start);
            let mut ok = true;
            for _ in 0..pieces {
                if !self.gbs_interval(sys, lambda, width) {
                    ok = false;
                    break;
                }
            }
            if ok {
                q.copy_from_slice(&self.zc[..d]);
                p.copy_from_slice(&self.zc[d..]);
                return Ok(());
            }
        }
        Err(SolveError::NotConverged {
            iterations: GBS_ROWS << GBS_MAX_SPLITS,
            residual: f64::NAN,
        })
    }

    /// One extrapolated interval of length `width` from `zc` (in place).
    /// Returns false when the table did not converge.
    fn gbs_interval<S: ConstrainedSystem>(&mut self, sys: &S, lambda: &[f64], width: f64) -> bool {
        let (d, m) = (self.d, self.m);
        let n = 2 * d;
        let mut prev_err = f64::INFINITY;
        for j in 0..GBS_ROWS {
            let steps = 2 * (j + 1);
            let eta = width / steps as f64;
            // Modified midpoint: za = z_{k−1}, zb = z_k.
            self.za.copy_from_slice(&self.zc);
            Self::field(sys, &mut self.g_z, d, m, lambda, &self.za, &mut self.f);
            for i in 0..n {
                self.zb[i] = self.za[i] + eta * self.f[i];
            }
            for _ in 1..steps {
                Self::field(sys, &mut self.g_z, d, m, lambda, &self.zb, &mut self.f);
                for i in 0..n {
                    let next = self.za[i] + 2.0 * eta * self.f[i];
                    self.za[i] = self.zb[i];
                    self.zb[i] = next;
                }
            }
            Self::field(sys, &mut self.g_z, d, m, lambda, &self.zb, &mut self.f);
            std::mem::swap(&mut self.row, &mut self.row_prev);
            for i in 0..n {
                self.row[i] = 0.5 * (self.zb[i] + self.za[i] + eta * self.f[i]);
            }
            // Neville: T_{j,k} = T_{j,k−1} + (T_{j,k−1} − T_{j−1,k−1}) / ((n_j/n_{j−k})² − 1).
            for k in 1..=j {
                let ratio = (steps as f64) / (2 * (j + 1 - k)) as f64;
                let denom = ratio * ratio - 1.0;
                for i in 0..n {
                    let a = self.row[(k - 1) * n + i];
                    let b = self.row_prev[(k - 1) * n + i];
                    self.row[k * n + i] = a + (a - b) / denom;
                }
            }
            if j == 0 {
                continue;
            }
            let diag = &self.row[j * n..(j + 1) * n];
            let sub = &self.row[(j - 1) * n..j * n];
            let err = diag
                .iter()
                .zip(sub)
                .fold(0.0f64, |e, (a, b)| e.max((a - b).abs()));
            let scale = norm_inf(diag).max(f64::MIN_POSITIVE);
            if !err.is_finite() {
                return false;
            }
            let accept = err <= 8.0 * f64::EPSILON * scale
                || (err >= prev_err && prev_err <= 64.0 * f64::EPSILON * scale);
            if accept {
                self.zc.copy_from_slice(diag);
                return true;
            }
            prev_err = err;
        }
        false
    }
}
/// For one quadratic constraint with no linear part (∇g(0) = 0), the
/// generator L = J∇²g of its fibre flow, if L² = −ω²I to round-off: then
/// exp(λL) = cos(ωλ) I + sin(ωλ)/ω · L, a closed form (the Hopf constraint
/// |q|² + |p|² − r² has L = 2J, ω = 2: the rotation z_k ↦ e^{−2iλ} z_k).
fn rotation_generator(hess: &[Vec<f64>], g_z0: &[f64], d: usize) -> Option<(f64, Vec<f64>)> {
    if hess.len() != 1 || g_z0.iter().any(|&x| x != 0.0) {
        return None;
    }
    let n = 2 * d;
    let a = &hess[0];
    let mut l = vec![0.0; n * n];
    for j in 0..n {
        for r in 0..d {
            // (J A)[r, j] = A[d+r, j]; (J A)[d+r, j] = −A[r, j].
            l[r + j * n] = a[(d + r) + j * n];
            l[(d + r) + j * n] = -a[r + j * n];
        }
    }
    let mut l2 = vec![0.0; n * n];
    crate::linalg::matmul(&l, &l, &mut l2, n);
    let w2 = -l2[0];
    if !(w2 > 0.0) || !w2.is_finite() {
        return None;
    }
    let tol = 64.0 * f64::EPSILON * w2;
    for j in 0..n {
        for i in 0..n {
            let want = if i == j { -w2 } else { 0.0 };
            if (l2[i + j * n] - want).abs() > tol {
                return None;
            }
        }
    }
    Some((w2.sqrt(), l))
}

/// Δz = a z + b L z for z = (q, p), into `out` (`z` is scratch): the
/// increment of the rotation exp(λL) with a = cos(ωλ) − 1, b = sin(ωλ)/ω.
fn rotate(l: &[f64], a: f64, b: f64, q: &[f64], p: &[f64], z: &mut [f64], out: &mut [f64]) {
    let d = q.len();
    let n = 2 * d;
    z[..d].copy_from_slice(q);
    z[d..].copy_from_slice(p);
    for r in 0..n {
        let lz: f64 = (0..n).map(|j| l[r + j * n] * z[j]).sum();
        out[r] = a * z[r] + b * lz;
    }
}
