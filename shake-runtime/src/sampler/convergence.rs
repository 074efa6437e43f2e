//! Convergence diagnostics of several chains: the rank-normalised split-R̂
//! and the bulk effective sample size of Vehtari, Gelman, Simpson,
//! Carpenter and Bürkner (2021, "Rank-normalization, folding, and
//! localization: an improved R̂ for assessing convergence of MCMC",
//! Bayesian Analysis 16(2)), computed as ArviZ and Stan compute them.
//!
//! - *Split*: each chain of n draws is cut into its first and last ⌊n/2⌋
//!   draws, so that a trend inside a chain shows as two chains that
//!   disagree.
//! - *Rank normalisation*: the S pooled draws are replaced by
//!   z = Φ⁻¹((r − 3/8)/(S + 1/4)), r their rank (ties get the mean rank);
//!   the diagnostics then do not depend on monotone transformations and
//!   exist for heavy tails.
//! - R̂ = √((n − 1)/n + B/(nW)) over the split chains (W the mean
//!   within-chain variance, B/n the variance of the chain means); the
//!   rank-normalised R̂ is the larger of R̂(z(x)) and R̂(z(|x − median x|)),
//!   the second seeing chains that differ in scale only.
//! - ESS = M n / τ, τ = −1 + 2 Σ ρ̂_t summed by Geyer's initial monotone
//!   sequence, with ρ̂_t = 1 − (W − mean_m acov_m(t))/var⁺ the combined
//!   autocorrelation of the M chains and var⁺ = (n − 1)/n W + B/n. The
//!   bulk ESS is that of the rank-normalised split chains; the ESS of the
//!   mean (for a Monte Carlo standard error, sd/√ESS) is that of the split
//!   chains themselves. τ is kept at least 1/log₁₀(S) (S = M n), so the
//!   ESS of antithetic chains is at most S·log₁₀(S); chains so antithetic
//!   that 1 + ρ̂₁ ≤ 0 (Geyer's sum has no first pair) get that cap, as in
//!   ArviZ.
//!
//! - The tail ESS is the smaller ESS of the indicators I(x ≤ q₀.₀₅) and
//!   I(x ≤ q₀.₉₅) of the split chains.
//!
//! Chains of unequal length are cut to the shortest. Fewer than four
//! draws per chain (ten for an ESS: Geyer's sequence needs a pair of lags
//! in each half), chains that are all constant, or a NaN among the draws
//! (as ArviZ: ranks of NaN mean nothing) give NaN.

/// The rank-normalised split-R̂ (Vehtari et al. 2021): near 1 when the
/// chains agree, above 1.01 a sign that they have not mixed.
///
/// ```
/// use geoshake_runtime::sampler::rhat;
/// // Two chains that sample disjoint regions: R̂ far above 1 (ranks bound
/// // it: about 1.8 for two chains of 100 draws).
/// let a: Vec<f64> = (0..100).map(|i| (i as f64 * 0.7).sin()).collect();
/// let b: Vec<f64> = a.iter().map(|x| x + 5.0).collect();
/// assert!(rhat(&[&a, &b]) > 1.5);
/// assert!((rhat(&[&a[..50], &a[50..]]) - 1.0).abs() < 0.05);
/// ```
pub fn rhat<C: AsRef<[f64]>>(chains: &[C]) -> f64 {
    let Some(split) = split_chains(chains) else {
        return f64::NAN;
    };
    let bulk = plain_rhat(&rank_normalise(&split));
    let median = median(split.iter().flatten().copied());
    let folded: Vec<Vec<f64>> = split
        .iter()
        .map(|c| c.iter().map(|x| (x - median).abs()).collect())
        .collect();
    let tail = plain_rhat(&rank_normalise(&folded));
    if bulk.is_nan() || tail.is_nan() {
        f64::NAN
    } else {
        bulk.max(tail)
    }
}

/// The bulk effective sample size (Vehtari et al. 2021): the ESS of the
/// rank-normalised split chains, a measure of how well the chains explore
/// the centre of the distribution.
///
/// ```
/// use geoshake_runtime::sampler::ess_bulk;
/// // An AR(1) chain x_t = 0.9 x_{t−1} + e_t has τ = (1 + 0.9)/(1 − 0.9) = 19.
/// let mut x = vec![0.0f64; 4000];
/// let mut s = 1u64;
/// for t in 1..x.len() {
///     // A small LCG: the uniforms' sum, centred, as the noise.
///     let mut e = 0.0;
///     for _ in 0..12 {
///         s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
///         e += (s >> 11) as f64 / (1u64 << 53) as f64;
///     }
///     x[t] = 0.9 * x[t - 1] + (e - 6.0);
/// }
/// let ess = ess_bulk(&[&x]);
/// assert!(ess > 4000.0 / 19.0 / 2.0 && ess < 4000.0 / 19.0 * 2.0, "{ess}");
/// ```
pub fn ess_bulk<C: AsRef<[f64]>>(chains: &[C]) -> f64 {
    match split_chains(chains) {
        Some(split) => ess(&rank_normalise(&split)),
        None => f64::NAN,
    }
}

/// The effective sample size for the mean (split chains, no rank
/// normalisation): the Monte Carlo standard error of the mean of the
/// draws is their standard deviation over √ESS.
///
/// ```
/// use geoshake_runtime::sampler::ess_mean;
/// // Alternating draws are anticorrelated: the mean is known better than
/// // from independent draws, ESS > the number of draws.
/// let x: Vec<f64> = (0..400).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 } + 0.01 * (i as f64).sin()).collect();
/// assert!(ess_mean(&[&x]) > 400.0);
/// ```
pub fn ess_mean<C: AsRef<[f64]>>(chains: &[C]) -> f64 {
    match split_chains(chains) {
        Some(split) => ess(&split),
        None => f64::NAN,
    }
}

/// The tail effective sample size (Vehtari et al. 2021): the smaller ESS
/// of the indicators I(x ≤ q₀.₀₅) and I(x ≤ q₀.₉₅) over the split chains,
/// q_p the pooled draws' p-quantile (linear interpolation, NumPy's
/// default, as ArviZ): how well the chains explore the tails, where the
/// 5 % and 95 % quantiles of an interval are estimated.
///
/// ```
/// use geoshake_runtime::sampler::ess_tail;
/// let a: Vec<f64> = (0..200).map(|i| (i as f64 * 0.618_033_988_75).fract()).collect();
/// let b: Vec<f64> = a.iter().rev().copied().collect();
/// let ess = ess_tail(&[&a, &b]);
/// assert!(ess > 100.0, "{ess}");
/// ```
pub fn ess_tail<C: AsRef<[f64]>>(chains: &[C]) -> f64 {
    let Some(split) = split_chains(chains) else {
        return f64::NAN;
    };
    // The quantiles of the chains as given (cut to the shortest), as
    // ArviZ: the split drops an odd n's middle draw, the quantile keeps it.
    let n = chains.iter().map(|c| c.as_ref().len()).min().unwrap_or(0);
    let mut pooled: Vec<f64> = chains
        .iter()
        .flat_map(|c| c.as_ref()[..n].iter().copied())
        .collect();
    pooled.sort_by(f64::total_cmp);
    let quantile = |p: f64| {
        let h = (pooled.len() - 1) as f64 * p;
        let lo = h.floor() as usize;
        let hi = (lo + 1).min(pooled.len() - 1);
        pooled[lo] + (h - lo as f64) * (pooled[hi] - pooled[lo])
    };
    let below = |q: f64| -> Vec<Vec<f64>> {
        split
            .iter()
            .map(|c| c.iter().map(|&x| if x <= q { 1.0 } else { 0.0 }).collect())
            .collect()
    };
    let lower = ess(&below(quantile(0.05)));
    let upper = ess(&below(quantile(0.95)));
    if lower.is_nan() || upper.is_nan() {
        f64::NAN
    } else {
        lower.min(upper)
    }
}

/// The chains cut to the shortest and split in halves; `None` with fewer
/// than four draws per chain (two per half) or no chain.
fn split_chains<C: AsRef<[f64]>>(chains: &[C]) -> Option<Vec<Vec<f64>>> {
    let n = chains.iter().map(|c| c.as_ref().len()).min()?;
    if n < 4
        || chains
            .iter()
            .any(|c| c.as_ref()[..n].iter().any(|x| x.is_nan()))
    {
        return None;
    }
    let half = n / 2;
    let mut out = Vec::with_capacity(2 * chains.len());
    for c in chains {
        let c = &c.as_ref()[..n];
        out.push(c[..half].to_vec());
        out.push(c[n - half..].to_vec());
    }
    Some(out)
}

fn median(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.collect();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// z = Φ⁻¹((r − 3/8)/(S + 1/4)) of the pooled draws, ties at their mean
/// rank (Blom's offsets, as Vehtari et al.).
fn rank_normalise(chains: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let total: usize = chains.iter().map(Vec::len).sum();
    let mut order: Vec<(f64, usize, usize)> = Vec::with_capacity(total);
    for (c, chain) in chains.iter().enumerate() {
        for (i, &x) in chain.iter().enumerate() {
            order.push((x, c, i));
        }
    }
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<Vec<f64>> = chains.iter().map(|c| vec![0.0; c.len()]).collect();
    let s = total as f64;
    let mut start = 0;
    while start < total {
        let mut end = start + 1;
        // `==`, not `total_cmp`: −0.0 and 0.0 are one value, a tie.
        while end < total && order[end].0 == order[start].0 {
            end += 1;
        }
        // Ranks start..end − 1 counted from 1: their mean.
        let rank = 0.5 * ((start + 1) + end) as f64;
        let z = normal_quantile((rank - 0.375) / (s + 0.25));
        for &(_, c, i) in &order[start..end] {
            out[c][i] = z;
        }
        start = end;
    }
    out
}

/// Mean and unbiased variance of one chain.
fn mean_var(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0);
    (mean, var)
}

/// R̂ of chains of equal length n ≥ 2.
fn plain_rhat(chains: &[Vec<f64>]) -> f64 {
    let n = chains[0].len() as f64;
    let stats: Vec<(f64, f64)> = chains.iter().map(|c| mean_var(c)).collect();
    let within = stats.iter().map(|s| s.1).sum::<f64>() / stats.len() as f64;
    let means: Vec<f64> = stats.iter().map(|s| s.0).collect();
    let between = n * mean_var(&means).1;
    if !(within > 0.0) {
        return f64::NAN;
    }
    ((between / within + n - 1.0) / n).sqrt()
}

/// The ESS of chains of equal length n ≥ 2 (Geyer's initial monotone
/// sequence on the combined autocorrelation; Stan's and ArviZ's estimator).
fn ess(chains: &[Vec<f64>]) -> f64 {
    let m = chains.len() as f64;
    let n = chains[0].len();
    if n < 5 {
        return f64::NAN;
    }
    let nf = n as f64;
    let means: Vec<f64> = chains.iter().map(|c| c.iter().sum::<f64>() / nf).collect();
    // The mean over chains of the biased autocovariance at lag t.
    let acov = |t: usize| -> f64 {
        chains
            .iter()
            .zip(&means)
            .map(|(c, mu)| {
                c[..n - t]
                    .iter()
                    .zip(&c[t..])
                    .map(|(a, b)| (a - mu) * (b - mu))
                    .sum::<f64>()
                    / nf
            })
            .sum::<f64>()
            / m
    };
    let mean_var = acov(0) * nf / (nf - 1.0);
    let mut var_plus = mean_var * (nf - 1.0) / nf;
    if chains.len() > 1 {
        var_plus += mean_var_of(&means);
    }
    if !(var_plus > 0.0) || !var_plus.is_finite() {
        return f64::NAN;
    }
    let rho = |t: usize| 1.0 - (mean_var - acov(t)) / var_plus;
    let mut rho_hat = vec![0.0; n];
    rho_hat[0] = 1.0;
    let mut even = 1.0;
    let mut odd = rho(1);
    rho_hat[1] = odd;
    // Geyer's initial positive sequence: sums of pairs while positive.
    let mut t = 1;
    while t + 3 < n && even + odd > 0.0 {
        even = rho(t + 1);
        odd = rho(t + 2);
        if even + odd >= 0.0 {
            rho_hat[t + 1] = even;
            rho_hat[t + 2] = odd;
        }
        t += 2;
    }
    let total = m * nf;
    // τ ≥ 1/log₁₀(S) caps the ESS of antithetic chains at S·log₁₀(S).
    let cap = 1.0 / total.log10();
    if t == 1 {
        // The loop never ran: 1 + ρ̂₁ ≤ 0 (antithetic chains), and no pair
        // of lags enters τ. ArviZ's sum is then over no pair, plus ρ̂₀ = 1
        // as the last term: τ = −1 + 1 = 0, capped like any small τ.
        return total / cap;
    }
    let max_t = t - 2;
    if even > 0.0 {
        rho_hat[max_t + 1] = even;
    }
    // ... made monotone.
    let mut t = 1;
    while t + 2 <= max_t {
        if rho_hat[t + 1] + rho_hat[t + 2] > rho_hat[t - 1] + rho_hat[t] {
            rho_hat[t + 1] = 0.5 * (rho_hat[t - 1] + rho_hat[t]);
            rho_hat[t + 2] = rho_hat[t + 1];
        }
        t += 2;
    }
    let tau = -1.0 + 2.0 * rho_hat[..=max_t].iter().sum::<f64>() + rho_hat[max_t + 1];
    total / tau.max(cap)
}

/// The unbiased variance of a few numbers.
fn mean_var_of(x: &[f64]) -> f64 {
    mean_var(x).1
}

/// Φ⁻¹(p), the standard normal quantile, by Wichura's algorithm AS 241
/// (PPND16, Applied Statistics 37, 1988), accurate to about 1e-16.
// The coefficients as published, so that they can be checked against the
// paper digit by digit; f64 rounds them as the compiler reads them.
#[allow(clippy::excessive_precision)]
pub(crate) fn normal_quantile(p: f64) -> f64 {
    if !(p > 0.0 && p < 1.0) {
        return match p {
            0.0 => f64::NEG_INFINITY,
            1.0 => f64::INFINITY,
            _ => f64::NAN,
        };
    }
    let q = p - 0.5;
    if q.abs() <= 0.425 {
        let r = 0.180625 - q * q;
        return q
            * (((((((r * 2509.0809287301226727 + 33430.575583588128105) * r
                + 67265.770927008700853)
                * r
                + 45921.953931549871457)
                * r
                + 13731.693765509461125)
                * r
                + 1971.5909503065514427)
                * r
                + 133.14166789178437745)
                * r
                + 3.387132872796366608)
            / (((((((r * 5226.495278852545925 + 28729.085735721942674) * r
                + 39307.89580009271061)
                * r
                + 21213.794301586595867)
                * r
                + 5394.1960214247511077)
                * r
                + 687.1870074920579083)
                * r
                + 42.313330701600911252)
                * r
                + 1.0);
    }
    let mut r = if q < 0.0 { p } else { 1.0 - p };
    r = (-r.ln()).sqrt();
    let value = if r <= 5.0 {
        r -= 1.6;
        (((((((r * 7.7454501427834140764e-4 + 0.0227238449892691845833) * r
            + 0.24178072517745061177)
            * r
            + 1.27045825245236838258)
            * r
            + 3.64784832476320460504)
            * r
            + 5.7694972214606914055)
            * r
            + 4.6303378461565452959)
            * r
            + 1.42343711074968357734)
            / (((((((r * 1.05075007164441684324e-9 + 5.475938084995344946e-4) * r
                + 0.0151986665636164571966)
                * r
                + 0.14810397642748007459)
                * r
                + 0.68976733498510000455)
                * r
                + 1.6763848301838038494)
                * r
                + 2.05319162663775882187)
                * r
                + 1.0)
    } else {
        r -= 5.0;
        (((((((r * 2.01033439929228813265e-7 + 2.71155556874348757815e-5) * r
            + 0.0012426609473880784386)
            * r
            + 0.026532189526576123093)
            * r
            + 0.29656057182850489123)
            * r
            + 1.7848265399172913358)
            * r
            + 5.4637849111641143699)
            * r
            + 6.6579046435011037772)
            / (((((((r * 2.04426310338993978564e-15 + 1.4215117583164458887e-7) * r
                + 1.8463183175100546818e-5)
                * r
                + 7.868691311456132591e-4)
                * r
                + 0.0148753612908506148525)
                * r
                + 0.13692988092273580531)
                * r
                + 0.59983220655588793769)
                * r
                + 1.0)
    };
    if q < 0.0 {
        -value
    } else {
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The upper tail 1 − Φ(x) = ∫ₓ^{x+16} φ for x ≥ 0, by composite
    /// Simpson with 200 000 panels (relative error below 1e-12 for x ≤ 22,
    /// where φ⁗/φ ≈ x⁴; the rest of the tail is below e^{−128}): an oracle
    /// independent of AS 241.
    fn upper_tail(x: f64) -> f64 {
        let n = 200_000;
        let h = 16.0 / n as f64;
        let f = |t: f64| (-0.5 * t * t).exp() / (2.0 * std::f64::consts::PI).sqrt();
        let mut s = f(x) + f(x + 16.0);
        for k in 1..n {
            s += f(x + k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
        }
        s * h / 3.0
    }

    #[test]
    fn normal_quantile_inverts_the_cdf() {
        // The three branches of AS 241: central, r ≤ 5, r > 5 (p < e^{−25}).
        for &p in &[0.6, 0.9, 0.975, 0.99, 0.3, 1e-3, 1e-6, 1e-12, 1e-20, 1e-100] {
            let x = normal_quantile(p);
            // The smaller of p and 1 − p, from the tail on its side.
            let (tail, want) = if x < 0.0 {
                (upper_tail(-x), p)
            } else {
                (upper_tail(x), 1.0 - p)
            };
            assert!(
                (tail - want).abs() <= 1e-12 * want,
                "p = {p}: x = {x}, tail {tail} vs {want}"
            );
        }
        assert!((normal_quantile(0.975) - 1.959963984540054).abs() < 1e-15);
        assert_eq!(normal_quantile(0.5), 0.0);
        assert!(normal_quantile(0.0).is_infinite() && normal_quantile(1.5).is_nan());
    }

    /// R̂ of chains drawn alike is near 1, and it sees chains that differ
    /// only in scale (the folded half).
    #[test]
    fn rhat_sees_location_and_scale() {
        let base: Vec<f64> = (0..1000)
            .map(|i| normal_quantile((i as f64 * 0.618_033_988_75).fract().max(1e-9)))
            .collect();
        let a = base[..500].to_vec();
        let b = base[500..].to_vec();
        let same = rhat(&[&a, &b]);
        assert!((same - 1.0).abs() < 0.01, "{same}");
        let wide: Vec<f64> = b.iter().map(|x| 3.0 * x).collect();
        assert!(rhat(&[&a, &wide]) > 1.05);
    }

    /// Independent draws have ESS near their number (both estimators),
    /// and constant chains have none.
    #[test]
    fn ess_of_independent_and_constant_chains() {
        // A 64-bit LCG's top bits as uniforms, through Φ⁻¹: independent
        // normals as far as these estimators can tell.
        let mut s = 42u64;
        let mut u = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let chains: Vec<Vec<f64>> = (0..4)
            .map(|_| (0..1000).map(|_| normal_quantile(u())).collect())
            .collect();
        for ess in [ess_bulk(&chains), ess_mean(&chains)] {
            // The estimator's own spread at S = 4000 is a few per cent.
            assert!(ess > 3400.0 && ess < 4700.0, "{ess}");
        }
        let flat = vec![vec![1.0; 100]; 2];
        assert!(ess_mean(&flat).is_nan() && rhat(&flat).is_nan());
        assert!(ess_bulk(&[[1.0, 2.0, 3.0]]).is_nan());
    }

    /// Exactly alternating chains have ρ̂₁ ≤ −1, so Geyer's loop never
    /// runs (its first pair sum 1 + ρ̂₁ is not positive): τ = 0 as in
    /// ArviZ, and the ESS is the cap S·log₁₀(S), not a panic.
    #[test]
    fn ess_of_exactly_alternating_chains_is_capped() {
        for (chains, n) in [(1, 20), (2, 20), (4, 64)] {
            let x: Vec<Vec<f64>> = (0..chains)
                .map(|_| {
                    (0..n)
                        .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
                        .collect()
                })
                .collect();
            let s = (chains * n) as f64;
            let cap = s * s.log10();
            for ess in [ess_mean(&x), ess_bulk(&x)] {
                assert!((ess - cap).abs() <= 1e-12 * cap, "{ess} vs {cap}");
            }
        }
    }

    /// The three estimators against ArviZ (arviz-stats 0.8:
    /// `ess(method="bulk")`, `ess(method="mean")`, `rhat(method="rank")`)
    /// on three chains of 101 draws (odd: the split drops the middle one),
    /// and on the same rounded to halves (ties, and −0.0 beside 0.0).
    #[test]
    fn agrees_with_arviz() {
        let chains: Vec<Vec<f64>> = (0..3)
            .map(|c| {
                (0..101)
                    .map(|t| {
                        let (t, c) = (t as f64, c as f64);
                        (0.9 * t + c).sin()
                            + 0.3 * (0.05 * t * (c + 1.0)).sin()
                            + 0.1 * ((7.0 * t + 3.0 * c) % 11.0)
                    })
                    .collect()
            })
            .collect();
        let rounded: Vec<Vec<f64>> = chains
            .iter()
            .map(|c| c.iter().map(|x| (2.0 * x).round() / 2.0).collect())
            .collect();
        let cases = [
            (
                &chains,
                [161.27770874496144, 156.6984704660489, 0.9997289400314645],
            ),
            (
                &rounded,
                [162.43960487960524, 159.07448916289724, 1.0017144572377483],
            ),
        ];
        for (x, want) in cases {
            let got = [ess_bulk(x), ess_mean(x), rhat(x)];
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() <= 1e-10 * w, "{got:?} vs ArviZ {want:?}");
            }
        }
    }

    /// One NaN among 400 draws: every diagnostic is NaN, never a number
    /// computed from ranks that the NaN made meaningless.
    #[test]
    fn a_nan_draw_gives_nan() {
        let mut chains: Vec<Vec<f64>> = (0..4)
            .map(|c| (0..100).map(|i| ((i * 7 + c * 13) % 17) as f64).collect())
            .collect();
        assert!(rhat(&chains).is_finite() && ess_bulk(&chains).is_finite());
        chains[2][37] = f64::NAN;
        for (name, v) in [
            ("rhat", rhat(&chains)),
            ("ess_bulk", ess_bulk(&chains)),
            ("ess_mean", ess_mean(&chains)),
            ("ess_tail", ess_tail(&chains)),
        ] {
            assert!(v.is_nan(), "{name} = {v}");
        }
    }
}
