//! Adaptive schedule (Syed et al. 2021, as in Pigeons): estimate the
//! communication barrier from neighbour rejection rates and move the levels
//! so that every neighbour pair has the same rejection rate.
//!
//! With `r_i = 1 − E[α_{i,i+1}]` the rejection rate of neighbour pair
//! `(i, i+1)`, the cumulative barrier is `Λ(β_i) = Σ_{k<i} r_k` and the
//! total barrier `Λ = Σ r_i`. `Λ(β)` is interpolated monotonically
//! (Fritsch–Carlson) and the new `β_k` solve `Λ(β_k) = k·Λ/(M−1)`, keeping
//! both ends fixed. Use rounds of doubling length (`tune_schedule`), then
//! stop calling it ("frozen"); `Λ` is reported by
//! [`crate::replica::ReplicaStatistics::barrier`]. Rule of thumb from
//! Pigeons: `M ≈ 2Λ` levels suffice.

use super::ensemble::ReplicaExchange;
use super::family::TunableFamily;
use crate::chain::Algorithm;
use crate::error::{Result, invalid};

/// Cumulative barrier `[0, r_0, r_0 + r_1, …]` at each level.
pub fn cumulative_barrier(rejections: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(rejections.len() + 1);
    let mut acc = 0.0;
    out.push(0.0);
    for r in rejections {
        acc += r;
        out.push(acc);
    }
    out
}

/// Fritsch–Carlson monotone cubic interpolant through increasing `x` and
/// non-decreasing `y`.
struct Monotone {
    x: Vec<f64>,
    y: Vec<f64>,
    m: Vec<f64>,
}

impl Monotone {
    fn new(x: Vec<f64>, y: Vec<f64>) -> Self {
        let n = x.len();
        let d: Vec<f64> = (0..n - 1)
            .map(|i| (y[i + 1] - y[i]) / (x[i + 1] - x[i]))
            .collect();
        let mut m = vec![0.0; n];
        m[0] = d[0];
        m[n - 1] = d[n - 2];
        for i in 1..n - 1 {
            m[i] = if d[i - 1] * d[i] <= 0.0 {
                0.0
            } else {
                (d[i - 1] + d[i]) / 2.0
            };
        }
        for i in 0..n - 1 {
            if d[i] == 0.0 {
                m[i] = 0.0;
                m[i + 1] = 0.0;
                continue;
            }
            let (a, b) = (m[i] / d[i], m[i + 1] / d[i]);
            let s = a * a + b * b;
            if s > 9.0 {
                let t = 3.0 / s.sqrt();
                m[i] = t * a * d[i];
                m[i + 1] = t * b * d[i];
            }
        }
        Monotone { x, y, m }
    }

    fn eval(&self, t: f64) -> f64 {
        let n = self.x.len();
        let i = match self.x.partition_point(|&v| v <= t) {
            0 => 0,
            k if k >= n => n - 2,
            k => k - 1,
        };
        let h = self.x[i + 1] - self.x[i];
        let s = ((t - self.x[i]) / h).clamp(0.0, 1.0);
        let (s2, s3) = (s * s, s * s * s);
        (2.0 * s3 - 3.0 * s2 + 1.0) * self.y[i]
            + (s3 - 2.0 * s2 + s) * h * self.m[i]
            + (-2.0 * s3 + 3.0 * s2) * self.y[i + 1]
            + (s3 - s2) * h * self.m[i + 1]
    }

    /// Smallest `t` with `eval(t) ≥ target`, by bisection (the interpolant
    /// is non-decreasing).
    fn invert(&self, target: f64) -> f64 {
        let (mut lo, mut hi) = (self.x[0], self.x[self.x.len() - 1]);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.eval(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }
}

/// New parameters (`β_0 = 1 > … > β_{M−1}`) equalising the neighbour
/// rejection rates `rejections[i]` of pair `(i, i+1)`. Both ends stay.
pub fn equalised_schedule(betas: &[f64], rejections: &[f64]) -> Result<Vec<f64>> {
    let m = betas.len();
    if rejections.len() + 1 != m {
        return Err(invalid(
            "rejections",
            "need one rejection rate per neighbour pair",
        ));
    }
    if rejections
        .iter()
        .any(|r| !(r.is_finite() && (0.0..=1.0).contains(r)))
    {
        return Err(invalid(
            "rejections",
            "every neighbour pair needs a rejection rate in [0, 1] (were all pairs attempted?)",
        ));
    }
    if betas.windows(2).any(|w| w[1] >= w[0]) {
        return Err(invalid("betas", "must strictly decrease"));
    }
    let lambda = cumulative_barrier(rejections);
    let total = lambda[m - 1];
    if m < 3 || total <= 0.0 {
        return Ok(betas.to_vec());
    }
    // Λ as a non-decreasing function of x = −β (from the target down).
    let f = Monotone::new(betas.iter().map(|b| -b).collect(), lambda);
    let mut out = Vec::with_capacity(m);
    out.push(betas[0]);
    for k in 1..m - 1 {
        out.push(-f.invert(total * k as f64 / (m - 1) as f64));
    }
    out.push(betas[m - 1]);
    // Guard the strict order against flat stretches of Λ.
    for k in 1..m {
        if out[k] >= out[k - 1] {
            out[k] = out[k - 1] - (out[k - 1] - betas[m - 1]) * 1e-9 - f64::MIN_POSITIVE;
        }
    }
    Ok(out)
}

/// What a schedule adaptation did.
#[derive(Clone, Debug, PartialEq)]
pub struct ScheduleUpdate {
    /// Parameters before.
    pub old: Vec<f64>,
    /// Parameters after.
    pub new: Vec<f64>,
    /// Estimated barrier `Λ` from the round that just ended.
    pub barrier: f64,
    /// Neighbour rejection rates of that round.
    pub rejections: Vec<f64>,
}

impl<S, F, A> ReplicaExchange<S, F, A>
where
    S: Clone + Send + Sync,
    F: TunableFamily<S> + Sync,
    F::Payload: Send + Sync,
    A: Algorithm<S, F::Payload> + Send,
{
    /// Ends a tuning round: computes `Λ` from the neighbour rejection rates
    /// since the last call ([`ReplicaStatistics::neighbour_rejection`]:
    /// end-of-sweep probes, so any exchange move works for a power family),
    /// moves the levels to equalise rejection, re-targets every chain's
    /// sample and clears the pair counts.
    ///
    /// [`ReplicaStatistics::neighbour_rejection`]: super::ReplicaStatistics::neighbour_rejection
    pub fn adapt_schedule(&mut self) -> Result<ScheduleUpdate> {
        self.adapt_schedule_with(|_, _, _, _| {})
    }

    /// [`Self::adapt_schedule`], then `rescale(level, old, new, algorithm)`
    /// for every level whose parameter moved, so that the level's kernel
    /// can follow its density (a power family's level `β` is `1/√β` wide:
    /// [`temperature_rescale`] gives the factor for a random walk).
    pub fn adapt_schedule_with(
        &mut self,
        mut rescale: impl FnMut(usize, f64, f64, &mut A),
    ) -> Result<ScheduleUpdate> {
        let rejections = self.stats.neighbour_rejection();
        let old = self.family.parameters();
        let new = equalised_schedule(&old, &rejections)?;
        self.family.set_parameters(new.clone())?;
        for (level, algorithm) in self.algorithms.iter_mut().enumerate() {
            if old[level] != new[level] {
                rescale(level, old[level], new[level], algorithm);
            }
        }
        for (level, chain) in self.chains.iter_mut().enumerate() {
            let ld = self.family.log_density_of(level, &chain.current);
            self.family.retarget(level, &mut chain.current, ld);
        }
        self.stats.reset_pairs();
        Ok(ScheduleUpdate {
            old,
            new,
            barrier: rejections.iter().sum(),
            rejections,
        })
    }

    /// Pigeons-style tuning: `rounds` rounds of `2^r` sweeps (r = 0, 1, …),
    /// adapting the schedule after each. Returns the last update.
    pub fn tune_schedule(&mut self, rounds: u32) -> Result<Option<ScheduleUpdate>> {
        self.tune_schedule_with(rounds, |_, _, _, _| {})
    }

    /// [`Self::tune_schedule`] with the kernels rescaled after every round
    /// (see [`Self::adapt_schedule_with`]).
    pub fn tune_schedule_with(
        &mut self,
        rounds: u32,
        mut rescale: impl FnMut(usize, f64, f64, &mut A),
    ) -> Result<Option<ScheduleUpdate>> {
        let mut last = None;
        for r in 0..rounds {
            for _ in 0..(1u64 << r) {
                self.sweep();
            }
            last = Some(self.adapt_schedule_with(&mut rescale)?);
        }
        Ok(last)
    }
}

/// The factor by which a random walk's scale should change when its
/// level's inverse temperature moves from `old` to `new`: `√(old/new)`,
/// since `π^β` of a density of width `w` has width `w/√β` (the rule
/// [`super::kernel_scales`] uses). `None` when either `β` is 0 (a level
/// that is the prior alone has no such width).
pub fn temperature_rescale(old: f64, new: f64) -> Option<f64> {
    (old > 0.0 && new > 0.0).then(|| (old / new).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_rejections_keep_the_schedule_and_skewed_ones_move_it() {
        let betas = [1.0, 0.5, 0.25, 0.125];
        let same = equalised_schedule(&betas, &[0.3, 0.3, 0.3]).unwrap();
        for (a, b) in same.iter().zip(&betas) {
            assert!((a - b).abs() < 1e-9, "{same:?}");
        }
        // All rejection between the first two levels: the new levels crowd
        // into [0.5, 1].
        let moved = equalised_schedule(&betas, &[0.9, 0.0, 0.0]).unwrap();
        assert_eq!(moved[0], 1.0);
        assert_eq!(moved[3], 0.125);
        assert!(moved[1] > 0.5 && moved[2] > 0.5, "{moved:?}");
        assert!(moved.windows(2).all(|w| w[1] < w[0]), "{moved:?}");
    }

    #[test]
    fn piecewise_linear_barrier_is_inverted_exactly() {
        // Λ linear in β ⇒ the equalised schedule is equally spaced in β.
        let betas = [1.0, 0.9, 0.3, 0.0];
        let rej = [0.1, 0.6, 0.3];
        let new = equalised_schedule(&betas, &rej).unwrap();
        for (k, b) in new.iter().enumerate() {
            assert!((b - (1.0 - k as f64 / 3.0)).abs() < 1e-6, "{new:?}");
        }
    }
}
