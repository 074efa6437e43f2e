//! What a sampler run returns: the draws as a (chains, draws, dim) array,
//! the statistics of every draw, and summaries.

use std::fmt;

use crate::error::StepError;

use super::convergence::{ess_bulk, ess_mean, ess_tail, rhat};

/// Why a proposal was rejected. Every failure of a transition is one of
/// these, counted, and the chain stays where it was; none is an error of
/// the run.
///
/// ```
/// use geoshake_runtime::sampler::Rejection;
/// assert_eq!(Rejection::Reverse.name(), "reverse");
/// ```
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Rejection {
    /// The Metropolis test: u ≥ e^{−ΔH}.
    Metropolis,
    /// The step back failed: R_{−h}(R_h z) misses z by more than the
    /// reverse tolerance, or the step back itself could not be taken (any
    /// failure of its solves: Newton, a singular or degenerate N, a
    /// non-finite state, a jump). Either way the forward step is not
    /// undone, the proposal map would not be an involution there, and
    /// accepting it would bias the chain. Only the step back gives this
    /// kind.
    Reverse,
    /// A Newton solve of a forward step (or of the projection of the fresh
    /// momentum) did not converge, or its matrix was singular: no point of
    /// M was found for that step.
    Newton,
    /// A state or the energy of the forward trajectory came out infinite
    /// or NaN (a density that is zero or undefined along the trajectory,
    /// or a step far too large).
    NonFinite,
    /// N = g_q g_qᵀ is (nearly) singular along the forward trajectory: the
    /// constraints' gradients are (nearly) dependent there, and M is not a
    /// manifold of the expected dimension (the engine's nondegeneracy
    /// checks).
    Degenerate,
    /// A forward step's solve (or the momentum's projection) converged,
    /// but the engine's own fibre- or branch-jump check refused the result
    /// (`StepError::FibreJump`, `StepError::BranchJump`): it is another
    /// crossing of the fibre with M than the nearby one. The defect the
    /// step back would find, caught before it is taken; counted apart from
    /// [`Rejection::Reverse`], which counts what the step back found.
    Jump,
}

impl Rejection {
    /// Every kind, in the order of [`RejectionCounts`]' fields.
    pub const ALL: [Rejection; 6] = [
        Rejection::Metropolis,
        Rejection::Reverse,
        Rejection::Newton,
        Rejection::NonFinite,
        Rejection::Degenerate,
        Rejection::Jump,
    ];

    /// A short lower-case name (`metropolis`, `reverse`, `newton`,
    /// `non_finite`, `degenerate`, `jump`), as in the example's output.
    pub const fn name(self) -> &'static str {
        match self {
            Rejection::Metropolis => "metropolis",
            Rejection::Reverse => "reverse",
            Rejection::Newton => "newton",
            Rejection::NonFinite => "non_finite",
            Rejection::Degenerate => "degenerate",
            Rejection::Jump => "jump",
        }
    }

    /// The kind of a forward step's failure in the engine (a failure of
    /// the step back is always [`Rejection::Reverse`]).
    ///
    /// ```
    /// use geoshake_runtime::{sampler::Rejection, SolveError, Stage, StepError};
    /// let e = StepError::NewtonNotConverged {
    ///     stage: Stage::Shake, step: 1, t: 0.1,
    ///     source: SolveError::NotConverged { iterations: 50, residual: 1e-3 },
    /// };
    /// assert_eq!(Rejection::of(&e), Rejection::Newton);
    /// let jump = StepError::FibreJump {
    ///     stage: Stage::Shake, step: 1, t: 0.1, lambda: 0.9, predicted: 0.01,
    /// };
    /// assert_eq!(Rejection::of(&jump), Rejection::Jump);
    /// ```
    pub fn of(e: &StepError) -> Rejection {
        match e {
            StepError::NewtonNotConverged { .. }
            | StepError::AtMember { .. }
            | StepError::SingularShakeJacobian { .. }
            | StepError::NotOnConstraint { .. } => Rejection::Newton,
            StepError::FibreJump { .. } | StepError::BranchJump { .. } => Rejection::Jump,
            StepError::NonFinite { .. } => Rejection::NonFinite,
            StepError::SingularNondegeneracyMatrix { .. }
            | StepError::NondegeneracyLost { .. }
            | StepError::ComponentJump { .. } => Rejection::Degenerate,
            // The sampler checks its inputs before the first transition,
            // so these cannot come from a step; should one come, it is
            // still a rejection, never a panic.
            StepError::InvalidInput { .. }
            | StepError::Shape { .. }
            | StepError::Topology(_)
            | StepError::Solver { .. }
            | StepError::Unavailable { .. }
            | StepError::Storage { .. } => Rejection::NonFinite,
        }
    }
}

/// Rejections by kind.
///
/// ```
/// use geoshake_runtime::sampler::{Rejection, RejectionCounts};
/// let mut c = RejectionCounts::default();
/// c.add(Rejection::Newton);
/// assert_eq!((c.newton, c.total()), (1, 1));
/// ```
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct RejectionCounts {
    /// By the Metropolis test.
    pub metropolis: usize,
    /// By the reversibility check: the step back missed, or failed.
    pub reverse: usize,
    /// By a Newton solve that failed.
    pub newton: usize,
    /// By a non-finite state or energy.
    pub non_finite: usize,
    /// By a (nearly) singular N.
    pub degenerate: usize,
    /// By the engine's fibre- or branch-jump check of a forward step.
    pub jump: usize,
}

impl RejectionCounts {
    /// Counts one rejection.
    pub fn add(&mut self, kind: Rejection) {
        *self.get_mut(kind) += 1;
    }

    /// The count of one kind.
    ///
    /// ```
    /// use geoshake_runtime::sampler::{Rejection, RejectionCounts};
    /// let c = RejectionCounts { reverse: 3, ..Default::default() };
    /// assert_eq!(c.get(Rejection::Reverse), 3);
    /// ```
    pub fn get(&self, kind: Rejection) -> usize {
        match kind {
            Rejection::Metropolis => self.metropolis,
            Rejection::Reverse => self.reverse,
            Rejection::Newton => self.newton,
            Rejection::NonFinite => self.non_finite,
            Rejection::Degenerate => self.degenerate,
            Rejection::Jump => self.jump,
        }
    }

    fn get_mut(&mut self, kind: Rejection) -> &mut usize {
        match kind {
            Rejection::Metropolis => &mut self.metropolis,
            Rejection::Reverse => &mut self.reverse,
            Rejection::Newton => &mut self.newton,
            Rejection::NonFinite => &mut self.non_finite,
            Rejection::Degenerate => &mut self.degenerate,
            Rejection::Jump => &mut self.jump,
        }
    }

    /// All rejections.
    pub fn total(&self) -> usize {
        Rejection::ALL.iter().map(|&k| self.get(k)).sum()
    }

    /// Rejections by a check (every kind but the Metropolis test).
    pub fn by_checks(&self) -> usize {
        self.total() - self.metropolis
    }
}

/// The draws of a run and their statistics, chain-major: the draw i of
/// chain c is `positions[(c·draws + i)·dim ..][..dim]`, and entry
/// c·draws + i of every per-draw vector describes it. As arrays of shape
/// (chains, draws, dim) and (chains, draws) these are what ArviZ's
/// `from_dict` takes (`posterior`, `sample_stats`).
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    /// Number of chains.
    pub chains: usize,
    /// Draws per chain (after warm-up).
    pub draws: usize,
    /// d, the length of q.
    pub dim: usize,
    /// The positions q, (chains, draws, dim) row-major.
    pub positions: Vec<f64>,
    /// Whether the proposal of the transition was accepted (dynamic
    /// integration time: whether the draw left its start).
    pub accepted: Vec<bool>,
    /// The Metropolis acceptance probability min(1, e^{−ΔH}) of the
    /// proposal (0 when a check rejected it); with the dynamic integration
    /// time, its mean over the trajectory's states (Stan's statistic).
    pub acceptance_probability: Vec<f64>,
    /// H(q, p) of the state the transition kept: the proposal if accepted,
    /// else the start with its fresh momentum. NaN when that momentum
    /// could not be projected onto T*_q M (Π failed: the transition is a
    /// `newton`, `degenerate` or `jump` rejection with 0 steps, and there is
    /// no momentum to give an energy); skip NaN entries when averaging.
    pub energy: Vec<f64>,
    /// RATTLE steps taken (L, or fewer when a step failed; with the
    /// dynamic integration time, the trajectory's length).
    pub steps: Vec<usize>,
    /// Why the proposal was rejected (`None`: accepted).
    pub rejection: Vec<Option<Rejection>>,
    /// The step size h each chain sampled with (after adaptation).
    pub step_size: Vec<f64>,
}

impl Samples {
    /// Draw `i` of chain `c`; `None` when `c ≥ chains` or `i ≥ draws` (an
    /// index past a chain's end would otherwise read the next chain).
    ///
    /// ```
    /// # use geoshake_runtime::sampler::{sample, SamplerOptions};
    /// # use geoshake_runtime::examples::Pendulum;
    /// let opts = SamplerOptions { chains: 2, draws: 5, warmup: 0, ..Default::default() };
    /// let s = sample(&Pendulum { gravity: 0.0, length: 1.0 }, &[[1.0, 0.0]], &opts).unwrap();
    /// let q = s.draw(1, 4).unwrap();
    /// assert!((q[0] * q[0] + q[1] * q[1] - 1.0).abs() < 1e-12);
    /// assert!(s.draw(0, 5).is_none() && s.draw(2, 0).is_none());
    /// ```
    pub fn draw(&self, c: usize, i: usize) -> Option<&[f64]> {
        (c < self.chains && i < self.draws).then(|| self.draw_at(c, i))
    }

    /// Draw `i` of chain `c`, both in range.
    fn draw_at(&self, c: usize, i: usize) -> &[f64] {
        let at = (c * self.draws + i) * self.dim;
        &self.positions[at..at + self.dim]
    }

    /// The series f(q) of every chain, `[chain][draw]`: the input of
    /// [`Estimate::of`] for an expectation E(f).
    ///
    /// ```
    /// # use geoshake_runtime::sampler::{sample, SamplerOptions};
    /// # use geoshake_runtime::examples::Pendulum;
    /// let opts = SamplerOptions { chains: 2, draws: 5, warmup: 0, ..Default::default() };
    /// let s = sample(&Pendulum { gravity: 0.0, length: 1.0 }, &[[1.0, 0.0]], &opts).unwrap();
    /// let x2 = s.series(|q| q[0] * q[0]);
    /// assert_eq!((x2.len(), x2[0].len()), (2, 5));
    /// ```
    pub fn series(&self, f: impl Fn(&[f64]) -> f64) -> Vec<Vec<f64>> {
        (0..self.chains)
            .map(|c| (0..self.draws).map(|i| f(self.draw_at(c, i))).collect())
            .collect()
    }

    /// The rejections of chain `c` by kind.
    ///
    /// ```
    /// # use geoshake_runtime::sampler::{sample, SamplerOptions};
    /// # use geoshake_runtime::examples::Pendulum;
    /// let opts = SamplerOptions { chains: 1, draws: 50, warmup: 0, ..Default::default() };
    /// let s = sample(&Pendulum { gravity: 0.0, length: 1.0 }, &[[1.0, 0.0]], &opts).unwrap();
    /// let accepted = s.accepted.iter().filter(|a| **a).count();
    /// assert_eq!(s.rejections(0).total() + accepted, 50);
    /// ```
    pub fn rejections(&self, c: usize) -> RejectionCounts {
        let mut counts = RejectionCounts::default();
        for r in self.rejection[c * self.draws..(c + 1) * self.draws]
            .iter()
            .flatten()
        {
            counts.add(*r);
        }
        counts
    }

    /// Per coordinate: mean, standard deviation, R̂ and ESS; per chain:
    /// acceptance, step size, rejections.
    ///
    /// ```
    /// # use geoshake_runtime::sampler::{sample, SamplerOptions};
    /// # use geoshake_runtime::examples::Pendulum;
    /// let opts = SamplerOptions { chains: 2, draws: 400, warmup: 200, ..Default::default() };
    /// let s = sample(&Pendulum { gravity: 1.0, length: 1.0 }, &[[1.0, 0.0]], &opts).unwrap();
    /// let summary = s.summary();
    /// assert_eq!((summary.coordinates.len(), summary.chains.len()), (2, 2));
    /// assert!(summary.acceptance() > 0.5 && summary.min_ess_bulk() > 50.0);
    /// assert_eq!(summary.rejected().total(), s.rejections(0).total() + s.rejections(1).total());
    /// println!("{summary}"); // a table, then any warnings
    /// ```
    pub fn summary(&self) -> Summary {
        let coordinates = (0..self.dim)
            .map(|k| Estimate::of(&self.series(|q| q[k])))
            .collect();
        let chains = (0..self.chains)
            .map(|c| {
                let range = c * self.draws..(c + 1) * self.draws;
                let accepted = self.accepted[range].iter().filter(|a| **a).count();
                ChainSummary {
                    acceptance: accepted as f64 / self.draws as f64,
                    step_size: self.step_size[c],
                    rejected: self.rejections(c),
                    all_rejected: accepted == 0,
                }
            })
            .collect();
        Summary {
            coordinates,
            chains,
        }
    }
}

/// An expectation estimated from several chains of one series.
///
/// ```
/// use geoshake_runtime::sampler::Estimate;
/// let e = Estimate::of(&[vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0]]);
/// assert_eq!(e.mean, 5.5);
/// ```
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The mean over every chain and draw.
    pub mean: f64,
    /// The standard deviation of the draws.
    pub sd: f64,
    /// The Monte Carlo standard error of the mean, sd/√ESS_mean.
    pub mcse: f64,
    /// The ESS of the mean ([`ess_mean`]).
    pub ess_mean: f64,
    /// The bulk ESS ([`ess_bulk`]).
    pub ess_bulk: f64,
    /// The tail ESS ([`ess_tail`]).
    pub ess_tail: f64,
    /// The rank-normalised split-R̂ ([`rhat`]).
    pub rhat: f64,
}

impl Estimate {
    /// Estimates the expectation of x from chains `[chain][draw]` of x.
    pub fn of<C: AsRef<[f64]>>(chains: &[C]) -> Estimate {
        let all = || chains.iter().flat_map(|c| c.as_ref().iter().copied());
        let n = all().count() as f64;
        let mean = all().sum::<f64>() / n;
        let sd = (all().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)).sqrt();
        let ess_mean = ess_mean(chains);
        Estimate {
            mean,
            sd,
            mcse: sd / ess_mean.sqrt(),
            ess_mean,
            ess_bulk: ess_bulk(chains),
            ess_tail: ess_tail(chains),
            rhat: rhat(chains),
        }
    }
}

/// One chain at a glance.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct ChainSummary {
    /// Accepted proposals over draws.
    pub acceptance: f64,
    /// The step size it sampled with.
    pub step_size: f64,
    /// Its rejections by kind.
    pub rejected: RejectionCounts,
    /// No proposal was accepted: the chain never moved, and its draws say
    /// nothing about the target (the step size, or the start, is wrong).
    pub all_rejected: bool,
}

/// A run at a glance: [`Estimate`] per coordinate, [`ChainSummary`] per
/// chain. Its `Display` is a small table, then its
/// [warnings](Summary::warnings).
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Per coordinate q_k.
    pub coordinates: Vec<Estimate>,
    /// Per chain.
    pub chains: Vec<ChainSummary>,
}

impl Summary {
    /// The largest R̂ over the coordinates (NaN if any is NaN: a
    /// coordinate that never moved).
    pub fn max_rhat(&self) -> f64 {
        self.coordinates
            .iter()
            .map(|e| e.rhat)
            .fold(f64::NEG_INFINITY, |a, b| {
                if a.is_nan() || b.is_nan() {
                    f64::NAN
                } else {
                    a.max(b)
                }
            })
    }

    /// The smallest bulk ESS over the coordinates.
    pub fn min_ess_bulk(&self) -> f64 {
        self.coordinates
            .iter()
            .map(|e| e.ess_bulk)
            .fold(f64::INFINITY, |a, b| {
                if a.is_nan() || b.is_nan() {
                    f64::NAN
                } else {
                    a.min(b)
                }
            })
    }

    /// Accepted proposals over all draws.
    pub fn acceptance(&self) -> f64 {
        let n = self.chains.len() as f64;
        self.chains.iter().map(|c| c.acceptance).sum::<f64>() / n
    }

    /// Rejections by kind over all chains.
    pub fn rejected(&self) -> RejectionCounts {
        let mut total = RejectionCounts::default();
        for c in &self.chains {
            for k in Rejection::ALL {
                *total.get_mut(k) += c.rejected.get(k);
            }
        }
        total
    }

    /// What a user must know, with Vehtari et al.'s (2021) thresholds:
    ///
    /// - a chain that accepted no proposal (its draws are its start), or
    ///   fewer than [`Summary::MIN_ACCEPTANCE`] = 1 % of them (it hardly
    ///   moves: h is far too large, or the start is in a trap);
    /// - a coordinate whose R̂ is above [`Summary::MAX_RHAT`] = 1.01, or
    ///   NaN (chains that each stayed constant, at different values);
    /// - a coordinate whose bulk or tail ESS is below
    ///   [`Summary::MIN_ESS_PER_CHAIN`] = 100 per chain: below that R̂ and
    ///   the Monte Carlo standard errors themselves are not reliable.
    ///
    /// A coordinate constant over every draw of every chain is skipped: it
    /// is fixed on M (a sphere's coordinate of a flat family, a pinned
    /// entry), and its NaN R̂ and ESS say nothing about mixing; a chain
    /// stuck at its start is reported by the acceptance line instead.
    ///
    /// ```
    /// use geoshake_runtime::sampler::{ChainSummary, Estimate, RejectionCounts, Summary};
    /// let chain = |acceptance: f64| ChainSummary {
    ///     acceptance, step_size: 0.1, rejected: RejectionCounts::default(), all_rejected: false,
    /// };
    /// let mixed = Estimate { mean: 0.0, sd: 1.0, mcse: 0.02, ess_mean: 2500.0, ess_bulk: 2500.0, ess_tail: 2000.0, rhat: 1.001 };
    /// let fixed = Estimate { mean: 1.0, sd: 0.0, mcse: f64::NAN, ess_mean: f64::NAN, ess_bulk: f64::NAN, ess_tail: f64::NAN, rhat: f64::NAN };
    /// let ok = Summary { coordinates: vec![mixed, fixed], chains: vec![chain(0.8), chain(0.7)] };
    /// assert!(ok.warnings().is_empty());
    /// let slow = Summary { chains: vec![chain(0.8), chain(0.005)], ..ok.clone() };
    /// assert!(slow.warnings()[0].contains("chain 1 accepted 0.5 %"));
    /// let short = Estimate { ess_tail: 150.0, ..mixed };
    /// let few = Summary { coordinates: vec![short], ..ok };
    /// assert!(few.warnings()[0].contains("tail ESS"));
    /// ```
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (c, s) in self.chains.iter().enumerate() {
            if !s.all_rejected && s.acceptance < Self::MIN_ACCEPTANCE {
                out.push(format!(
                    "chain {c} accepted {:.1} % of its proposals with h = {:e}: it hardly moves",
                    100.0 * s.acceptance,
                    s.step_size
                ));
            }
            if s.all_rejected {
                let worst = Rejection::ALL
                    .into_iter()
                    .max_by_key(|&k| s.rejected.get(k))
                    .unwrap_or(Rejection::Metropolis);
                out.push(format!(
                    "chain {c} rejected every proposal (mostly by the {} check) with h = {:e}: \
                     its draws are its start repeated",
                    worst.name(),
                    s.step_size
                ));
            }
        }
        let min_ess = Self::MIN_ESS_PER_CHAIN * self.chains.len() as f64;
        for (k, e) in self.coordinates.iter().enumerate() {
            if e.sd == 0.0 {
                continue;
            }
            if !(e.rhat <= Self::MAX_RHAT) {
                out.push(format!(
                    "q[{k}]: R̂ = {:.3} > {}: the chains have not mixed; run longer",
                    e.rhat,
                    Self::MAX_RHAT
                ));
            }
            for (what, ess) in [("bulk", e.ess_bulk), ("tail", e.ess_tail)] {
                if !(ess >= min_ess) {
                    out.push(format!(
                        "q[{k}]: {what} ESS = {ess:.0} < {min_ess:.0} ({} per chain): too few to trust R̂ and the standard errors; run longer",
                        Self::MIN_ESS_PER_CHAIN
                    ));
                }
            }
        }
        out
    }

    /// R̂ above this is a warning (Vehtari et al. 2021).
    pub const MAX_RHAT: f64 = 1.01;
    /// A chain accepting less than this fraction of its proposals is a
    /// warning.
    pub const MIN_ACCEPTANCE: f64 = 0.01;
    /// A bulk or tail ESS below this many per chain is a warning (Vehtari
    /// et al. 2021: 100 per chain, 400 for four chains).
    pub const MIN_ESS_PER_CHAIN: f64 = 100.0;
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "coordinate       mean         sd       mcse   ess_bulk   ess_tail   rhat"
        )?;
        for (k, e) in self.coordinates.iter().enumerate() {
            writeln!(
                f,
                "q[{k:<3}]   {:>11.5} {:>10.5} {:>10.2e} {:>10.0} {:>10.0} {:>6.3}",
                e.mean, e.sd, e.mcse, e.ess_bulk, e.ess_tail, e.rhat
            )?;
        }
        for (c, s) in self.chains.iter().enumerate() {
            let r = s.rejected;
            writeln!(
                f,
                "chain {c}: acceptance {:.3}, h = {:.4e}, rejected metropolis={} reverse={} newton={} non_finite={} degenerate={} jump={}",
                s.acceptance,
                s.step_size,
                r.metropolis,
                r.reverse,
                r.newton,
                r.non_finite,
                r.degenerate,
                r.jump
            )?;
        }
        for w in self.warnings() {
            writeln!(f, "warning: {w}")?;
        }
        Ok(())
    }
}
