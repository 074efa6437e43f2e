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

/// What the building of one trajectory saw.
#[derive(Default)]
struct Stats {
    steps: usize,
    /// Σ min(1, e^{−(H − H₀)}) over the new states: Stan's acceptance
    /// statistic for the adaptation is its mean.
    acceptance: f64,
    failure: Option<Rejection>,
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

/// (a + b) · x, summed in the order of the coordinates.
fn dot_of_sum(a: &[f64], b: &[f64], x: &[f64]) -> f64 {
    a.iter().zip(b).zip(x).map(|((a, b), x)| (a + b) * x).sum()
}

/// The trajectory keeps going: with p♯_sum = a + b (formed term by term
/// inside the dot products, so that a join needs no vector for it), it
/// has not turned back on itself.
fn no_u_turn(a: &[f64], b: &[f64], p_first: &[f64], p_last: &[f64]) -> bool {
    dot_of_sum(a, b, p_first) > 0.0 && dot_of_sum(a, b, p_last) > 0.0
}

/// A contiguous stretch of the trajectory, as far as the sampling and the
/// no-U-turn checks need it. Its buffers are reused from one subtree to
/// the next: a leaf copies into them, a join adds or swaps into them.
struct Tree {
    /// Σ p over its states.
    p_sum: Vec<f64>,
    /// The momenta of its earliest and latest states in the trajectory's
    /// time.
    p_first: Vec<f64>,
    p_last: Vec<f64>,
    /// log Σ e^{−(H − H₀)} over its states.
    log_weight: f64,
    /// The state drawn from it with probability ∝ e^{−H}, and H there.
    /// Not kept when it is z₀ (`sample_is_start`): the chain holds z₀.
    sample: State,
    sample_energy: f64,
    /// Whether the state drawn is z₀ itself.
    sample_is_start: bool,
}

/// The buffers a chain builds its trajectories in, kept across
/// transitions: once the deepest tree so far has been built, a
/// transition allocates nothing for its tree.
pub(super) struct TreeBuffers {
    /// The earliest and latest states of the whole trajectory: a doubling
    /// steps on from one of them in place (a subtree's steps each start
    /// where the previous one ended, so no other state is ever stepped).
    first: State,
    last: State,
    /// `trees[0]` is the whole trajectory and `trees[1]` the subtree being
    /// added to it. A subtree built into `trees[k]` builds its earlier
    /// half (in the order of building) there too and its later half into
    /// `trees[k + 1]`, then joins the two into `trees[k]`; the halves are
    /// built one after the other, so one slot per level suffices and a
    /// subtree of depth j uses `trees[1..=j + 1]`.
    trees: Vec<Tree>,
}

impl Default for TreeBuffers {
    fn default() -> Self {
        TreeBuffers {
            first: State::zeros(0),
            last: State::zeros(0),
            trees: Vec::new(),
        }
    }
}

impl Tree {
    fn new(d: usize) -> Tree {
        Tree {
            p_sum: vec![0.0; d],
            p_first: vec![0.0; d],
            p_last: vec![0.0; d],
            log_weight: 0.0,
            sample: State::zeros(d),
            sample_energy: f64::NAN,
            sample_is_start: false,
        }
    }

    /// The trajectory of z₀ alone, with H(z₀) = h0.
    fn set_start(&mut self, z0: &State, h0: f64) {
        let p = z0.p.as_slice();
        self.p_sum.copy_from_slice(p);
        self.p_first.copy_from_slice(p);
        self.p_last.copy_from_slice(p);
        // log e^{−(H − H₀)} at z₀ as at any leaf: 0, NaN when H₀ is not
        // finite (as the leaf's own formula gives).
        #[allow(clippy::eq_op)]
        {
            self.log_weight = h0 - h0;
        }
        self.sample_energy = h0;
        self.sample_is_start = true;
    }

    /// The one state z, with H(z) = energy.
    fn set_leaf(&mut self, z: &State, energy: f64, h0: f64) {
        let p = z.p.as_slice();
        self.p_sum.copy_from_slice(p);
        self.p_first.copy_from_slice(p);
        self.p_last.copy_from_slice(p);
        self.log_weight = h0 - energy;
        self.sample.clone_from(z);
        self.sample_energy = energy;
        self.sample_is_start = false;
    }

    /// Makes this tree the union of itself and `new`, the stretch built
    /// next to it (later in time when `forward`, earlier otherwise), its
    /// sample taken from `new` when `take_new`; `new` is left holding
    /// stale buffers. Returns whether the union goes on: no U-turn over
    /// the whole, nor across the join (Stan's extra checks: the earlier
    /// half with the first state of the later one, and the later half with
    /// the last state of the earlier one).
    fn join(&mut self, new: &mut Tree, forward: bool, take_new: bool) -> bool {
        let (earlier, later) = if forward {
            (&*self, &*new)
        } else {
            (&*new, &*self)
        };
        let goes_on = no_u_turn(
            &earlier.p_sum,
            &later.p_sum,
            &earlier.p_first,
            &later.p_last,
        ) && no_u_turn(
            &earlier.p_sum,
            &later.p_first,
            &earlier.p_first,
            &later.p_first,
        ) && no_u_turn(
            &later.p_sum,
            &earlier.p_last,
            &earlier.p_last,
            &later.p_last,
        );
        let log_weight = log_add_exp(earlier.log_weight, later.log_weight);
        // Σ p of the union in place: one addition per coordinate rounds
        // the same whichever half comes first in time.
        for (s, n) in self.p_sum.iter_mut().zip(&new.p_sum) {
            *s += n;
        }
        if forward {
            std::mem::swap(&mut self.p_last, &mut new.p_last);
        } else {
            std::mem::swap(&mut self.p_first, &mut new.p_first);
        }
        self.log_weight = log_weight;
        if take_new {
            std::mem::swap(&mut self.sample, &mut new.sample);
            self.sample_energy = new.sample_energy;
            self.sample_is_start = new.sample_is_start;
        }
        goes_on
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
        // Out of the chain while the tree is built, since every step
        // borrows the chain; the empty one left behind allocates nothing.
        let mut buffers = std::mem::take(&mut self.trees);
        let transition = self.build_trajectory(&mut buffers, h0, max_depth);
        self.trees = buffers;
        transition
    }

    /// The trajectory from z₀ = the chain's state, with H(z₀) = h0, built
    /// in `buffers`, and the chain moved to the state drawn from it.
    fn build_trajectory(
        &mut self,
        buffers: &mut TreeBuffers,
        h0: f64,
        max_depth: u32,
    ) -> Transition {
        let d = self.current.q.len();
        if buffers.trees.is_empty() {
            buffers.trees.push(Tree::new(d));
        }
        buffers.trees[0].set_start(&self.current, h0);
        buffers.first.clone_from(&self.current);
        buffers.last.clone_from(&self.current);
        let mut stats = Stats::default();
        for depth in 0..max_depth {
            // Made when first needed, so that a chain whose trees stay
            // shallow does not pay for the depth limit.
            while buffers.trees.len() < depth as usize + 2 {
                buffers.trees.push(Tree::new(d));
            }
            let forward: bool = self.rng.random();
            let end = if forward {
                &mut buffers.last
            } else {
                &mut buffers.first
            };
            let (whole, new) = buffers.trees.split_at_mut(1);
            if !self.subtree(new, end, depth, forward, h0, &mut stats) {
                break;
            }
            let (whole, new) = (&mut whole[0], &mut new[0]);
            // Biased progressive sampling across the doubling.
            let u: f64 = self.rng.random();
            let take_new = u < (new.log_weight - whole.log_weight).exp();
            if !whole.join(new, forward, take_new) {
                break;
            }
        }
        let alpha = if stats.steps > 0 {
            stats.acceptance / stats.steps as f64
        } else {
            0.0
        };
        let whole = &mut buffers.trees[0];
        let moved = !whole.sample_is_start;
        // A trajectory that never left z₀ because its first step failed
        // is that failure's rejection; one whose draw fell on z₀ is the
        // multinomial analogue of a Metropolis rejection.
        let rejection = match (moved, stats.failure) {
            (true, _) => None,
            (false, Some(kind)) if stats.steps <= 1 => Some(kind),
            (false, _) => Some(Rejection::Metropolis),
        };
        if moved {
            std::mem::swap(&mut self.current, &mut whole.sample);
        }
        Transition {
            accepted: moved,
            alpha,
            energy: whole.sample_energy,
            steps: stats.steps,
            rejection,
            failed: stats.failure.is_some(),
        }
    }

    /// Builds into `trees[0]` the subtree of 2^depth steps from z (not
    /// included) in the given direction, stepping z itself on to the
    /// subtree's last state in the order of building, with `trees[1..]`
    /// as room for its halves. False when the subtree must be dropped: a
    /// U-turn inside it, a divergence, a failed solve or check (z and the
    /// trees are then left part-built).
    fn subtree(
        &mut self,
        trees: &mut [Tree],
        z: &mut State,
        depth: u32,
        forward: bool,
        h0: f64,
        stats: &mut Stats,
    ) -> bool {
        if depth == 0 {
            stats.steps += 1;
            if let Err(kind) = self.checked_step_from(z, forward) {
                stats.failure = Some(kind);
                return false;
            }
            let energy = self.energy(z);
            if !energy.is_finite() {
                stats.failure = Some(Rejection::NonFinite);
                return false;
            }
            stats.acceptance += (h0 - energy).exp().min(1.0);
            if energy - h0 > MAX_ENERGY_ERROR {
                return false;
            }
            trees[0].set_leaf(z, energy, h0);
            return true;
        }
        // The inner half into trees[0], then, from where it ended, the
        // outer half into trees[1].
        if !self.subtree(trees, z, depth - 1, forward, h0, stats)
            || !self.subtree(&mut trees[1..], z, depth - 1, forward, h0, stats)
        {
            return false;
        }
        let (inner, outer) = trees.split_at_mut(1);
        let (inner, outer) = (&mut inner[0], &mut outer[0]);
        // Uniform progressive sampling inside the subtree: the outer half
        // with probability W_outer / (W_inner + W_outer).
        let u: f64 = self.rng.random();
        let total = log_add_exp(inner.log_weight, outer.log_weight);
        let take_outer = u < (outer.log_weight - total).exp();
        inner.join(outer, forward, take_outer)
    }
}
