//! SHAKE for a few constraints (2 ≤ m ≤ 8) on stack arrays of the
//! system's own sizes, with N and Π on the stack: the kernel of the
//! fixed-size classical step (`step::classical`) when `constrained_system!`
//! can see d and m at compile time.
//!
//! The map is the slice path's ([`super::shake_step`], [`super::project`]),
//! computed with the same operations in the same order (the same kick,
//! residual, Jacobian from the same list of terms, the same banded LU
//! kernels, the same stopping rules), so it gives the same steps to the
//! last bit (`tests/suite/fast_paths.rs`). What moves to the stack is SHAKE's
//! Newton iteration (λ, r, q1, Δ and the m×m Jacobian), N with its factors,
//! and Π's σ: arrays whose lengths the compiler knows, so the loops over
//! them unroll and the generated derivatives inline with their sizes. Both
//! matrices are factorised in their band, as the slice path does: a
//! chain's are tridiagonal from three links on (`linalg::tridiagonal`,
//! O(m) with the recursion in registers). N on the stack and the
//! tridiagonal kernels bring a 4-link chain's RATTLE run to about 1.5 times
//! the hand-written step (BENCHMARKS.md, section 7).
//! `geoshake-macros`' tests show the macro emits this step for m = 2 to 8.

use super::{packed_jacobian, Buffers};
use crate::compensated::kahan_add;
use crate::error::{SolveError, Stage, StepError};
use crate::linalg::{
    all_finite, band_lu_factor, band_lu_solve, dense_lu_factor, dense_lu_solve,
    full_band_lu_factor, full_band_lu_solve, lu_det, norm_inf, Band,
};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::rattle::{estimate_inverse, FactorN, NondegeneracyCheck};
use crate::shake::{ShakeReport, Workspace};
use crate::system::ConstrainedSystem;

/// Π at (q, p), p in place, with N's factors on the stack: one solve
/// N σ = {g, H}, then the kick along the fibre (σ left in `ws.sigma`).
#[inline(always)]
pub(crate) fn project_on_stack<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    q: &[f64; D],
    p: &mut [f64],
    (a, piv, band): (&[[f64; M]; M], &[usize; M], Band),
    ws: &mut Workspace,
) {
    let mut sigma = [0.0; M];
    sys.hidden_constraints(q, p, &mut sigma);
    if band == Band::full(M) {
        dense_lu_solve(a.as_flattened(), M, piv, &mut sigma);
    } else {
        band_lu_solve(a.as_flattened(), M, band, piv, &mut sigma);
    }
    ws.sigma.copy_from_slice(&sigma);
    let mut y = *q;
    if !sys.fibre_flow(&sigma, &mut y, p).applied() {
        let cl = &mut ws.classical;
        packed_jacobian(
            sys,
            q,
            p,
            (&cl.pattern, cl.whole),
            &mut ws.g_z_1,
            &mut cl.g1,
        );
        for (&(i, k), g) in cl.pattern.iter().zip(&cl.g1) {
            p[k] -= g * sigma[i];
        }
    }
}

/// N at the new state on the stack, column-major, and its factors once
/// made in its structural band (`ws.n.band`); the workspace for N at the
/// last checked state and for the factors' copy.
pub(crate) struct StackN<'a, const M: usize> {
    pub(crate) a: [[f64; M]; M],
    pub(crate) piv: [usize; M],
    pub(crate) band: Band,
    pub(crate) ws: &'a mut Workspace,
}

impl<const M: usize> StackN<'_, M> {
    /// `rattle::read_n` on the stack: ‖N‖₁ and ‖N − N_prev‖₁ (the entries
    /// outside N's band are structural zeros, which add nothing), N_prev ←
    /// N, and the fill of a banded LU zeroed.
    #[inline(always)]
    pub(crate) fn read(&mut self) -> (f64, f64) {
        let band = self.band;
        if band != Band::full(M) {
            let fill = band.lower + band.upper;
            for (j, col) in self.a.iter_mut().enumerate() {
                col[j.saturating_sub(fill)..j.saturating_sub(band.upper)].fill(0.0);
            }
        }
        let prev = &mut self.ws.n.prev[..M * M];
        let (mut norm, mut change) = (0.0f64, 0.0f64);
        for (col, prev) in self.a.iter().zip(prev.chunks_exact_mut(M)) {
            let (mut sum, mut diff) = (0.0, 0.0);
            for (&v, prev) in col.iter().zip(prev) {
                sum += v.abs();
                diff += (v - *prev).abs();
                *prev = v;
            }
            norm = norm.max(sum);
            change = change.max(diff);
        }
        (norm, change)
    }
}

impl<const M: usize> FactorN for StackN<'_, M> {
    fn order(&self) -> usize {
        M
    }

    /// `rattle::factor_and_check` for m ≥ 2, on the stack.
    #[inline(always)]
    fn factor_and_check(&mut self, norm: f64, bound: Option<f64>) -> NondegeneracyCheck {
        if !norm.is_finite() {
            return NondegeneracyCheck {
                det: f64::NAN,
                norm,
                inverse_norm: f64::INFINITY,
            };
        }
        // `factor_n`'s kernels: the dense LU for the full band, else the
        // banded one, whose band the spare slots of `ws.piv` record.
        let (a, band) = (self.a.as_flattened_mut(), self.band);
        let factored = if band == Band::full(M) {
            dense_lu_factor(a, M, &mut self.piv)
        } else {
            band_lu_factor(a, M, band, &mut self.piv)
        };
        let ws = &mut *self.ws;
        ws.jac[..M * M].copy_from_slice(self.a.as_flattened());
        ws.piv[..M].copy_from_slice(&self.piv);
        (ws.piv[M], ws.piv[M + 1]) = if band == Band::full(M) {
            (0, 0)
        } else {
            (band.lower, band.upper + 1)
        };
        match factored {
            Err(_) => NondegeneracyCheck {
                det: 0.0,
                norm,
                inverse_norm: f64::INFINITY,
            },
            Ok(()) => NondegeneracyCheck {
                det: lu_det(&ws.jac, M, &ws.piv),
                norm,
                inverse_norm: match bound {
                    Some(b) => b,
                    None => estimate_inverse(ws),
                },
            },
        }
    }

    fn estimate_inverse(&mut self) -> f64 {
        estimate_inverse(self.ws)
    }
}

/// The stack state of SHAKE's iteration: u (the momentum increment before
/// the last kick), Δq, q1 and r = g(q1).
struct Iterate<const D: usize, const M: usize> {
    u: [f64; D],
    dq: [f64; D],
    q1: [f64; D],
    r: [f64; M],
}

/// q1(λ) and r(λ) as `geoshake::classical::residual` computes them (λ = 0 when
/// `lambda` is `None`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn residual<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    h: f64,
    q0: &[f64; D],
    p0: &[f64; D],
    kick: &[f64; D],
    g0: &[f64],
    pattern: &[(usize, usize)],
    lambda: Option<&[f64; M]>,
) -> Iterate<D, M> {
    let mut u = *kick;
    if let Some(l) = lambda {
        let mut y = *q0;
        if !sys.fibre_flow(l, &mut y, &mut u).applied() {
            for (&(i, k), g) in pattern.iter().zip(g0) {
                u[k] -= g * l[i];
            }
        }
    }
    let mut v = [0.0; D];
    for k in 0..D {
        v[k] = p0[k] + u[k];
    }
    let mut w = [0.0; D];
    sys.grad_p(q0, &v, &mut w);
    let (mut dq, mut q1) = ([0.0; D], [0.0; D]);
    for k in 0..D {
        dq[k] = h * w[k];
        q1[k] = q0[k] + dq[k];
    }
    let mut r = [0.0; M];
    sys.constraints(&q1, p0, &mut r);
    Iterate { u, dq, q1, r }
}

/// The fitted roots of decoupled constraints after the first update
/// (`super::fitted_roots`, λ in place) and the residual there; `None` if
/// nothing moved. Out of line and cold: inlined, this third copy of the
/// residual (the system's g, ∂H/∂p and fibre flow) sits inside the
/// iteration's loop of every system, and one with a banded Jacobian never
/// takes it but fetches and decodes around it at every update (the time
/// of a step depends on the size of that loop, not only on the
/// instructions it executes).
#[cold]
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn fitted<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    h: f64,
    q0: &[f64; D],
    p0: &[f64; D],
    kick: &[f64; D],
    g0: &[f64],
    pattern: &[(usize, usize)],
    lambda: &mut [f64; M],
    r0: &[f64; M],
    r: &[f64; M],
    jac: &[[f64; M]; M],
) -> Option<(Iterate<D, M>, f64)> {
    let jump = super::fitted_roots(lambda, r0, r, |i| jac[i][i])?;
    let next = residual::<S, D, M>(sys, h, q0, p0, kick, g0, pattern, Some(lambda));
    Some((next, jump))
}

/// SHAKE's Jacobian −h G(q1) A G0ᵀ at `q1`, factorised in `jac`/`piv`, as
/// `geoshake::classical::jacobian` forms it (the list of terms when A is diagonal,
/// else the column groups through `grad_p`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn jacobian<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    h: f64,
    (q0, p0, q1): (&[f64; D], &[f64; D], &[f64; D]),
    (cl, dense, band, groups): (&mut Buffers, &mut [f64], Band, usize),
    jac: &mut [[f64; M]; M],
    piv: &mut [usize; M],
    iterations: usize,
) -> Result<(), StepError> {
    packed_jacobian(sys, q1, p0, (&cl.pattern, cl.whole), dense, &mut cl.g1);
    let (g0, g1) = (&cl.g0, &cl.g1);
    let jac = jac.as_flattened_mut();
    let fill = band.lower + band.upper;
    for j in 0..M {
        let lo = j.saturating_sub(fill);
        let hi = (j + band.lower).min(M - 1);
        jac[lo + j * M..=hi + j * M].fill(0.0);
    }
    if !cl.mass.is_empty() {
        cl.subtract_products(h, jac);
    } else {
        for c in 0..groups {
            let mut v = [0.0; D];
            for ((&(_, k), &grp), g) in cl.pattern.iter().zip(&cl.group).zip(g0) {
                if grp == c {
                    v[k] -= g;
                }
            }
            let mut w = [0.0; D];
            sys.grad_p(q0, &v, &mut w);
            let mut jv = [0.0; M];
            for (&(i, k), g) in cl.pattern.iter().zip(g1) {
                jv[i] += g * w[k];
            }
            for i in 0..M {
                let lo = i.saturating_sub(band.lower);
                let j = lo + (c + groups - lo % groups) % groups;
                if j > i + band.upper || j >= M {
                    continue;
                }
                jac[i + j * M] = h * jv[i];
            }
        }
    }
    // The slice path's kernels: the full band's with its order a
    // constant, or the banded one (a chain's: tridiagonal).
    if band == Band::full(M) {
        full_band_lu_factor::<M>(jac, piv)
    } else {
        band_lu_factor(jac, M, band, piv)
    }
    .map_err(|_| StepError::from_solve(Stage::Shake, SolveError::Singular { iterations }))
}

/// `geoshake::classical::shake_step` on the stack: (q, p) becomes z1⁻ in place;
/// the last λ, its first iterate and the last residual r are left in
/// `ws.lambda`, `ws.lambda_first` and `ws.g` (on failure too, as the slice
/// path leaves them), G0 and G at the last Jacobian's q1 packed in
/// `ws.classical.g0`/`g1`. The slice path's other buffers are not written: nothing
/// after the step reads them before writing them.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn shake<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    (a, b): (f64, f64),
    h: f64,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    opts: &NewtonOptions,
    carry: Option<&mut [f64]>,
) -> Result<ShakeReport, StepError> {
    let q0: [f64; D] = (&*q).try_into().expect("checked by substep");
    let p0: [f64; D] = (&*p).try_into().expect("checked by substep");
    // The first kick and G0 (kept in the workspace: the checks after the
    // step measure g's scale with it).
    let mut hq = [0.0; D];
    sys.grad_q(&q0, &p0, &mut hq);
    let mut kick = [0.0; D];
    for k in 0..D {
        kick[k] = -(a * h) * hq[k];
    }
    let cl = &mut ws.classical;
    packed_jacobian(
        sys,
        &q0,
        &p0,
        (&cl.pattern, cl.whole),
        &mut ws.g_z_y,
        &mut cl.g0,
    );
    // g's round-off level near q0 and ‖∂g_i/∂z‖₁ at q0, in one pass over
    // G0 (as the slice path, `geoshake::classical::shake_step`).
    let mut floor = [0.0; M];
    ws.g_size.fill(0.0);
    for (&(i, k), &g) in cl.pattern.iter().zip(&cl.g0) {
        floor[i] += f64::EPSILON * (g * q0[k]).abs();
        ws.g_size[i] += g.abs();
    }
    let mut it = residual::<S, D, M>(sys, h, &q0, &p0, &kick, &cl.g0, &cl.pattern, None);
    let mut lambda = [0.0; M];
    let mut lambda_first = [0.0; M];
    let mut jac = [[0.0; M]; M];
    let mut piv = [0usize; M];
    let band: Band = ws.jac_band;
    let diagonal = band.lower == 0 && band.upper == 0;
    let mut mon = Monitor::new(*opts).refresh_beyond(super::REFRESH_HORIZON);
    let mut fresh = true;
    let mut need_jacobian = true;
    let mut r_first = 0.0;
    let not_finite =
        |iterations| StepError::from_solve(Stage::Shake, SolveError::NonFinite { iterations });
    let outcome = loop {
        let r = norm_inf(&it.r);
        if !(r.is_finite() && all_finite(&it.r) && all_finite(&it.dq)) {
            break Err(not_finite(mon.iterations));
        }
        // At round-off: the confirming update (`geoshake::classical::shake_step`).
        let at_floor = r == 0.0 || it.r.iter().zip(&floor).all(|(g, f)| g.abs() <= *f);
        if at_floor && (r == 0.0 || need_jacobian || mon.exhausted()) {
            break Ok(());
        }
        if mon.exhausted() {
            break Err(StepError::from_solve(
                Stage::Shake,
                SolveError::NotConverged {
                    iterations: mon.iterations,
                    residual: r,
                },
            ));
        }
        if mon.iterations == 0 {
            r_first = r;
        }
        if need_jacobian {
            let at = (&mut ws.classical, &mut ws.g_z_1[..], band, ws.groups);
            let z = (&q0, &p0, &it.q1);
            if let Err(e) = jacobian(sys, h, z, at, &mut jac, &mut piv, 0) {
                break Err(e);
            }
            need_jacobian = false;
        }
        let mut delta = it.r;
        if band == Band::full(M) {
            full_band_lu_solve::<M>(jac.as_flattened(), &piv, &mut delta);
        } else {
            band_lu_solve(jac.as_flattened(), M, band, &piv, &mut delta);
        }
        for (l, dl) in lambda.iter_mut().zip(&delta) {
            *l -= dl;
        }
        let (step, size) = (norm_inf(&delta), norm_inf(&lambda));
        if mon.iterations == 0 {
            lambda_first = lambda;
            // λ's round-off level (`geoshake::classical::shake_step`).
            mon.set_floor(step / r_first * norm_inf(&floor));
        }
        let verdict = mon.update_frozen(step, size, fresh);
        let r0 = it.r;
        let cl = &ws.classical;
        it = residual::<S, D, M>(sys, h, &q0, &p0, &kick, &cl.g0, &cl.pattern, Some(&lambda));
        if !(step.is_finite() && size.is_finite()) {
            break Err(not_finite(mon.iterations));
        }
        if at_floor {
            break Ok(());
        }
        if diagonal && mon.iterations == 1 {
            // Decoupled constraints: the fitted root of each, as the
            // slice path takes them (`geoshake::classical::shake_step`).
            let cl = &ws.classical;
            let (g0, pattern) = (&cl.g0[..], &cl.pattern[..]);
            let (r, lambda) = (&it.r, &mut lambda);
            if let Some((next, jump)) =
                fitted::<S, D, M>(sys, h, &q0, &p0, &kick, g0, pattern, lambda, &r0, r, &jac)
            {
                it = next;
                mon.jump(jump);
                fresh = false;
                continue;
            }
        }
        // The one stopping rule of simplified Newton (`newton`).
        match verdict {
            Verdict::Converged => break Ok(()),
            Verdict::Continue => fresh = false,
            Verdict::Refresh => {
                let at = (&mut ws.classical, &mut ws.g_z_1[..], band, ws.groups);
                let z = (&q0, &p0, &it.q1);
                if let Err(e) = jacobian(sys, h, z, at, &mut jac, &mut piv, mon.iterations) {
                    break Err(e);
                }
                fresh = true;
            }
        }
    };
    // As the slice path leaves them, whether SHAKE converged or not: the
    // last residual and λ (and λ's first iterate once there was one).
    ws.g.copy_from_slice(&it.r);
    ws.lambda.copy_from_slice(&lambda);
    let iterations = mon.iterations;
    if iterations > 0 {
        ws.lambda_first.copy_from_slice(&lambda_first);
    }
    outcome?;
    // p1 − p0 = u − b h ∇V(q1).
    let mut dp = it.u;
    if b != 0.0 {
        let mut hq1 = [0.0; D];
        sys.grad_q(&it.q1, &p0, &mut hq1);
        for k in 0..D {
            dp[k] = it.u[k] - (b * h) * hq1[k];
        }
    }
    match carry {
        Some(c) => {
            let (cq, cp) = c.split_at_mut(D);
            for k in 0..D {
                kahan_add(&mut q[k], &mut cq[k], it.dq[k]);
                kahan_add(&mut p[k], &mut cp[k], dp[k]);
            }
        }
        None => {
            for k in 0..D {
                q[k] += it.dq[k];
                p[k] += dp[k];
            }
        }
    }
    let mut report = ShakeReport {
        iterations,
        lambda: norm_inf(&lambda),
        ..ShakeReport::default()
    };
    if iterations > 0 {
        report.lambda_predicted = norm_inf(&lambda_first);
        report.lambda_correction = lambda
            .iter()
            .zip(&lambda_first)
            .fold(0.0f64, |e, (x, y)| e.max((x - y).abs()));
    }
    Ok(report)
}
