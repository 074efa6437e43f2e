//! The classical step of one constraint on stack arrays of the system's
//! own size: what `constrained_system!` calls when it can see d at compile
//! time, m = 1, g holonomic and H separable with quadratic T.
//!
//! The map is the classical path's (the parent module): the same kick, the
//! same Newton iteration on λ, the same checks of the guard
//! (`crate::guard`) and the same Π, so it gives the same steps to
//! round-off (`tests/fast_paths.rs`; the same bits for a constraint of
//! degree ≤ 2, [`ConstrainedSystem::quadratic_constraints`], whose first
//! iterate both paths take as the root of g's exact quadratic along
//! SHAKE's line, `classical::quadratic_root`). What differs is
//! where the numbers live:
//! `[f64; D]` and scalars instead of the workspace's vectors, so that the
//! generated derivatives inline with their lengths known, the Newton
//! matrix N = G A Gᵀ and SHAKE's Jacobian are numbers (their factorisation
//! a reciprocal, the nondegeneracy check and condition estimate O(1)), and
//! nothing is copied to and from the heap. The slice path costs 0.24 µs
//! more than a hand-written step of the pendulum (8× its cost); that cost
//! was the loops over run-time lengths, the copies and the 1×1 "matrices".
//!
//! The step reaches a system through [`ConstrainedSystem::with_sizes`]: a
//! system that offers d and m as constants gets it (`Substep` is a
//! [`SizeVisitor`](crate::SizeVisitor)). A wrapper around a system (one
//! that changes any of its functions) must not forward `with_sizes` to the
//! wrapped system: this step would call the wrapped system's functions,
//! not the wrapper's.

use super::lane::Lane;
use crate::compensated::kahan_add;
use crate::error::{SolveError, Stage, StepError};
use crate::guard::Guard;
use crate::newton::NewtonOptions;
use crate::rattle::NondegeneracyCheck;
use crate::report::StepInfo;
use crate::shake::{ShakeReport, Workspace};
use crate::state::State;
use crate::system::ConstrainedSystem;

/// One substep's arguments, the visitor [`ConstrainedSystem::with_sizes`] takes:
/// the state in place, the step size, the kick fractions of the base map,
/// whether Π follows, and the integrator's guard, workspace and carry.
/// Built only by the runtime.
pub struct Substep<'a> {
    pub(crate) q: &'a mut [f64],
    pub(crate) p: &'a mut [f64],
    pub(crate) h: f64,
    pub(crate) kdk: (f64, f64),
    pub(crate) project: bool,
    pub(crate) step: u64,
    pub(crate) t: f64,
    pub(crate) newton: NewtonOptions,
    pub(crate) guard: &'a mut Guard,
    pub(crate) ws: &'a mut Workspace,
    pub(crate) carry: Option<&'a mut [f64]>,
    /// Where to write Π of the new state when `project` is false (a lazily
    /// projecting run shows it): a substep that succeeds writes it.
    pub(crate) show: Option<&'a mut State>,
    /// A run's steps to take in this call instead of one substep
    /// (`classical::lane`): the step loops here, where the system's sizes
    /// are known.
    pub(crate) lane: Option<Lane<'a>>,
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

/// The fixed-size classical step as a size visitor
/// ([`ConstrainedSystem::with_sizes`]): m = 1 takes [`substep`], two to
/// eight constraints `fixed_m::substep`; `None` (run-time sizes, or a
/// state whose length is not `D`) leaves the step to the slice path.
impl<S: ConstrainedSystem> crate::system::SizeVisitor<S> for Substep<'_> {
    type Output = Option<Result<StepInfo, StepError>>;
    #[inline]
    fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output {
        match M {
            1 => substep::<S, D>(sys, self),
            _ => super::fixed_m::substep::<S, D, M>(sys, self),
        }
    }
    #[inline]
    fn dynamic(self, _: &S) -> Self::Output {
        None
    }
}

/// One classical substep for m = 1 and d = `D` (module docs): SHAKE, the
/// guard's checks, then Π if asked; or the steps of a run's lane
/// (`Substep::lane`, `classical::lane`). `None` when the state's length
/// is not `D` (the caller takes the slice path).
#[inline]
pub fn substep<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    mut cx: Substep<'_>,
) -> Option<Result<StepInfo, StepError>> {
    if cx.q.len() != D || cx.p.len() != D || sys.constraint_count() != 1 {
        return None;
    }
    if let Some(lane) = cx.lane.take() {
        let one = |cx: &mut Substep<'_>,
                   (q, p): (&mut [f64; D], &mut [f64; D]),
                   k,
                   t,
                   show: Option<&mut State>| {
            let info;
            (*q, *p, info) = run_substep::<S, D>(sys, cx, *q, *p, k, t, show)?;
            Ok(info)
        };
        return Some(super::lane::run(&mut cx, lane, one));
    }
    let (step, t, show) = (cx.step, cx.t, cx.show.take());
    Some(in_place::<S, D>(sys, &mut cx, step, t, show))
}

/// [`run_substep`] from and into `cx.q`, `cx.p` (left as they were on an
/// error).
#[inline(always)]
fn in_place<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<StepInfo, StepError> {
    let (Ok(q0), Ok(p0)) = (<[f64; D]>::try_from(&*cx.q), <[f64; D]>::try_from(&*cx.p)) else {
        // (`substep` checked the lengths.)
        return Err(StepError::InvalidInput {
            what: "state length differs from the system's fixed size",
            value: cx.q.len() as f64,
        });
    };
    let (q, p, info) = run_substep(sys, cx, q0, p0, step, t, show)?;
    cx.q.copy_from_slice(&q);
    cx.p.copy_from_slice(&p);
    Ok(info)
}

/// The substep from (q0, p0) at step `step`, time `t`: the new state and
/// what the step did, or the first check it failed. Π of the new state
/// goes into `show` when given and the substep is not projected.
#[inline(always)]
fn run_substep<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    q0: [f64; D],
    p0: [f64; D],
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<([f64; D], [f64; D], StepInfo), StepError> {
    let (a, b) = cx.kdk;
    let h = cx.h;
    let opts = &cx.newton;
    let at = |e: StepError| e.at(step, t);
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
    let mut iterations = 0;
    let mut fresh = true;
    let mut prev = f64::INFINITY;
    let mut refreshed = false;
    let mut inv_j = f64::NAN;
    let mut lambda_noise = 0.0;
    let mut r_first = 0.0;
    let not_finite = |iterations| {
        at(StepError::from_solve(
            Stage::Shake,
            SolveError::NonFinite { iterations },
        ))
    };
    // A distance constraint: the first iterate is the root of g's exact
    // quadratic along the line, in place of the loop's Newton update and
    // fitted root (the same root, one residual fewer). At g's round-off
    // there (the loop's own test) the iteration is done; otherwise it
    // goes on from it as from that one. (Before the loop rather than in
    // its first pass: there it made the step 20 % slower.)
    let g_qq = &cx.ws.classical.g_qq;
    let mut solved = false;
    if !g_qq.is_empty() && r.is_finite() && r.abs() > floor {
        if let Some((root, first, r1)) = quadratic_root(sys, h, (&q0, &p0, &g0), &q1, r, g_qq) {
            r_first = r.abs();
            inv_j = 1.0 / r1;
            (lambda, lambda_first, iterations) = (root, first, 1);
            (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(root));
            prev = (root - first).abs();
            fresh = false;
            solved = r.abs() <= floor && dq.iter().all(|x| x.is_finite());
        }
    }
    if !solved {
        loop {
            if !r.is_finite() || !dq.iter().all(|x| x.is_finite()) {
                return Err(not_finite(iterations));
            }
            // At round-off: the confirming update (`classical::shake_step`).
            let at_floor = r == 0.0 || r.abs() <= floor;
            if at_floor && (r == 0.0 || iterations == 0 || iterations >= opts.max_iterations) {
                break;
            }
            if iterations >= opts.max_iterations {
                return Err(at(StepError::from_solve(
                    Stage::Shake,
                    SolveError::NotConverged {
                        iterations,
                        residual: r.abs(),
                    },
                )));
            }
            if iterations == 0 {
                r_first = r.abs();
                inv_j = inverse_jacobian(sys, h, &q0, &p0, &g0, &q1, 0).map_err(at)?;
            }
            let delta = r * inv_j;
            lambda -= delta;
            let (step_size, size) = (delta.abs(), lambda.abs());
            if iterations == 0 {
                lambda_first = lambda;
            }
            iterations += 1;
            let r0 = r;
            (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(lambda));
            if !(step_size.is_finite() && size.is_finite()) {
                return Err(not_finite(iterations));
            }
            if at_floor {
                break;
            }
            if iterations == 1 && lambda != 0.0 {
                // The small root of r0 + r1 λ + r2 λ², exact for a distance
                // constraint (parent module).
                let (l1, r1) = (lambda, 1.0 / inv_j);
                let r2 = r / (l1 * l1);
                let disc = r1 * r1 - 4.0 * r0 * r2;
                if disc >= 0.0 && r1 != 0.0 {
                    let root = 2.0 * r0 / (-r1 - r1.signum() * disc.sqrt());
                    if root.is_finite() {
                        lambda = root;
                        (r, u, dq, q1) = residual(sys, h, &q0, &p0, &kick, &g0, Some(lambda));
                        iterations += 1;
                        prev = (root - l1).abs();
                        fresh = false;
                        continue;
                    }
                }
            }
            if iterations == 1 {
                lambda_noise = step_size / r_first * floor;
            }
            let tol = (opts.step_tolerance * size).max(lambda_noise);
            let theta = step_size / prev;
            prev = step_size;
            if step_size <= tol {
                break;
            }
            if theta > 0.5
                && step_size <= opts.stagnation_threshold * size.max(1.0)
                && (fresh || refreshed)
            {
                break;
            }
            fresh = false;
            if theta > 0.25 {
                inv_j = inverse_jacobian(sys, h, &q0, &p0, &g0, &q1, iterations).map_err(at)?;
                fresh = true;
                refreshed |= step_size <= opts.stagnation_threshold * size.max(1.0);
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
    match cx.carry.as_deref_mut() {
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
    let mut info = StepInfo {
        shake_iterations: iterations,
        lambda: report.lambda,
        ..StepInfo::default()
    };
    // As the slice path leaves them, whether the checks below pass or not:
    // g at the new state, and the multipliers where the diagnostics read
    // them. (The state itself goes to the caller only if they pass; after
    // a failed step nothing reads it.)
    let ws = &mut *cx.ws;
    ws.g[0] = r;
    ws.lambda[0] = lambda;
    ws.lambda_first[0] = lambda_first;
    Guard::finite(&q, &p, "state", step, t)?;
    // The guard, with N = {{H,g},g} a number: its factorisation is itself,
    // its condition estimate 1/|N|.
    let guard = &mut *cx.guard;
    let scales = (
        crate::tolerance::max_abs(&q, &[]),
        crate::tolerance::max_abs(&[], &p),
    );
    let size = g0.iter().map(|x| x.abs()).sum::<f64>();
    guard.on_m(
        Stage::Shake,
        &[r],
        &[size],
        &ws.g_reads,
        scales,
        iterations,
        step,
        t,
    )?;
    let mut n = [0.0];
    sys.nondegeneracy_matrix(&q, &p, &mut n);
    let n = n[0];
    let nd = if !n.is_finite() {
        NondegeneracyCheck {
            det: f64::NAN,
            norm: n.abs(),
            inverse_norm: f64::INFINITY,
        }
    } else if n == 0.0 {
        NondegeneracyCheck {
            det: 0.0,
            norm: 0.0,
            inverse_norm: f64::INFINITY,
        }
    } else {
        NondegeneracyCheck {
            det: n,
            norm: n.abs(),
            inverse_norm: 1.0 / n.abs(),
        }
    };
    // As `read_n` and `factor_and_check` leave the workspace: N
    // factorised in `jac` (for the lazy Π of `classical::project`), N in
    // `n.mat` and `n.prev`.
    let change = (n - ws.n.prev[0]).abs();
    ws.n.prev[0] = n;
    ws.n.mat[0] = n;
    ws.jac[0] = n;
    guard.judge_shake(&nd, change, &report, &mut info, cx.project, h, step, t)?;
    if cx.project {
        (p, ws.sigma[0]) = project(sys, &q, p, n);
        info.rattle_iterations = 1;
        // (Π can overflow where SHAKE did not: `check_and_project`.)
        Guard::finite(&q, &p, "state", step, t)?;
    } else if let Some(z) = show {
        self::show(sys, &q, &p, n, &mut ws.sigma[0], z);
    }
    Ok((q, p, info))
}

/// Π of the new state into `z`, for the run to show (`Substep::show`).
/// Out of line: inlined, its registers slowed the step itself.
#[inline(never)]
fn show<S: ConstrainedSystem, const D: usize>(
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
/// The operations of `classical::project` (the slice path's lazy Π), in
/// its order.
#[inline(always)]
fn project<S: ConstrainedSystem, const D: usize>(
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
