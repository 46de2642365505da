//! Monte Carlo standard errors (MCSE) of the mean, standard deviation and quantiles.

use statrs::function::beta::inv_beta_reg;

use super::DiagnosticsError;
use super::draws::{DrawMatrix, MIN_DRAWS_SPLIT, mean, variance};
use super::ess::{check_probability, ess_core, ess_quantile_of};
use super::rank::sorted;

/// Φ(−1) and Φ(1): the central ±1 σ band the quantile MCSE is read from (ArviZ's constants).
const ONE_SIGMA_PROBS: [f64; 2] = [0.158_655_3, 0.841_344_7];

fn validated<C: AsRef<[f64]>>(chains: &[C]) -> Result<DrawMatrix, DiagnosticsError> {
    DrawMatrix::from_chains(chains, MIN_DRAWS_SPLIT)
}

/// MCSE of the posterior mean: `sd / sqrt(ESS_mean)`, with `sd` the sample standard
/// deviation (ddof 1) of all draws and `ESS_mean` the basic split ESS
/// ([`super::ess_mean`]) — Vehtari et al. (2021) §3.2, `arviz.mcse(method="mean")`.
/// The error of the reported mean is about this size: compare it with the precision you
/// need. `NaN` for constant draws.
pub fn mcse_mean<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(mcse_mean_of(&validated(chains)?))
}

pub(crate) fn mcse_mean_of(m: &DrawMatrix) -> f64 {
    (variance(&m.data, 1) / ess_core(&m.split())).sqrt()
}

/// MCSE of the posterior standard deviation as ArviZ 0.23 computes it
/// (`arviz.mcse(method="sd")`): with `s² = (x − x̄)²`, `E = mean(s²)`,
/// `Var(E) ≈ (mean(s⁴) − E²) / ESS_mean(s²)`, and the delta method for `sd = √E`:
/// `MCSE(sd) = sqrt(Var(E) / (4 E))`. `NaN` for constant draws.
pub fn mcse_sd<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(mcse_sd_of(&validated(chains)?))
}

pub(crate) fn mcse_sd_of(m: &DrawMatrix) -> f64 {
    let mu = mean(&m.data);
    let sq = m.map(|x| (x - mu) * (x - mu));
    let ess = ess_core(&sq.split());
    let evar = mean(&sq.data);
    let fourth = sq.data.iter().map(|s| s * s).sum::<f64>() / sq.len() as f64;
    let varvar = (fourth - evar * evar) / ess;
    (varvar / evar / 4.0).sqrt()
}

/// MCSE of the quantile at level `p` (Vehtari et al. 2021 §4.3; `arviz.mcse(method=
/// "quantile", prob=p)`): with `S = ESS_quantile(p)` ([`super::ess_quantile`]), the
/// ±1σ interval of the quantile's rank is taken from `Beta(S p + 1, S (1 − p) + 1)` at
/// probabilities Φ(−1), Φ(1), mapped to order statistics `x₍⌊N a − 1⌋₎`, `x₍⌈N b − 1⌉₎`
/// (0-based, clamped to the sample), and half their distance is returned.
///
/// `NaN` if the quantile ESS is `NaN` (constant indicator). Errors if `p ∉ (0, 1)`.
pub fn mcse_quantile<C: AsRef<[f64]>>(chains: &[C], p: f64) -> Result<f64, DiagnosticsError> {
    check_probability(p)?;
    let m = validated(chains)?;
    let s = sorted(&m.data);
    Ok(mcse_quantile_of(&m, &s, p))
}

pub(crate) fn mcse_quantile_of(m: &DrawMatrix, sorted: &[f64], p: f64) -> f64 {
    let ess = ess_quantile_of(m, sorted, p);
    if !ess.is_finite() {
        return f64::NAN;
    }
    let (a, b) = (ess * p + 1.0, ess * (1.0 - p) + 1.0);
    let size = sorted.len();
    let lo = inv_beta_reg(a, b, ONE_SIGMA_PROBS[0]) * size as f64 - 1.0;
    let hi = inv_beta_reg(a, b, ONE_SIGMA_PROBS[1]) * size as f64 - 1.0;
    let lo = lo.max(0.0).floor() as usize;
    let hi = (hi.min((size - 1) as f64).ceil() as usize).min(size - 1);
    (sorted[hi] - sorted[lo]) / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_draws_give_nan() {
        let c = [[3.0; 6], [3.0; 6]];
        assert!(mcse_mean(&c).unwrap().is_nan());
        assert!(mcse_sd(&c).unwrap().is_nan());
        assert!(mcse_quantile(&c, 0.5).unwrap().is_nan());
    }
}
