//! The fibre flow of general constraints, integrated over unit time by
//! Gragg–Bulirsch–Stoer extrapolation with step doubling (the module docs
//! of [`fibre`](super) give the acceptance rules).

use super::FibreFlow;
use crate::linalg::norm_inf;
use crate::system::ConstrainedSystem;
use crate::SolveError;

/// Rows of the extrapolation table before the interval is halved.
pub(super) const GBS_ROWS: usize = 10;
/// At most 2^GBS_MAX_SPLITS pieces of the unit interval.
const GBS_MAX_SPLITS: u32 = 10;

impl FibreFlow {
    /// f ← Σ λ_i X_{g_i}(z) = (g_pᵀλ, −g_qᵀλ).
    pub(super) fn field<S: ConstrainedSystem>(
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
    pub(super) fn integrate<S: ConstrainedSystem>(
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
    pub(super) fn gbs_interval<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        lambda: &[f64],
        width: f64,
    ) -> bool {
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
