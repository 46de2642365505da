//! Potential scale reduction factors (R-hat).

use super::DiagnosticsError;
use super::draws::{DrawMatrix, MIN_DRAWS_SPLIT, mean, variance};
use super::rank::{fold, z_scale};

/// Gelman–Rubin R-hat of chains taken as they are (no splitting, no transformation):
///
/// ```text
/// B = n · var(chain means)        (ddof 1)      W = mean(chain variances)   (ddof 1)
/// R̂ = sqrt( (B / W + n − 1) / n )  =  sqrt( ((n−1)/n · W + B/n) / W )
/// ```
///
/// `NaN` when all draws are equal (`0/0`), `+∞` when every chain is constant but the
/// chains disagree.
pub(crate) fn rhat_core(m: &DrawMatrix) -> f64 {
    let n = m.draws as f64;
    let means: Vec<f64> = (0..m.chains).map(|c| mean(m.chain(c))).collect();
    let within = (0..m.chains).map(|c| variance(m.chain(c), 1)).sum::<f64>() / m.chains as f64;
    let between = n * variance(&means, 1);
    ((between / within + n - 1.0) / n).sqrt()
}

fn validated<C: AsRef<[f64]>>(chains: &[C]) -> Result<DrawMatrix, DiagnosticsError> {
    DrawMatrix::from_chains(chains, MIN_DRAWS_SPLIT)
}

/// Classic split R-hat (Gelman et al. 2013, BDA3 §11.4): every chain is cut into its first
/// and last `⌊n/2⌋` draws and the Gelman–Rubin R-hat (see `rhat_core` in the source) is
/// taken over the `2m` half-chains. Equals `arviz.rhat(method="split")`.
///
/// Works with a single chain (its two halves are compared), unlike ArviZ which returns NaN
/// for fewer than 2 chains; Stan/posterior compute it. Needs ≥ 4 draws per chain.
pub fn split_rhat<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(rhat_core(&validated(chains)?.split()))
}

/// Bulk R-hat: split R-hat of the rank-normalised split chains (Vehtari et al. 2021, §4.1;
/// `arviz.rhat(method="z_scale")`).
pub fn z_scale_split_rhat<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(rhat_core(&z_scale(&validated(chains)?.split())))
}

/// Tail R-hat: split R-hat of the rank-normalised folded split chains `|x − median|`, the
/// median taken over the split draws (Vehtari et al. 2021, §4.2;
/// `arviz.rhat(method="folded")`).
pub fn folded_split_rhat<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(rhat_core(&z_scale(&fold(&validated(chains)?.split()))))
}

/// Rank-normalised split R-hat, the convergence diagnostic of Vehtari, Gelman, Simpson,
/// Carpenter & Bürkner (2021), "Rank-normalization, folding, and localization: an improved
/// R-hat for assessing convergence of MCMC", Bayesian Analysis 16(2), Eq. 15–16:
///
/// ```text
/// R̂ = max( R̂_split(z(split(x))),  R̂_split(z(|split(x) − median(split(x))|)) )
/// ```
///
/// with `z` the rank normalisation (Blom normal scores of the pooled ranks). This is what
/// Stan prints, `posterior::rhat` and `arviz.rhat(method="rank")` (the default). Values
/// above 1.01 signal chains that have not mixed.
///
/// Conventions (those of `arviz.rhat`): chains are split first and the fold uses the median
/// of the split draws — for odd chain lengths this differs slightly from `arviz.summary`
/// and posterior, which fold about the median of all draws before splitting. One chain is
/// allowed (R-hat between its halves, as posterior; ArviZ returns NaN). If one of the two
/// parts is NaN because its draws are all equal (e.g. folded draws of a symmetric two-valued
/// quantity), the other part is returned; `NaN` only if all draws are equal.
pub fn rank_normalized_split_rhat<C: AsRef<[f64]>>(chains: &[C]) -> Result<f64, DiagnosticsError> {
    Ok(rank_rhat_of(&validated(chains)?))
}

/// [`rank_normalized_split_rhat`] of validated draws.
pub(crate) fn rank_rhat_of(m: &DrawMatrix) -> f64 {
    let split = m.split();
    rank_rhat_from_split(&split, &z_scale(&split))
}

/// [`rank_normalized_split_rhat`] from the split draws and their rank normalisation (which
/// the bulk ESS also needs, so a summary computes it once).
pub(crate) fn rank_rhat_from_split(split: &DrawMatrix, z_split: &DrawMatrix) -> f64 {
    let bulk = rhat_core(z_split);
    let tail = rhat_core(&z_scale(&fold(split)));
    bulk.max(tail)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_chains_give_rhat_below_one() {
        // Split halves that are exact copies: B = 0 and R̂ = sqrt((n−1)/n).
        let chain = [1.0, 2.0, 3.0, 1.0, 2.0, 3.0];
        let r = split_rhat(&[chain, chain]).unwrap();
        assert!((r - (2.0f64 / 3.0).sqrt()).abs() < 1e-15);
    }

    #[test]
    fn constant_draws_give_nan_and_stuck_chains_infinity() {
        assert!(
            rank_normalized_split_rhat(&[[1.0; 8], [1.0; 8]])
                .unwrap()
                .is_nan()
        );
        assert!(split_rhat(&[[1.0; 8], [1.0; 8]]).unwrap().is_nan());
        let r = split_rhat(&[[1.0; 8], [2.0; 8]]).unwrap();
        assert_eq!(r, f64::INFINITY);
        assert_eq!(
            rank_normalized_split_rhat(&[[1.0; 8], [2.0; 8]]).unwrap(),
            f64::INFINITY
        );
    }

    #[test]
    fn errors() {
        let none: [&[f64]; 0] = [];
        assert_eq!(split_rhat(&none), Err(DiagnosticsError::NoChains));
        assert_eq!(
            split_rhat(&[&[1.0, 2.0, 3.0][..]]),
            Err(DiagnosticsError::TooFewDraws { draws: 3, min: 4 })
        );
        assert_eq!(
            split_rhat(&[vec![1.0; 5], vec![1.0; 4]]),
            Err(DiagnosticsError::UnequalLengths {
                chain: 1,
                len: 4,
                expected: 5
            })
        );
        assert!(matches!(
            rank_normalized_split_rhat(&[vec![1.0, 2.0, f64::INFINITY, 0.0]]),
            Err(DiagnosticsError::NonFinite {
                chain: 0,
                draw: 2,
                ..
            })
        ));
    }
}
