//! The classical case, solved the way a hand-written RATTLE solves it:
//! holonomic constraints g(q), a separable H = ½ pᵀA p + V(q) with constant
//! A, and a base map that is a kick–drift–kick for such H (Störmer–Verlet,
//! symplectic Euler; [`BaseMap::kick_drift_kick`]).
//!
//! # SHAKE
//!
//! The fibre flow is the kick p ↦ p − G0ᵀλ (G0 = g_q(q0)), and the base map
//! is explicit, so with p* = p0 − a h ∇V(q0):
//!
//! q1(λ) = q0 + h A (p* − G0ᵀλ),  p1 = p* − G0ᵀλ − b h ∇V(q1).
//!
//! Only q1 depends on λ, affinely: the equation g(q1(λ)) = 0 needs no
//! momentum, no base-map stage, no fibre-flow call. Its Jacobian is exact
//! and analytic, −h G(q1) A G0ᵀ (from g_z at two points and one
//! `grad_p`, which is A·v for a quadratic T), banded like the general one
//! (columns compressed by the predicted band, see `shake`). It is formed
//! at λ = 0 and kept (simplified Newton), formed again only when the
//! contraction is slow. The iteration stops on an update below the
//! round-off of λ (4ε‖λ‖, or the round-off that g's own rounding puts into
//! λ: the floor of g below, through J⁻¹, whose size the first update shows
//! as ‖Δ₁‖/‖r(0)‖, whichever is larger), or once the residual is at
//! round-off: when every |g_i(q1)| is below ε Σ_k |∂g_i/∂q_k| |q_k| (what
//! rounding q1 in its last bit changes g_i by), no update can bring q1
//! closer to M. λ is then still off by J⁻¹r, and the momenta see λ
//! divided by h (p½ = (q1 − q0)/h): so the update from that residual is
//! taken, with the Jacobian in hand, before the iteration ends (the
//! confirming update). Stopping without it left the double pendulum's
//! SHAKE step 67ε from the classical formulas at h = 0.05, against 12ε
//! with it (`tests/suite/classical_agrees.rs`, the paper's claim 2).
//! Stagnation at the noise floor with a fresh Jacobian stops it too: the
//! one rule of simplified Newton ([`Monitor::update_frozen`], with λ's
//! round-off level as its floor), which the general kernel uses too. So
//! does its rule 3: where the contraction puts the error left in λ below
//! 4ε‖λ‖ (θ/(1−θ)‖Δ_k‖, or θ²‖Δ_k‖ after a fresh Jacobian; Hairer &
//! Wanner, *Solving ODEs II*, IV.8), λ is as close as the confirming
//! update would bring it, and that update is not taken. A residual at
//! round-off says nothing of the error in λ, which is why it alone is
//! followed by the confirming update.
//!
//! For one constraint of degree ≤ 2 (a distance, as the system declares,
//! [`ConstrainedSystem::quadratic_constraints`]) r(λ) = r0 + r1 λ + r2 λ²
//! exactly, r2 from g's constant Hessian read once: the first iterate is its
//! small root (`quadratic_root`), on this path and on the fixed-size one with
//! the same operations. For any other single constraint the first Newton
//! iterate λ1 fits that quadratic through r(λ1) and its root is the next
//! iterate. Several constraints whose Jacobian is diagonal (each g_i reads
//! coordinates no other g_j reads, as two circles of a torus: the predicted
//! band is 0) are decoupled, r_i depending on λ_i alone, and each takes its
//! own fitted root the same way (`fitted_root`). Where the Jacobian is cheap
//! to form (here: g_q once more, and one product), the frozen one is kept
//! only while its contraction reaches round-off within `REFRESH_HORIZON`
//! updates (`newton`, "Cheap Jacobians"): at h|p| ≈ 0.3 of a radius it
//! contracts by only ≈ 0.2. The closed-form root is the equation's solution
//! up to the rounding of its formula, not an iterate of Newton's, so at g's
//! round-off it is taken without a confirming update.
//!
//! # Projection and checks
//!
//! {g_i, H} = (G A p)_i is linear in p and the fibre moves p only, so
//! Π's equation for σ is linear: N σ = G A p with N = G A Gᵀ, which is the
//! nondegeneracy matrix {{H,g_i},g_j} and depends on q alone. One
//! evaluation and factorisation of N per step serves the nondegeneracy
//! check (det N, condition estimate; O(1) for m = 1) and the projection
//! (one solve, exact), whether the projection happens at once or only when
//! the state is stored (q does not change between the two).
//!
//! # Fixed sizes
//!
//! A system that knows its d and m at compile time (every
//! `constrained_system!`) takes the same step on stack arrays: for one
//! constraint with N and the Jacobian as numbers ([`fixed`]), for two to
//! eight with SHAKE's iteration, N and Π on the stack ([`fixed_m`]). The
//! functions here serve every other classical system. The checks of the
//! new state are the guard's, in `step::classical`, for all three.

pub(crate) mod fixed;
pub(crate) mod fixed_m;

pub(crate) use super::workspace::{packed_jacobian, Buffers};

use crate::base_map::BaseMap;
use crate::compensated::kahan_add;
use crate::error::{SolveError, Stage, StepError};
use crate::linalg::{all_finite, band_lu_factor, band_lu_solve, lu_solve, norm_inf, zero_short};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::shake::{ShakeReport, Workspace};
use crate::system::{ConstrainedSystem, ConstraintKind};

/// The frozen Jacobian's horizon (`newton`, "Cheap Jacobians"): its
/// contraction must reach the tolerance within this many updates, or it
/// is evaluated afresh. A refresh costs about one residual here (g_q at
/// q1 and one product with A G0ᵀ) while m is at most
/// [`CHEAP_REFRESH_M`].
pub(crate) const REFRESH_HORIZON: i32 = 3;

/// The most constraints for which a refresh of SHAKE's Jacobian costs
/// about an update (`REFRESH_HORIZON`): the sizes the fixed-size kernels
/// take, whose Jacobian is a few numbers. Beyond, a refresh forms the
/// banded product over m rows and factorises it, the cost of two to three
/// updates, more than the updates it saves at the step sizes a run takes:
/// the frozen Jacobian is kept while it quarters.
pub(crate) const CHEAP_REFRESH_M: usize = 8;

/// The kick fractions (a, b) of the base map when the classical path
/// applies to `S`, else `None`.
pub(crate) fn classical<S: ConstrainedSystem, B: BaseMap>(sys: &S, base: &B) -> Option<(f64, f64)> {
    if sys.kind() == ConstraintKind::Holonomic
        && sys.separable()
        && sys.quadratic_kinetic()
        && sys.constraint_count() > 0
    {
        base.kick_drift_kick()
    } else {
        None
    }
}

/// q1(λ) and r(λ) = g(q1(λ)) for the λ in `ws.lambda`: the momentum
/// increment before the last kick, p* − p0 − G0ᵀλ, in `ws.classical.u`
/// (`first`: λ = 0, u = the first kick only), Δq in `ws.dz[..d]`, q1 in
/// `ws.z1[..d]`, r in `ws.g`.
fn residual<S: ConstrainedSystem>(sys: &S, h: f64, ws: &mut Workspace, first: bool) {
    let d = ws.d;
    let cl = &mut ws.classical;
    cl.u.copy_from_slice(&cl.kick);
    if !first {
        // u ← u − G0ᵀλ: the fibre flow's kick, in the system's closed form
        // when it has compiled one (straight-line code), else through the
        // pattern with the G0 in hand (an interpreted closed form would run
        // its whole program for G0 again at every iterate).
        ws.y[..d].copy_from_slice(&ws.z0[..d]);
        if sys.interpreted()
            || !sys
                .fibre_flow(&ws.lambda, &mut ws.y[..d], &mut cl.u)
                .applied()
        {
            for (&(i, k), g) in cl.pattern.iter().zip(&cl.g0) {
                cl.u[k] -= g * ws.lambda[i];
            }
        }
    }
    // p½ = p0 + u; Δq = h A p½ (grad_p is linear in p; for an
    // interpreted system, A's diagonal when it is one).
    for k in 0..d {
        cl.v[k] = ws.z0[d + k] + cl.u[k];
    }
    if cl.mass.is_empty() || !sys.interpreted() {
        sys.grad_p(&ws.z0[..d], &cl.v, &mut cl.w);
    } else {
        for ((w, a), v) in cl.w.iter_mut().zip(&cl.mass).zip(&cl.v) {
            *w = a * v;
        }
    }
    for k in 0..d {
        ws.dz[k] = h * ws.classical.w[k];
        ws.z1[k] = ws.z0[k] + ws.dz[k];
    }
    sys.constraints(&ws.z1[..d], &ws.z0[d..], &mut ws.g);
}

/// The Jacobian −h G(q1) A G0ᵀ at the current q1 (`ws.z1`), within the
/// predicted band, factorised in `ws.jac`/`ws.piv_j`.
fn jacobian<S: ConstrainedSystem>(
    sys: &S,
    h: f64,
    ws: &mut Workspace,
    iterations: usize,
) -> Result<(), StepError> {
    let (d, m) = (ws.d, ws.m);
    let band = ws.jac_band;
    let groups = ws.groups;
    let cl = &mut ws.classical;
    let at = (&cl.pattern[..], cl.whole);
    packed_jacobian(sys, &ws.z1[..d], &ws.z0[d..], at, &mut ws.g_z_1, &mut cl.g1);
    let fill = band.lower + band.upper;
    for j in 0..m {
        let lo = j.saturating_sub(fill);
        let hi = (j + band.lower).min(m - 1);
        zero_short(&mut ws.jac[lo + j * m..=hi + j * m]);
    }
    if !ws.classical.mass.is_empty() {
        // A diagonal (masses): J = −h Σ_k a_k G1[:,k] G0[:,k]ᵀ, a sum of
        // outer products of G's sparse columns, with no call to `grad_p`
        // and no column groups (a chain: 4 products per variable).
        // (The terms in the band are listed once per system, in the
        // order of this sum: `Buffers::products`.)
        ws.classical.subtract_products(h, &mut ws.jac);
        return band_lu_factor(&mut ws.jac, m, band, &mut ws.piv_j)
            .map_err(|_| StepError::from_solve(Stage::Shake, SolveError::Singular { iterations }));
    }
    for c in 0..groups {
        // v = −G0ᵀ s_c, s_c the indicator of the columns j ≡ c; w = h A v.
        let cl = &mut ws.classical;
        cl.v.fill(0.0);
        for ((&(_, k), &grp), g) in cl.pattern.iter().zip(&cl.group).zip(&cl.g0) {
            if grp == c {
                cl.v[k] -= g;
            }
        }
        sys.grad_p(&ws.z0[..d], &cl.v, &mut cl.w);
        ws.jv.fill(0.0);
        for (&(i, k), g) in cl.pattern.iter().zip(&cl.g1) {
            ws.jv[i] += g * cl.w[k];
        }
        for i in 0..m {
            let lo = i.saturating_sub(band.lower);
            let j = lo + (c + groups - lo % groups) % groups;
            if j > i + band.upper || j >= m {
                continue;
            }
            ws.jac[i + j * m] = h * ws.jv[i];
        }
    }
    band_lu_factor(&mut ws.jac, m, band, &mut ws.piv_j)
        .map_err(|_| StepError::from_solve(Stage::Shake, SolveError::Singular { iterations }))
}

/// The small root of SHAKE's residual r0 + r1 λ + r2 λ² for one
/// constraint of degree at most 2 (a distance; its constant Hessian
/// `g_qq` read once, `Buffers`): along the line q1(λ) = q̃ + λ h w,
/// w = A(−G0ᵀ), g(q1(λ)) is exactly that quadratic, with r0 = g(q̃),
/// r1 = h G(q̃)·w and r2 = ½ h² wᵀ g_qq w (`whw` = wᵀ g_qq w). Returns the
/// root nearest 0, in the form without cancellation, Newton's first
/// iterate −r0/r1 (the guard compares the two) and r1; `None` where the
/// quadratic has no real root or the slope vanishes (the Newton iteration
/// then decides). Both paths take it as the first iterate, with the same
/// operations (`fixed` on arrays, [`first_iterate`] on slices).
#[inline(always)]
pub(crate) fn quadratic_root(h: f64, r0: f64, r1: f64, whw: f64) -> Option<(f64, f64, f64)> {
    let r2 = 0.5 * h * h * whw;
    let disc = r1 * r1 - 4.0 * r0 * r2;
    if !(r1 != 0.0 && r1.is_finite() && disc >= 0.0) {
        return None;
    }
    let root = 2.0 * r0 / (-r1 - r1.signum() * disc.sqrt());
    root.is_finite().then_some((root, -r0 / r1, r1))
}

/// The small root of r0 + r1 λ + r2 λ² for one decoupled constraint
/// along its line, with r1 = J(0) (the slope at λ = 0) and r2 fitted
/// through the residual `r_l1` at the first Newton iterate λ1 = −r0/r1
/// (where r0 + r1 λ1 vanishes, so r2 = r(λ1)/λ1²), in the form without
/// cancellation. Exact for a constraint of degree 2 (a distance), a better
/// iterate than λ1 for any other; `None` where the fitted quadratic has no
/// real root. Every classical kernel takes it with these operations.
#[inline(always)]
pub(crate) fn fitted_root(r0: f64, r1: f64, l1: f64, r_l1: f64) -> Option<f64> {
    let r2 = r_l1 / (l1 * l1);
    let disc = r1 * r1 - 4.0 * r0 * r2;
    if !(disc >= 0.0 && r1 != 0.0) {
        return None;
    }
    let root = 2.0 * r0 / (-r1 - r1.signum() * disc.sqrt());
    root.is_finite().then_some(root)
}

/// [`fitted_root`] for each of several decoupled constraints (a diagonal
/// SHAKE Jacobian, whose factors hold 1/J(0)_ii: `inv_j(i)`), from the
/// residuals `r0` at λ = 0 and `r` at the first iterate λ1 (in `lambda`,
/// replaced by the roots). A constraint with λ1_i = 0 or without a real
/// root keeps λ1_i. Returns the largest move, `None` if nothing moved.
#[inline(always)]
pub(crate) fn fitted_roots(
    lambda: &mut [f64],
    r0: &[f64],
    r: &[f64],
    inv_j: impl Fn(usize) -> f64,
) -> Option<f64> {
    let mut jump = None;
    for (i, l) in lambda.iter_mut().enumerate() {
        let l1 = *l;
        if l1 != 0.0
            && let Some(root) = fitted_root(r0[i], 1.0 / inv_j(i), l1, r[i])
        {
            *l = root;
            jump = Some(jump.unwrap_or(0.0f64).max((root - l1).abs()));
        }
    }
    jump
}

/// [`quadratic_root`] on the slice path, at q̃ = `ws.z1` with r0 = `ws.g[0]`:
/// G(q̃) packed, w = A(−G0ᵀ), then r1 and wᵀ g_qq w in the order of the
/// fixed-size step's `slope` (the same bits).
fn first_iterate<S: ConstrainedSystem>(
    sys: &S,
    h: f64,
    ws: &mut Workspace,
) -> Option<(f64, f64, f64)> {
    let d = ws.d;
    let cl = &mut ws.classical;
    let at = (&cl.pattern[..], cl.whole);
    packed_jacobian(sys, &ws.z1[..d], &ws.z0[d..], at, &mut ws.g_z_1, &mut cl.g1);
    cl.v.fill(0.0);
    for (&(_, k), g) in cl.pattern.iter().zip(&cl.g0) {
        cl.v[k] = -g;
    }
    sys.grad_p(&ws.z0[..d], &cl.v, &mut cl.w);
    let mut jv = 0.0;
    for (&(_, k), g) in cl.pattern.iter().zip(&cl.g1) {
        jv += g * cl.w[k];
    }
    let mut whw = 0.0;
    for &(j, k, x) in &cl.g_qq {
        whw += cl.w[j] * x * cl.w[k];
    }
    quadratic_root(h, ws.g[0], h * jv, whw)
}

/// One classical SHAKE step in place (module docs): (q, p) = z0 ∈ M
/// becomes z1⁻, added as an increment (with Kahan's carry in runs). The
/// final λ is in `ws.lambda`, and r = g(z1⁻) in `ws.g`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn shake_step<S: ConstrainedSystem>(
    sys: &S,
    (a, b): (f64, f64),
    h: f64,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    opts: &NewtonOptions,
    carry: Option<&mut [f64]>,
) -> Result<ShakeReport, StepError> {
    let (d, m) = (ws.d, ws.m);
    ws.z0[..d].copy_from_slice(q);
    ws.z0[d..].copy_from_slice(p);
    ws.lambda.fill(0.0);
    // The first kick and G0.
    sys.grad_q(q, p, &mut ws.classical.hq);
    for k in 0..d {
        ws.classical.kick[k] = -(a * h) * ws.classical.hq[k];
    }
    let cl = &mut ws.classical;
    packed_jacobian(
        sys,
        q,
        p,
        (&cl.pattern, cl.whole),
        &mut ws.g_z_y,
        &mut cl.g0,
    );
    // The round-off level of each g_i near q0: what rounding q to its
    // last bit changes it by, ε Σ_k |∂g_i/∂q_k| |q_k|. (Not more: the
    // momenta come out of λ divided by h, so a residual left 4 times above
    // this shows in p as 4 times the round-off of a converged step.)
    // In the same pass over G0, ‖∂g_i/∂z‖₁: the scale of the guard's test
    // that the new state is on M (`check_and_project`).
    cl.floor.fill(0.0);
    ws.g_size.fill(0.0);
    for (&(i, k), &g) in cl.pattern.iter().zip(&cl.g0) {
        cl.floor[i] += f64::EPSILON * (g * q[k]).abs();
        ws.g_size[i] += g.abs();
    }
    residual(sys, h, ws, true);
    let mut report = ShakeReport::default();
    let diagonal = ws.jac_band.lower == 0 && ws.jac_band.upper == 0;
    let mut mon = Monitor::new(*opts);
    if m <= CHEAP_REFRESH_M {
        mon = mon.refresh_beyond(REFRESH_HORIZON);
    }
    let mut fresh = true;
    let mut need_jacobian = true;
    let mut r_first = 0.0;
    let not_finite =
        |iterations| StepError::from_solve(Stage::Shake, SolveError::NonFinite { iterations });
    // One distance constraint: the first iterate is the root of g's exact
    // quadratic along the line (`quadratic_root`), in place of the Newton
    // update and the fitted root below. At g's round-off there the
    // iteration is done; otherwise it goes on from it, with the slope r1
    // as its 1×1 Jacobian (factorised, it holds 1/r1).
    let mut solved = false;
    if m == 1 && !ws.classical.g_qq.is_empty() {
        let (r0, floor) = (ws.g[0], ws.classical.floor[0]);
        if r0.is_finite()
            && r0.abs() > floor
            && let Some((root, first, r1)) = first_iterate(sys, h, ws)
        {
            r_first = r0.abs();
            (ws.jac[0], ws.piv_j[0], need_jacobian) = (1.0 / r1, 0, false);
            (ws.lambda[0], ws.lambda_first[0]) = (root, first);
            mon.jump((root - first).abs());
            residual(sys, h, ws, false);
            fresh = false;
            solved = ws.g[0].abs() <= floor && all_finite(&ws.dz[..d]);
        }
    }
    loop {
        if solved {
            break;
        }
        let r = norm_inf(&ws.g);
        // (norm_inf skips NaN: look at every entry.)
        if !(r.is_finite() && all_finite(&ws.g) && all_finite(&ws.dz[..d])) {
            return Err(not_finite(mon.iterations));
        }
        // The residual at round-off: no update can bring q1 closer to M.
        // λ is still off by J⁻¹ r, which the momenta see divided by h, so
        // the update from this residual is taken with the Jacobian in hand
        // (none is formed for it), and then the iteration ends: the
        // confirming update (module docs).
        let at_floor = r == 0.0
            || ws
                .g
                .iter()
                .zip(&ws.classical.floor)
                .all(|(g, f)| g.abs() <= *f);
        if at_floor && (r == 0.0 || need_jacobian || mon.exhausted()) {
            break;
        }
        if mon.exhausted() {
            return Err(StepError::from_solve(
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
            // At λ = 0, once the residual is seen to need it.
            jacobian(sys, h, ws, 0)?;
            need_jacobian = false;
        }
        ws.delta.copy_from_slice(&ws.g);
        band_lu_solve(&ws.jac, m, ws.jac_band, &ws.piv_j, &mut ws.delta);
        for (l, dl) in ws.lambda.iter_mut().zip(&ws.delta) {
            *l -= dl;
        }
        let (step, size) = (norm_inf(&ws.delta), norm_inf(&ws.lambda));
        if mon.iterations == 0 {
            ws.lambda_first.copy_from_slice(&ws.lambda);
            // The round-off level of λ: the floor of g seen through J⁻¹,
            // whose size the first update shows (‖Δ₁‖/‖r(0)‖).
            mon.set_floor(step / r_first * norm_inf(&ws.classical.floor));
        }
        let verdict = mon.update_frozen(step, size, fresh);
        if diagonal && mon.iterations == 1 {
            ws.classical.r0.copy_from_slice(&ws.g);
        }
        residual(sys, h, ws, false);
        if !(step.is_finite() && size.is_finite()) {
            return Err(not_finite(mon.iterations));
        }
        if at_floor {
            break;
        }
        if diagonal && mon.iterations == 1 {
            // Decoupled constraints (one, or several whose Jacobian is
            // diagonal: r_i depends on λ_i alone): each r_i along its
            // line is a quadratic when g_i is (a distance), and its fitted
            // root (`fitted_root`) is then exact; for any other g_i it is
            // a better iterate than λ1 and the iteration goes on from it.
            // Either way the residual decides. (The factorised diagonal
            // Jacobian holds 1/J(0)_ii.)
            let inv_j = &ws.jac;
            let roots = fitted_roots(&mut ws.lambda, &ws.classical.r0, &ws.g, |i| {
                inv_j[i + i * m]
            });
            if let Some(jump) = roots {
                residual(sys, h, ws, false);
                mon.jump(jump);
                fresh = false;
                continue;
            }
        }
        // The one stopping rule of simplified Newton (`newton`): an update
        // at round-off or the noise floor ends it; a slow contraction asks
        // for a Jacobian at this iterate.
        match verdict {
            Verdict::Converged => break,
            Verdict::Continue => fresh = false,
            Verdict::Refresh => {
                jacobian(sys, h, ws, mon.iterations)?;
                fresh = true;
            }
        }
    }
    // p1 − p0 = u − b h ∇V(q1), each part a small quantity.
    if b != 0.0 {
        sys.grad_q(&ws.z1[..d], &ws.z0[d..], &mut ws.classical.hq);
    }
    for k in 0..d {
        ws.dz[d + k] = if b != 0.0 {
            ws.classical.u[k] - (b * h) * ws.classical.hq[k]
        } else {
            ws.classical.u[k]
        };
    }
    match carry {
        Some(c) => {
            let (cq, cp) = c.split_at_mut(d);
            for k in 0..d {
                kahan_add(&mut q[k], &mut cq[k], ws.dz[k]);
                kahan_add(&mut p[k], &mut cp[k], ws.dz[d + k]);
            }
        }
        None => {
            for k in 0..d {
                q[k] += ws.dz[k];
                p[k] += ws.dz[d + k];
            }
        }
    }
    report.iterations = mon.iterations;
    report.lambda = norm_inf(&ws.lambda);
    if mon.iterations > 0 {
        report.lambda_predicted = norm_inf(&ws.lambda_first);
        report.lambda_correction = ws
            .lambda
            .iter()
            .zip(&ws.lambda_first)
            .fold(0.0f64, |e, (x, y)| e.max((x - y).abs()));
    }
    Ok(report)
}

/// Π in the classical case: one solve N σ = {g, H}(q, p) with the factors
/// of N at this q already in `ws.jac`/`ws.piv` (from the step's
/// nondegeneracy check), then the kick p ← p − G(q)ᵀσ. Returns ‖σ‖∞.
pub(crate) fn project<S: ConstrainedSystem>(
    sys: &S,
    q: &[f64],
    p: &mut [f64],
    ws: &mut Workspace,
) -> f64 {
    let m = ws.m;
    sys.hidden_constraints(q, p, &mut ws.hidden);
    ws.sigma.copy_from_slice(&ws.hidden);
    if m == 1 {
        ws.sigma[0] /= ws.jac[0];
    } else {
        lu_solve(&ws.jac, m, &ws.piv, &mut ws.sigma);
    }
    // The kick, through the system's closed form when it has one.
    ws.classical.v[..q.len()].copy_from_slice(q);
    if !sys.fibre_flow(&ws.sigma, &mut ws.classical.v, p).applied() {
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
            p[k] -= g * ws.sigma[i];
        }
    }
    norm_inf(&ws.sigma)
}
