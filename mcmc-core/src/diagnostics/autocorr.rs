//! Autocovariance and autocorrelation of one chain by FFT.

use std::sync::Arc;

use realfft::num_complex::Complex;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};

use super::DiagnosticsError;
use super::draws::{check_finite, mean};

/// Biased (divide by `n`) autocovariance of `chain` at every lag `0..n`:
///
/// ```text
/// γ̂(k) = (1/n) Σ_{t=0}^{n-1-k} (x_t − x̄)(x_{t+k} − x̄),   k = 0, …, n−1
/// ```
///
/// This is the estimator Stan, posterior and ArviZ (`arviz.autocov`) use: dividing by `n`
/// rather than `n − k` keeps the sequence positive semi-definite, which Geyer's truncation
/// relies on. It is computed in O(n log n) with a real FFT of the centred chain,
/// zero-padded to at least `2n` points so that the circular correlation has no wrap-around.
///
/// Errors: an empty chain ([`DiagnosticsError::TooFewDraws`]) or a non-finite draw.
pub fn autocovariance(chain: &[f64]) -> Result<Vec<f64>, DiagnosticsError> {
    if chain.is_empty() {
        return Err(DiagnosticsError::TooFewDraws { draws: 0, min: 1 });
    }
    check_finite(chain, 0)?;
    let mut out = vec![0.0; chain.len()];
    AutocovPlan::new(chain.len()).compute(chain, &mut out);
    Ok(out)
}

/// Autocorrelation `ρ̂(k) = γ̂(k) / γ̂(0)` of `chain` at every lag `0..n`, from
/// [`autocovariance`] (as `arviz.autocorr`).
///
/// A constant chain has `γ̂(0) = 0`; its autocorrelation is then `NaN` at every lag, as
/// ArviZ's, rather than an arbitrary value.
pub fn autocorrelation(chain: &[f64]) -> Result<Vec<f64>, DiagnosticsError> {
    let mut acov = autocovariance(chain)?;
    let var = acov[0];
    for a in &mut acov {
        *a /= var;
    }
    Ok(acov)
}

/// FFT plans and buffers for the autocovariance of chains of one length, so that a
/// multi-chain estimator plans once and reuses the buffers for every chain.
pub(crate) struct AutocovPlan {
    n: usize,
    forward: Arc<dyn RealToComplex<f64>>,
    inverse: Arc<dyn ComplexToReal<f64>>,
    signal: Vec<f64>,
    spectrum: Vec<Complex<f64>>,
    scratch_forward: Vec<Complex<f64>>,
    scratch_inverse: Vec<Complex<f64>>,
}

impl AutocovPlan {
    /// Plans for chains of `n ≥ 1` draws.
    pub(crate) fn new(n: usize) -> Self {
        // 2·(5-smooth ≥ n) is even (realfft's fast path) and ≥ 2n (no circular wrap);
        // 5-smooth lengths keep rustfft on its fast radix-2/3/5 algorithms.
        let padded = 2 * next_five_smooth(n);
        let mut planner = RealFftPlanner::<f64>::new();
        let forward = planner.plan_fft_forward(padded);
        let inverse = planner.plan_fft_inverse(padded);
        let signal = forward.make_input_vec();
        let spectrum = forward.make_output_vec();
        let scratch_forward = forward.make_scratch_vec();
        let scratch_inverse = inverse.make_scratch_vec();
        Self {
            n,
            forward,
            inverse,
            signal,
            spectrum,
            scratch_forward,
            scratch_inverse,
        }
    }

    /// Writes the biased autocovariance of `chain` (length `n`) into `out[..n]`.
    pub(crate) fn compute(&mut self, chain: &[f64], out: &mut [f64]) {
        let n = self.n;
        debug_assert_eq!(chain.len(), n);
        let m = mean(chain);
        let padded = self.signal.len();
        for (s, &x) in self.signal.iter_mut().zip(chain) {
            *s = x - m;
        }
        self.signal[n..].fill(0.0);
        self.forward
            .process_with_scratch(
                &mut self.signal,
                &mut self.spectrum,
                &mut self.scratch_forward,
            )
            .expect("buffer lengths come from the plan");
        for z in &mut self.spectrum {
            *z = Complex::new(z.norm_sqr(), 0.0);
        }
        // |z|² is real, so the first and last bins have the zero imaginary part realfft
        // requires of the inverse transform's input.
        self.inverse
            .process_with_scratch(
                &mut self.spectrum,
                &mut self.signal,
                &mut self.scratch_inverse,
            )
            .expect("buffer lengths come from the plan");
        // realfft's inverse is unnormalised: divide by the padded length, then by n for the
        // biased estimator.
        let scale = 1.0 / (padded as f64 * n as f64);
        for (o, &s) in out.iter_mut().zip(&self.signal[..n]) {
            *o = s * scale;
        }
    }
}

/// Smallest integer `≥ n` whose only prime factors are 2, 3 and 5.
fn next_five_smooth(n: usize) -> usize {
    let mut best = usize::MAX;
    let mut p5 = 1usize;
    while p5 < 2 * n.max(1) {
        let mut p35 = p5;
        while p35 < 2 * n.max(1) {
            // Smallest power of two lifting p35 to at least n.
            let mut v = p35;
            while v < n {
                v *= 2;
            }
            best = best.min(v);
            p35 *= 3;
        }
        p5 *= 5;
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct O(n²) evaluation of the defining sum.
    fn naive(chain: &[f64]) -> Vec<f64> {
        let n = chain.len();
        let m = mean(chain);
        (0..n)
            .map(|k| {
                (0..n - k)
                    .map(|t| (chain[t] - m) * (chain[t + k] - m))
                    .sum::<f64>()
                    / n as f64
            })
            .collect()
    }

    #[test]
    fn fft_matches_direct_sum() {
        for n in [1usize, 2, 3, 7, 16, 97, 250] {
            let chain: Vec<f64> = (0..n)
                .map(|i| ((i * 7919) % 113) as f64 * 0.37 - 9.0)
                .collect();
            let fast = autocovariance(&chain).unwrap();
            for (k, (a, b)) in fast.iter().zip(naive(&chain)).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-12 * naive(&chain)[0].max(1.0),
                    "n={n} k={k}"
                );
            }
        }
    }

    #[test]
    fn five_smooth() {
        assert_eq!(next_five_smooth(1), 1);
        assert_eq!(next_five_smooth(7), 8);
        assert_eq!(next_five_smooth(11), 12);
        assert_eq!(next_five_smooth(1001), 1024);
        assert_eq!(next_five_smooth(1025), 1080);
    }

    #[test]
    fn constant_chain_has_nan_autocorrelation() {
        let rho = autocorrelation(&[2.5; 10]).unwrap();
        assert!(rho.iter().all(|r| r.is_nan()));
    }

    #[test]
    fn rejects_empty_and_non_finite() {
        assert!(matches!(
            autocovariance(&[]),
            Err(DiagnosticsError::TooFewDraws { .. })
        ));
        assert!(matches!(
            autocovariance(&[1.0, f64::NAN]),
            Err(DiagnosticsError::NonFinite { draw: 1, .. })
        ));
    }
}
