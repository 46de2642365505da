//! Welford estimators of the metric, regularised like Stan.

use crate::kernel::Metric;

/// Running mean and (co)variance of warm-up draws.
#[derive(Clone, Debug)]
pub struct MetricEstimator {
    dense: bool,
    n: usize,
    mean: Vec<f64>,
    // Diagonal: sums of squared deviations; dense: the d×d co-moment matrix.
    m2: Vec<f64>,
    delta: Vec<f64>,
}

impl MetricEstimator {
    /// Estimates the marginal variances in dimension `d`.
    pub fn diagonal(d: usize) -> Self {
        MetricEstimator {
            dense: false,
            n: 0,
            mean: vec![0.0; d],
            m2: vec![0.0; d],
            delta: vec![0.0; d],
        }
    }

    /// Estimates the full covariance in dimension `d`.
    pub fn dense(d: usize) -> Self {
        MetricEstimator {
            dense: true,
            n: 0,
            mean: vec![0.0; d],
            m2: vec![0.0; d * d],
            delta: vec![0.0; d],
        }
    }

    /// Draws added since the last reset.
    pub fn count(&self) -> usize {
        self.n
    }

    /// Adds a draw (ignored if its length is wrong or it is not finite).
    pub fn add(&mut self, x: &[f64]) {
        let d = self.mean.len();
        if x.len() != d || !x.iter().all(|v| v.is_finite()) {
            return;
        }
        self.n += 1;
        let n = self.n as f64;
        for i in 0..d {
            self.delta[i] = x[i] - self.mean[i];
            self.mean[i] += self.delta[i] / n;
        }
        if self.dense {
            // m2 += (x − mean_old)(x − mean_new)ᵀ
            for i in 0..d {
                for j in 0..d {
                    self.m2[i * d + j] += self.delta[i] * (x[j] - self.mean[j]);
                }
            }
        } else {
            for i in 0..d {
                self.m2[i] += self.delta[i] * (x[i] - self.mean[i]);
            }
        }
    }

    /// Appends the draws' count, mean and co-moments (bit for bit) for
    /// checkpoints; the shape is the estimator's setting, not saved.
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        out.push(self.n as u64);
        crate::checkpoint::put_f64s(out, &self.mean);
        crate::checkpoint::put_f64s(out, &self.m2);
    }

    /// Restores [`Self::words`] of an estimator of this shape from the
    /// front of `input`; false when cut.
    pub(crate) fn restore(&mut self, input: &mut &[u64]) -> bool {
        use crate::checkpoint::{take_f64s, take_word};
        let n = take_word(input).and_then(|n| usize::try_from(n).ok());
        let mean = take_f64s(input, self.mean.len());
        let m2 = take_f64s(input, self.m2.len());
        let (Some(n), Some(mean), Some(m2)) = (n, mean, m2) else {
            return false;
        };
        (self.n, self.mean, self.m2) = (n, mean, m2);
        true
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The unregularised sample variances `m2/(n − 1)` of a diagonal
    /// estimator (the diagonal of the covariance for a dense one); `None`
    /// with fewer than 3 draws.
    pub fn variances(&self) -> Option<Vec<f64>> {
        if self.n < 3 {
            return None;
        }
        let (d, n) = (self.mean.len(), self.n as f64);
        Some(
            (0..d)
                .map(|i| {
                    let m2 = if self.dense {
                        self.m2[i * d + i]
                    } else {
                        self.m2[i]
                    };
                    m2 / (n - 1.0)
                })
                .collect(),
        )
    }

    /// Forgets every draw.
    pub fn reset(&mut self) {
        self.n = 0;
        self.mean.fill(0.0);
        self.m2.fill(0.0);
    }

    /// The regularised estimate `n/(n+5) Σ̂ + 10⁻³ · 5/(n+5) I` (Stan), or
    /// `None` with fewer than 3 draws or a non-positive-definite result.
    pub fn metric(&self) -> Option<Metric> {
        if self.n < 3 {
            return None;
        }
        let d = self.mean.len();
        let n = self.n as f64;
        let shrink = n / (n + 5.0);
        let ridge = 1e-3 * 5.0 / (n + 5.0);
        if self.dense {
            let rows: Vec<Vec<f64>> = (0..d)
                .map(|i| {
                    (0..d)
                        .map(|j| {
                            // Symmetrise: the Welford update is only symmetric up to rounding.
                            let c = 0.5 * (self.m2[i * d + j] + self.m2[j * d + i]) / (n - 1.0);
                            shrink * c + if i == j { ridge } else { 0.0 }
                        })
                        .collect()
                })
                .collect();
            Metric::dense(&rows).ok()
        } else {
            let v = self
                .m2
                .iter()
                .map(|m| shrink * m / (n - 1.0) + ridge)
                .collect();
            Metric::diagonal(v).ok()
        }
    }
}
