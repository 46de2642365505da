//! The energy Bayesian fraction of missing information (E-BFMI) of a
//! Hamiltonian chain (Betancourt 2016): how well the momentum resampling
//! explores the energy distribution.

use super::DiagnosticsError;

/// E-BFMI of one chain's per-draw energies `H_n`:
/// `Σ (H_n − H_{n−1})² / Σ (H_n − H̄)²`, Stan's `check_energy` and ArviZ's
/// `bfmi` (mean squared jump over the sample variance with `N − 1`: the
/// same number). Values below 0.3 flag a chain whose momentum resampling
/// moves too little in energy (heavy tails, funnels).
///
/// ```
/// use mcmc_core::diagnostics::e_bfmi;
/// // Alternating energies: jumps of 1, spread ½ around the mean.
/// let b = e_bfmi(&[1.0, 2.0, 1.0, 2.0]).unwrap();
/// assert!((b - 3.0).abs() < 1e-12);
/// ```
pub fn e_bfmi(energy: &[f64]) -> Result<f64, DiagnosticsError> {
    if energy.len() < 2 {
        return Err(DiagnosticsError::TooFewDraws {
            draws: energy.len(),
            min: 2,
        });
    }
    if let Some((draw, &value)) = energy.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(DiagnosticsError::NonFinite {
            chain: 0,
            draw,
            value,
        });
    }
    let mean = energy.iter().sum::<f64>() / energy.len() as f64;
    let spread = energy.iter().map(|e| (e - mean).powi(2)).sum::<f64>();
    let jumps = energy
        .windows(2)
        .map(|w| (w[1] - w[0]).powi(2))
        .sum::<f64>();
    Ok(jumps / spread)
}
