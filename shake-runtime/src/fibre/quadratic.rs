//! The fibre flows of quadratic constraints: Σ λ_i X_{g_i}(z) = A z + b is
//! affine, so the flow is exp(A) z + φ₁(A) b (the augmented matrix
//! exponential), or a rotation in closed form when the generator squares
//! to −ω²I (the module docs of [`fibre`](super)).

use super::FibreFlow;
use crate::linalg::expm;

impl FibreFlow {
    /// (δq, δp) = φ₁(A)(A z + b) for the affine field A z + b of λ.
    pub(super) fn linear_increment(
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

    /// z ← exp(A) z + φ₁(A) b for the affine field A z + b.
    pub(super) fn linear_flow(&mut self, lambda: &[f64], q: &mut [f64], p: &mut [f64]) {
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
}

/// For one quadratic constraint with no linear part (∇g(0) = 0), the
/// generator L = J∇²g of its fibre flow, if L² = −ω²I to round-off: then
/// exp(λL) = cos(ωλ) I + sin(ωλ)/ω · L, a closed form (the Hopf constraint
/// |q|² + |p|² − r² has L = 2J, ω = 2: the rotation z_k ↦ e^{−2iλ} z_k).
pub(super) fn rotation_generator(
    hess: &[Vec<f64>],
    g_z0: &[f64],
    d: usize,
) -> Option<(f64, Vec<f64>)> {
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
