//! Step-size adaptation in warm-up: the dual averaging of Hoffman and
//! Gelman (2014, Section 3.2.1, Algorithm 5), with their constants.
//!
//! After warm-up transition t with acceptance statistic α_t (the
//! Metropolis probability min(1, e^{−ΔH}), 0 for a proposal rejected by a
//! check):
//!
//!   H̄_t = (1 − 1/(t + t₀)) H̄_{t−1} + (δ − α_t)/(t + t₀),
//!   log h_t = μ − (√t/γ) H̄_t,
//!   log h̄_t = t^{−κ} log h_t + (1 − t^{−κ}) log h̄_{t−1},
//!
//! with δ the target acceptance, μ = log(10 h₀), γ = 0.05, t₀ = 10,
//! κ = 0.75. Warm-up transitions use h_t; sampling uses h̄ at the end of
//! warm-up, which averages the noise out of h_t.

/// γ: how strongly log h is pulled towards μ.
const GAMMA: f64 = 0.05;
/// t₀: damps the first iterations.
const T0: f64 = 10.0;
/// κ: the decay of the weights of h̄.
const KAPPA: f64 = 0.75;
/// log h stays within e^{±LOG_LIMIT}: far beyond any usable step, yet
/// finite, so the engine sees a number (a step that large fails, which
/// pulls h back down) and never an infinity.
const LOG_LIMIT: f64 = 690.0;

/// The state of the dual averaging of one chain.
#[derive(Clone, Debug)]
pub(crate) struct DualAveraging {
    target: f64,
    mu: f64,
    /// H̄_t, the running mean of δ − α.
    error: f64,
    log_h: f64,
    log_h_bar: f64,
    t: u64,
}

impl DualAveraging {
    /// Starts from h₀ towards the acceptance `target` ∈ (0, 1).
    pub(crate) fn new(h0: f64, target: f64) -> Self {
        DualAveraging {
            target,
            mu: (10.0 * h0).ln(),
            error: 0.0,
            log_h: h0.ln(),
            log_h_bar: 0.0,
            t: 0,
        }
    }

    /// The step size of the next warm-up transition.
    pub(crate) fn step_size(&self) -> f64 {
        self.log_h.exp()
    }

    /// The step size for sampling: h̄ (h₀ itself if no update was made).
    pub(crate) fn final_step_size(&self) -> f64 {
        if self.t == 0 {
            self.log_h.exp()
        } else {
            self.log_h_bar.exp()
        }
    }

    /// Takes the acceptance statistic of one warm-up transition (NaN
    /// counts as 0: a transition that failed accepted nothing).
    pub(crate) fn update(&mut self, alpha: f64) {
        let alpha = if alpha.is_nan() {
            0.0
        } else {
            alpha.clamp(0.0, 1.0)
        };
        self.t += 1;
        let t = self.t as f64;
        let eta = 1.0 / (t + T0);
        self.error = (1.0 - eta) * self.error + eta * (self.target - alpha);
        self.log_h = (self.mu - t.sqrt() / GAMMA * self.error).clamp(-LOG_LIMIT, LOG_LIMIT);
        let w = t.powf(-KAPPA);
        self.log_h_bar = w * self.log_h + (1.0 - w) * self.log_h_bar;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With α a decreasing function of h, the iteration settles where α
    /// meets the target: α(h) = e^{−h} reaches 0.8 at h = −log 0.8.
    #[test]
    fn finds_the_step_of_the_target_acceptance() {
        let mut da = DualAveraging::new(1.0, 0.8);
        for _ in 0..2000 {
            let h = da.step_size();
            da.update((-h).exp());
        }
        let h = da.final_step_size();
        assert!((h - (-(0.8f64).ln())).abs() < 0.01, "h = {h}");
    }

    /// Every proposal failing drives h down, never to zero or NaN.
    #[test]
    fn all_rejected_shrinks_the_step() {
        let mut da = DualAveraging::new(0.5, 0.8);
        for _ in 0..100_000 {
            da.update(f64::NAN);
        }
        let h = da.final_step_size();
        assert!(h > 0.0 && h < 1e-10, "h = {h}");
    }
}
