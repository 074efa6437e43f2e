//! SHAKE for one constraint on stack arrays of the system's own size: the
//! kernel of the fixed-size classical step (`step::classical`), which
//! `constrained_system!` reaches when it can see d at compile time, m = 1,
//! g holonomic and H separable with quadratic T.
//!
//! The map is the slice path's (the parent module): the same kick, the
//! same Newton iteration on λ and the same Π, so it gives the same steps
//! to round-off (`tests/suite/fast_paths.rs`; the same bits for a constraint of
//! degree ≤ 2, [`ConstrainedSystem::quadratic_constraints`], whose first
//! iterate both paths take as the root of g's exact quadratic along
//! SHAKE's line, `quadratic_root`). What differs is where the numbers
//! live: `[f64; D]` and scalars instead of the workspace's vectors, so
//! that the generated derivatives inline with their lengths known, the
//! Newton matrix N = G A Gᵀ and SHAKE's Jacobian are numbers (their
//! factorisation a reciprocal, the nondegeneracy check and condition
//! estimate O(1)), and nothing is copied to and from the heap. The slice
//! path costs 0.24 µs more than a hand-written step of the pendulum (8×
//! its cost); that cost was the loops over run-time lengths, the copies
//! and the 1×1 "matrices".

use crate::compensated::kahan_add;
use crate::error::{SolveError, Stage, StepError};
use crate::newton::{Monitor, NewtonOptions, Verdict};
use crate::shake::{ShakeReport, Workspace};
use crate::state::State;
use crate::system::ConstrainedSystem;

/// What [`shake`] hands the checks: the new state z1⁻, r = g(q1) (the
/// state's residual up to the rounding of z0 + Δ), ‖G0‖₁ (the scale of
/// the test that z1⁻ is on M) and the iteration's report.
pub(crate) struct Shaken<const D: usize> {
    pub(crate) q: [f64; D],
    pub(crate) p: [f64; D],
    pub(crate) r: f64,
    pub(crate) g_size: f64,
    pub(crate) report: ShakeReport,
}

/// SHAKE's residual along its line: q1(λ) = q0 + h A (p0 + kick − λ G0ᵀ)
/// and r = g(q1). Returns (r, u, Δq, q1), u = kick − λ G0ᵀ the momentum
/// increment before the last kick.
#[inline(always)]
fn residual<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    h: f64,
    q0: &[f64; D],
    p0: &[f64; D],
    kick: &[f64; D],
    g0: &[f64; D],
    lambda: Option<f64>,
) -> (f64, [f64; D], [f64; D], [f64; D]) {
    let mut u = *kick;
    if let Some(l) = lambda {
        // The fibre flow's kick, in the system's closed form when it has one.
        let mut y = *q0;
        if !sys.fibre_flow(&[l], &mut y, &mut u).applied() {
            for k in 0..D {
                u[k] -= g0[k] * l;
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
    let mut g = [0.0];
    sys.constraints(&q1, p0, &mut g);
    (g[0], u, dq, q1)
}

/// SHAKE's 1×1 Jacobian −h G(q1) A G0ᵀ at q1, the slope r1 = dr/dλ of
/// its residual, and w = A(−G0ᵀ), the line's direction: q1(λ) moves by
/// h w per unit λ.
#[inline(always)]
fn slope<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    h: f64,
    q0: &[f64; D],
    p0: &[f64; D],
    g0: &[f64; D],
    q1: &[f64; D],
) -> (f64, [f64; D]) {
    let mut gz = [[0.0; D]; 2];
    sys.constraint_jacobian(q1, p0, gz.as_flattened_mut());
    let mut v = [0.0; D];
    for k in 0..D {
        v[k] = -g0[k];
    }
    let mut w = [0.0; D];
    sys.grad_p(q0, &v, &mut w);
    let mut jv = 0.0;
    for k in 0..D {
        jv += gz[0][k] * w[k];
    }
    (h * jv, w)
}

/// The reciprocal of SHAKE's 1×1 Jacobian ([`slope`]) at q1, or the
/// singular-Jacobian error.
#[inline(always)]
fn inverse_jacobian<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    h: f64,
    q0: &[f64; D],
    p0: &[f64; D],
    g0: &[f64; D],
    q1: &[f64; D],
    iterations: usize,
) -> Result<f64, StepError> {
    let (j, _) = slope(sys, h, q0, p0, g0, q1);
    if j == 0.0 || !j.is_finite() {
        return Err(StepError::from_solve(
            Stage::Shake,
            SolveError::Singular { iterations },
        ));
    }
    Ok(1.0 / j)
}

/// [`super::quadratic_root`] along the line of [`slope`]: r1 = h G(q̃)·w
/// and wᵀ g_qq w from w = A(−G0ᵀ), g_qq g's constant Hessian.
#[inline(always)]
fn quadratic_root<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    h: f64,
    (q0, p0, g0): (&[f64; D], &[f64; D], &[f64; D]),
    q_tilde: &[f64; D],
    r0: f64,
    g_qq: &[(usize, usize, f64)],
) -> Option<(f64, f64, f64)> {
    let (r1, w) = slope(sys, h, q0, p0, g0, q_tilde);
    let mut whw = 0.0;
    for &(j, k, x) in g_qq {
        whw += w[j] * x * w[k];
    }
    super::quadratic_root(h, r0, r1, whw)
}

/// SHAKE for m = 1 from (q0, p0) on the stack (module docs): the new state
/// z1⁻ and what the checks read ([`Shaken`]); λ, its first iterate and r
/// left in `ws` as the slice path leaves them. The caller times the error
/// (`StepError::at`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn shake<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    (a, b): (f64, f64),
    h: f64,
    q0: [f64; D],
    p0: [f64; D],
    ws: &mut Workspace,
    opts: &NewtonOptions,
    carry: Option<&mut [f64]>,
) -> Result<Shaken<D>, StepError> {
    // The first kick and G0.
    let mut hq = [0.0; D];
    sys.grad_q(&q0, &p0, &mut hq);
    let mut kick = [0.0; D];
    for k in 0..D {
        kick[k] = -(a * h) * hq[k];
    }
    let mut gz0 = [[0.0; D]; 2];
    sys.constraint_jacobian(&q0, &p0, gz0.as_flattened_mut());
    let g0 = gz0[0];
    // g's round-off level near q0, ε Σ_k |∂g/∂q_k| |q_k| (parent module).
    let mut floor = 0.0;
    for k in 0..D {
        floor += f64::EPSILON * (g0[k] * q0[k]).abs();
    }
    let (mut r, mut u, mut dq, mut q1) = residual(sys, h, &q0, &p0, &kick, &g0, None);
    let mut lambda = 0.0f64;
    let mut lambda_first = 0.0f64;
    let mut mon = Monitor::new(*opts).refresh_beyond(super::REFRESH_HORIZON);
    let mut fresh = true;
    let mut inv_j = f64::NAN;
    let mut r_first = 0.0;
    let not_finite =
        |iterations| StepError::from_solve(Stage::Shake, SolveError::NonFinite { iterations });
    // A distance constraint: the first iterate is the root of g's exact
    // quadratic along the line, in place of the loop's Newton update and
    // fitted root (the same root, one residual fewer). At g's round-off
    // there (the loop's own test) the iteration is done; otherwise it
    // goes on from it as from that one. (Before the loop rather than in
    // its first pass: there it made the step 20 % slower.)
    let g_qq = &ws.classical.g_qq;
    let mut solved = false;
    if !g_qq.is_empty()
        && r.is_finite()
        && r.abs() > floor
        && let Some((root, first, r1)) = quadratic_root(sys, h, (&q0, &p0, &g0), &q1, r, g_qq)
    {
        r_first = r.abs();
        inv_j = 1.0 / r1;
        (lambda, lambda_first) = (root, first);
        mon.jump((root - first).abs());
        (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(root));
        fresh = false;
        solved = r.abs() <= floor && dq.iter().all(|x| x.is_finite());
    }
    if !solved {
        loop {
            if !r.is_finite() || !dq.iter().all(|x| x.is_finite()) {
                return Err(not_finite(mon.iterations));
            }
            // At round-off: the confirming update (`geoshake::classical::shake_step`).
            let at_floor = r == 0.0 || r.abs() <= floor;
            if at_floor && (r == 0.0 || mon.iterations == 0 || mon.exhausted()) {
                break;
            }
            if mon.exhausted() {
                return Err(StepError::from_solve(
                    Stage::Shake,
                    SolveError::NotConverged {
                        iterations: mon.iterations,
                        residual: r.abs(),
                    },
                ));
            }
            if mon.iterations == 0 {
                r_first = r.abs();
                inv_j = inverse_jacobian(sys, h, &q0, &p0, &g0, &q1, 0)?;
            }
            let delta = r * inv_j;
            lambda -= delta;
            let (step_size, size) = (delta.abs(), lambda.abs());
            if mon.iterations == 0 {
                lambda_first = lambda;
                // λ's round-off level (`geoshake::classical::shake_step`).
                mon.set_floor(step_size / r_first * floor);
            }
            let verdict = mon.update_frozen(step_size, size, fresh);
            let r0 = r;
            (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(lambda));
            if !(step_size.is_finite() && size.is_finite()) {
                return Err(not_finite(mon.iterations));
            }
            if at_floor {
                break;
            }
            if mon.iterations == 1
                && lambda != 0.0
                && let Some(root) = super::fitted_root(r0, 1.0 / inv_j, lambda, r)
            {
                // Exact for a distance constraint (parent module).
                mon.jump((root - lambda).abs());
                lambda = root;
                (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(lambda));
                fresh = false;
                continue;
            }
            // The one stopping rule of simplified Newton (`newton`).
            match verdict {
                Verdict::Converged => break,
                Verdict::Continue => fresh = false,
                Verdict::Refresh => {
                    inv_j = inverse_jacobian(sys, h, &q0, &p0, &g0, &q1, mon.iterations)?;
                    fresh = true;
                }
            }
        }
    }
    // p1 − p0 = u − b h ∇V(q1).
    let mut dp = u;
    if b != 0.0 {
        let mut hq = [0.0; D];
        sys.grad_q(&q1, &p0, &mut hq);
        for k in 0..D {
            dp[k] = u[k] - (b * h) * hq[k];
        }
    }
    let (mut q, mut p) = (q0, p0);
    match carry {
        Some(c) => {
            let (cq, cp) = c.split_at_mut(D);
            for k in 0..D {
                kahan_add(&mut q[k], &mut cq[k], dq[k]);
                kahan_add(&mut p[k], &mut cp[k], dp[k]);
            }
        }
        None => {
            for k in 0..D {
                q[k] += dq[k];
                p[k] += dp[k];
            }
        }
    }
    let iterations = mon.iterations;
    let report = ShakeReport {
        iterations,
        base_iterations: 0,
        lambda: lambda.abs(),
        lambda_predicted: if iterations > 0 {
            lambda_first.abs()
        } else {
            0.0
        },
        lambda_correction: if iterations > 0 {
            (lambda - lambda_first).abs()
        } else {
            0.0
        },
    };
    // As the slice path leaves them, whether the checks pass or not: g at
    // the new state, and the multipliers where the diagnostics read them.
    // (The state itself goes to the caller only if the checks pass; after
    // a failed step nothing reads it.)
    ws.g[0] = r;
    ws.lambda[0] = lambda;
    ws.lambda_first[0] = lambda_first;
    Ok(Shaken {
        q,
        p,
        r,
        g_size: g0.iter().map(|x| x.abs()).sum::<f64>(),
        report,
    })
}

/// Π of the new state into `z`, for a lazily projecting run to show.
/// Out of line: inlined, its registers slowed the step itself.
#[inline(never)]
pub(crate) fn show<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    q: &[f64; D],
    p: &[f64; D],
    n: f64,
    sigma: &mut f64,
    z: &mut State,
) {
    let shown;
    (shown, *sigma) = project(sys, q, *p, n);
    z.q.as_mut_slice().copy_from_slice(q);
    z.p.as_mut_slice().copy_from_slice(&shown);
}

/// Π at (q, p) given N = {{H,g},g} there: one solve N σ = {g, H}, then
/// the kick p ← p − σ G(q)ᵀ (the fibre flow). Returns the new p and σ.
/// The operations of `geoshake::classical::project` (the slice path's lazy Π), in
/// its order.
#[inline(always)]
pub(crate) fn project<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    q: &[f64; D],
    mut p: [f64; D],
    n: f64,
) -> ([f64; D], f64) {
    let mut hidden = [0.0];
    sys.hidden_constraints(q, &p, &mut hidden);
    let sigma = hidden[0] / n;
    let mut y = *q;
    if !sys.fibre_flow(&[sigma], &mut y, &mut p).applied() {
        let mut gz = [[0.0; D]; 2];
        sys.constraint_jacobian(q, &p, gz.as_flattened_mut());
        for k in 0..D {
            p[k] -= gz[0][k] * sigma;
        }
    }
    (p, sigma)
}
