//! The reverse-step check of a composed step (Section 4): take the step
//! back with −h and compare with where it started.
//!
//! Over a symmetric base map RATTLE is symmetric: R_{−γh} ∘ R_{γh} = id on
//! M^H (the paper's Section on time reversibility). SHAKE is not (S_{−h}
//! does not preserve M^{H,h}): S_{−γh} ∘ S_{γh} only returns to the
//! start's fibre. A composed step Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h} (every
//! substep but possibly the last projected, so Φ = R there) is undone by
//! the substeps in reverse order with −γ_k h, each projected exactly when
//! its forward substep was. A last substep that was a SHAKE step is undone
//! up to the fibre, which the next substep back, a RATTLE step, does not
//! see (R_{γh}(z) = R_{γh}(Π z)): with at least two stages the first
//! substep back is always followed by a projected one. For the same reason
//! the step back from a start z₀ on M but not on M^H (a lazily projected
//! run, SHAKE) returns Π z₀: that is what it is compared with.
//!
//! A substep that converged to another solution than the nearby one (a
//! branch jump: another crossing of a fibre with M or M^H) is a solution
//! of the same symmetric equations, but the step back, started at λ = 0,
//! finds the nearby solution from the new state, and that one does not
//! lead back. Near a fold of M^H where N is small, such a jump can keep
//! det N's sign and λ near its first prediction, so no other check sees it
//! (`tests/suite/hard_degenerate.rs`, `tests/suite/hard_random_systems.rs`).
//!
//! The step back runs on its own [`StepMap`] (its own workspaces) and a
//! copy of the guard, so the forward step's state (N at the new state, the
//! Kahan carry, the factors the classical path keeps) is untouched. Its substeps are held only to
//! convergence (finite, on M to round-off): the fibre-jump, component and
//! condition tests are the forward step's, and the miss is the verdict.

use crate::base_map::BaseMap;
use crate::composition::Composition;
use crate::error::StepError;
use crate::guard::Guard;
use crate::rattle::project_hidden;
use crate::step::{Composed, StepMap};
use crate::system::ConstrainedSystem;
use crate::tolerance::max_abs;

/// The step back: its own substep map and the two states.
#[derive(Clone, Debug)]
pub(crate) struct Reverse<B: BaseMap> {
    map: StepMap<B>,
    /// The step's start (q, p), then (if it was not on M^H) Π of it.
    start_q: Vec<f64>,
    start_p: Vec<f64>,
    /// The state stepped back.
    back_q: Vec<f64>,
    back_p: Vec<f64>,
    /// An estimate of the start's distance from M (see `keep_start`).
    start_off: f64,
}

impl<B: BaseMap> Composed<B> {
    /// Whether composed steps are checked by stepping back: a composition
    /// over a symmetric base map, constraints, and a finite tolerance.
    pub(crate) fn reverse_checked<S: ConstrainedSystem>(&self, sys: &S, guard: &Guard) -> bool {
        self.composition.stages() > 1
            && B::SYMMETRIC
            && sys.constraint_count() > 0
            && guard.options.reverse_tolerance.is_finite()
    }

    /// Allocates the step back's buffers (once per integrator, before the
    /// first step that needs them).
    pub(crate) fn reverse_buffers<S: ConstrainedSystem>(&mut self, sys: &S) -> &mut Reverse<B> {
        let d = sys.dof();
        let base = self.map.base;
        self.reverse.get_or_insert_with(|| Reverse {
            map: StepMap::new(sys, base),
            start_q: vec![0.0; d],
            start_p: vec![0.0; d],
            back_q: vec![0.0; d],
            back_p: vec![0.0; d],
            start_off: 0.0,
        })
    }

    /// Keeps the start of a composed step for [`reverse`](Self::reverse),
    /// and how far off M it is: a start that the constraint tolerance let
    /// through off M (initial data) is not returned to by the step back,
    /// whose states are on M; it lands about that distance away,
    /// √(2d) · max_i |g_i| / ‖∂g_i/∂z‖₁ ≥ |g_i| / ‖∇g_i‖₂.
    pub(crate) fn keep_start<S: ConstrainedSystem>(&mut self, sys: &S, q: &[f64], p: &[f64]) {
        let d = sys.dof();
        let rev = self.reverse_buffers(sys);
        rev.start_q.copy_from_slice(q);
        rev.start_p.copy_from_slice(p);
        let ws = &mut rev.map.ws;
        sys.constraints(q, p, &mut ws.g);
        sys.constraint_jacobian(q, p, &mut ws.g_z_1);
        crate::tolerance::gradient_sizes(&ws.pattern, &ws.g_z_1, &mut ws.g_size);
        rev.start_off =
            ws.g.iter()
                .zip(&ws.g_size)
                .map(|(g, s)| if *g == 0.0 { 0.0 } else { g.abs() / s })
                .fold(0.0f64, f64::max)
                * ((2 * d) as f64).sqrt();
    }

    /// The check: the composed step from the kept start to (q, p), taken
    /// back with −h, must land within `Options::reverse_tolerance` · max(‖z₀‖∞,
    /// ‖z₁‖∞) of the start (of Π of it when `start_on_mh` is false).
    /// `project` is the forward step's: whether its last substep was
    /// projected.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn reverse<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        guard: &Guard,
        h: f64,
        q: &[f64],
        p: &[f64],
        project: bool,
        start_on_mh: bool,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        let Some(rev) = self.reverse.as_mut() else {
            return Ok(());
        };
        // The step back starts from what the forward map knows of the new
        // state: N there (the guard's fold indicator compares with it) and
        // the scale of SHAKE's difference quotients.
        rev.map.ws.n.prev.copy_from_slice(&self.map.ws.n.prev);
        rev.map.ws.probe.lambda_scale = self.map.ws.probe.lambda_scale;
        // (And on the same path as the forward map, whatever the builder
        // set since the buffers were made.)
        rev.map.fast_paths = self.map.fast_paths;
        rev.map.fixed_size = self.map.fixed_size;
        // The step back is judged by where it lands, not by the checks of
        // a forward step: its λ at tiny h is round-off against round-off
        // (the fibre-jump test would refuse noise), and a jump of its own
        // shows in the miss. Only its solves must converge.
        let mut guard = guard.clone();
        guard.options.jump_ratio = f64::INFINITY;
        guard.options.check_component = false;
        guard.options.max_condition = f64::INFINITY;
        let back = Back {
            system: sys,
            composition: self.composition,
            h,
            step,
            t,
        };
        back.check(rev, &mut guard, q, p, project, start_on_mh)
    }
}

/// A composed step taken back: the system, the composition and its h, and
/// the index and time of the step checked (its errors carry them).
struct Back<'a, S> {
    system: &'a S,
    composition: Composition,
    h: f64,
    step: u64,
    t: f64,
}

impl<S: ConstrainedSystem> Back<'_, S> {
    /// The substeps of the composition in reverse order with −γ_k h, from
    /// (q, p) on `rev`'s map, against `rev`'s start.
    fn check<B: BaseMap>(
        &self,
        rev: &mut Reverse<B>,
        guard: &mut Guard,
        q: &[f64],
        p: &[f64],
        project: bool,
        start_on_mh: bool,
    ) -> Result<(), StepError> {
        let (step, t) = (self.step, self.t);
        let gammas = self.composition.coefficients();
        let last = gammas.len() - 1;
        // Relative to the state's size, plus four times the start's
        // distance from M (zero after the first step of a run: every
        // step's result is on M to round-off).
        let tolerance = guard.options.reverse_tolerance
            * max_abs(&rev.start_q, &rev.start_p).max(max_abs(q, p))
            + 4.0 * rev.start_off;
        let jump = |miss: Option<f64>, cause: Option<StepError>| StepError::BranchJump {
            step,
            t,
            miss,
            tolerance,
            cause: cause.map(Box::new),
        };
        debug_assert!(gammas.len() >= 2, "only composed steps are stepped back");
        if !start_on_mh {
            let newton = *guard.newton();
            project_hidden(
                self.system,
                &mut rev.start_q,
                &mut rev.start_p,
                &mut rev.map.ws,
                &newton,
            )
            .map_err(|e| jump(None, Some(e.at(step, t))))?;
        }
        rev.back_q.copy_from_slice(q);
        rev.back_p.copy_from_slice(p);
        for (k, &gamma) in gammas.iter().enumerate().rev() {
            rev.map
                .apply(
                    self.system,
                    guard,
                    &mut rev.back_q,
                    &mut rev.back_p,
                    -gamma * self.h,
                    project || k < last,
                    None,
                    step,
                    t,
                )
                .map_err(|e| jump(None, Some(e)))?;
        }
        let miss = rev
            .back_q
            .iter()
            .chain(&rev.back_p)
            .zip(rev.start_q.iter().chain(&rev.start_p))
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        if miss <= tolerance {
            Ok(())
        } else {
            Err(jump(Some(miss), None))
        }
    }
}
