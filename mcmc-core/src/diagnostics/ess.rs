//! Effective sample sizes (ESS): Geyer's initial monotone sequence on the multi-chain
//! autocorrelation, applied to raw, rank-normalised or indicator-transformed draws.

use super::DiagnosticsError;
use super::autocorr::AutocovPlan;
use super::draws::{DrawMatrix, MIN_DRAWS_SPLIT, mean, variance};
use super::rank::{quantile_sorted, sorted, z_scale};

/// Draws spanning less than this (absolute) are constant: ArviZ's threshold
/// (`numpy.finfo(float).resolution`).
const CONSTANT_RESOLUTION: f64 = 1e-15;

/// Lower tail probability of the tail ESS; the upper one is `1 − TAIL_PROB`.
const TAIL_PROB: f64 = 0.05;

/// Multi-chain ESS of `m` as given (no splitting), Vehtari et al. (2021) §3.2, Eq. 10,
/// exactly as Stan and ArviZ (`_ess`) compute it:
///
/// * `γ̂_{c}(t)` the biased FFT autocovariance of chain `c` (see [`super::autocovariance`]);
///   `W = mean_c γ̂_c(0) · n/(n−1)`; `var⁺ = W (n−1)/n + var(chain means)` (the second term
///   only for more than one chain);
/// * combined autocorrelation `ρ̂(t) = 1 − (W − mean_c γ̂_c(t)) / var⁺`;
/// * Geyer's initial positive sequence: sum pairs `P̂_k = ρ̂(2k) + ρ̂(2k+1)` while positive,
///   then the initial monotone sequence (each pair sum capped by the previous one);
/// * `τ̂ = −1 + 2 Σ_{t=0}^{2K+1} ρ̂(t) + ρ̂(2K+2)`: the last term, kept when positive, is
///   Stan's improvement for antithetic chains whose ρ̂ alternates in sign;
/// * `τ̂ ≥ 1/log₁₀(N)`, so `ESS = N/τ̂ ≤ N log₁₀ N` (N = total draws).
///
/// Returns `NaN` when the draws are constant (the documented degenerate behaviour).
pub(crate) fn ess_core(m: &DrawMatrix) -> f64 {
    if is_constant(&m.data) {
        return f64::NAN;
    }
    let (n_chain, n) = (m.chains, m.draws);
    let nf = n as f64;
    // Mean over chains of the autocovariance at every lag.
    let mut acov = vec![0.0; n];
    let mut one = vec![0.0; n];
    let mut plan = AutocovPlan::new(n);
    for c in 0..n_chain {
        plan.compute(m.chain(c), &mut one);
        for (a, o) in acov.iter_mut().zip(&one) {
            *a += o;
        }
    }
    for a in &mut acov {
        *a /= n_chain as f64;
    }
    let chain_means: Vec<f64> = (0..n_chain).map(|c| mean(m.chain(c))).collect();
    let mean_var = acov[0] * nf / (nf - 1.0);
    let mut var_plus = mean_var * (nf - 1.0) / nf;
    if n_chain > 1 {
        var_plus += variance(&chain_means, 1);
    }
    let rho_at = |t: usize| 1.0 - (mean_var - acov[t]) / var_plus;

    let mut rho = vec![0.0; n];
    let mut rho_even = 1.0;
    rho[0] = rho_even;
    let mut rho_odd = rho_at(1);
    rho[1] = rho_odd;

    // Initial positive sequence. `t + 3 < n` is ArviZ's `t < n − 3` without underflow.
    let mut t = 1usize;
    while t + 3 < n && rho_even + rho_odd > 0.0 {
        rho_even = rho_at(t + 1);
        rho_odd = rho_at(t + 2);
        if rho_even + rho_odd >= 0.0 {
            rho[t + 1] = rho_even;
            rho[t + 2] = rho_odd;
        }
        t += 2;
    }
    // Last lag of the truncated sum; −1 when the loop never ran (n ≤ 4), then the sum below
    // is empty and only ρ̂(0) enters through the antithetic term, exactly as in ArviZ.
    let max_t = t as isize - 2;
    let next = (max_t + 1) as usize;
    if rho_even > 0.0 {
        rho[next] = rho_even;
    }
    // Initial monotone sequence.
    let mut t = 1isize;
    while t <= max_t - 2 {
        let u = t as usize;
        if rho[u + 1] + rho[u + 2] > rho[u - 1] + rho[u] {
            rho[u + 1] = (rho[u - 1] + rho[u]) / 2.0;
            rho[u + 2] = rho[u + 1];
        }
        t += 2;
    }
    let total = (n_chain * n) as f64;
    let tau = -1.0 + 2.0 * rho[..next].iter().sum::<f64>() + rho[next];
    let tau = tau.max(1.0 / total.log10());
    if rho.iter().any(|r| r.is_nan()) {
        return f64::NAN;
    }
    total / tau
}

/// Whether the draws are constant to within [`CONSTANT_RESOLUTION`].
pub(crate) fn is_constant(xs: &[f64]) -> bool {
    let (lo, hi) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        });
    hi - lo < CONSTANT_RESOLUTION
}

fn validated<C: AsRef<[f64]>>(chains: &[C]) -> Result<DrawMatrix, DiagnosticsError> {
    DrawMatrix::from_chains(chains, MIN_DRAWS_SPLIT)
}

/// Checks a quantile level.
pub(crate) fn check_probability(p: f64) -> Result<(), DiagnosticsError> {
    if p > 0.0 && p < 1.0 {
        Ok(())
    } else {
        Err(DiagnosticsError::InvalidProbability(p))
    }
}

/// Basic ESS for the mean: the Geyer ESS of the split chains, without rank
/// normalisation (Vehtari et al. 2021 §3.2; `arviz.ess(method="mean")`,
/// `posterior::ess_mean`). Valid as the ESS of the mean when the variance is finite;
/// `mcse_mean` uses it.
///
/// Degenerate input: `NaN` for constant draws (posterior returns NA; ArviZ 0.23 returns
/// the number of draws). Needs ≥ 4 draws per chain; one chain is fine.
pub fn ess_mean<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(ess_core(&validated(chains)?.split()))
}

/// Bulk ESS: the Geyer ESS of the rank-normalised split chains (Vehtari et al. 2021 §4.1;
/// Stan's `ess_bulk`, `arviz.ess(method="bulk")`, the default). Robust to heavy tails and
/// insensitive to monotone transformations; reliable for the bulk of the distribution
/// (means, medians). Vehtari et al. recommend ≥ 100 per chain (≥ 400 with 4 chains).
///
/// `NaN` for constant draws. Needs ≥ 4 draws per chain.
pub fn ess_bulk<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(ess_core(&z_scale(&validated(chains)?.split())))
}

/// ESS of the quantile at level `p`: the Geyer ESS of the split indicator chains
/// `I(x ≤ q̂_p)`, `q̂_p` the type-7 sample quantile of all draws (Vehtari et al. 2021 §4.3;
/// `arviz.ess(method="quantile", prob=p)`).
///
/// `NaN` if the indicator is constant (e.g. more than a fraction `1 − p` of draws tie at
/// the maximum). Errors if `p ∉ (0, 1)`.
pub fn ess_quantile<C: AsRef<[f64]>>(chains: &[C], p: f64) -> Result<f64, DiagnosticsError> {
    check_probability(p)?;
    let m = validated(chains)?;
    let s = sorted(&m.data);
    Ok(ess_quantile_of(&m, &s, p))
}

/// [`ess_quantile`] of validated draws, `sorted` their sorted copy.
pub(crate) fn ess_quantile_of(m: &DrawMatrix, sorted: &[f64], p: f64) -> f64 {
    let q = quantile_sorted(sorted, p);
    ess_core(&m.map(|x| if x <= q { 1.0 } else { 0.0 }).split())
}

/// Tail ESS: `min(ESS(I(x ≤ q̂₀.₀₅)), ESS(I(x ≤ q̂₀.₉₅)))`, the smaller of the quantile ESS
/// at 5 % and 95 % (Vehtari et al. 2021 §4.3; Stan's `ess_tail`,
/// `arviz.ess(method="tail")`). Measures how well the chains explore the tails, i.e. how
/// reliable 90 % intervals are.
///
/// If one indicator is constant (NaN ESS, it carries no information) the other one is
/// returned; `NaN` if both are. Needs ≥ 4 draws per chain.
pub fn ess_tail<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    let m = validated(chains)?;
    Ok(ess_tail_of(&m, &sorted(&m.data)))
}

/// [`ess_tail`] of validated draws, `sorted` their sorted copy.
pub(crate) fn ess_tail_of(m: &DrawMatrix, sorted: &[f64]) -> f64 {
    let low = ess_quantile_of(m, sorted, TAIL_PROB);
    let high = ess_quantile_of(m, sorted, 1.0 - TAIL_PROB);
    low.min(high)
}

/// ESS for the standard deviation as ArviZ 0.23 defines it: the basic split ESS of the
/// squared deviations `(x − x̄)²` (`arviz.ess(method="sd")`). `NaN` for constant draws.
pub fn ess_sd<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    let m = validated(chains)?;
    let mu = mean(&m.data);
    Ok(ess_core(&m.map(|x| (x - mu) * (x - mu)).split()))
}

/// Geyer ESS of the chains exactly as given: no splitting, no transformation
/// (`arviz.ess(method="identity")`). Useful when the caller has already split or
/// transformed the draws. Needs ≥ 2 draws per chain; `NaN` for constant draws.
pub fn ess_unsplit<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(ess_core(&DrawMatrix::from_chains(chains, 2)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_draws_give_nan() {
        let c = [[0.5; 10], [0.5; 10]];
        assert!(ess_mean(&c).unwrap().is_nan());
        assert!(ess_bulk(&c).unwrap().is_nan());
        assert!(ess_tail(&c).unwrap().is_nan());
        assert!(ess_unsplit(&c).unwrap().is_nan());
    }

    #[test]
    fn minimal_chains_work() {
        // 4 draws per chain → half-chains of 2: the shortest input, all branches with max_t = −1.
        let e = ess_mean(&[[0.1, 0.4, -0.3, 0.2], [0.0, 0.5, 0.3, -0.2]]).unwrap();
        assert!(e.is_finite() && e > 0.0);
        assert!(ess_bulk(&[[0.1, 0.4, -0.3, 0.2]]).unwrap().is_finite());
    }

    #[test]
    fn invalid_probability() {
        let c = [[0.1, 0.4, -0.3, 0.2]];
        for p in [0.0, 1.0, -0.5, f64::NAN] {
            assert!(matches!(
                ess_quantile(&c, p),
                Err(DiagnosticsError::InvalidProbability(_))
            ));
        }
    }

    #[test]
    fn cap_at_n_log10_n() {
        // A perfectly alternating chain is maximally antithetic: τ̂ would be ≈ 0, the cap
        // makes ESS = N log₁₀ N.
        let chain: Vec<f64> = (0..1000)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let e = ess_unsplit(&[&chain]).unwrap();
        assert!((e - 1000.0 * 3.0).abs() < 1e-9, "{e}");
    }
}
