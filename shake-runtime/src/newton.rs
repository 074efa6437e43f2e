//! Newton iterations to round-off, and the rule that stops them.
//!
//! Every implicit equation of the runtime (the stage equations of implicit
//! base maps, SHAKE's equation for λ, RATTLE's equation for σ, the projection
//! of initial data) is solved by Newton's method *to round-off*: the
//! geometric properties of SHAKE and RATTLE (presymplecticity, symmetry,
//! g = 0 after every step) hold exactly for the exact solution of these
//! equations, so a loose tolerance would show up as drift.
//!
//! # Stopping rule
//!
//! There is no fixed tolerance on the residual. After each update Δ of the
//! unknown x, the iteration stops when
//!
//! 1. ‖Δ‖ ≤ `step_tolerance` · ‖x‖ (default 4ε: the update no longer changes
//!    x beyond its last bits), or Δ = 0 or the residual is exactly 0; or
//! 2. *stagnation*: ‖Δ‖ did not at least halve compared with the previous
//!    update while already ‖Δ‖ ≤ `stagnation_threshold` · max(‖x‖, 1)
//!    (default 1e-6): the iteration is now driven by rounding noise, and more
//!    iterations cannot improve x.
//!
//! Newton converges quadratically, so both happen within one or two
//! iterations of the first one at round-off. Simplified Newton may also
//! stop one update earlier, when the contraction shows that the update
//! rule 1 waits for would be below its tolerance (rule 3, "Stopping on
//! the contraction" below). If none happens within
//! `max_iterations`, the step fails with a typed error carrying the residual.
//!
//! # Simplified Newton
//!
//! SHAKE keeps its Jacobian from the start of a step (evaluated at λ = 0)
//! instead of evaluating it at every iterate: a *simplified* Newton method.
//! It converges linearly, with a ratio of the order of the Jacobian's
//! change over the step (O(‖λ‖) = O(h)) — in practice one or two more
//! iterations, each far cheaper. Its stopping rule
//! (`Monitor::update_frozen`) keeps rule 1, and keeps iterating while the
//! updates at least quarter (fast linear contraction). Any other update
//! asks the caller for a Jacobian at the current iterate: a slowing
//! contraction and rounding noise cannot be told apart from the update
//! sizes alone (with a 1e-6 stagnation threshold, a contraction ratio that
//! drifts from 0.2 to 0.3 near 1e-8 would otherwise be taken for the noise
//! floor and stop there), and an update made with a fresh Jacobian that
//! does not quarter is Newton's own pre-asymptotic phase, where a Jacobian
//! per iterate is what converges. Stagnation (rule 2) is accepted with a
//! fresh Jacobian, or once a Jacobian has been evaluated in the quadratic
//! regime (a fresh update, or an update before a refresh, already below
//! the stagnation threshold): from there on a stale Jacobian differs from a
//! fresh one by O(update), and a non-contracting update is noise. The
//! result is as close to round-off as plain Newton's, and the noise floor
//! is recognised without a coin toss on every refresh.
//!
//! # Stopping on the contraction
//!
//! Rule 1 stops on an update that no longer changes x, so the last update
//! of an iteration only confirms the iterate before it: a residual, a
//! solve, sometimes a Jacobian, for nothing. Simplified Newton predicts it
//! instead (Hairer & Wanner, *Solving ODEs II*, IV.8; Deuflhard): with
//! θ = ‖Δ_k‖/‖Δ_{k−1}‖, the error left in x after a frozen Jacobian's
//! update is about θ/(1 − θ) ‖Δ_k‖, and after an update with a fresh one
//! (Newton proper, e_k ≈ C e_{k−1}², e_{k−1} ≈ ‖Δ_k‖, C at most
//! ‖Δ_k‖/‖Δ_{k−1}‖²) about θ² ‖Δ_k‖. Rule 3 stops when that estimate is
//! below 4ε‖x‖ (`step_tolerance`, not a caller's floor: the error left
//! must be the one rule 1 accepts), for a contraction θ < ½ of updates
//! already below the stagnation threshold, so that x is at round-off as
//! by rule 1. The same θ² is the rate at which a Jacobian kept after a
//! fresh update goes on contracting (its error is the size of that
//! update), which is what the refresh horizon below is judged by. An
//! update that follows a caller's jump to a closed-form root
//! (`Monitor::jump`) has no rate: its ratio to the jump says how good the
//! root was, not how fast the Jacobian contracts, and neither use is made
//! of it.
//!
//! A caller that knows the round-off level of x itself (classical SHAKE:
//! the floor of g seen through J⁻¹, `Monitor::set_floor`) stops on an
//! update below it as on rule 1; a caller that moves x by a closed-form
//! root between updates records it with `Monitor::jump`. Every SHAKE
//! kernel (the general one and the classical ones, slice and fixed-size)
//! stops by this one rule.
//!
//! # Cheap Jacobians
//!
//! Where the Jacobian costs about as much as a residual (classical SHAKE:
//! G(q1) A G0ᵀ, one more evaluation of g_q), a contraction that merely
//! quarters is too slow to keep: two circles stepped at h|p|/r ≈ 0.3
//! contract at θ ≈ 0.2 and took 13–20 updates per step, where Newton's
//! quadratic convergence with a fresh Jacobian per update takes a few.
//! Such a caller sets a horizon k (`Monitor::refresh_beyond`): the frozen
//! Jacobian is kept only while ‖Δ‖ θ^k (θ² after a fresh update, above),
//! the update its contraction would reach k updates on, is below the
//! tolerance; otherwise a fresh one is asked for. Small steps, where θ is
//! 10⁻³ or less, keep theirs.
//!
//! # Iterations judged by their residual
//!
//! The particle path's solves (each cluster's SHAKE, the coupled solve of
//! a chain) know a relative tolerance for the residual itself, |g_i| /
//! (|∇g_i| · extent_i) ≤ tol, and judge iterates by it. The caller decides
//! convergence (where the scale is taken is its own); `Residuals` says
//! what a residual still above the tolerance means: non-finite, the
//! budget spent or a millionfold growth over the first residual (a
//! diverging iteration, stopped before the budget), both `NotConverged`;
//! otherwise a contraction slower than ½ per iteration (the residual is
//! linear in g) asks a simplified Newton for a fresh Jacobian.
//!
//! A tolerance can lie below what the coordinates can resolve: each
//! coordinate x of a converged iterate is rounded by up to ε|x|, which
//! moves a member's relative residual by up to ε ‖x_member‖ / extent (a
//! bond of length 1 at 10⁵ from the origin: ≈ 1e-11, above a tolerance of
//! 1e-12). There the residual stops going down and wanders at that level
//! whatever the iteration does, or creeps down without reaching the
//! tolerance: once the update along the large coordinates is below half
//! their ulp it is lost, and only the member's small coordinates move, each
//! iteration removing the share of g their part of ∇g carries (a dimer at
//! 10⁴ turned 1° off an axis: a few 1e-4 of the residual per iteration, so
//! the budget ran out at 1.1e-12). An iterate whose residual did not at
//! least halve (a Newton iteration in its quadratic or fast linear regime
//! does, so this is rounding, not progress) and whose every member is
//! within the tolerance or its own round-off floor (the caller's test,
//! `tolerance::roundoff_floor`) is accepted as `RoundOff`: converged as
//! far as f64 can tell, its residual reported as it is. An iterate still
//! halving its residual, or with a member above both its tolerance and its
//! floor, is never stopped by this rule.
//!
//! # Polish
//!
//! Rule 1 judges an update against x, not the residual against its own
//! round-off, and the two part where x is large or the equation
//! ill-conditioned: on a periodic fibre Newton may settle at σ ≈ 10³,
//! where an update of 10⁻¹⁴ is lost in the rounding of σ + Δσ while the
//! residual it was meant to remove is 10⁵ times its round-off. A caller
//! that can tell whether its residual is at round-off asks `Polish`
//! after rule 1 or 2: up to a budget of further iterations are spent while
//! they lower the residual, and one that does not is undone.

/// Tolerances and limits of every Newton iteration of a step.
///
/// ```
/// use geoshake_runtime::NewtonOptions;
/// let opts = NewtonOptions { max_iterations: 30, ..NewtonOptions::default() };
/// assert_eq!(opts.step_tolerance, 4.0 * f64::EPSILON);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct NewtonOptions {
    /// Stop when ‖Δx‖ ≤ `step_tolerance` · ‖x‖ (default 4ε).
    pub step_tolerance: f64,
    /// Stagnation is only accepted once ‖Δx‖ ≤ `stagnation_threshold` ·
    /// max(‖x‖, 1) (default 1e-6).
    pub stagnation_threshold: f64,
    /// Iterations before the step fails with
    /// [`StepError::NewtonNotConverged`](crate::StepError::NewtonNotConverged)
    /// (default 50).
    pub max_iterations: usize,
}

impl Default for NewtonOptions {
    fn default() -> Self {
        NewtonOptions {
            step_tolerance: 4.0 * f64::EPSILON,
            stagnation_threshold: 1e-6,
            max_iterations: 50,
        }
    }
}

/// What the stopping rule says after an update.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Verdict {
    Continue,
    Converged,
    /// Simplified Newton only: the iteration contracts too slowly with the
    /// Jacobian it has; evaluate a fresh one at the current iterate.
    Refresh,
}

/// Tracks the size of successive updates of one Newton iteration and applies
/// the stopping rule of the module docs.
#[derive(Copy, Clone, Debug)]
pub(crate) struct Monitor {
    opts: NewtonOptions,
    prev_step: f64,
    /// Simplified Newton: a Jacobian was evaluated in the quadratic regime
    /// (where the updates were already below the stagnation threshold).
    jacobian_near: bool,
    /// The round-off level of x, when the caller knows it (0 otherwise).
    floor: f64,
    /// The previous step was a [`jump`](Self::jump): the next update's
    /// ratio to it is no contraction rate.
    after_jump: bool,
    /// Simplified Newton whose Jacobian costs about a residual: keep a
    /// frozen Jacobian only while its contraction reaches the tolerance
    /// within this many more updates (`None`: whenever it quarters).
    horizon: Option<i32>,
    pub(crate) iterations: usize,
}

impl Monitor {
    pub(crate) fn new(opts: NewtonOptions) -> Self {
        Monitor {
            opts,
            prev_step: f64::INFINITY,
            jacobian_near: false,
            floor: 0.0,
            after_jump: false,
            horizon: None,
            iterations: 0,
        }
    }

    /// For a Jacobian about as cheap as a residual (classical SHAKE, where
    /// it is G(q1) A G0ᵀ from one more evaluation of g_q): a frozen
    /// Jacobian contracting at θ = ‖Δ_k‖/‖Δ_{k−1}‖ is kept only if
    /// ‖Δ_k‖ θ^`updates` is below the tolerance, else a fresh one is asked
    /// for (module docs, "Cheap Jacobians").
    pub(crate) fn refresh_beyond(mut self, updates: i32) -> Self {
        self.horizon = Some(updates);
        self
    }

    /// An update no larger than `floor` is at round-off (rule 1): the
    /// caller's estimate of the rounding level of x.
    pub(crate) fn set_floor(&mut self, floor: f64) {
        self.floor = floor;
    }

    /// The caller moved x by `step` to a closed-form root instead of an
    /// update of this iteration: it counts as an iteration and as the
    /// previous update, and the next update is judged against it.
    pub(crate) fn jump(&mut self, step: f64) {
        self.iterations += 1;
        self.prev_step = step;
        self.after_jump = true;
    }

    /// Called after each update with ‖Δx‖ and the updated ‖x‖ (∞-norms).
    pub(crate) fn update(&mut self, step: f64, x: f64) -> Verdict {
        self.iterations += 1;
        let prev = self.prev_step;
        self.prev_step = step;
        if step <= self.opts.step_tolerance * x {
            return Verdict::Converged;
        }
        if step > 0.5 * prev && step <= self.opts.stagnation_threshold * x.max(1.0) {
            return Verdict::Converged;
        }
        Verdict::Continue
    }

    /// [`update`](Self::update) for simplified Newton: `fresh` says whether
    /// the Jacobian that gave this update was evaluated at the iterate it
    /// was applied to. [`Verdict::Refresh`] asks for a Jacobian at the
    /// current iterate. See the module docs.
    pub(crate) fn update_frozen(&mut self, step: f64, x: f64, fresh: bool) -> Verdict {
        self.iterations += 1;
        let prev = self.prev_step;
        self.prev_step = step;
        let after_jump = std::mem::take(&mut self.after_jump);
        let target = (self.opts.step_tolerance * x).max(self.floor);
        if step <= target {
            return Verdict::Converged;
        }
        let tiny = step <= self.opts.stagnation_threshold * x.max(1.0);
        self.jacobian_near |= fresh && tiny;
        // Rule 2, trusted once a Jacobian from the quadratic regime is in
        // use: a non-contracting update is then noise.
        if step > 0.5 * prev && tiny && (fresh || self.jacobian_near) {
            return Verdict::Converged;
        }
        // θ = 0 after the first update (prev = ∞): nothing to judge by.
        let theta = step / prev;
        // The rate a frozen Jacobian goes on contracting at: θ, or θ² after
        // an update made with a fresh one (module docs, "Stopping on the
        // contraction"). After a jump to a closed-form root θ is no rate:
        // the jump removed most of an error the frozen Jacobian would not.
        let rate = if fresh && !after_jump {
            theta * theta
        } else {
            theta
        };
        // Rule 3: the error left in x, estimated from the contraction, is
        // already below rule 1's tolerance; the update that would confirm
        // it is not taken.
        if tiny && !after_jump && theta > 0.0 && theta < 0.5 {
            let left = if fresh {
                rate * step
            } else {
                theta / (1.0 - theta) * step
            };
            if left <= self.opts.step_tolerance * x {
                return Verdict::Converged;
            }
        }
        if step <= 0.25 * prev && self.horizon.is_none_or(|k| step * rate.powi(k) <= target) {
            return Verdict::Continue;
        }
        // The Jacobian the caller evaluates now is at an iterate whose
        // update was already tiny: it is from the quadratic regime.
        self.jacobian_near |= tiny;
        Verdict::Refresh
    }

    /// True once the iteration budget is spent.
    pub(crate) fn exhausted(&self) -> bool {
        self.iterations >= self.opts.max_iterations
    }
}

/// What [`Residuals::judge`] says of an iterate whose residual is above
/// the tolerance.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Rate {
    /// The residual at least halved since the previous iterate.
    Fast,
    /// It did not: a simplified Newton should evaluate its Jacobian here.
    Slow,
    /// The residual did not at least halve and is within its round-off
    /// floor: converged as far as the coordinates resolve (module docs).
    RoundOff,
    /// The residual is NaN or infinite.
    NonFinite,
    /// The budget is spent, or the residual has grown a millionfold over
    /// the first one.
    NotConverged,
}

impl Rate {
    /// Whether the contraction is slow; `None` when the iteration failed.
    /// (`RoundOff` is not asked here: the caller accepts the iterate.)
    #[inline(always)]
    pub(crate) fn slow(self) -> Option<bool> {
        match self {
            Rate::Fast => Some(false),
            Rate::Slow | Rate::RoundOff => Some(true),
            Rate::NonFinite | Rate::NotConverged => None,
        }
    }
}

/// The rule of the iterations judged by their residual (module docs).
#[derive(Copy, Clone, Debug)]
pub(crate) struct Residuals {
    max_iterations: usize,
    first: f64,
    prev: f64,
}

/// Growth of the residual over the first one at which an iteration counts
/// as diverging.
const DIVERGENCE: f64 = 1e6;

impl Residuals {
    pub(crate) fn new(max_iterations: usize) -> Self {
        Residuals {
            max_iterations,
            first: f64::NAN,
            prev: f64::INFINITY,
        }
    }

    /// `worst`, the largest relative residual of the iterate after
    /// `updates` updates, is above the tolerance: what to do.
    /// `at_roundoff` says whether every member's residual is within the
    /// tolerance or the round-off floor of its coordinates (asked only
    /// when the residual did not at least halve).
    #[inline(always)]
    pub(crate) fn judge(
        &mut self,
        worst: f64,
        updates: usize,
        at_roundoff: impl FnOnce() -> bool,
    ) -> Rate {
        if !worst.is_finite() {
            return Rate::NonFinite;
        }
        if updates == 0 {
            self.first = worst;
        }
        // A stall is a residual that did not halve, not only one that did
        // not go down: at round-off the iterate can creep down by a few
        // 1e-4 per update for ever (module docs), and a residual within
        // the floor is all the coordinates can resolve.
        let slow = worst > 0.5 * self.prev;
        if slow && at_roundoff() {
            return Rate::RoundOff;
        }
        if updates >= self.max_iterations || worst > DIVERGENCE * self.first {
            return Rate::NotConverged;
        }
        self.prev = worst;
        if slow {
            Rate::Slow
        } else {
            Rate::Fast
        }
    }
}

/// What [`Polish::judge`] says about a converged iteration.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Finish {
    /// Keep the iterate: its residual is at round-off, the budget is
    /// spent, or this is the unpolished result.
    Done,
    /// The last polishing iteration did not lower the residual: bring
    /// back the iterate from before it.
    Undo,
    /// Keep the iterate as the one to come back to, and iterate again.
    Again,
}

/// The polish after convergence (see the module docs): at most `budget`
/// further iterations, each kept only if it lowers the residual.
#[derive(Copy, Clone, Debug)]
pub(crate) struct Polish {
    left: u32,
    /// The residual of the iterate kept before the current polishing
    /// iteration (`None` before the first).
    from: Option<f64>,
}

impl Polish {
    pub(crate) fn new(budget: u32) -> Self {
        Polish {
            left: budget,
            from: None,
        }
    }

    /// Whether a polishing iteration is under way.
    pub(crate) fn active(&self) -> bool {
        self.from.is_some()
    }

    /// The iteration converged with residual `r`; `at_roundoff` says
    /// whether that residual is at its round-off (asked only when it
    /// matters).
    pub(crate) fn judge(&mut self, r: f64, at_roundoff: impl FnOnce() -> bool) -> Finish {
        if let Some(from) = self.from
            && !(r < from)
        {
            return Finish::Undo;
        }
        if self.left == 0 || at_roundoff() {
            return Finish::Done;
        }
        self.left -= 1;
        self.from = Some(r);
        Finish::Again
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn residuals_ask_for_a_jacobian_when_the_contraction_slows_and_stop_on_divergence() {
        let mut r = Residuals::new(5);
        // The first iterate is never slow; halving or better is fast.
        assert_eq!(r.judge(1.0, 0, || false), Rate::Fast);
        assert_eq!(r.judge(0.5, 1, || false), Rate::Fast);
        assert_eq!(r.judge(0.3, 2, || false), Rate::Slow);
        assert_eq!(r.judge(f64::NAN, 3, || false), Rate::NonFinite);
        assert_eq!(r.judge(f64::INFINITY, 3, || false), Rate::NonFinite);
        // The budget: 5 updates done and still above the tolerance.
        assert_eq!(r.judge(1e-3, 5, || false), Rate::NotConverged);
        // A millionfold growth over the first residual, within the budget.
        let mut r = Residuals::new(50);
        assert_eq!(r.judge(2.0, 0, || false), Rate::Fast);
        assert_eq!(r.judge(1.9e6, 1, || false), Rate::Slow);
        assert_eq!(r.judge(2.1e6, 2, || false), Rate::NotConverged);
    }

    #[test]
    fn residuals_accept_a_stall_only_at_round_off() {
        let mut r = Residuals::new(50);
        assert_eq!(r.judge(1e-6, 0, || true), Rate::Fast);
        // Halving: never stopped by the floor (not even asked).
        assert_eq!(r.judge(0.4e-6, 1, || unreachable!()), Rate::Fast);
        // Not down, but some member above both tolerance and floor.
        assert_eq!(r.judge(0.4e-6, 2, || false), Rate::Slow);
        // Going down, but slower than halving, with some member above both:
        // never stopped by the floor.
        assert_eq!(r.judge(0.39e-6, 3, || false), Rate::Slow);
        // Not down and every member at its floor: accepted.
        assert_eq!(r.judge(0.4e-6, 4, || true), Rate::RoundOff);
        // Creeping down by a few 1e-4 per update at the floor (the large
        // coordinates frozen, the small ones absorbing the update): a stall
        // as well, accepted at once rather than when the budget is spent.
        let mut r = Residuals::new(50);
        assert_eq!(r.judge(1.1291e-12, 0, || true), Rate::Fast);
        assert_eq!(r.judge(1.1287e-12, 1, || true), Rate::RoundOff);
        // The same creep with a member above its floor still fails once
        // the budget is spent.
        let mut r = Residuals::new(3);
        for (k, g) in [1.1291e-12, 1.1287e-12, 1.1283e-12].into_iter().enumerate() {
            assert_ne!(r.judge(g, k, || false), Rate::NotConverged);
        }
        assert_eq!(r.judge(1.1279e-12, 3, || false), Rate::NotConverged);
        // A stall at round-off is accepted even with the budget spent.
        let mut r = Residuals::new(2);
        assert_eq!(r.judge(1e-12, 0, || true), Rate::Fast);
        assert_eq!(r.judge(1.1e-12, 2, || true), Rate::RoundOff);
        // The floor test is not asked while the residual goes down.
        let mut r = Residuals::new(50);
        assert_eq!(r.judge(1.0, 0, || unreachable!()), Rate::Fast);
        assert_eq!(r.judge(0.1, 1, || unreachable!()), Rate::Fast);
    }

    #[test]
    fn newton_for_sqrt2_stops_at_round_off() {
        let mut x: f64 = 1.0;
        let mut mon = Monitor::new(NewtonOptions::default());
        loop {
            let dx = -(x * x - 2.0) / (2.0 * x);
            x += dx;
            if mon.update(dx.abs(), x.abs()) == Verdict::Converged {
                break;
            }
            assert!(!mon.exhausted());
        }
        assert!((x - 2f64.sqrt()).abs() <= f64::EPSILON * 2.0);
        assert!(mon.iterations <= 7, "{}", mon.iterations);
    }

    #[test]
    fn a_cheap_jacobian_is_refreshed_unless_its_contraction_reaches_round_off_soon() {
        // Contraction by 0.2 from 1e-2: quarters, so kept without a horizon
        // (17 more updates to 4ε); with a horizon of 3 a fresh Jacobian.
        let mut slow = Monitor::new(NewtonOptions::default());
        let mut cheap = Monitor::new(NewtonOptions::default()).refresh_beyond(3);
        for mon in [&mut slow, &mut cheap] {
            assert_eq!(mon.update_frozen(1e-2, 1.0, true), Verdict::Continue);
        }
        assert_eq!(slow.update_frozen(2e-3, 1.0, false), Verdict::Continue);
        assert_eq!(cheap.update_frozen(2e-3, 1.0, false), Verdict::Refresh);
        // Contraction by 1e-4 from 1e-8: 1e-8 · 1e-12 is below 4ε within
        // three updates, so the frozen Jacobian is kept.
        let mut cheap = Monitor::new(NewtonOptions::default()).refresh_beyond(3);
        assert_eq!(cheap.update_frozen(1e-4, 1.0, true), Verdict::Continue);
        assert_eq!(cheap.update_frozen(1e-8, 1.0, false), Verdict::Continue);
        // The floor counts as the tolerance: 1e-6 · 0.01³ is below it.
        let mut cheap = Monitor::new(NewtonOptions::default()).refresh_beyond(3);
        cheap.set_floor(1e-11);
        assert_eq!(cheap.update_frozen(1e-4, 1.0, true), Verdict::Continue);
        assert_eq!(cheap.update_frozen(1e-6, 1.0, false), Verdict::Continue);
    }

    #[test]
    fn simplified_newton_refreshes_unless_fast_and_stops_only_on_a_fresh_jacobian() {
        let mut mon = Monitor::new(NewtonOptions::default());
        // Fast linear contraction with a stale Jacobian: keep going.
        assert_eq!(mon.update_frozen(1e-3, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(1e-6, 1.0, false), Verdict::Continue);
        assert_eq!(mon.update_frozen(1e-9, 1.0, false), Verdict::Continue);
        // Contraction slowed near 1e-9: noise or a slower rate? A stale
        // Jacobian cannot tell; refresh instead of stopping.
        assert_eq!(mon.update_frozen(0.3e-9, 1.0, false), Verdict::Refresh);
        // With the fresh Jacobian the update stops shrinking: the noise floor.
        assert_eq!(mon.update_frozen(0.2e-9, 1.0, true), Verdict::Converged);

        let mut mon = Monitor::new(NewtonOptions::default());
        assert_eq!(mon.update_frozen(1e-3, 1.0, true), Verdict::Continue);
        // Slow contraction with a stale Jacobian: refresh.
        assert_eq!(mon.update_frozen(0.6e-3, 1.0, false), Verdict::Refresh);
        assert_eq!(mon.update_frozen(0.5e-6, 1.0, true), Verdict::Continue);
        // Tiny and barely shrinking, but the Jacobian is stale: refresh.
        assert_eq!(mon.update_frozen(0.2e-6, 1.0, false), Verdict::Refresh);
        // A fresh Jacobian whose update does not quarter: Newton's own
        // pre-asymptotic phase, a Jacobian per iterate.
        assert_eq!(mon.update_frozen(0.7e-3, 1.0, true), Verdict::Refresh);
        assert_eq!(mon.update_frozen(0.6e-6, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(0.5e-6, 1.0, true), Verdict::Converged);
        // Rule 1 holds whatever the Jacobian.
        assert_eq!(mon.update_frozen(1e-17, 1.0, false), Verdict::Converged);

        // Noise after a fresh Jacobian took the updates below the threshold:
        // a stale non-contracting update is accepted as the floor.
        let mut mon = Monitor::new(NewtonOptions::default());
        assert_eq!(mon.update_frozen(1e-3, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(1e-6, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(1e-10, 1.0, false), Verdict::Continue);
        assert_eq!(mon.update_frozen(0.9e-10, 1.0, false), Verdict::Converged);
    }

    #[test]
    fn a_contraction_that_puts_the_next_update_below_the_tolerance_stops() {
        // Fresh Jacobians: 2.3e-5 then 2.3e-10 (θ = 1e-5). The error left
        // is about θ² · 2.3e-10 = 2.3e-20, below 4ε: no confirming update.
        let mut mon = Monitor::new(NewtonOptions::default());
        assert_eq!(mon.update_frozen(7.3e-3, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(2.3e-5, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(2.3e-10, 1.0, true), Verdict::Converged);
        // A frozen Jacobian contracting by 1e-5: θ/(1 − θ) · 2e-10 = 2e-15
        // is above 4ε, one more update; then 2e-20.
        let mut mon = Monitor::new(NewtonOptions::default());
        assert_eq!(mon.update_frozen(2e-5, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(2e-10, 1.0, false), Verdict::Continue);
        assert_eq!(mon.update_frozen(2e-15, 1.0, false), Verdict::Converged);
        // Not before the updates are tiny, however fast the contraction.
        let mut mon = Monitor::new(NewtonOptions::default());
        assert_eq!(mon.update_frozen(1.0, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(1e-5, 1.0, true), Verdict::Continue);
    }

    #[test]
    fn after_a_fresh_update_the_frozen_jacobian_is_judged_by_the_square_of_its_ratio() {
        // A fresh update of 2.3e-5 after 7.3e-3 (θ = 3e-3): a Jacobian kept
        // from here contracts at about θ² = 1e-5, which reaches 4ε within
        // 3 updates; judged by θ it would not (2.3e-5 · (3e-3)³ = 6e-13).
        let mut mon = Monitor::new(NewtonOptions::default()).refresh_beyond(3);
        assert_eq!(mon.update_frozen(7.3e-3, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(2.3e-5, 1.0, true), Verdict::Continue);
        // The same ratio from a frozen Jacobian: refresh.
        let mut mon = Monitor::new(NewtonOptions::default()).refresh_beyond(3);
        assert_eq!(mon.update_frozen(7.3e-3, 1.0, true), Verdict::Continue);
        assert_eq!(mon.update_frozen(2.3e-5, 1.0, false), Verdict::Refresh);
    }

    #[test]
    fn a_known_floor_is_round_off_and_a_jump_is_the_previous_update() {
        let mut mon = Monitor::new(NewtonOptions::default());
        mon.set_floor(1e-12);
        assert_eq!(mon.update_frozen(1e-3, 1.0, true), Verdict::Continue);
        // Far above 4ε·‖x‖, but at the caller's round-off level of x.
        assert_eq!(mon.update_frozen(0.9e-12, 1.0, false), Verdict::Converged);

        let mut mon = Monitor::new(NewtonOptions::default());
        mon.jump(1e-4);
        assert_eq!(mon.iterations, 1);
        // Judged against the jump: it did not quarter, so a Jacobian here.
        assert_eq!(mon.update_frozen(0.5e-4, 1.0, false), Verdict::Refresh);
        assert_eq!(mon.iterations, 2);
        // A tiny update after a jump that removed most of the error: its
        // ratio to the jump (1e-7) is no contraction rate, and rule 3 does
        // not stop on it.
        let mut mon = Monitor::new(NewtonOptions::default());
        mon.jump(1e-3);
        assert_eq!(mon.update_frozen(1e-10, 1.0, false), Verdict::Continue);
    }

    #[test]
    fn a_slow_iteration_is_not_mistaken_for_stagnation() {
        let mut mon = Monitor::new(NewtonOptions::default());
        // Steps halving exactly far above the threshold: keep going.
        assert_eq!(mon.update(1e-2, 1.0), Verdict::Continue);
        assert_eq!(mon.update(0.9e-2, 1.0), Verdict::Continue);
        // Tiny but still decreasing fast: keep going.
        assert_eq!(mon.update(1e-9, 1.0), Verdict::Continue);
        // Tiny and no longer decreasing: stagnation.
        assert_eq!(mon.update(1e-9, 1.0), Verdict::Converged);
    }
}
