//! Shared helpers for the cross-crate and statistical tests.

/// Mean and standard error of independent replicate estimates.
///
/// For `C` independent chains started in stationarity, the chain means are
/// i.i.d., so `sd(chain means)/√C` is an exact-in-expectation Monte Carlo
/// standard error (no autocorrelation model needed).
pub fn mean_and_se(values: &[f64]) -> (f64, f64) {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt())
}

/// Asserts `|estimate − truth| ≤ z·se`, with a readable message.
#[track_caller]
pub fn assert_within(name: &str, estimate: f64, truth: f64, se: f64, z: f64) {
    assert!(
        (estimate - truth).abs() <= z * se,
        "{name}: estimate {estimate} vs truth {truth}: |diff| = {:.3e} exceeds {z}·SE = {:.3e}",
        (estimate - truth).abs(),
        z * se
    );
}

/// Threshold on |t| for C = 32 replicates: a correct sampler exceeds it with
/// probability 2.1e-5 per check (Student t with 31 degrees of freedom,
/// P(|t| > 5) computed by quadrature). With a few dozen checks per file the
/// family-wise false-failure probability stays below 1e-3, while a bias of
/// more than 5 standard errors is caught.
pub const Z_32_CHAINS: f64 = 5.0;
