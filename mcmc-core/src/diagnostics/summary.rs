//! Per-quantity summary (moments, quantiles, MCSE, ESS, R-hat) and a Stan-like table.

use std::fmt;

use rayon::prelude::*;

use super::DiagnosticsError;
use super::draws::{DrawMatrix, MIN_DRAWS_SPLIT, mean, variance};
use super::ess::{ess_core, ess_tail_of};
use super::mcse::{mcse_mean_of, mcse_sd_of};
use super::rank::{quantile_sorted, sorted, z_scale};
use super::rhat::rank_rhat_from_split;

/// Posterior summary and convergence diagnostics of one scalar quantity, pooled over chains.
///
/// Every field follows the free function of the same name in
/// [`diagnostics`](super); they agree with ArviZ's `summary` (for even chain lengths) and
/// Stan's `print`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// Mean of all draws.
    pub mean: f64,
    /// Standard deviation of all draws (ddof 1).
    pub sd: f64,
    /// Monte Carlo standard error of the mean ([`super::mcse_mean`]).
    pub mcse_mean: f64,
    /// Monte Carlo standard error of the standard deviation ([`super::mcse_sd`]).
    pub mcse_sd: f64,
    /// 5 % quantile (type 7) of all draws.
    pub q5: f64,
    /// Median (type-7 50 % quantile) of all draws.
    pub q50: f64,
    /// 95 % quantile (type 7) of all draws.
    pub q95: f64,
    /// Bulk effective sample size ([`super::ess_bulk`]).
    pub ess_bulk: f64,
    /// Tail effective sample size ([`super::ess_tail`]).
    pub ess_tail: f64,
    /// Rank-normalised split R-hat ([`super::rank_normalized_split_rhat`]).
    pub rhat: f64,
}

impl Summary {
    fn of(m: &DrawMatrix) -> Self {
        let s = sorted(&m.data);
        let split = m.split();
        let z_split = z_scale(&split);
        Self {
            mean: mean(&m.data),
            sd: variance(&m.data, 1).sqrt(),
            mcse_mean: mcse_mean_of(m),
            mcse_sd: mcse_sd_of(m),
            q5: quantile_sorted(&s, 0.05),
            q50: quantile_sorted(&s, 0.5),
            q95: quantile_sorted(&s, 0.95),
            ess_bulk: ess_core(&z_split),
            ess_tail: ess_tail_of(m, &s),
            rhat: rank_rhat_from_split(&split, &z_split),
        }
    }
}

/// [`Summary`] of one scalar quantity given as chains × draws.
///
/// Errors as the individual estimators (≥ 4 draws per chain, equal lengths, finite draws).
pub fn summarize_chains<C: AsRef<[f64]>>(chains: &[C]) -> Result<Summary, DiagnosticsError> {
    Ok(Summary::of(&DrawMatrix::from_chains(
        chains,
        MIN_DRAWS_SPLIT,
    )?))
}

/// One [`Summary`] per coordinate of a chains × draws × coordinates array
/// (`chains[c][t][i]` = coordinate `i` of draw `t` of chain `c`, the layout a sampler
/// records states in). Coordinates are summarised in parallel (rayon); the result does not
/// depend on the thread count.
///
/// Errors: no chains, unequal chain lengths, draws with differing numbers of coordinates,
/// fewer than 4 draws per chain, or a non-finite coordinate (reported by chain and draw).
pub fn summarize(chains: &[Vec<Vec<f64>>]) -> Result<Vec<Summary>, DiagnosticsError> {
    let first = chains.first().ok_or(DiagnosticsError::NoChains)?;
    let draws = first.len();
    let dim = first.first().map_or(0, Vec::len);
    for (c, chain) in chains.iter().enumerate() {
        if chain.len() != draws {
            return Err(DiagnosticsError::UnequalLengths {
                chain: c,
                len: chain.len(),
                expected: draws,
            });
        }
        for (t, x) in chain.iter().enumerate() {
            if x.len() != dim {
                return Err(DiagnosticsError::UnequalDimensions {
                    chain: c,
                    draw: t,
                    len: x.len(),
                    expected: dim,
                });
            }
            if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                return Err(DiagnosticsError::NonFinite {
                    chain: c,
                    draw: t,
                    value: x[i],
                });
            }
        }
    }
    if draws < MIN_DRAWS_SPLIT {
        return Err(DiagnosticsError::TooFewDraws {
            draws,
            min: MIN_DRAWS_SPLIT,
        });
    }
    Ok((0..dim)
        .into_par_iter()
        .map(|i| {
            let data = chains
                .iter()
                .flat_map(|ch| ch.iter().map(|x| x[i]))
                .collect();
            Summary::of(&DrawMatrix::from_raw(chains.len(), draws, data))
        })
        .collect())
}

/// A printable table of summaries, one row per named quantity, in the spirit of Stan's
/// `print`: mean, MCSE, sd, 5/50/95 % quantiles, bulk and tail ESS, R-hat.
#[derive(Debug, Clone, PartialEq)]
pub struct SummaryTable {
    /// Row labels.
    pub names: Vec<String>,
    /// One summary per row.
    pub rows: Vec<Summary>,
}

impl SummaryTable {
    /// Table with rows labelled `x[0]`, `x[1]`, ….
    pub fn new(rows: Vec<Summary>) -> Self {
        let names = (0..rows.len()).map(|i| format!("x[{i}]")).collect();
        Self { names, rows }
    }

    /// Table with the given row labels (extra labels are ignored, missing ones numbered).
    pub fn with_names<S: Into<String>>(
        rows: Vec<Summary>,
        names: impl IntoIterator<Item = S>,
    ) -> Self {
        let mut table = Self::new(rows);
        for (slot, name) in table.names.iter_mut().zip(names) {
            *slot = name.into();
        }
        table
    }
}

/// Formats `x` with about 4 significant digits in a fixed-point field.
fn sig4(x: f64) -> String {
    if !x.is_finite() || x == 0.0 {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if !(-4..=6).contains(&magnitude) {
        return format!("{x:.3e}");
    }
    let decimals = (3 - magnitude).max(0) as usize;
    format!("{x:.decimals$}")
}

impl fmt::Display for SummaryTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let label = self.names.iter().map(String::len).max().unwrap_or(0).max(4);
        writeln!(
            f,
            "{:label$} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>9} {:>9} {:>7}",
            "", "mean", "mcse", "sd", "5%", "50%", "95%", "ess_bulk", "ess_tail", "r_hat"
        )?;
        for (name, s) in self.names.iter().zip(&self.rows) {
            writeln!(
                f,
                "{name:label$} {:>10} {:>10} {:>10} {:>10} {:>10} {:>10} {:>9.0} {:>9.0} {:>7.3}",
                sig4(s.mean),
                sig4(s.mcse_mean),
                sig4(s.sd),
                sig4(s.q5),
                sig4(s.q50),
                sig4(s.q95),
                s.ess_bulk,
                s.ess_tail,
                s.rhat
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_errors() {
        assert_eq!(summarize(&[]), Err(DiagnosticsError::NoChains));
        let ragged = vec![vec![vec![0.0, 1.0]; 4], vec![vec![0.0, 1.0], vec![0.0]]];
        assert!(matches!(
            summarize(&ragged),
            Err(DiagnosticsError::UnequalLengths { chain: 1, .. })
        ));
        let mut bad_dim = vec![vec![vec![0.0, 1.0]; 4]; 2];
        bad_dim[1][2] = vec![0.0];
        assert_eq!(
            summarize(&bad_dim),
            Err(DiagnosticsError::UnequalDimensions {
                chain: 1,
                draw: 2,
                len: 1,
                expected: 2
            })
        );
        let mut nan = vec![vec![vec![0.0, 1.0]; 4]; 2];
        nan[0][3][1] = f64::NAN;
        assert!(matches!(
            summarize(&nan),
            Err(DiagnosticsError::NonFinite {
                chain: 0,
                draw: 3,
                ..
            })
        ));
        assert!(matches!(
            summarize(&[vec![vec![0.0]; 3]]),
            Err(DiagnosticsError::TooFewDraws { draws: 3, min: 4 })
        ));
    }

    #[test]
    fn table_prints_every_row() {
        let chains: Vec<Vec<Vec<f64>>> = (0..2)
            .map(|c| {
                (0..20)
                    .map(|t| vec![(t * 7 + c * 3) as f64 % 11.0, 1.0e7 + t as f64])
                    .collect()
            })
            .collect();
        let table = SummaryTable::with_names(summarize(&chains).unwrap(), ["alpha", "beta"]);
        let text = table.to_string();
        assert_eq!(text.lines().count(), 3);
        assert!(text.contains("alpha") && text.contains("beta") && text.contains("r_hat"));
    }
}
