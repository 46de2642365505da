//! The energy Bayesian fraction of missing information (E-BFMI) of a
//! Hamiltonian chain (Betancourt 2016): how well the momentum resampling
//! explores the energy distribution.

use super::DiagnosticsError;

/// E-BFMI of one chain's per-draw energies `H_n`:
/// `mean((H_n − H_{n−1})²) / var(H)` (population variance), ArviZ's
/// `bfmi`. Stan's `check_energy` uses sums instead of means, i.e. the same
/// value times `(N − 1)/N`. Values below 0.3 flag a chain whose momentum
/// resampling moves too little in energy (heavy tails, funnels).
///
/// ```
/// use mcmc_core::diagnostics::e_bfmi;
/// // Alternating energies: large jumps relative to the spread.
/// let b = e_bfmi(&[1.0, 2.0, 1.0, 2.0]).unwrap();
/// assert!((b - 4.0).abs() < 1e-12);
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
    let n = energy.len() as f64;
    let mean = energy.iter().sum::<f64>() / n;
    let var = energy.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n;
    let jumps = energy
        .windows(2)
        .map(|w| (w[1] - w[0]).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    Ok(jumps / var)
}
