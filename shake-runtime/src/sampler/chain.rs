//! One chain: the transition kernel and its warm-up.
//!
//! The chain holds two integrators over Störmer–Verlet, one stepping with
//! h and one with −h, so that the forward one keeps the engine's cache of
//! its last checked state: from the second step of a trajectory on,
//! `step_in_place` resumes from it instead of checking the start and
//! factorising N there again. The step back starts from the forward
//! step's result, never from its own last one: it takes over the forward
//! integrator's record of that state (`Integrator::adopt_checked`), so no
//! step of a trajectory checks its start twice.

use std::sync::atomic::{AtomicBool, Ordering};

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use crate::base_map::StormerVerlet;
use crate::guard::Options;
use crate::integrator::Integrator;
use crate::state::State;
use crate::system::ConstrainedSystem;

use super::adapt::DualAveraging;
use super::output::Rejection;
use super::tree::TreeBuffers;
use super::{SamplerOptions, MAX_STEP_SIZE};

/// What one transition did.
#[derive(Copy, Clone, Debug)]
pub(crate) struct Transition {
    pub(crate) accepted: bool,
    /// min(1, e^{−ΔH}), 0 when a check rejected the proposal.
    pub(crate) alpha: f64,
    /// H of the state kept; NaN when the fresh momentum could not be
    /// projected (there is no state on T*M to give an energy).
    pub(crate) energy: f64,
    /// Forward steps taken.
    pub(crate) steps: usize,
    pub(crate) rejection: Option<Rejection>,
    /// A failed solve or check ended the trajectory: the whole proposal
    /// (static HMC) or the rest of the tree (dynamic).
    pub(crate) failed: bool,
}

impl Transition {
    /// A proposal lost to a failed solve or check after `steps` steps;
    /// `energy` is H at the start.
    pub(super) fn rejected(kind: Rejection, energy: f64, steps: usize) -> Transition {
        Transition {
            accepted: false,
            alpha: 0.0,
            energy,
            steps,
            rejection: Some(kind),
            failed: kind != Rejection::Metropolis,
        }
    }

    /// Cut short by a failed solve or check.
    pub(crate) fn failed(&self) -> bool {
        self.failed
    }
}

/// The draws of one chain, in the layout of `Samples` (draw-major).
pub(crate) struct ChainOutput {
    pub(crate) positions: Vec<f64>,
    pub(crate) transitions: Vec<Transition>,
    pub(crate) step_size: f64,
}

pub(crate) struct Chain<S: ConstrainedSystem> {
    forward: Integrator<S, StormerVerlet>,
    backward: Integrator<S, StormerVerlet>,
    pub(super) rng: ChaCha8Rng,
    steps: usize,
    /// Dynamic integration time with trees of at most this depth.
    max_tree_depth: Option<u32>,
    jitter: f64,
    reverse_tolerance: f64,
    /// The chain's position (on M) with the momentum of the transition.
    pub(super) current: State,
    /// The moving state of the trajectory.
    z: State,
    /// The state before the step being taken, for the reverse check.
    before: State,
    /// The step back from z.
    back: State,
    /// Where dynamic trajectories are built, reused from one to the next.
    pub(super) trees: TreeBuffers,
}

impl<S: ConstrainedSystem + Clone> Chain<S> {
    /// A chain from q0 (checked on M by the caller), on stream `chain` of
    /// the generator seeded with `seed`: the chain's draws depend on
    /// (seed, chain) only, not on which thread runs it or when.
    pub(crate) fn new(
        system: &S,
        q0: &[f64],
        seed: u64,
        chain: usize,
        opts: &SamplerOptions,
    ) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(chain as u64);
        let d = system.dof();
        let mut current = State::zeros(d);
        current.q.as_mut_slice().copy_from_slice(q0);
        // Every solve of a transition to the sampler's Newton options.
        let solves = |i: Integrator<S, StormerVerlet>| {
            let options = Options {
                newton: opts.newton,
                ..*i.options()
            };
            i.with_options(options)
        };
        Chain {
            forward: solves(
                Integrator::new(system.clone(), StormerVerlet, opts.step_size).rattle(),
            ),
            backward: {
                // Its starts are the forward steps' results, each already
                // checked against N at the trajectory's start (which was
                // judged against N's terms): judging every step back's
                // start against the terms too would cost m + 1 Hessians a
                // step for nothing.
                let mut back = solves(
                    Integrator::new(system.clone(), StormerVerlet, -opts.step_size).rattle(),
                );
                back.guard.judge_terms = false;
                back
            },
            rng,
            steps: opts.steps,
            max_tree_depth: opts.max_tree_depth,
            jitter: opts.step_size_jitter,
            reverse_tolerance: opts.reverse_tolerance,
            current,
            z: State::zeros(d),
            before: State::zeros(d),
            back: State::zeros(d),
            trees: TreeBuffers::default(),
        }
    }

    /// Warm-up (with dual averaging when asked), then the draws; None once
    /// `stop` is set (checked before every transition).
    ///
    /// The adaptation first brings h within a factor 2 of the scale where
    /// one step's acceptance crosses ½ ([`Chain::initial_step_size`]),
    /// then runs two dual averagings side by side, each transition taking
    /// the smaller of their step sizes: one drives the mean acceptance
    /// statistic to its target, the other the fraction of proposals lost
    /// to a failed solve or check to at most `target_failure_rate`. The
    /// second matters wherever a step can be too long for M (a step of
    /// length h|p| across a circle of radius r < h|p| has no solution):
    /// those failures come where |p| is largest, at the crossings between
    /// modes, and a step size tuned on acceptance alone (which counts them
    /// only as rejections) keeps the chain on one side of M for thousands
    /// of draws while every chain agrees, R̂ ≈ 1, on a wrong mean. With the
    /// dynamic integration time a failure only cuts the trajectory short,
    /// the chain still moves, and the second averaging is not used: the
    /// same von Mises density with a quarter of its trajectories cut came
    /// out right from either end of the circle, and holding the cuts to
    /// 1 % cost 1.6× in effective samples per second (von Mises–Fisher on
    /// S², κ = 2).
    pub(crate) fn run(mut self, opts: &SamplerOptions, stop: &AtomicBool) -> Option<ChainOutput> {
        let stopped = || stop.load(Ordering::Relaxed);
        let mut h = opts.step_size;
        if let Some(target) = opts.target_acceptance {
            if opts.warmup > 0 {
                let h0 = self.initial_step_size(h);
                let mut acceptance = DualAveraging::new(h0, target);
                let mut solved = DualAveraging::new(h0, 1.0 - opts.target_failure_rate);
                // A failure loses a static proposal whole, but only cuts a
                // dynamic trajectory short: the chain still moves.
                let static_hmc = self.max_tree_depth.is_none();
                for _ in 0..opts.warmup {
                    if stopped() {
                        return None;
                    }
                    let h = if static_hmc {
                        acceptance.step_size().min(solved.step_size())
                    } else {
                        acceptance.step_size()
                    };
                    let t = self.transition(h.min(MAX_STEP_SIZE));
                    acceptance.update(t.alpha);
                    solved.update(if t.failed() { 0.0 } else { 1.0 });
                }
                h = acceptance.final_step_size();
                if static_hmc {
                    h = h.min(solved.final_step_size());
                }
                h = h.min(MAX_STEP_SIZE);
            }
        } else {
            for _ in 0..opts.warmup {
                if stopped() {
                    return None;
                }
                self.transition(h);
            }
        }
        let d = self.current.q.len();
        let mut positions = Vec::with_capacity(opts.draws * d);
        let mut transitions = Vec::with_capacity(opts.draws);
        for _ in 0..opts.draws {
            if stopped() {
                return None;
            }
            transitions.push(self.transition(h));
            positions.extend_from_slice(self.current.q.as_slice());
        }
        Some(ChainOutput {
            positions,
            transitions,
            step_size: h,
        })
    }

    /// A starting step size for the adaptation (Hoffman and Gelman 2014,
    /// Algorithm 4): from h, double (or halve) it while one RATTLE step
    /// from the chain's position with a fresh momentum is accepted with
    /// probability above (or below) ½, a failed solve or check counting
    /// as 0 (each trial is a static transition of one step, unjittered,
    /// which the chain keeps as it keeps any warm-up transition). The
    /// adaptation's μ = log(10 h₀) then sits near the scale of M and of U,
    /// whatever the units of q: dual averaging from a step 10¹⁰ too small
    /// would need far more than a warm-up to get there. Kept within
    /// [2⁻¹⁰⁷⁴·h, 10⁶] (the bound on any step size), so it ends.
    fn initial_step_size(&mut self, h: f64) -> f64 {
        let steps = self.steps;
        self.steps = 1;
        let up = self.transition_static(h).alpha > 0.5;
        let mut h = h;
        for _ in 0..2200 {
            let next = if up { 2.0 * h } else { 0.5 * h };
            if !(next > 0.0 && next <= MAX_STEP_SIZE) {
                break;
            }
            h = next;
            let alpha = self.transition_static(h).alpha;
            if (alpha > 0.5) != up {
                break;
            }
        }
        self.steps = steps;
        h
    }

    /// One transition with step size h (jittered when asked): static
    /// ([`Chain::transition_static`]) or dynamic
    /// ([`Chain::transition_dynamic`]) as the options say.
    pub(crate) fn transition(&mut self, h: f64) -> Transition {
        let h = if self.jitter > 0.0 {
            let u: f64 = self.rng.random();
            h * (1.0 + self.jitter * (2.0 * u - 1.0))
        } else {
            h
        };
        match self.max_tree_depth {
            None => self.transition_static(h),
            Some(depth) => self.transition_dynamic(h, depth),
        }
    }

    /// A fresh momentum p ~ N(0, I) projected onto T*_q M at the chain's
    /// position, and H there; the rejection when that fails.
    pub(super) fn refresh(&mut self, h: f64) -> Result<f64, Transition> {
        for p in self.current.p.iter_mut() {
            *p = self.rng.sample(StandardNormal);
        }
        // Π along the fibre p ↦ p − g_qᵀσ onto {g_q p = 0}: for
        // H = |p|²/2 + U the orthogonal projection onto the tangent space,
        // which turns N(0, I) into the standard normal on T*_q M.
        match self.forward.project(&self.current) {
            Ok(z) => self.current = z,
            Err(e) => return Err(Transition::rejected(Rejection::of(&e), f64::NAN, 0)),
        }
        let h0 = self.energy(&self.current);
        if !h0.is_finite() {
            return Err(Transition::rejected(Rejection::NonFinite, h0, 0));
        }
        self.forward.with_step_size(h);
        self.backward.with_step_size(-h);
        Ok(h0)
    }

    /// H(z).
    pub(super) fn energy(&self, z: &State) -> f64 {
        self.forward
            .system()
            .hamiltonian(z.q.as_slice(), z.p.as_slice())
    }

    /// Static HMC: p ~ N(0, I) projected onto T*_q M, L RATTLE steps each
    /// checked by its step back, the Metropolis test on ΔH.
    fn transition_static(&mut self, h: f64) -> Transition {
        let h0 = match self.refresh(h) {
            Ok(h0) => h0,
            Err(t) => return t,
        };
        self.z.clone_from(&self.current);
        for k in 0..self.steps {
            if let Err(kind) = self.checked_step() {
                return Transition::rejected(kind, h0, k);
            }
        }
        let h1 = self.energy(&self.z);
        if !h1.is_finite() {
            return Transition::rejected(Rejection::NonFinite, h0, self.steps);
        }
        let alpha = (h0 - h1).exp().min(1.0);
        let u: f64 = self.rng.random();
        if u < alpha {
            self.current.clone_from(&self.z);
            Transition {
                accepted: true,
                alpha,
                energy: h1,
                steps: self.steps,
                rejection: None,
                failed: false,
            }
        } else {
            Transition {
                accepted: false,
                alpha,
                energy: h0,
                steps: self.steps,
                rejection: Some(Rejection::Metropolis),
                failed: false,
            }
        }
    }

    /// z ← R_h(z), accepted only if R_{−h} takes the result back to z.
    ///
    /// For H even in p, R_{−h} = ρ ∘ R_h ∘ ρ with ρ(q, p) = (q, −p): the
    /// step back is the forward step from the end with negated momentum.
    /// A proposal is an involution ρ ∘ R_h^L only where each solve found
    /// the solution the step back finds again; elsewhere (a Newton
    /// iteration that converged to another intersection of the fibre with
    /// M) the step back lands elsewhere, and accepting would break detailed
    /// balance (Zappa, Holmes-Cerfon and Goodman 2018; Lelièvre, Rousset
    /// and Stoltz 2019). The test is symmetric: a trajectory passes it
    /// when its reversal does, to round-off and away from the limit of the
    /// conditions (a miss at the tolerance, a solve at the edge of
    /// convergence), so rejecting is itself reversible to that precision.
    fn checked_step(&mut self) -> Result<(), Rejection> {
        let mut z = std::mem::replace(&mut self.z, State::zeros(0));
        let res = self.checked_step_from(&mut z, true);
        self.z = z;
        res
    }

    /// [`Chain::checked_step`] on z, forward in time (R_h, checked by
    /// R_{−h}) or backward (R_{−h}, checked by R_h).
    pub(super) fn checked_step_from(
        &mut self,
        z: &mut State,
        forward: bool,
    ) -> Result<(), Rejection> {
        let (step, back) = if forward {
            (&mut self.forward, &mut self.backward)
        } else {
            (&mut self.backward, &mut self.forward)
        };
        self.before.clone_from(z);
        step.step_in_place(z).map_err(|e| Rejection::of(&e))?;
        if !self.reverse_tolerance.is_finite() {
            return Ok(());
        }
        // The step back starts where this step ended, which this step has
        // just checked. Only its positions are compared (`reverse_ok`), so
        // it is S_h without Π, which R_h's positions are; but with all of
        // R_h's checks: a move x → y must pass the same tests as y → x
        // (the forward step's fibre-jump check, applied to the step back
        // too), else detailed balance fails (the wavy curve at h = 0.5 in
        // tests/suite/sampler.rs, biased by 4.5 standard errors).
        back.adopt_checked(step);
        self.back.clone_from(z);
        // Whatever stops the step back (its Newton, a degenerate N, a jump)
        // leaves the forward step not undone: a reversibility failure, not
        // a failure of the forward trajectory.
        back.shake_in_place(&mut self.back)
            .map_err(|_| Rejection::Reverse)?;
        if reverse_ok(
            self.before.q.as_slice(),
            z.q.as_slice(),
            self.back.q.as_slice(),
            self.reverse_tolerance,
        ) {
            Ok(())
        } else {
            Err(Rejection::Reverse)
        }
    }
}

/// The reversibility test of one step q₀ → q₁ whose step back landed at
/// q_back: positions only (as mici), against the step's own length,
///
///   ‖q_back − q₀‖∞ ≤ tol · (‖q₁ − q₀‖∞ + ε·max(‖q₀‖∞, ‖q₁‖∞)), ε = 1e-4.
///
/// Positions only: for RATTLE the momenta are functions of the two
/// positions (p_{1/2} = (q₁ − q₀)/h, then a linear projection with a unique
/// solution where N is invertible), so a step back that returns to q₀
/// returns p₀ too, and a p miss cannot be read against a q scale. The
/// step's length as the scale: a step back on the same branch misses by
/// round-off times the conditioning of its solves, a jump to another
/// crossing of the fibre by a distance comparable to the step itself, and
/// neither changes when M is translated. The ε term is a round-off floor
/// only (round-off is relative to the coordinates' size): it matters for a
/// step shorter than 1e-4 of ‖q‖, where a correct step back may miss by
/// more than tol times the step.
pub(crate) fn reverse_ok(q0: &[f64], q1: &[f64], back: &[f64], tol: f64) -> bool {
    // (f64::max drops a NaN; this keeps it, so that a NaN fails.)
    let dist = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).fold(0.0f64, |m, (x, y)| {
            let d = (x - y).abs();
            if d.is_nan() || d > m {
                d
            } else {
                m
            }
        })
    };
    let size = |a: &[f64]| a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let scale = dist(q1, q0) + ROUND_OFF_FLOOR * size(q0).max(size(q1));
    // (NaN anywhere fails the test.)
    dist(back, q0) <= tol * scale
}

/// ε of [`reverse_ok`].
const ROUND_OFF_FLOOR: f64 = 1e-4;

#[cfg(test)]
mod tests {
    use super::reverse_ok;

    /// The test reads positions against the step's length: the same step
    /// and miss pass or fail alike wherever M lies (the round-off floor
    /// aside, which only widens the test far from the origin).
    #[test]
    fn the_reverse_test_is_translation_invariant() {
        let tol = 1e-8;
        let (step, good, jump) = (0.1, 1e-14, 1e-3);
        for shift in [0.0, 1.0, 1e3, 1e6] {
            let q0 = [shift, 0.0];
            let q1 = [shift + step, 0.0];
            // A step back on the same branch: round-off (shift + 1e-14
            // rounds to a neighbour of shift at most an ulp away).
            let near = [shift + good, 0.0];
            assert!(reverse_ok(&q0, &q1, &near, tol), "shift {shift}");
            // A miss of 1e-3 on a step of 0.1 is a branch jump anywhere
            // (a test relative to ‖z‖∞ would pass it from ‖q‖ ≈ 1e5).
            let far = [shift + jump, 0.0];
            assert!(!reverse_ok(&q0, &q1, &far, tol), "shift {shift}");
        }
        assert!(!reverse_ok(&[0.0], &[0.1], &[f64::NAN], tol));
    }
}
