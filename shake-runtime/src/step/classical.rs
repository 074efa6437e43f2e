//! The classical substep: SHAKE by the classical kernel
//! ([`crate::shake::classical`]), then the guard's checks of its result and,
//! if asked, Π (Section 4 of the paper; the kernel's module docs give the
//! maths). Three storages compute the same map: the slice path for any
//! classical system ([`check_and_project`] after `shake_step`), and for a
//! system that knows d and m at compile time (every `constrained_system!`)
//! stack arrays of those sizes, one constraint with N and SHAKE's Jacobian
//! as numbers (`check_one`), two to eight with N and its factors on the
//! stack (`check_few`). The same checks in the same order, so the same
//! steps (`tests/suite/fast_paths.rs`: the same bits where the kernels are).
//!
//! The sizes reach the step through [`ConstrainedSystem::with_sizes`]:
//! [`Substep`] is a [`SizeVisitor`]. A wrapper around a system (one that
//! changes any of its functions) must not forward `with_sizes` to the
//! wrapped system: this step would call the wrapped system's functions,
//! not the wrapper's.

use crate::error::{Stage, StepError};
use crate::guard::Guard;
use crate::newton::NewtonOptions;
use crate::rattle::NondegeneracyCheck;
use crate::report::StepInfo;
use crate::shake::classical::fixed::{self, Shaken};
use crate::shake::classical::{self, fixed_m};
use crate::shake::{ShakeReport, Workspace};
use crate::state::State;
use crate::system::{ConstrainedSystem, SizeVisitor};
use crate::tolerance::max_abs;

/// One substep's arguments, the visitor [`ConstrainedSystem::with_sizes`]
/// takes: the state in place, the step size, the kick fractions of the
/// base map, whether Π follows, and the integrator's guard, workspace and
/// carry. Built only by the runtime.
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
}

/// The fixed-size step as a size visitor: one substep in place on
/// (`q`, `p`). `None` (run-time sizes, or sizes the fixed-size step does
/// not take, [`fits`]) leaves the step to the slice path.
impl<S: ConstrainedSystem> SizeVisitor<S> for Substep<'_> {
    type Output = Option<Result<StepInfo, StepError>>;
    #[inline]
    fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output {
        let mut cx = self;
        if !fits::<S, D, M>(sys, &cx) {
            return None;
        }
        let (step, t, show) = (cx.step, cx.t, cx.show.take());
        if M == 1 {
            return Some(one_in_place::<S, D>(sys, &mut cx, step, t, show));
        }
        // (The state is lent to `few` apart from `cx`, which it does not
        // read it through.)
        let (q, p) = (std::mem::take(&mut cx.q), std::mem::take(&mut cx.p));
        Some(few::<S, D, M>(sys, &mut cx, (q, p), step, t, show))
    }
    #[inline]
    fn dynamic(self, _: &S) -> Self::Output {
        None
    }
}

/// Whether the fixed-size step takes `cx`'s state for d = `D`, m = `M`:
/// the state has length `D` and the system `M` constraints, 1 ≤ M ≤ 8 (the
/// sizes the macro offers).
#[inline(always)]
pub(crate) fn fits<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    cx: &Substep<'_>,
) -> bool {
    cx.q.len() == D && cx.p.len() == D && sys.constraint_count() == M && (1..=8).contains(&M)
}

/// One fixed-size substep in place on (q, p) at step `step`, time `t`, Π of
/// its result into `show` when given and the substep is not projected:
/// what a run's lane (`run::lane`) takes at every step, the state kept in
/// its arrays. For sizes that [`fits`].
#[inline(always)]
pub(crate) fn fixed_step<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    (q, p): (&mut [f64; D], &mut [f64; D]),
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<StepInfo, StepError> {
    if M == 1 {
        let z = shake_one::<S, D>(sys, cx, (*q, *p), step, t)?;
        let info;
        (*q, *p, info) = check_one::<S, D>(sys, cx, z, step, t, show)?;
        Ok(info)
    } else {
        few::<S, D, M>(sys, cx, (q, p), step, t, show)
    }
}

/// The substep for m = 1 from and into `cx.q`, `cx.p` (left as they were
/// on an error).
#[inline(always)]
fn one_in_place<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<StepInfo, StepError> {
    let (Ok(q0), Ok(p0)) = (<[f64; D]>::try_from(&*cx.q), <[f64; D]>::try_from(&*cx.p)) else {
        // (`fits` checked the lengths.)
        return Err(StepError::InvalidInput {
            what: "state length differs from the system's fixed size",
            value: cx.q.len() as f64,
        });
    };
    let z = shake_one::<S, D>(sys, cx, (q0, p0), step, t)?;
    let (q, p, info) = check_one::<S, D>(sys, cx, z, step, t, show)?;
    cx.q.copy_from_slice(&q);
    cx.p.copy_from_slice(&p);
    Ok(info)
}

/// SHAKE for m = 1 from (q0, p0), its error timed.
#[inline(always)]
fn shake_one<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    (q0, p0): ([f64; D], [f64; D]),
    step: u64,
    t: f64,
) -> Result<Shaken<D>, StepError> {
    let carry = cx.carry.as_deref_mut();
    fixed::shake::<S, D>(sys, cx.kdk, cx.h, q0, p0, cx.ws, &cx.newton, carry)
        .map_err(|e| e.at(step, t))
}

/// The substep for 2 ≤ m ≤ 8 in place on (q, p): SHAKE on the stack, then
/// [`check_few`].
#[inline(always)]
fn few<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    (q, p): (&mut [f64], &mut [f64]),
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<StepInfo, StepError> {
    let carry = cx.carry.as_deref_mut();
    let report = fixed_m::shake::<S, D, M>(sys, cx.kdk, cx.h, q, p, cx.ws, &cx.newton, carry)
        .map_err(|e| e.at(step, t))?;
    check_few::<S, D, M>(
        sys,
        q,
        p,
        cx.ws,
        cx.guard,
        &report,
        (cx.project, show),
        cx.h,
        step,
        t,
    )
}

/// The checks of a classical substep's new state (q, p) = z1⁻ (finite, on
/// M to round-off with g's scale from G0, then the guard's nondegeneracy,
/// component and fibre-jump checks, one evaluation and factorisation of N
/// at the new q), and, if `project`, Π: one linear solve with those
/// factors. The slice path's; the fixed-size steps do the same on the
/// stack (`check_few`, and `check_one` with numbers for one constraint).
#[allow(clippy::too_many_arguments)]
pub(crate) fn check_and_project<S: ConstrainedSystem>(
    sys: &S,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    guard: &mut Guard,
    report: &ShakeReport,
    project_onto_mh: bool,
    h: f64,
    step: u64,
    t: f64,
) -> Result<StepInfo, StepError> {
    let mut info = StepInfo {
        shake_iterations: report.iterations,
        shake_iterations_total: report.iterations as u64,
        lambda: report.lambda,
        ..StepInfo::default()
    };
    Guard::finite(q, p, "state", step, t)?;
    // g at the new state was the last residual of SHAKE's iteration (the
    // state is z0 + Δ, rounded once more by the addition); the tolerance's
    // scale ‖∂g_i/∂z‖₁ is G0's, at the start of the step, which the SHAKE
    // step left in `ws.g_size`.
    guard.after_shake(
        sys,
        q,
        p,
        ws,
        report,
        &mut info,
        project_onto_mh,
        h,
        step,
        t,
    )?;
    if project_onto_mh {
        // Linear in σ: one solve, no second root to jump to.
        classical::project(sys, q, p, ws);
        info.rattle_iterations = 1;
        // Π can overflow where SHAKE did not (σ = N⁻¹{g, H}): as on the
        // general path, NaN or ∞ is an error at this step.
        Guard::finite(q, p, "state", step, t)?;
    }
    Ok(info)
}

/// The checks of the m = 1 step's new state and Π, with N = {{H,g},g} a
/// number (its factorisation is itself, its condition estimate 1/|N|): the
/// slice path's checks ([`check_and_project`]) in O(1). Π of the new state
/// goes into `show` when given and the substep is not projected.
#[inline(always)]
fn check_one<S: ConstrainedSystem, const D: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    z: Shaken<D>,
    step: u64,
    t: f64,
    show: Option<&mut State>,
) -> Result<([f64; D], [f64; D], StepInfo), StepError> {
    let Shaken {
        q,
        mut p,
        r,
        g_size,
        report,
    } = z;
    let mut info = StepInfo {
        shake_iterations: report.iterations,
        shake_iterations_total: report.iterations as u64,
        lambda: report.lambda,
        ..StepInfo::default()
    };
    Guard::finite(&q, &p, "state", step, t)?;
    let (guard, ws) = (&mut *cx.guard, &mut *cx.ws);
    let scales = (
        crate::tolerance::max_abs(&q, &[]),
        crate::tolerance::max_abs(&[], &p),
    );
    guard.on_m(
        Stage::Shake,
        &[r],
        &[g_size],
        &ws.g_reads,
        scales,
        report.iterations,
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
    // factorised in `jac` (for the lazy Π of `geoshake::classical::project`), N in
    // `n.mat` and `n.prev`.
    let change = (n - ws.n.prev[0]).abs();
    ws.n.prev[0] = n;
    ws.n.mat[0] = n;
    ws.jac[0] = n;
    guard.judge_shake(&nd, change, &report, &mut info, cx.project, cx.h, step, t)?;
    if cx.project {
        (p, ws.sigma[0]) = fixed::project(sys, &q, p, n);
        info.rattle_iterations = 1;
        // (Π can overflow where SHAKE did not: `check_and_project`.)
        Guard::finite(&q, &p, "state", step, t)?;
    } else if let Some(z) = show {
        fixed::show(sys, &q, &p, n, &mut ws.sigma[0], z);
    }
    Ok((q, p, info))
}

/// [`check_and_project`] with N on the stack: the same checks
/// (finite, on M, N's condition, component and fibre jump, through the
/// guard) and the same Π, computed with the same operations in the same
/// order (`factor_n`'s kernels: the dense LU for the full band, else the
/// banded one), so the same bits;
/// but N, its factors and σ live in arrays whose sizes the compiler knows,
/// so the loops unroll and nothing is indexed through run-time lengths.
/// N's factors are left in `ws.jac`/`ws.piv`, as `factor_n` leaves them,
/// for the lazy Π (`geoshake::classical::project`) and Hager's estimate. Without
/// `project`, Π of the new state goes to `show` if given (the same solve).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn check_few<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    q: &mut [f64],
    p: &mut [f64],
    ws: &mut Workspace,
    guard: &mut Guard,
    report: &ShakeReport,
    (project, show): (bool, Option<&mut State>),
    h: f64,
    step: u64,
    t: f64,
) -> Result<StepInfo, StepError> {
    let mut info = StepInfo {
        shake_iterations: report.iterations,
        shake_iterations_total: report.iterations as u64,
        lambda: report.lambda,
        ..StepInfo::default()
    };
    Guard::finite(q, p, "state", step, t)?;
    let scales = (max_abs(q, &[]), max_abs(&[], p));
    guard.on_m(
        Stage::Shake,
        &ws.g,
        &ws.g_size,
        &ws.g_reads,
        scales,
        report.iterations,
        step,
        t,
    )?;
    let q: &[f64; D] = (&*q).try_into().expect("checked by `fits`");
    let mut n = fixed_m::StackN::<M> {
        a: [[0.0; M]; M],
        piv: [0; M],
        band: ws.n.band,
        ws,
    };
    sys.nondegeneracy_matrix(q, p, n.a.as_flattened_mut());
    let (norm, change) = n.read();
    guard.check_n(&mut n, norm, change, report, &mut info, project, h, step, t)?;
    if project {
        let fixed_m::StackN { a, piv, band, ws } = n;
        fixed_m::project_on_stack::<S, D, M>(sys, q, p, (&a, &piv, band), ws);
        info.rattle_iterations = 1;
        // (Π can overflow where SHAKE did not: [`check_and_project`].)
        Guard::finite(q, p, "state", step, t)?;
    } else if let Some(z) = show {
        let fixed_m::StackN { a, piv, band, ws } = n;
        z.q.as_mut_slice().copy_from_slice(q);
        z.p.as_mut_slice().copy_from_slice(p);
        fixed_m::project_on_stack::<S, D, M>(sys, q, z.p.as_mut_slice(), (&a, &piv, band), ws);
    }
    Ok(info)
}
