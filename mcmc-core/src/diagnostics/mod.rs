//! MCMC convergence diagnostics following Vehtari, Gelman, Simpson, Carpenter & Bürkner
//! (2021), "Rank-normalization, folding, and localization: an improved R-hat for assessing
//! convergence of MCMC" (Bayesian Analysis 16(2)), as implemented by Stan, the R package
//! `posterior` and ArviZ.
//!
//! # Example
//!
//! ```
//! use mcmc_core::diagnostics::{self, SummaryTable};
//!
//! // Two chains of one scalar quantity (in practice: thousands of draws per chain).
//! let chains = vec![
//!     vec![0.1, -0.4, 0.3, 0.9, -1.2, 0.5, 0.0, -0.3],
//!     vec![0.7, -0.1, -0.8, 0.2, 1.1, -0.6, 0.4, -0.2],
//! ];
//! let rhat = diagnostics::rank_normalized_split_rhat(&chains)?;
//! let bulk = diagnostics::ess_bulk(&chains)?;
//! let tail = diagnostics::ess_tail(&chains)?;
//! let mcse = diagnostics::mcse_mean(&chains)?;
//! assert!(rhat.is_finite() && bulk > 0.0 && tail > 0.0 && mcse > 0.0);
//!
//! // Several coordinates at once: chains × draws × coordinates.
//! let draws: Vec<Vec<Vec<f64>>> = chains
//!     .iter()
//!     .map(|c| c.iter().map(|&x| vec![x, x * x]).collect())
//!     .collect();
//! let table = SummaryTable::with_names(diagnostics::summarize(&draws)?, ["x", "x^2"]);
//! println!("{table}");
//! # Ok::<(), diagnostics::DiagnosticsError>(())
//! ```
//!
//! # Input
//!
//! Every estimator takes the draws of ONE scalar quantity as chains × draws: anything
//! slice-like per chain (`&[Vec<f64>]`, `&[&[f64]]`, `&[[f64; N]]`). All chains must have
//! the same length and every draw must be finite; otherwise a typed
//! [`DiagnosticsError`] is returned. The split estimators need ≥ 4 draws per chain (2 per
//! half). A single chain is accepted everywhere: it is split in two halves.
//! [`summarize`] takes a chains × draws × coordinates array.
//!
//! # Degenerate input (documented behaviour)
//!
//! When the draws an estimator looks at are constant (span < 1e-15), there is nothing to
//! estimate and the statistic is `NaN`, like posterior's `NA`: ESS of constant draws,
//! R-hat when all draws are equal, autocorrelation of a constant chain. (ArviZ 0.23 agrees
//! for R-hat and autocorrelation but reports the number of draws as the ESS of constant
//! draws.) If every chain is constant but at different values, R-hat is `+∞`.
//!
//! # Agreement with ArviZ
//!
//! `tests/tests/diagnostics_arviz.rs` checks every estimator against ArviZ 0.23 on fixed
//! arrays (`tests/arviz/generate_expected.py`) to 1e-8 relative. Where the conventions of
//! ArviZ's functions differ among themselves, the individual functions (`arviz.rhat`,
//! `arviz.ess`, `arviz.mcse`) are followed; see each item.
//!
//! # Cost
//!
//! Autocovariances use a zero-padded real FFT and ranks a sort: all estimators are
//! O(N log N) in the total number of draws N.

mod autocorr;
mod draws;
mod energy;
mod error;
mod ess;
mod mcse;
#[cfg(test)]
mod proptests;
mod rank;
mod rhat;
mod summary;

pub use autocorr::{autocorrelation, autocovariance};
pub use energy::e_bfmi;
pub use error::DiagnosticsError;
pub use ess::{ess_bulk, ess_mean, ess_quantile, ess_sd, ess_tail, ess_unsplit};
pub use mcse::{mcse_mean, mcse_quantile, mcse_sd};
pub use rhat::{folded_split_rhat, rank_normalized_split_rhat, split_rhat, z_scale_split_rhat};
pub use summary::{Summary, SummaryTable, summarize, summarize_chains};
