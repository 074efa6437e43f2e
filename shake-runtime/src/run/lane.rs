//! A run's steps taken inside the fixed-size classical step's own frame:
//! the loop of [`Run::execute`](crate::Run::execute) for the common case,
//! where every step is one fixed-size classical substep
//! (`step::classical`) and a stored
//! state needs nothing but its Π, the observers and the push (no
//! diagnostics, one substep a step, the fast paths and fixed sizes on).
//!
//! The driver's loop reaches the substep through six calls (the step's
//! composition, the integrator, the substep map and its classical step,
//! the system's hook, the fixed-size step) and stores a state through a seventh that copies it,
//! and the state goes through memory between steps. For the pendulum the
//! layers and the record were a third of a run step's instructions, and
//! the state's trip through memory a sixth of its time (the state in
//! registers: 0.056 → 0.047 µs a step). Here the substep is called in a
//! loop that the compiler sees whole, with the system's sizes known, the
//! state lives in local arrays from step to step, and a shown state's Π
//! is written by the step straight into the state the observer sees.
//!
//! Only the loop moves, not the semantics: the same substeps (the same
//! function, so the same bits), the same guard, the same checks of a
//! stored state, the same stored states. On the first error the lane
//! stops with what the driver's loop would hold at that step (the state
//! before it where that is read, the SHAKE state of the last stored step
//! of a lazily projecting run) and hands the error to the driver, which
//! ends the run as it ends any run (`tests/suite/run_lane.rs` compares the two
//! loops state by state, and on failure, trajectory and error).

use crate::base_map::BaseMap;
use crate::error::StepError;
use crate::guard::Guard;
use crate::report::{RunSummary, StepInfo};
use crate::run::event::{StepEvent, StepObserver};
use crate::state::State;
use crate::step::classical::{fits, fixed_step, Substep};
use crate::step::map::StepMap;
use crate::system::{ConstrainedSystem, SizeVisitor};
use crate::trajectory::Trajectory;

/// A run's steps for the fixed-size substep to take in one call: steps
/// `first..=last` of size h from the state in the substep's (q, p),
/// showing (and, with `store`, storing) every `stride`-th state and the
/// last.
pub(crate) struct Lane<'a> {
    pub(crate) first: u64,
    pub(crate) last: u64,
    /// The run's observer of every step, called after each as the
    /// driver's loop calls it (`steps` = `last`).
    pub(crate) on_step: Option<&'a mut StepObserver<'a>>,
    pub(crate) stride: u64,
    pub(crate) t0: f64,
    /// A RATTLE run that steps with SHAKE and shows Π of the states it
    /// stores (the substeps are then not projected).
    pub(crate) lazy: bool,
    pub(crate) store: bool,
    pub(crate) traj: &'a mut Trajectory,
    pub(crate) observer: &'a mut dyn FnMut(u64, f64, &State),
    /// The state the observer sees.
    pub(crate) shown: &'a mut State,
    /// The state before a failing step when that step's predecessor was
    /// not stored (the run must end on it), and the SHAKE state of the
    /// last stored step of a lazy run with stride > 1 (the run replays
    /// from it on failure): the driver's `prev` and `rec`.
    pub(crate) prev: (&'a mut [f64], &'a mut [f64]),
    pub(crate) rec: (&'a mut [f64], &'a mut [f64]),
    /// In and out: the run's summary, to which every step is added.
    pub(crate) summary: &'a mut RunSummary,
    /// Out: how the lane ended. The driver reads this, not the hook's
    /// answer (which a hand-written hook could change).
    pub(crate) end: &'a mut LaneEnd,
}

/// How a lane ended (`Lane::end`).
#[derive(Clone, Debug, Default)]
pub(crate) enum LaneEnd {
    /// Never entered (a hook that answered without the runtime's
    /// fixed-size step): nothing was done, the driver runs.
    #[default]
    NotEntered,
    /// Every step taken and every state to store stored.
    Done,
    /// Step `k` failed with `error`; `last_recorded` is the last stored
    /// step.
    Failed {
        k: u64,
        last_recorded: u64,
        error: StepError,
    },
    /// The `on_step` observer ended the run after step `k`, whose state is
    /// left in (q, p), unstored unless `last_recorded` = k.
    Stopped { k: u64, last_recorded: u64 },
}

/// The steps of `lane` from (q, p), in place, each the substep
/// [`StepMap::apply`] would take (projected if `project`), when the system
/// has a fixed-size classical step and the fast paths are on. `None`: not
/// taken, no step done (the one-shot flags `n_fresh`, `show`,
/// `shown_fresh` are reset, as `apply` resets them).
#[allow(clippy::too_many_arguments)]
pub(crate) fn enter<'a, S: ConstrainedSystem, B: BaseMap>(
    map: &'a mut StepMap<B>,
    sys: &S,
    guard: &'a mut Guard,
    q: &'a mut [f64],
    p: &'a mut [f64],
    h: f64,
    project: bool,
    carry: Option<&'a mut [f64]>,
    lane: Lane<'a>,
) -> Option<Result<StepInfo, StepError>> {
    let kdk = map.classical?;
    if !(map.fast_paths && map.fixed_size) {
        return None;
    }
    (map.n_fresh, map.show, map.shown_fresh) = (false, false, false);
    let newton = *guard.newton();
    let cx = Substep {
        q,
        p,
        h,
        kdk,
        project,
        step: lane.first,
        t: lane.t0,
        newton,
        guard,
        ws: &mut map.ws,
        carry,
        show: None,
    };
    let result = sys.with_sizes(LaneVisitor { cx, lane })?;
    // As `apply` leaves it after the last substep.
    map.n_fresh = result.is_ok();
    Some(result)
}

/// One step from `z`, the substep [`StepMap::apply`] would take (projected
/// if `project`), taken by the fixed-size classical step on local arrays
/// when the system has one and the fast paths are on: `step_in_place`'s
/// fast path, without the layers between the integrator and that step and
/// without copies of the state through the integrator's buffers. On
/// success the new state is written into `z` and into `checked` (q then
/// p); on an error `z` is left as it was. Step 1 at t = h, no carry, as
/// `step_in_place` takes any step. `None`: not taken, nothing done.
pub(crate) fn single<S: ConstrainedSystem, B: BaseMap>(
    map: &mut StepMap<B>,
    sys: &S,
    guard: &mut Guard,
    z: &mut State,
    checked: &mut [f64],
    h: f64,
    project: bool,
) -> Option<Result<StepInfo, StepError>> {
    let kdk = map.classical?;
    if !(map.fast_paths && map.fixed_size) {
        return None;
    }
    (map.n_fresh, map.show, map.shown_fresh) = (false, false, false);
    let newton = *guard.newton();
    let (q, p) = (z.q.as_mut_slice(), z.p.as_mut_slice());
    let cx = Substep {
        q,
        p,
        h,
        kdk,
        project,
        step: 1,
        t: h,
        newton,
        guard,
        ws: &mut map.ws,
        carry: None,
        show: None,
    };
    let result = sys.with_sizes(SingleVisitor { cx, checked })?;
    // As `apply` leaves it after the substep.
    map.n_fresh = result.is_ok();
    Some(result)
}

/// [`single`] as a size visitor: the state copied into arrays of the
/// system's sizes, one [`fixed_step`] on them, and the result copied back.
struct SingleVisitor<'a> {
    cx: Substep<'a>,
    checked: &'a mut [f64],
}

impl<S: ConstrainedSystem> SizeVisitor<S> for SingleVisitor<'_> {
    type Output = Option<Result<StepInfo, StepError>>;
    #[inline]
    fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output {
        let SingleVisitor { mut cx, checked } = self;
        if !fits::<S, D, M>(sys, &cx) || checked.len() != 2 * D {
            return None;
        }
        let (Ok(mut q), Ok(mut p)) = (<[f64; D]>::try_from(&*cx.q), <[f64; D]>::try_from(&*cx.p))
        else {
            return None;
        };
        let (step, t) = (cx.step, cx.t);
        let info = fixed_step::<S, D, M>(sys, &mut cx, (&mut q, &mut p), step, t, None);
        if info.is_ok() {
            cx.q.copy_from_slice(&q);
            cx.p.copy_from_slice(&p);
            let (cq, cp) = checked.split_at_mut(D);
            cq.copy_from_slice(&q);
            cp.copy_from_slice(&p);
        }
        Some(info)
    }
    #[inline]
    fn dynamic(self, _: &S) -> Self::Output {
        None
    }
}

/// The lane as a size visitor ([`ConstrainedSystem::with_sizes`]): a
/// system with fixed sizes that [`fits`] gets [`run`] for them; `None`
/// (nothing done) otherwise.
struct LaneVisitor<'a> {
    cx: Substep<'a>,
    lane: Lane<'a>,
}

impl<S: ConstrainedSystem> SizeVisitor<S> for LaneVisitor<'_> {
    type Output = Option<Result<StepInfo, StepError>>;
    #[inline]
    fn fixed<const D: usize, const M: usize>(self, sys: &S) -> Self::Output {
        let LaneVisitor { mut cx, lane } = self;
        if !fits::<S, D, M>(sys, &cx) {
            return None;
        }
        Some(run::<S, D, M>(sys, &mut cx, lane))
    }
    #[inline]
    fn dynamic(self, _: &S) -> Self::Output {
        None
    }
}

/// Takes the lane's steps from (`cx.q`, `cx.p`), each one fixed-size
/// classical substep in place ([`fixed_step`], writing Π of its result into
/// the state to show, if any), and leaves the last state in (`cx.q`,
/// `cx.p`). `Ok` once every step is taken and every state to store is
/// stored ([`LaneEnd::Done`]); on the first error at step k, the error
/// ([`LaneEnd::Failed`] with k, the last stored step and the error), and
/// `prev` and `rec` as described there. Out of line (one copy per system,
/// the substep inlined in it): inlined, the loop would add its code to
/// every caller of the system's hook.
#[inline(never)]
fn run<S: ConstrainedSystem, const D: usize, const M: usize>(
    sys: &S,
    cx: &mut Substep<'_>,
    lane: Lane<'_>,
) -> Result<StepInfo, StepError> {
    let Lane {
        first,
        last,
        mut on_step,
        stride,
        t0,
        lazy,
        store,
        traj,
        observer,
        shown,
        prev,
        rec,
        summary,
        end,
    } = lane;
    let h = cx.h;
    // The state lives here, where the compiler can keep it in registers
    // from step to step, and goes back to (cx.q, cx.p) at the end.
    let (Ok(mut q), Ok(mut p)) = (<[f64; D]>::try_from(&*cx.q), <[f64; D]>::try_from(&*cx.p))
    else {
        // (The fixed-size step checked the lengths.)
        return Err(StepError::InvalidInput {
            what: "state length differs from the system's fixed size",
            value: cx.q.len() as f64,
        });
    };
    let mut last_recorded = first - 1;
    // Steps to the next multiple of the stride (a division per step is
    // a visible part of a small system's step).
    let mut to_stride = stride - last_recorded % stride;
    let mut info = StepInfo::default();
    for k in first..=last {
        let t = t0 + k as f64 * h;
        // What the driver keeps before step k (`Run::execute`).
        if last_recorded != k - 1 {
            prev.0.copy_from_slice(&q);
            prev.1.copy_from_slice(&p);
        } else if lazy && stride > 1 {
            rec.0.copy_from_slice(&q);
            rec.1.copy_from_slice(&p);
        }
        to_stride -= 1;
        let on_stride = to_stride == 0 || k == last;
        let show = (lazy && on_stride).then_some(&mut *shown);
        info = match fixed_step::<S, D, M>(sys, cx, (&mut q, &mut p), k, t, show) {
            Ok(info) => {
                summary.add(&info);
                info
            }
            Err(e) => return Err(fail(end, k, last_recorded, e.at(k, t))),
        };
        if on_stride {
            to_stride = stride;
            if !lazy {
                shown.q.as_mut_slice().copy_from_slice(&q);
                shown.p.as_mut_slice().copy_from_slice(&p);
            }
            // Π can overflow where the SHAKE state did not (the guard
            // checks that before Π): NaN or ∞ is an error at this step,
            // never a stored state (the driver's `record` check).
            let (sq, sp) = (shown.q.as_slice(), shown.p.as_slice());
            if let Err(e) = Guard::finite(sq, sp, "projected state", k, t) {
                return Err(fail(end, k, last_recorded, e));
            }
            observer(k, t, shown);
            if store {
                traj.push(k, shown.q.as_slice(), shown.p.as_slice());
            }
            last_recorded = k;
        }
        if let Some(f) = on_step.as_deref_mut() {
            let event = StepEvent {
                step: k,
                steps: last,
                t,
                info,
            };
            if f(&event).is_break() {
                *end = LaneEnd::Stopped { k, last_recorded };
                cx.q.copy_from_slice(&q);
                cx.p.copy_from_slice(&p);
                return Ok(info);
            }
        }
    }
    *end = LaneEnd::Done;
    cx.q.copy_from_slice(&q);
    cx.p.copy_from_slice(&p);
    Ok(info)
}

/// Records the failure of step k in `end` and returns its error.
#[cold]
fn fail(end: &mut LaneEnd, k: u64, last_recorded: u64, error: StepError) -> StepError {
    *end = LaneEnd::Failed {
        k,
        last_recorded,
        error: error.clone(),
    };
    error
}
