//! Geometric RATTLE (the paper's Definition 1.2) and the projections it is
//! made of.
//!
//! RATTLE is SHAKE followed by the projection Π along the fibre onto the
//! hidden constraint set M^H = {g = 0, {g_i, H} = 0}:
//! R_h = Π ∘ S_h, with Π(z) = exp(Σ σ_i X_{g_i})(z) and σ chosen so that
//! {g_i, H}(Π(z)) = 0 (the paper's Corollary 2.3).
//!
//! # The equation for σ
//!
//! Newton's method from σ = 0, to round-off. Its matrix is
//! d/dσ_j {g_i, H}(exp(Σ σ_k X_{g_k})(z)) = d{g_i,H} · X_{g_j} = {{g_i,H},g_j}
//! = −N_ij, with N the nondegeneracy matrix of the system, evaluated at the
//! current iterate (exact where the X_{g_i} commute, as in SHAKE). So the
//! update is σ ← σ + N⁻¹ {g, H}.
//!
//! # Why a run projects only where a state is observed
//!
//! Π maps a whole fibre to one point, and S_h does too (SHAKE's result does
//! not depend on where on the fibre of z0 it starts, Section 4). Since
//! R_h(z) = Π(S_h(z)) lies on the fibre of S_h(z),
//! S_h(R_h(z)) = S_h(S_h(z)), and by induction
//! Π ∘ S_hᵏ = Π ∘ R_hᵏ (the paper's equation after Proposition 4.2). RATTLE is
//! therefore a post-processing of SHAKE: a run steps with SHAKE and applies
//! Π only to the states it returns or shows to an observer.

use crate::error::{Stage, StepError};
use crate::linalg::{
    all_finite, band_lu_factor, inverse_norm1_estimate_from, lu_det, lu_factor, lu_solve, norm_inf,
    zero_short, Band, Singular,
};
use crate::newton::{Finish, Monitor, NewtonOptions, Polish, Verdict};
use crate::shake::Workspace;
use crate::system::ConstrainedSystem;
use crate::SolveError;

/// What a projection did.
#[derive(Copy, Clone, Debug, Default, PartialEq)]
pub(crate) struct ProjectionReport {
    pub(crate) iterations: usize,
    /// ‖σ‖∞ (or ‖Δz‖∞ for the projection onto M).
    pub(crate) displacement: f64,
    /// ‖σ₁‖∞: the first Newton iterate, the linear prediction
    /// N⁻¹{g,H} of the fibre displacement (projection onto M^H only).
    pub(crate) predicted: f64,
    /// An upper bound of ‖σ − σ₁‖∞: the sum of the later updates' norms.
    /// Small against `predicted` when Π lands on the nearby point of M^H; as
    /// large as it or larger when Newton has wandered to another crossing of
    /// the fibre with M^H (another component, Section 5.4.2).
    pub(crate) correction: f64,
}

/// Π: moves (q, p) ∈ M along its fibre onto M^H, in place.
pub(crate) fn project_hidden<S: ConstrainedSystem>(
    sys: &S,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    opts: &NewtonOptions,
) -> Result<ProjectionReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    if m == 0 {
        return Ok(ProjectionReport::default());
    }
    ws.y[..d].copy_from_slice(q);
    ws.y[d..].copy_from_slice(p);
    ws.sigma.fill(0.0);
    let mut mon = Monitor::new(*opts);
    let mut converged = false;
    let (mut predicted, mut correction) = (0.0f64, 0.0f64);
    // ‖σ‖∞ of the rounds before a polish restarted σ from 0.
    let mut moved = 0.0f64;
    let mut polish = Polish::new(2);
    loop {
        ws.z1.copy_from_slice(&ws.y);
        {
            let (zq, zp) = ws.z1.split_at_mut(d);
            ws.fibre
                .apply(sys, &ws.sigma, zq, zp)
                .map_err(|e| StepError::from_solve(Stage::Fibre, e))?;
        }
        sys.hidden_constraints(&ws.z1[..d], &ws.z1[d..], &mut ws.hidden);
        let r = norm_inf(&ws.hidden);
        if !r.is_finite() {
            return Err(StepError::from_solve(
                Stage::Rattle,
                SolveError::NonFinite {
                    iterations: mon.iterations,
                },
            ));
        }
        if r == 0.0 {
            break;
        }
        if converged {
            // Far along a fibre (|σ| of 10²–10³ after Newton went round a
            // periodic one) the last update can be lost in the rounding of
            // σ + Δσ with {g,H} still far above its round-off. A polish
            // restarts σ from 0 at the iterate, where the update is not
            // lost; it is undone if it does not lower the residual.
            match polish.judge(r, || hidden_at_roundoff(sys, ws)) {
                Finish::Done => break,
                Finish::Undo => {
                    ws.z1.copy_from_slice(&ws.y);
                    sys.hidden_constraints(&ws.y[..d], &ws.y[d..], &mut ws.hidden);
                    break;
                }
                Finish::Again => {
                    ws.y.copy_from_slice(&ws.z1);
                    moved += norm_inf(&ws.sigma);
                    ws.sigma.fill(0.0);
                }
            }
        }
        if mon.exhausted() {
            return Err(StepError::from_solve(
                Stage::Rattle,
                SolveError::NotConverged {
                    iterations: mon.iterations,
                    residual: r,
                },
            ));
        }
        sys.nondegeneracy_matrix(&ws.z1[..d], &ws.z1[d..], &mut ws.n.mat);
        read_n(ws, false);
        factor_n(ws).map_err(|_| {
            StepError::from_solve(
                Stage::Rattle,
                SolveError::Singular {
                    iterations: mon.iterations,
                },
            )
        })?;
        ws.delta.copy_from_slice(&ws.hidden);
        lu_solve(&ws.jac, m, &ws.piv, &mut ws.delta);
        for (s, ds) in ws.sigma.iter_mut().zip(&ws.delta) {
            *s += ds;
        }
        let step = norm_inf(&ws.delta);
        if mon.iterations == 0 {
            predicted = step;
        } else {
            correction += step;
        }
        converged = mon.update(step, norm_inf(&ws.sigma)) == Verdict::Converged;
    }
    // Newton stops on its update; the residual must also be at round-off
    // for the scale of {g,H}'s terms, else the update stalled short of the
    // root (huge parameters or states, N ill-conditioned near an
    // exceptional fibre): a typed error, never a state off M^H.
    let residual = norm_inf(&ws.hidden);
    let bound = hidden_roundoff(sys, &ws.z1[..2 * d], &mut ws.y[..2 * d]);
    if !(residual <= bound) {
        return Err(StepError::from_solve(
            Stage::Rattle,
            SolveError::NotConverged {
                iterations: mon.iterations,
                residual,
            },
        ));
    }
    q.copy_from_slice(&ws.z1[..d]);
    p.copy_from_slice(&ws.z1[d..]);
    Ok(ProjectionReport {
        iterations: mon.iterations,
        displacement: moved + norm_inf(&ws.sigma),
        predicted,
        correction,
    })
}

/// Whether every |{g_i,H}| at z1 (in `ws.hidden`) is within 16ε of the
/// size of its terms, Σ_k |∂g_i/∂z_k| |(J∇H)_k| at z1 (ws.z1): what
/// rounding those products leaves, the mark a polish aims at. (Stricter
/// than [`hidden_roundoff`], the bound a result must meet: a polish that
/// cannot reach it is undone, never an error. Evaluates g_z and ∇H at z1
/// into `ws.g_z_1` and `ws.tv`, the sizes into `ws.g_size`.)
fn hidden_at_roundoff<S: ConstrainedSystem>(sys: &S, ws: &mut Workspace) -> bool {
    let (d, m) = (ws.d, ws.m);
    let (q, p) = ws.z1.split_at(d);
    sys.constraint_jacobian(q, p, &mut ws.g_z_1);
    let (hq, hp) = ws.tv[..2 * d].split_at_mut(d);
    sys.gradient(q, p, hq, hp);
    ws.g_size.fill(0.0);
    for &(i, k) in &ws.pattern {
        // (J∇H)_k: H_p for a q-component, H_q for a p-component.
        let jh = if k < d { hp[k] } else { hq[k - d] };
        ws.g_size[i] += (ws.g_z_1[i + k * m] * jh).abs();
    }
    let hidden = &ws.hidden;
    hidden
        .iter()
        .zip(&ws.g_size)
        .all(|(r, s)| r.abs() <= 16.0 * f64::EPSILON * s)
}

/// The round-off level of {g,H} at z = (q, p): 1e-12 · (1 + |z|∞) ·
/// (1 + |z|∞ + |∇H(z)|∞). Each term of {g,H} = g_q·H_p − g_p·H_q is a
/// gradient of g (O(1 + |z|) for the constraints of the paper, quadratic in
/// z) times one of H, so rounding z in its last bit changes {g,H} by about
/// ε times this scale; 1e-12 ≈ 4500ε leaves room for the few thousand
/// roundings of a projection (the bound `tests/fuzz_api.rs` and
/// `tests/suite/runtime_proptest.rs` hold every projection to). `grad` is
/// scratch of length 2d.
pub(crate) fn hidden_roundoff<S: ConstrainedSystem>(sys: &S, z: &[f64], grad: &mut [f64]) -> f64 {
    let d = z.len() / 2;
    let (hq, hp) = grad.split_at_mut(d);
    sys.gradient(&z[..d], &z[d..], hq, hp);
    let zmax = norm_inf(z);
    1e-12 * (1.0 + zmax) * (1.0 + zmax + norm_inf(grad))
}

/// The largest (m + 1)(2d)² for which [`nondegeneracy_terms`] is
/// evaluated: about a million multiply-adds, once per starting state. Past
/// it (large dense systems) N is judged by its condition alone.
const TERMS_BUDGET: usize = 1 << 20;

/// ‖T‖₁, where T_ij is the sum of the absolute values of the terms of
/// N_ij = ∇{g_i,H} · J∇g_j (Section 5.2), with
/// ∇{g_i,H} = ∇²g_i J∇H − ∇²H J∇g_i:
///
///   T_ij = Σ_k (Σ_l |∇²g_i|_kl |J∇H|_l + |∇²H|_kl |J∇g_i|_l) |J∇g_j|_k.
///
/// Rounding the data of N in their last bit moves N_ij by about ε T_ij, so
/// an N whose entries are small against T is round-off: a degeneracy that
/// holds identically (such as N ≡ 0 for an angular momentum under any
/// radial potential) evaluates to numbers of size ε‖T‖, not to 0, and only
/// this scale tells them from a genuine small N. NaN when the system is too
/// large for the budget or a derivative is not finite. Allocates its
/// scratch (in `ws.terms`) on first use.
pub(crate) fn nondegeneracy_terms<S: ConstrainedSystem>(
    sys: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
) -> f64 {
    let (d, m) = (ws.d, ws.m);
    let n = 2 * d;
    if m == 0 || (m + 1).saturating_mul(n.saturating_mul(n)) > TERMS_BUDGET {
        return f64::NAN;
    }
    ws.terms.resize(2 * n * n + 2 * n + 2 * m * n + m, 0.0);
    let (hess_h, rest) = ws.terms.split_at_mut(n * n);
    let (hess_g, rest) = rest.split_at_mut(n * n);
    let (grad, rest) = rest.split_at_mut(n);
    let (jh, rest) = rest.split_at_mut(n);
    let (g_z, rest) = rest.split_at_mut(m * n);
    let (a, unit) = rest.split_at_mut(m * n);
    // |J v|_k = |v_{k ± d}|: J swaps the halves of z (and signs, which the
    // absolute values drop).
    let swap = |k: usize| if k < d { k + d } else { k - d };
    hess_h.fill(0.0);
    sys.hessian(q, p, hess_h);
    let (hq, hp) = grad.split_at_mut(d);
    sys.gradient(q, p, hq, hp);
    g_z.fill(0.0);
    sys.constraint_jacobian(q, p, g_z);
    for k in 0..n {
        jh[k] = grad[swap(k)].abs();
    }
    // Where J∇H and g_z are finite, a term whose two second derivatives
    // are both zero is +0 and adds nothing to a sum of non-negative terms:
    // skipping it leaves every sum the same to the bit. The sums run over
    // l column by column (each a[i, k] still adds its terms by increasing
    // l), and only the entries ∇²g_i wrote are cleared for the next i:
    // the second derivatives are sparse (SO(3)'s six constraints in R⁹
    // leave about 95 % of the terms zero), and the dense sums were a
    // tenth of a sampler transition there.
    let sparse = all_finite(jh) && all_finite(g_z);
    hess_g.fill(0.0);
    for i in 0..m {
        unit.fill(0.0);
        unit[i] = 1.0;
        sys.constraint_hessian(q, p, unit, hess_g);
        for k in 0..n {
            a[i + k * m] = 0.0;
        }
        for l in 0..n {
            let (jl, gl) = (jh[l], g_z[i + swap(l) * m].abs());
            let (cg, ch) = (&mut hess_g[l * n..(l + 1) * n], &hess_h[l * n..(l + 1) * n]);
            for (k, (hg, &hh)) in cg.iter_mut().zip(ch).enumerate() {
                if sparse && *hg == 0.0 && hh == 0.0 {
                    continue;
                }
                a[i + k * m] += hg.abs() * jl + hh.abs() * gl;
                *hg = 0.0;
            }
        }
    }
    // The same for the zeros of g_z against finite sums.
    let sparse = sparse && all_finite(a);
    let mut norm = 0.0f64;
    for j in 0..m {
        let mut column = 0.0;
        for i in 0..m {
            for k in 0..n {
                let g = g_z[j + swap(k) * m];
                if sparse && g == 0.0 {
                    continue;
                }
                column += a[i + k * m] * g.abs();
            }
        }
        norm = norm.max(column);
    }
    if norm.is_finite() {
        norm
    } else {
        f64::NAN
    }
}

/// Whether g(q, p) is at its round-off: every |g_i| ≤ 64 ε Σ_k
/// |∂g_i/∂z_k| |z_k|, what rounding each entry of z in its last bit
/// changes g_i by, with room (64) for the roundings of the projection and
/// fibre flow that computed z and of g's own evaluation.
pub(crate) fn g_at_roundoff<S: ConstrainedSystem>(
    sys: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
) -> bool {
    sys.constraints(q, p, &mut ws.g);
    sys.constraint_jacobian(q, p, &mut ws.g_z_1);
    crate::tolerance::g_within_roundoff(&ws.g, &ws.pattern, &ws.g_z_1, (q, p), 64.0, &mut ws.g_size)
}

/// Brings (q, p) onto M = {g = 0} by Gauss–Newton with the minimum-norm
/// update Δz = −g_zᵀ (g_z g_zᵀ)⁻¹ g(z) (orthogonal to M, not along a fibre:
/// fibres lie inside level sets of g), in place.
pub(crate) fn project_constraint<S: ConstrainedSystem>(
    sys: &S,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    opts: &NewtonOptions,
) -> Result<ProjectionReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    if m == 0 {
        return Ok(ProjectionReport::default());
    }
    let n = 2 * d;
    let mut mon = Monitor::new(*opts);
    let mut converged = false;
    let mut moved = 0.0f64;
    loop {
        sys.constraints(q, p, &mut ws.g);
        let r = norm_inf(&ws.g);
        if !r.is_finite() {
            return Err(StepError::from_solve(
                Stage::ProjectionOntoM,
                SolveError::NonFinite {
                    iterations: mon.iterations,
                },
            ));
        }
        if converged || r == 0.0 {
            break;
        }
        if mon.exhausted() {
            return Err(StepError::from_solve(
                Stage::ProjectionOntoM,
                SolveError::NotConverged {
                    iterations: mon.iterations,
                    residual: r,
                },
            ));
        }
        sys.constraint_jacobian(q, p, &mut ws.g_z_1);
        let gz = &ws.g_z_1;
        for j in 0..m {
            for i in 0..m {
                ws.gram[i + j * m] = (0..n).map(|k| gz[i + k * m] * gz[j + k * m]).sum();
            }
        }
        lu_factor(&mut ws.gram, m, &mut ws.piv).map_err(|_| {
            StepError::from_solve(
                Stage::ProjectionOntoM,
                SolveError::Singular {
                    iterations: mon.iterations,
                },
            )
        })?;
        ws.delta.copy_from_slice(&ws.g);
        lu_solve(&ws.gram, m, &ws.piv, &mut ws.delta);
        let mut step = 0.0f64;
        for k in 0..n {
            let dz: f64 = (0..m).map(|i| gz[i + k * m] * ws.delta[i]).sum();
            step = step.max(dz.abs());
            if k < d {
                q[k] -= dz;
            } else {
                p[k - d] -= dz;
            }
        }
        moved += step;
        let size = norm_inf(q).max(norm_inf(p));
        converged = mon.update(step, size) == Verdict::Converged;
    }
    Ok(ProjectionReport {
        iterations: mon.iterations,
        displacement: moved,
        ..ProjectionReport::default()
    })
}

/// N at a point, factorised: its determinant, ‖N‖₁ and an estimate of
/// ‖N⁻¹‖₁ (∞ when N is exactly singular).
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) struct NondegeneracyCheck {
    pub(crate) det: f64,
    pub(crate) norm: f64,
    pub(crate) inverse_norm: f64,
}

impl NondegeneracyCheck {
    /// The condition number of N relative to `reference` (‖N‖₁ at the
    /// start): max(‖N‖₁, reference) · ‖N⁻¹‖₁. For m ≥ 2 this is at least the
    /// usual κ₁(N); for m = 1 (where κ is always 1) it measures how much N
    /// has shrunk since the start.
    pub(crate) fn condition(&self, reference: f64) -> f64 {
        if self.inverse_norm.is_infinite() {
            return f64::INFINITY;
        }
        self.norm.max(reference) * self.inverse_norm
    }
}

/// Factorises N, which [`read_n`] copied into `ws.jac`, there, within its
/// structural band `ws.n.band` when that is narrower than the matrix:
/// O(m b²) for a chain instead of O(m²) passes over a dense m×m buffer.
/// The band is recorded in the spare slots of `ws.piv`, so `lu_solve` and
/// the condition estimate use the banded factors.
fn factor_n(ws: &mut Workspace) -> Result<(), Singular> {
    let m = ws.m;
    let band = ws.n.band;
    if band == Band::full(m) {
        return lu_factor(&mut ws.jac, m, &mut ws.piv);
    }
    band_lu_factor(&mut ws.jac, m, band, &mut ws.piv)?;
    ws.piv[m] = band.lower;
    ws.piv[m + 1] = band.upper + 1;
    Ok(())
}

/// One pass over N (in `ws.n.mat`) within its structural band: returns
/// ‖N‖₁ and, when `track`, ‖N − N_prev‖₁ (how much N changed since the
/// last checked state) with N_prev ← N (`ws.n.prev`; 0 and untouched
/// otherwise); and copies N into `ws.jac` for [`factor_n`], with the fill
/// of the banded LU (rows j − l − u ..= j − u − 1 of column j) zeroed.
/// Nothing outside the band and its fill is ever read. (One pass, not
/// three: on a chain of 64 links these were a few per cent of a step.)
pub(crate) fn read_n(ws: &mut Workspace, track: bool) -> (f64, f64) {
    let (m, band) = (ws.m, ws.n.band);
    let fill = band.lower + band.upper;
    let (mut norm, mut change) = (0.0f64, 0.0f64);
    for j in 0..m {
        let (top, hi) = (j.saturating_sub(band.upper), (j + band.lower).min(m - 1));
        let col = j * m;
        zero_short(&mut ws.jac[j.saturating_sub(fill) + col..top + col]);
        let (mut sum, mut diff) = (0.0, 0.0);
        if track {
            for k in top + col..=hi + col {
                let v = ws.n.mat[k];
                sum += v.abs();
                diff += (v - ws.n.prev[k]).abs();
                ws.n.prev[k] = v;
                ws.jac[k] = v;
            }
        } else {
            for k in top + col..=hi + col {
                let v = ws.n.mat[k];
                sum += v.abs();
                ws.jac[k] = v;
            }
        }
        norm = norm.max(sum);
        change = change.max(diff);
    }
    (norm, change)
}

/// Evaluates and factorises N(q, p).
pub(crate) fn check_nondegeneracy<S: ConstrainedSystem>(
    sys: &S,
    q: &[f64],
    p: &[f64],
    ws: &mut Workspace,
) -> NondegeneracyCheck {
    sys.nondegeneracy_matrix(q, p, &mut ws.n.mat);
    let (norm, _) = read_n(ws, false);
    factor_and_check(ws, norm, None)
}

/// Factorises N (copied into `ws.jac` by [`read_n`], which also gave
/// `norm` = ‖N‖₁) and checks it: det N, ‖N‖₁ and ‖N⁻¹‖₁, estimated by
/// Hager's method for m ≥ 2 unless `bound` gives an upper bound of it
/// already (see `Guard::judge_shake`).
pub(crate) fn factor_and_check(
    ws: &mut Workspace,
    norm: f64,
    bound: Option<f64>,
) -> NondegeneracyCheck {
    let m = ws.m;
    if !norm.is_finite() {
        return NondegeneracyCheck {
            det: f64::NAN,
            norm,
            inverse_norm: f64::INFINITY,
        };
    }
    match factor_n(ws) {
        Err(_) => NondegeneracyCheck {
            det: 0.0,
            norm,
            inverse_norm: f64::INFINITY,
        },
        // m = 1: N⁻¹ is a number.
        Ok(()) if m == 1 => NondegeneracyCheck {
            det: ws.jac[0],
            norm,
            inverse_norm: 1.0 / ws.jac[0].abs(),
        },
        Ok(()) => NondegeneracyCheck {
            det: lu_det(&ws.jac, m, &ws.piv),
            norm,
            inverse_norm: match bound {
                Some(b) => b,
                None => estimate_inverse(ws),
            },
        },
    }
}

/// N read and ready to factorise, wherever it is held: in the workspace
/// ([`read_n`] copied it into `ws.jac`) or on the stack (the fixed-size
/// classical step, `geoshake::classical::fixed_m`). What
/// [`Guard::check_n`](crate::guard::Guard::check_n) needs of it.
pub(crate) trait FactorN {
    /// N's order m.
    fn order(&self) -> usize;
    /// [`factor_and_check`]: factorises N and checks it, with ‖N⁻¹‖₁ =
    /// `bound` when given, else estimated.
    fn factor_and_check(&mut self, norm: f64, bound: Option<f64>) -> NondegeneracyCheck;
    /// [`estimate_inverse`]: Hager's estimate from the factors just made.
    fn estimate_inverse(&mut self) -> f64;
}

impl FactorN for Workspace {
    fn order(&self) -> usize {
        self.m
    }
    fn factor_and_check(&mut self, norm: f64, bound: Option<f64>) -> NondegeneracyCheck {
        factor_and_check(self, norm, bound)
    }
    fn estimate_inverse(&mut self) -> f64 {
        estimate_inverse(self)
    }
}

/// Hager's estimate of ‖N⁻¹‖₁ from the factors [`factor_and_check`] left
/// in `ws.jac`/`ws.piv` (m ≥ 2), started from the column the last
/// estimate ended on.
pub(crate) fn estimate_inverse(ws: &mut Workspace) -> f64 {
    inverse_norm1_estimate_from(
        &ws.jac,
        ws.m,
        &ws.piv,
        &mut ws.n.s1,
        &mut ws.n.s2,
        &mut ws.n.cond_column,
    )
}
