//! The guard: every check a step must pass, in one type, run once per step
//! and configured in one place ([`Options`]).
//!
//! A step map (see [`step`](crate::step)) computes; the guard decides
//! whether its result may be kept. The checks, in the order they run:
//!
//! - **finite**: no NaN or infinity in the new state;
//! - **on M**: |g_i(z1)| at its round-off, max(64ε, Newton's step
//!   tolerance) · ‖∂g_i/∂z‖₁ · ‖z‖ (SHAKE's Newton stops on the size of
//!   its updates, so far outside its basin or with an ill-conditioned λ it
//!   can stop short of M; [`Options::constraint_tolerance`] is for the
//!   data a run starts from);
//! - **nondegeneracy** (the paper's Assumption 1.1): the condition of
//!   N_ij = {{H,g_i},g_j} relative to its size at the start stays below
//!   [`Options::max_condition`];
//! - **component**: det N keeps its sign (a sign change means the step
//!   crossed or jumped over a singular N onto another component of M^H,
//!   Section 5.4.2 case iii);
//! - **fibre jump**: the converged fibre displacement (SHAKE's λ, the
//!   projection's σ) stays within [`Options::jump_ratio`] of its own linear
//!   prediction, so Newton found the nearby crossing of the fibre.
//!
//! The guard keeps the little state these checks need across steps: ‖N‖₁
//! at the start of the run and det N at the previous state.

use crate::error::{SolveError, Stage, StepError};
use crate::linalg::all_finite;
use crate::newton::NewtonOptions;
use crate::rattle::{
    check_nondegeneracy, factor_and_check, nondegeneracy_terms, read_n, FactorN,
    NondegeneracyCheck, ProjectionReport,
};
use crate::report::StepInfo;
use crate::shake::{ShakeReport, Workspace};
use crate::system::ConstrainedSystem;
use crate::tolerance::max_abs;

pub(crate) mod membership;
mod options;

pub use options::Options;

/// The checks of [`Options`] and the state they carry from step to step.
#[derive(Clone, Debug)]
pub(crate) struct Guard {
    /// The limits, in one place.
    pub(crate) options: Options,
    /// ‖N‖₁ at the start of the run (or step): the scale the condition of
    /// N is measured against.
    reference_norm: f64,
    /// det N at the previous state (NaN before the first).
    det_prev: f64,
    /// ‖N‖₁ at the result of the last substep.
    last_norm: f64,
    /// Whether `ws.n.prev` holds N at the last checked state.
    n_prev_valid: bool,
    /// ‖N⁻¹‖₁ at the last checked state as the check used it (an
    /// estimate or a bound from one, see `inverse_bound`), and the last
    /// estimate made (m ≥ 2).
    inverse_prev: f64,
    estimated: f64,
    /// Whether a starting state's N is also judged against the size of its
    /// terms (`nondegenerate_at_start`); off only for an integrator whose
    /// starts are states another integrator has just accepted.
    pub(crate) judge_terms: bool,
}

impl Guard {
    pub(crate) fn new(options: Options) -> Self {
        Guard {
            options,
            reference_norm: f64::NAN,
            det_prev: f64::NAN,
            last_norm: f64::NAN,
            n_prev_valid: false,
            inverse_prev: f64::NAN,
            estimated: f64::NAN,
            judge_terms: true,
        }
    }

    /// ‖N‖₁ and det N at the last accepted state.
    pub(crate) fn last(&self) -> (f64, f64) {
        (self.last_norm, self.det_prev)
    }

    /// Continues from a state this guard already accepted (its ‖N‖₁ and
    /// det N), instead of evaluating and factorising N there again.
    pub(crate) fn resume(&mut self, norm: f64, det: f64) {
        self.reference_norm = norm;
        self.det_prev = det;
    }

    /// A starting state: finite, on M, N well conditioned there. Sets the
    /// reference ‖N‖₁ and det N to it.
    pub(crate) fn start<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        q: &[f64],
        p: &[f64],
        ws: &mut Workspace,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        Self::finite(q, p, "initial state", step, t)?;
        self.reference_norm = f64::NAN;
        self.det_prev = f64::NAN;
        if sys.constraint_count() == 0 {
            return Ok(());
        }
        if let Some(e) =
            membership::off_constraint(sys, q, p, ws, self.options.constraint_tolerance)
        {
            return Err(e.at(step, t));
        }
        sys.nondegeneracy_matrix(q, p, &mut ws.n.mat);
        let (norm, _) = read_n(ws, true);
        let nd = factor_and_check(ws, norm, None);
        self.n_prev_valid = true;
        self.inverse_prev = nd.inverse_norm;
        self.estimated = nd.inverse_norm;
        self.nondegenerate_at_start(sys, q, p, ws, &nd, Stage::Shake, step, t)?;
        self.reference_norm = nd.norm;
        self.det_prev = nd.det;
        Ok(())
    }

    /// No NaN or infinity in (q, p).
    #[inline]
    pub(crate) fn finite(
        q: &[f64],
        p: &[f64],
        what: &'static str,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        if all_finite(q) && all_finite(p) {
            return Ok(());
        }
        Self::not_finite(q, p, what, step, t)
    }

    /// The error of [`Self::finite`], out of the step's way.
    #[cold]
    #[inline(never)]
    fn not_finite(
        q: &[f64],
        p: &[f64],
        what: &'static str,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        match q.iter().chain(p).position(|x| !x.is_finite()) {
            None => Ok(()),
            Some(entry) => Err(StepError::NonFinite {
                what,
                step,
                t,
                entry,
            }),
        }
    }

    /// The fibre-jump test shared by SHAKE's λ and the projection's σ: the
    /// Newton correction beyond the first (linear) iterate must stay below
    /// `jump_ratio` times that prediction (plus 1e-8·|h| so that a step
    /// starting exactly on M^H, where the prediction is 0, passes).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn jump(
        &self,
        stage: Stage,
        correction: f64,
        predicted: f64,
        found: f64,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        if correction > self.options.jump_ratio * predicted + 1e-8 * h.abs() {
            return Err(StepError::FibreJump {
                stage,
                step,
                t,
                lambda: found,
                predicted,
            });
        }
        Ok(())
    }

    /// The projection Π of a step: its σ must be the nearby crossing.
    pub(crate) fn after_projection(
        &self,
        pr: &ProjectionReport,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        self.jump(
            Stage::Rattle,
            pr.correction,
            pr.predicted,
            pr.displacement,
            h,
            step,
            t,
        )
    }

    /// Every check after a SHAKE (sub)step, the same on both paths: g(z1)
    /// at its round-off ([`on_m`](Self::on_m)), N's condition and the sign of det N,
    /// and λ against its linear prediction. `ws.g` holds g at the new state;
    /// `info` receives N's condition and determinant. (Not inlined: it is
    /// the slice path's, and inlined into a fixed-size step's caller it
    /// made the pendulum's step 2–4 % slower, `cargo bench -p
    /// geoshake-bench --bench step_cost`.)
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub(crate) fn after_shake<S: ConstrainedSystem>(
        &mut self,
        sys: &S,
        q: &[f64],
        p: &[f64],
        ws: &mut Workspace,
        report: &ShakeReport,
        info: &mut StepInfo,
        projected: bool,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        let scales = (max_abs(q, &[]), max_abs(&[], p));
        self.on_m(
            Stage::Shake,
            &ws.g,
            &ws.g_size,
            &ws.g_reads,
            scales,
            report.iterations,
            step,
            t,
        )?;
        sys.nondegeneracy_matrix(q, p, &mut ws.n.mat);
        let (norm, change) = read_n(ws, true);
        self.check_n(ws, norm, change, report, info, projected, h, step, t)
    }

    /// The checks of N at the new state, N read (`norm` = ‖N‖₁, `change` =
    /// ‖N₁ − N₀‖₁) and ready to factorise in `n`: in the workspace
    /// ([`after_shake`](Self::after_shake)) or on the stack (the
    /// fixed-size classical step of 2 to 8 constraints,
    /// `geoshake::classical::fixed_m`). ‖N⁻¹‖₁ is the Neumann bound from the last
    /// state's when it is sharp enough, else Hager's estimate.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) fn check_n(
        &mut self,
        n: &mut impl FactorN,
        norm: f64,
        change: f64,
        report: &ShakeReport,
        info: &mut StepInfo,
        projected: bool,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        let bound = self.inverse_bound(change);
        let mut nd = n.factor_and_check(norm, bound);
        if bound.is_none() || !(nd.condition(self.reference_norm) <= self.options.max_condition) {
            // No bound, or one not sharp enough to pass the limit (the
            // state is refused only on an estimate): estimate, from the
            // factors just made (none when N is singular or not finite:
            // ‖N⁻¹‖₁ is ∞ then, bound or not).
            if bound.is_some() && n.order() >= 2 && nd.inverse_norm.is_finite() {
                nd.inverse_norm = n.estimate_inverse();
            }
            self.estimated = nd.inverse_norm;
        }
        self.inverse_prev = nd.inverse_norm;
        self.judge_shake(&nd, change, report, info, projected, h, step, t)
    }

    /// An upper bound of ‖N₁⁻¹‖₁ from the last state's, without an
    /// estimate: with E = N₁ − N₀ and ‖N₀⁻¹‖₁‖E‖₁ = x < 1,
    /// ‖N₁⁻¹‖₁ ≤ ‖N₀⁻¹‖₁ / (1 − x) (the Neumann series of (I + N₀⁻¹E)⁻¹).
    /// Along a regular trajectory x is O(h) (it is the fold indicator of
    /// [`StepInfo::fold`]), so the bound grows slowly; it is used while
    /// x < ½ and it stays within twice the last estimate, so the reported
    /// condition is at most twice what an estimate would say, and Hager's
    /// estimate (two triangular solve pairs, a third of a chain's step)
    /// runs once in many steps instead of every step. Started from an
    /// estimate (a lower bound of the true ‖N₀⁻¹‖₁ within a small factor),
    /// the bound is as reliable as the estimate itself. `None` for m = 1
    /// is harmless (N⁻¹ is a number there, computed exactly).
    fn inverse_bound(&self, change: f64) -> Option<f64> {
        if !self.n_prev_valid || !self.inverse_prev.is_finite() {
            return None;
        }
        let x = self.inverse_prev * change;
        if !(x < 0.5) {
            return None;
        }
        let b = self.inverse_prev / (1.0 - x);
        // (A bound that overflowed bounds nothing: estimate instead.)
        (b.is_finite() && b <= 2.0 * self.estimated).then_some(b)
    }

    /// The new state is on M to round-off: every |g_i| within
    /// `tolerance::step_bound`, max(64ε, Newton's step tolerance) · s_i ·
    /// scale, from `sizes[i]` = ‖∂g_i/∂z‖₁ measured in the step and the
    /// scale (‖q‖∞, ‖p‖∞) of the variables g_i reads at the new state (NaN
    /// is never within). A residual above it means SHAKE's Newton stopped
    /// on its update short of its root (an ill-conditioned λ, an absurd h):
    /// `NewtonNotConverged`, never a state off M.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) fn on_m(
        &self,
        stage: Stage,
        g: &[f64],
        sizes: &[f64],
        reads: &[u8],
        scales: (f64, f64),
        iterations: usize,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        let tol = self.options.newton.step_tolerance;
        let (qmax, pmax) = scales;
        // Indexed over one length: for the fixed-size step's one
        // constraint the loop is a single test, where a zip of three
        // slices (one of run-time length) stayed a loop.
        let n = g.len().min(sizes.len()).min(reads.len());
        let within = (0..n).all(|i| {
            let scale = crate::tolerance::variable_scale(reads[i], qmax, pmax);
            g[i].abs() <= crate::tolerance::step_bound(tol, sizes[i], scale)
        });
        if within {
            return Ok(());
        }
        let (residual, _, bound) =
            crate::tolerance::worst_constraint_by(g, sizes, reads, scales, |s, scale| {
                crate::tolerance::step_bound(tol, s, scale)
            });
        if !(residual <= bound) {
            return Err(StepError::NewtonNotConverged {
                stage,
                step,
                t,
                source: SolveError::NotConverged {
                    iterations,
                    residual,
                },
            });
        }
        Ok(())
    }

    /// The checks of [`after_shake`](Self::after_shake) past the residual,
    /// given N's check at the new state and ‖N₁ − N₀‖₁ (`change`), however
    /// they were computed (the fixed-size classical step computes them on
    /// the stack, `geoshake::classical::fixed`).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(crate) fn judge_shake(
        &mut self,
        nd: &NondegeneracyCheck,
        change: f64,
        report: &ShakeReport,
        info: &mut StepInfo,
        projected: bool,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        // The fold indicator: the change of N over this (sub)step against
        // N's distance to the singular matrices, 1/‖N⁻¹‖₁.
        info.fold = if self.n_prev_valid && change > 0.0 {
            change * nd.inverse_norm
        } else {
            0.0
        };
        self.n_prev_valid = true;
        let stage = if projected {
            Stage::Rattle
        } else {
            Stage::Shake
        };
        info.condition = self.nondegenerate(nd, self.reference_norm, stage, step, t)?;
        info.det_n = nd.det;
        self.component(nd, step, t)?;
        self.det_prev = nd.det;
        self.last_norm = nd.norm;
        self.jump(
            Stage::Shake,
            report.lambda_correction,
            report.lambda_predicted,
            report.lambda,
            h,
            step,
            t,
        )
    }

    /// A state projected onto M^H only when it is stored (a RATTLE run that
    /// steps with SHAKE): σ must be the nearby crossing of the fibre, on the
    /// component the run is on.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn after_lazy_projection<S: ConstrainedSystem>(
        &self,
        sys: &S,
        q: &[f64],
        p: &[f64],
        ws: &mut Workspace,
        pr: &ProjectionReport,
        h: f64,
        step: u64,
        t: f64,
    ) -> Result<(), StepError> {
        self.after_projection(pr, h, step, t)?;
        if ws.g_reads.iter().any(|&r| r != 1) {
            // Π's fibre flow moves q as well when g reads p: the stored
            // state must still be on M to round-off, as after a projected
            // step (`after_shake`).
            sys.constraints(q, p, &mut ws.g);
            sys.constraint_jacobian(q, p, &mut ws.g_z_1);
            crate::tolerance::gradient_sizes(&ws.pattern, &ws.g_z_1, &mut ws.g_size);
            let scales = (max_abs(q, &[]), max_abs(&[], p));
            self.on_m(
                Stage::Rattle,
                &ws.g,
                &ws.g_size,
                &ws.g_reads,
                scales,
                pr.iterations,
                step,
                t,
            )?;
        }
        if self.options.check_component && sys.constraint_count() > 0 {
            let nd = check_nondegeneracy(sys, q, p, ws);
            self.component(&nd, step, t)?;
        }
        Ok(())
    }

    /// N at a starting state (of a run, or a projection's result): invertible
    /// and, besides its condition, large against the size of its terms
    /// (`nondegeneracy_terms`, ‖T‖₁ ≥ ‖N‖₁): ‖T‖₁ ‖N⁻¹‖₁ within the
    /// condition limit, else [`StepError::NondegeneracyLost`]. The
    /// condition alone cannot see an N that is round-off everywhere (for
    /// m = 1 it is always 1); this is the run-time half of Section 5.2's
    /// nondegeneracy check, whose compile-time half refuses the systems
    /// where N vanishes identically. Along a run N is then compared with
    /// its value here.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn nondegenerate_at_start<S: ConstrainedSystem>(
        &self,
        sys: &S,
        q: &[f64],
        p: &[f64],
        ws: &mut Workspace,
        nd: &NondegeneracyCheck,
        stage: Stage,
        step: u64,
        t: f64,
    ) -> Result<f64, StepError> {
        if nd.inverse_norm.is_infinite() || !self.judge_terms {
            return self.nondegenerate(nd, 0.0, stage, step, t);
        }
        let terms = nondegeneracy_terms(sys, q, p, ws);
        self.nondegenerate(nd, if terms.is_nan() { 0.0 } else { terms }, stage, step, t)
    }

    /// N is invertible (else [`StepError::SingularNondegeneracyMatrix`]) and
    /// its condition relative to `reference` within the limit (else
    /// [`StepError::NondegeneracyLost`]); returns the condition.
    fn nondegenerate(
        &self,
        nd: &NondegeneracyCheck,
        reference: f64,
        stage: Stage,
        step: u64,
        t: f64,
    ) -> Result<f64, StepError> {
        if nd.inverse_norm.is_infinite() {
            return Err(StepError::SingularNondegeneracyMatrix { stage, step, t });
        }
        let condition = nd.condition(reference);
        if !(condition <= self.options.max_condition) {
            return Err(StepError::NondegeneracyLost {
                stage,
                step,
                t,
                condition,
                limit: self.options.max_condition,
            });
        }
        Ok(condition)
    }

    /// det N kept the sign it had at the previous state.
    fn component(&self, nd: &NondegeneracyCheck, step: u64, t: f64) -> Result<(), StepError> {
        if self.options.check_component
            && self.det_prev.is_finite()
            && nd.det.signum() != self.det_prev.signum()
        {
            return Err(StepError::ComponentJump {
                step,
                t,
                det_before: self.det_prev,
                det_after: nd.det,
            });
        }
        Ok(())
    }

    /// The Newton options of every solve of a step.
    pub(crate) fn newton(&self) -> &NewtonOptions {
        &self.options.newton
    }
}
