//! Start-up bias elimination (Veach & Guibas; spec seed000-ch1-4 §3.6) and
//! running normalisation estimates (spec seed000-ch5-6 Eq. 6.4).
//!
//! Draw `N` candidates `u_i ~ p₀`, weight them by `w_i = π(u_i)/p₀(u_i)`,
//! start chains at candidates resampled with probability `∝ w_i`, and weight
//! every estimate by `b* = (1/N) Σ w_i`, an unbiased estimate of the
//! normalising constant `b = ∫π`. All weights are kept in log space.

use crate::error::{CoreError, Result, invalid};
use crate::math::{log_sum_exp, sample_log_categorical};
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;
use crate::space::ReferenceMeasure;
use crate::target::{DensityClass, Target};

/// The result of a start-up bootstrap.
#[derive(Clone, Debug)]
pub struct Bootstrap<S, P = ()> {
    candidates: Vec<Sample<S, P>>,
    log_weights: Vec<f64>,
    log_b: f64,
    standard_error: f64,
    invalid: usize,
}

impl<S: Clone, P: Clone> Bootstrap<S, P> {
    /// Bootstraps from `space`'s reference measure with `count` candidates.
    pub fn from_reference<Sp, T>(
        target: &T,
        space: &Sp,
        count: usize,
        rng: &mut ChainRng,
    ) -> Result<Self>
    where
        Sp: ReferenceMeasure<State = S>,
        T: Target<S, Payload = P>,
    {
        Self::from_sampler(target, count, rng, |rng| {
            let s = space.sample_reference(rng);
            let lp = space.log_reference_density(&s);
            (s, lp)
        })
    }

    /// Bootstraps from any independent sampler returning `(state, ln p₀(state))`.
    pub fn from_sampler<T: Target<S, Payload = P>>(
        target: &T,
        count: usize,
        rng: &mut ChainRng,
        mut sampler: impl FnMut(&mut ChainRng) -> (S, f64),
    ) -> Result<Self> {
        if count == 0 {
            return Err(invalid(
                "count",
                "the bootstrap needs at least one candidate",
            ));
        }
        let mut candidates = Vec::with_capacity(count);
        let mut log_weights = Vec::with_capacity(count);
        let mut invalid_count = 0;
        for _ in 0..count {
            let (state, log_p0) = sampler(rng);
            let sample = Sample::evaluate(target, state);
            let lw = match DensityClass::of(sample.log_density) {
                DensityClass::Finite if log_p0.is_finite() => sample.log_density - log_p0,
                DensityClass::Invalid => {
                    invalid_count += 1;
                    f64::NEG_INFINITY
                }
                _ => f64::NEG_INFINITY,
            };
            log_weights.push(lw);
            candidates.push(sample);
        }
        Ok(Self::from_weighted(candidates, log_weights, invalid_count))
    }

    fn from_weighted(candidates: Vec<Sample<S, P>>, log_weights: Vec<f64>, invalid: usize) -> Self {
        let n = log_weights.len() as f64;
        let log_b = log_sum_exp(&log_weights) - n.ln();
        // Standard error of the mean of w, computed relative to b to avoid overflow:
        // var(w)/b² = mean((w/b)²) − 1.
        let standard_error = if log_b == f64::NEG_INFINITY {
            0.0
        } else {
            let m2: f64 = log_weights
                .iter()
                .map(|lw| (2.0 * (lw - log_b)).exp())
                .sum::<f64>()
                / n;
            let rel_var = (m2 - 1.0).max(0.0) * n / (n - 1.0).max(1.0);
            (rel_var / n).sqrt() * log_b.exp()
        };
        Bootstrap {
            candidates,
            log_weights,
            log_b,
            standard_error,
            invalid,
        }
    }

    /// `b*`, the estimate of the normalising constant (0 when every candidate
    /// had zero density).
    pub fn b(&self) -> f64 {
        self.log_b.exp()
    }

    /// `ln b*`.
    pub fn log_b(&self) -> f64 {
        self.log_b
    }

    /// Standard error of `b*`.
    pub fn standard_error(&self) -> f64 {
        self.standard_error
    }

    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.candidates.len()
    }

    /// True when there are no candidates.
    pub fn is_empty(&self) -> bool {
        self.candidates.is_empty()
    }

    /// Candidates whose target density was NaN or `+∞` (given zero weight).
    pub fn invalid_candidates(&self) -> usize {
        self.invalid
    }

    /// The candidates and their log weights.
    pub fn candidates(&self) -> impl Iterator<Item = (&Sample<S, P>, f64)> {
        self.candidates.iter().zip(self.log_weights.iter().copied())
    }

    /// Draws one initial state with probability `∝ w_i`.
    pub fn resample_one(&self, rng: &mut ChainRng) -> Result<Sample<S, P>> {
        let i = sample_log_categorical(&self.log_weights, uniform(rng)).ok_or(
            CoreError::ZeroDensityBootstrap {
                candidates: self.candidates.len(),
            },
        )?;
        Ok(self.candidates[i].clone())
    }

    /// Draws `count` initial states independently, with replacement.
    ///
    /// Draws exactly what `count` calls of [`Bootstrap::resample_one`]
    /// would, but from one cumulative table (a binary search per draw):
    /// `resample_one` costs `N` exponentials per draw, which dominated
    /// renderer start-up (1000 draws from 600 000 candidates).
    pub fn resample(&self, count: usize, rng: &mut ChainRng) -> Result<Vec<Sample<S, P>>> {
        let table =
            CumulativeWeights::new(&self.log_weights).ok_or(CoreError::ZeroDensityBootstrap {
                candidates: self.candidates.len(),
            })?;
        Ok((0..count)
            .map(|_| self.candidates[table.draw(uniform(rng))].clone())
            .collect())
    }
}

/// Running sums of max-shifted weights, in the order and arithmetic of
/// [`sample_log_categorical`], so that a draw from a uniform `u` returns
/// the same index.
struct CumulativeWeights {
    cumulative: Vec<f64>,
    last_positive: usize,
}

impl CumulativeWeights {
    /// `None` when every weight is zero or any is NaN.
    fn new(log_weights: &[f64]) -> Option<Self> {
        let m = log_weights
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        if !m.is_finite() || log_weights.iter().any(|w| w.is_nan()) {
            return None;
        }
        let mut acc = 0.0;
        let mut last_positive = 0;
        let cumulative = log_weights
            .iter()
            .enumerate()
            .map(|(i, w)| {
                if *w != f64::NEG_INFINITY {
                    acc += (w - m).exp();
                    last_positive = i;
                }
                acc
            })
            .collect();
        Some(CumulativeWeights {
            cumulative,
            last_positive,
        })
    }

    /// The first index whose running sum exceeds `u · total` (a zero-weight
    /// index never is: its sum equals its predecessor's); the last
    /// positive-weight index if rounding leaves none.
    fn draw(&self, u: f64) -> usize {
        let total = self.cumulative.last().copied().unwrap_or(0.0);
        let threshold = u * total;
        let i = self.cumulative.partition_point(|&c| c <= threshold);
        if i < self.cumulative.len() {
            i
        } else {
            self.last_positive
        }
    }
}

/// A running estimate of `b = ∫π` from independent proposals (large steps):
/// `⟨b⟩ = (1/L) Σ π(u_j)/p(u_j)` over all `L` so far, with its standard
/// error. Kept in log space, so any magnitude works.
#[derive(Clone, Debug, PartialEq)]
pub struct RunningNormalization {
    count: u64,
    log_sum: f64,
    log_sum_sq: f64,
}

impl Default for RunningNormalization {
    fn default() -> Self {
        RunningNormalization {
            count: 0,
            log_sum: f64::NEG_INFINITY,
            log_sum_sq: f64::NEG_INFINITY,
        }
    }
}

impl RunningNormalization {
    /// An empty estimate.
    pub fn new() -> Self {
        Self::default()
    }

    /// The estimate's state `(count, ln Σ w, ln Σ w²)`, bit-exactly, for
    /// sending it to another process.
    pub fn parts(&self) -> (u64, f64, f64) {
        (self.count, self.log_sum, self.log_sum_sq)
    }

    /// The estimate with the state [`RunningNormalization::parts`] gave.
    pub fn from_parts((count, log_sum, log_sum_sq): (u64, f64, f64)) -> Self {
        RunningNormalization {
            count,
            log_sum,
            log_sum_sq,
        }
    }

    /// Adds one independent sample with `ln π(u) − ln p(u)` (NaN is ignored
    /// and counted as zero).
    pub fn add(&mut self, log_weight: f64) {
        self.count += 1;
        if log_weight.is_nan() || log_weight == f64::NEG_INFINITY {
            return;
        }
        self.log_sum = crate::math::log_sum_exp2(self.log_sum, log_weight);
        self.log_sum_sq = crate::math::log_sum_exp2(self.log_sum_sq, 2.0 * log_weight);
    }

    /// Merges another estimate (e.g. from another chain).
    pub fn merge(&mut self, other: &RunningNormalization) {
        self.count += other.count;
        self.log_sum = crate::math::log_sum_exp2(self.log_sum, other.log_sum);
        self.log_sum_sq = crate::math::log_sum_exp2(self.log_sum_sq, other.log_sum_sq);
    }

    /// Samples added.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// `ln ⟨b⟩` (`−∞` before any positive sample).
    pub fn log_b(&self) -> f64 {
        if self.count == 0 {
            return f64::NEG_INFINITY;
        }
        self.log_sum - (self.count as f64).ln()
    }

    /// `⟨b⟩`.
    pub fn b(&self) -> f64 {
        self.log_b().exp()
    }

    /// Standard error of `⟨b⟩`.
    pub fn standard_error(&self) -> f64 {
        if self.count < 2 || self.log_sum == f64::NEG_INFINITY {
            return 0.0;
        }
        let n = self.count as f64;
        let log_b = self.log_b();
        let m2_rel = (self.log_sum_sq - n.ln() - 2.0 * log_b).exp();
        let rel_var = (m2_rel - 1.0).max(0.0) * n / (n - 1.0);
        (rel_var / n).sqrt() * log_b.exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::stream_rng;

    /// The cumulative table must return exactly the index
    /// `sample_log_categorical` returns for the same uniform, including
    /// zero weights (never drawn), at the ends of `[0, 1)`, and with
    /// weights far from 1 in magnitude.
    #[test]
    fn cumulative_table_draws_like_sample_log_categorical() {
        let mut rng = stream_rng(7, 0);
        let mut weights: Vec<f64> = (0..2000)
            .map(|i| {
                if i % 7 == 0 {
                    f64::NEG_INFINITY
                } else {
                    600.0 + 5.0 * (uniform(&mut rng) - 0.5)
                }
            })
            .collect();
        weights[0] = f64::NEG_INFINITY;
        weights[1999] = f64::NEG_INFINITY;
        let table = CumulativeWeights::new(&weights).expect("positive weights");
        let mut us: Vec<f64> = (0..5000).map(|_| uniform(&mut rng)).collect();
        us.extend([0.0, 1.0 - f64::EPSILON, 0.5]);
        for u in us {
            let expected = sample_log_categorical(&weights, u).expect("positive weights");
            assert_eq!(table.draw(u), expected, "u = {u}");
            assert!(weights[expected].is_finite());
        }
        assert!(CumulativeWeights::new(&[f64::NEG_INFINITY; 3]).is_none());
        assert!(CumulativeWeights::new(&[0.0, f64::NAN]).is_none());
    }
}
