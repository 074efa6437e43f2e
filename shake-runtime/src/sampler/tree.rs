//! Dynamic integration time: multinomial HMC with the no-U-turn criterion
//! (Hoffman and Gelman 2014; Betancourt 2017, "A conceptual introduction
//! to Hamiltonian Monte Carlo", Appendix A), on M as mici's
//! `DynamicMultinomialHMC`.
//!
//! From z₀ = (q, p) with p fresh on T*_q M, the trajectory is doubled:
//! at depth j a direction is drawn (forward or backward in time) and a
//! subtree of 2^j RATTLE steps is built from the end of the trajectory on
//! that side, each step checked by its step back as in static HMC. The
//! chain moves to one state of the whole trajectory drawn with probability
//! ∝ e^{−H} (multinomial sampling), by progressive sampling: inside a
//! subtree uniformly by weight, and across the doubling biased towards the
//! new half, min(1, W_new/W_old), which favours states far from z₀ and
//! keeps e^{−H} invariant (Betancourt 2017, A.3.2). Doubling stops when
//! the trajectory turns back on itself,
//!
//!   p♯_sum · p_first ≤ 0  or  p♯_sum · p_last ≤ 0,
//!
//! with p♯_sum the sum of the momenta over the trajectory (p♯ = p for the
//! identity mass), checked on every subtree and, as in Stan, across the
//! two halves of each join; or at the depth limit. A subtree that turns,
//! diverges (H − H₀ > 1000) or meets a failed solve or check is dropped
//! whole: the trajectory is then one that the same tree built from any of
//! its states would also stop at, which is what makes the scheme
//! reversible (Hoffman and Gelman 2014, Section 3.1; Graham and Storkey's
//! mici treats a failed projection as this termination too).

use rand::RngExt;

use crate::state::State;
use crate::system::ConstrainedSystem;

use super::chain::{Chain, Transition};
use super::output::Rejection;

/// H − H₀ beyond which a step counts as divergent and ends the tree
/// (Stan's and mici's default).
const MAX_ENERGY_ERROR: f64 = 1000.0;

/// A contiguous stretch of the trajectory.
struct Tree {
    /// Its earliest and latest states in the trajectory's time.
    first: State,
    last: State,
    /// Σ p over its states.
    p_sum: Vec<f64>,
    /// log Σ e^{−(H − H₀)} over its states.
    log_weight: f64,
    /// The state drawn from it with probability ∝ e^{−H}, and H there.
    sample: State,
    sample_energy: f64,
    /// Whether `sample` is z₀ itself.
    sample_is_start: bool,
}

/// What the building of one trajectory saw.
#[derive(Default)]
struct Stats {
    steps: usize,
    /// Σ min(1, e^{−(H − H₀)}) over the new states: Stan's acceptance
    /// statistic for the adaptation is its mean.
    acceptance: f64,
    failure: Option<Rejection>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// log(e^a + e^b), exact for a or b = −∞.
fn log_add_exp(a: f64, b: f64) -> f64 {
    let (hi, lo) = if a > b { (a, b) } else { (b, a) };
    if hi == f64::NEG_INFINITY {
        hi
    } else {
        hi + (lo - hi).exp().ln_1p()
    }
}

/// The trajectory keeps going: it has not turned back on itself.
fn no_u_turn(p_sum: &[f64], p_first: &[f64], p_last: &[f64]) -> bool {
    dot(p_sum, p_first) > 0.0 && dot(p_sum, p_last) > 0.0
}

impl Tree {
    fn leaf(z: State, energy: f64, h0: f64, is_start: bool) -> Tree {
        Tree {
            first: z.clone(),
            last: z.clone(),
            p_sum: z.p.as_slice().to_vec(),
            log_weight: h0 - energy,
            sample: z,
            sample_energy: energy,
            sample_is_start: is_start,
        }
    }

    /// The tree made of `earlier` followed by `later`, its sample taken
    /// from `later` when `take_later`, and whether it goes on: no U-turn
    /// over the whole, nor across the join (Stan's extra checks: the
    /// earlier half with the first state of the later one, and the later
    /// half with the last state of the earlier one).
    fn join(earlier: Tree, later: Tree, take_later: bool) -> (Tree, bool) {
        let p_sum: Vec<f64> = earlier
            .p_sum
            .iter()
            .zip(&later.p_sum)
            .map(|(a, b)| a + b)
            .collect();
        let extended = |sum: &[f64], p: &State| -> Vec<f64> {
            sum.iter().zip(p.p.as_slice()).map(|(a, b)| a + b).collect()
        };
        let goes_on = no_u_turn(&p_sum, earlier.first.p.as_slice(), later.last.p.as_slice())
            && no_u_turn(
                &extended(&earlier.p_sum, &later.first),
                earlier.first.p.as_slice(),
                later.first.p.as_slice(),
            )
            && no_u_turn(
                &extended(&later.p_sum, &earlier.last),
                earlier.last.p.as_slice(),
                later.last.p.as_slice(),
            );
        let log_weight = log_add_exp(earlier.log_weight, later.log_weight);
        let (sample, sample_energy, sample_is_start) = if take_later {
            (later.sample, later.sample_energy, later.sample_is_start)
        } else {
            (
                earlier.sample,
                earlier.sample_energy,
                earlier.sample_is_start,
            )
        };
        let tree = Tree {
            first: earlier.first,
            last: later.last,
            p_sum,
            log_weight,
            sample,
            sample_energy,
            sample_is_start,
        };
        (tree, goes_on)
    }
}

impl<S: ConstrainedSystem + Clone> Chain<S> {
    /// One transition of multinomial HMC with step size h and trees of at
    /// most `max_depth` doublings (at most 2^max_depth − 1 steps).
    pub(super) fn transition_dynamic(&mut self, h: f64, max_depth: u32) -> Transition {
        let h0 = match self.refresh(h) {
            Ok(h0) => h0,
            Err(t) => return t,
        };
        let mut stats = Stats::default();
        let mut tree = Tree::leaf(self.current.clone(), h0, h0, true);
        for depth in 0..max_depth {
            let forward: bool = self.rng.random();
            let from = if forward { &tree.last } else { &tree.first };
            let Some(new) = self.subtree(from.clone(), depth, forward, h0, &mut stats) else {
                break;
            };
            // Biased progressive sampling across the doubling.
            let u: f64 = self.rng.random();
            let take_new = u < (new.log_weight - tree.log_weight).exp();
            let (joined, goes_on) = if forward {
                Tree::join(tree, new, take_new)
            } else {
                Tree::join(new, tree, !take_new)
            };
            tree = joined;
            if !goes_on {
                break;
            }
        }
        let alpha = if stats.steps > 0 {
            stats.acceptance / stats.steps as f64
        } else {
            0.0
        };
        let moved = !tree.sample_is_start;
        // A trajectory that never left z₀ because its first step failed
        // is that failure's rejection; one whose draw fell on z₀ is the
        // multinomial analogue of a Metropolis rejection.
        let rejection = match (moved, stats.failure) {
            (true, _) => None,
            (false, Some(kind)) if stats.steps <= 1 => Some(kind),
            (false, _) => Some(Rejection::Metropolis),
        };
        let energy = tree.sample_energy;
        if moved {
            self.current = tree.sample;
        }
        Transition {
            accepted: moved,
            alpha,
            energy,
            steps: stats.steps,
            rejection,
            failed: stats.failure.is_some(),
        }
    }

    /// The subtree of 2^depth steps from `from` (not included) in the
    /// given direction, or None when it must be dropped: a U-turn inside
    /// it, a divergence, a failed solve or check.
    fn subtree(
        &mut self,
        from: State,
        depth: u32,
        forward: bool,
        h0: f64,
        stats: &mut Stats,
    ) -> Option<Tree> {
        if depth == 0 {
            let mut z = from;
            stats.steps += 1;
            if let Err(kind) = self.checked_step_from(&mut z, forward) {
                stats.failure = Some(kind);
                return None;
            }
            let energy = self.energy(&z);
            if !energy.is_finite() {
                stats.failure = Some(Rejection::NonFinite);
                return None;
            }
            stats.acceptance += (h0 - energy).exp().min(1.0);
            if energy - h0 > MAX_ENERGY_ERROR {
                return None;
            }
            return Some(Tree::leaf(z, energy, h0, false));
        }
        let inner = self.subtree(from, depth - 1, forward, h0, stats)?;
        let next = if forward { &inner.last } else { &inner.first };
        let outer = self.subtree(next.clone(), depth - 1, forward, h0, stats)?;
        // Uniform progressive sampling inside the subtree: the outer half
        // with probability W_outer / (W_inner + W_outer).
        let u: f64 = self.rng.random();
        let total = log_add_exp(inner.log_weight, outer.log_weight);
        let take_outer = u < (outer.log_weight - total).exp();
        let (tree, goes_on) = if forward {
            Tree::join(inner, outer, take_outer)
        } else {
            Tree::join(outer, inner, !take_outer)
        };
        goes_on.then_some(tree)
    }
}
