//! The diagonal metric from draws and gradients (nuts-rs's default,
//! Seyboldt's "gradient-based" mass matrix): `M⁻¹_ii = √(var x_i / var ∂_i ln π)`.
//!
//! For a Gaussian with covariance `Σ`, `∇ln π = −Σ⁻¹(x − μ)` has covariance
//! `Σ⁻¹`, so the estimate is `√(Σ_ii / (Σ⁻¹)_ii)`: exactly `Σ_ii` for
//! independent coordinates, and between the marginal and the conditional
//! variance otherwise. Using the gradients as well as the draws, it
//! settles from fewer (and more autocorrelated) draws than the variances
//! alone, which is why nuts-rs can adapt it from early in the warm-up.

use super::MetricEstimator;
use crate::kernel::Metric;

/// Welford variances of warm-up draws and of their gradients.
#[derive(Clone, Debug)]
pub struct GradientMetricEstimator {
    draws: MetricEstimator,
    gradients: MetricEstimator,
}

impl GradientMetricEstimator {
    /// An estimator in dimension `d`.
    pub fn new(d: usize) -> Self {
        GradientMetricEstimator {
            draws: MetricEstimator::diagonal(d),
            gradients: MetricEstimator::diagonal(d),
        }
    }

    /// Pairs added since the last reset.
    pub fn count(&self) -> usize {
        self.draws.count()
    }

    /// Adds a draw and the gradient of `ln π` there (ignored, both, unless
    /// both are finite and of the right length).
    pub fn add(&mut self, x: &[f64], gradient: &[f64]) {
        let ok = |v: &[f64]| v.len() == self.draws.dim() && v.iter().all(|u| u.is_finite());
        if ok(x) && ok(gradient) {
            self.draws.add(x);
            self.gradients.add(gradient);
        }
    }

    /// Appends both estimators' state for checkpoints.
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        self.draws.words(out);
        self.gradients.words(out);
    }

    /// Restores [`Self::words`] from the front of `input`; false when cut.
    pub(crate) fn restore(&mut self, input: &mut &[u64]) -> bool {
        self.draws.restore(input) && self.gradients.restore(input)
    }

    /// Forgets every pair.
    pub fn reset(&mut self) {
        self.draws.reset();
        self.gradients.reset();
    }

    /// `M⁻¹_ii = √(var x_i / var g_i)` (sample variances), each clamped to
    /// `[10⁻²⁰, 10²⁰]` as nuts-rs does; `None` with fewer than 3 pairs or a
    /// non-finite ratio (a coordinate whose draws or gradients are constant).
    pub fn metric(&self) -> Option<Metric> {
        let vx = self.draws.variances()?;
        let vg = self.gradients.variances()?;
        let inv: Option<Vec<f64>> = vx
            .iter()
            .zip(&vg)
            .map(|(a, b)| {
                let r = (a / b).sqrt();
                r.is_finite().then(|| r.clamp(1e-20, 1e20))
            })
            .collect();
        Metric::diagonal(inv?).ok()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::needless_range_loop)]
    use super::*;
    use crate::rng::{standard_normal, stream_rng};

    /// Independent Gaussian coordinates with standard deviations `σ_i`: the
    /// gradient is `g_i = −x_i/σ_i²`, so the sample variances satisfy
    /// `s²_g = s²_x/σ_i⁴` for every sample and the estimate `√(s²_x/s²_g)`
    /// is `σ_i²` exactly (up to rounding), whatever the sample size.
    #[test]
    fn independent_gaussian_gives_the_variances_exactly() {
        let sigma = [0.1, 1.0, 7.0];
        let mut est = GradientMetricEstimator::new(3);
        let mut rng = stream_rng(4, 0);
        for _ in 0..10 {
            let x: Vec<f64> = sigma
                .iter()
                .map(|s| s * standard_normal(&mut rng))
                .collect();
            let g: Vec<f64> = x.iter().zip(&sigma).map(|(x, s)| -x / (s * s)).collect();
            est.add(&x, &g);
        }
        let m = est.metric().unwrap().inverse_mass_diagonal();
        for (mi, s) in m.iter().zip(&sigma) {
            assert!((mi / (s * s) - 1.0).abs() < 1e-12, "{mi} vs {}", s * s);
        }
        est.reset();
        assert!(est.metric().is_none());
    }

    /// An AR(1)-correlated Gaussian (`ρ = 0.8`, scales `σ_i`), exact draws:
    /// `Σ = S R S` with `R_ij = ρ^|i−j|`, `R⁻¹ = (1/(1−ρ²))·tridiag(−ρ,
    /// (1, 1+ρ², …, 1+ρ², 1), −ρ)`, so the estimator's limit is
    /// `Σ_ii/√((Σ⁻¹)_ii·Σ_ii) = σ_i²/√(R⁻¹)_ii`.
    ///
    /// Tolerance from the window's sample size `n`: for Gaussian draws
    /// `Var(ln s²) ≈ 2/(n−1)` for both sample variances, and
    /// `Var(½(ln s²_x − ln s²_g)) ≤ Var(ln s²) = 2/(n−1)` (Cauchy–Schwarz on
    /// the covariance), so `|ln(est/limit)| < 5√(2/(n−1))` fails with
    /// probability < 6e-7 per coordinate. Control: Stan's estimate from the
    /// draws alone, `Σ_ii`, is off by `ln √(R⁻¹)_ii ≥ 0.51` > the bound.
    #[test]
    fn correlated_gaussian_within_the_window_tolerance() {
        let (d, n, rho) = (20, 500, 0.8f64);
        let sigma: Vec<f64> = (0..d).map(|i| 0.1 * 1.3f64.powi(i as i32)).collect();
        let c = 1.0 / (1.0 - rho * rho);
        let rinv_diag = |i: usize| {
            if i == 0 || i == d - 1 {
                c
            } else {
                c * (1.0 + rho * rho)
            }
        };
        let mut est = GradientMetricEstimator::new(d);
        let mut draws_only = MetricEstimator::diagonal(d);
        let mut rng = stream_rng(11, 0);
        let mut z = vec![0.0; d];
        for _ in 0..n {
            z[0] = standard_normal(&mut rng);
            for i in 1..d {
                z[i] = rho * z[i - 1] + (1.0 - rho * rho).sqrt() * standard_normal(&mut rng);
            }
            let x: Vec<f64> = (0..d).map(|i| sigma[i] * z[i]).collect();
            // g = −S⁻¹ R⁻¹ z.
            let g: Vec<f64> = (0..d)
                .map(|i| {
                    let mut r = rinv_diag(i) * z[i];
                    if i > 0 {
                        r -= c * rho * z[i - 1];
                    }
                    if i + 1 < d {
                        r -= c * rho * z[i + 1];
                    }
                    -r / sigma[i]
                })
                .collect();
            est.add(&x, &g);
            draws_only.add(&x);
        }
        let tol = 5.0 * (2.0 / (n as f64 - 1.0)).sqrt();
        let m = est.metric().unwrap().inverse_mass_diagonal();
        let v = draws_only.variances().unwrap();
        for i in 0..d {
            let limit = sigma[i] * sigma[i] / rinv_diag(i).sqrt();
            let err = (m[i] / limit).ln();
            assert!(
                err.abs() < tol,
                "coordinate {i}: ln(est/limit) = {err}, tol {tol}"
            );
            let control = (v[i] / limit).ln();
            assert!(control.abs() > tol, "control {i}: {control}");
        }
    }
}
