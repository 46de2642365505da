//! Warm-up adaptation for gradient kernels, following Stan:
//!
//! - [`DualAveraging`]: the step size by Nesterov dual averaging (Hoffman &
//!   Gelman 2014, §3.2; constants γ = 0.05, t₀ = 10, κ = 0.75, μ = ln 10ε₀);
//! - [`WarmupSchedule`]: Stan's windows — an initial fast buffer (75
//!   iterations), slow windows that double in length from 25 in which the
//!   metric is estimated, and a final fast buffer (50);
//! - [`MetricEstimator`]: Welford estimates of the variances (diagonal) or
//!   covariance (dense), regularised towards `10⁻³ I` like Stan;
//! - [`StepSizeAdaptation`]: whether dual averaging restarts at every
//!   metric update (Stan) or runs once through the warm-up (nuts-rs; NUTS's
//!   default);
//! - [`Warmup`]: all of these together. After the last warm-up iteration (or
//!   [`Warmup::freeze`]) nothing changes any more, so sampling is an exact
//!   Markov chain.

mod dual_averaging;
mod gradient_metric;
mod schedule;
mod welford;

pub use dual_averaging::DualAveraging;
pub use gradient_metric::GradientMetricEstimator;
pub use schedule::WarmupSchedule;
pub use welford::MetricEstimator;

use crate::error::{Result, invalid};
use crate::kernel::Metric;

/// What the step-size adaptation does when the metric changes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StepSizeAdaptation {
    /// Stan's: after every metric update, re-run the step-size heuristic
    /// (NUTS) and restart dual averaging around the new step (`μ = ln 10ε`,
    /// history forgotten); the final step is the average over the terminal
    /// buffer only.
    #[default]
    Restart,
    /// nuts-rs's: one dual-averaging run through the whole warm-up,
    /// started once (after the initial heuristic) and never restarted. The
    /// late iterates then move with gain `1/(γ√t)` instead of restarting at
    /// `1/γ`, so they scatter less around the target acceptance and the
    /// averaged final step is not pulled below it (Stan's restarts leave a
    /// mean `accept_stat` of 0.83–0.91 for a target of 0.8 on the targets of
    /// `examples/hmc_vs_nuts`; see `docs/performance.md`).
    Continuous,
}

/// Which metric the warm-up estimates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MetricAdaptation {
    /// Keep the metric given to the kernel.
    None,
    /// Estimate a diagonal `M⁻¹` (the marginal variances).
    Diagonal,
    /// Estimate a dense `M⁻¹` (the covariance).
    Dense,
    /// Estimate a diagonal `M⁻¹_ii = √(var x_i / var ∂_i ln π)` from the
    /// draws and their gradients (nuts-rs's default;
    /// [`GradientMetricEstimator`]). Needs the kernel to pass the gradient
    /// ([`Warmup::observe_with_gradient`]): NUTS does; with a kernel that
    /// does not, the metric stays as given.
    DiagonalGradient,
}

/// The estimator behind a [`MetricAdaptation`].
#[derive(Clone, Debug)]
enum Estimator {
    Draws(MetricEstimator),
    Gradient(GradientMetricEstimator),
}

/// What one warm-up iteration changed.
#[derive(Clone, Debug, PartialEq)]
pub struct WarmupUpdate {
    /// The step size to use next.
    pub step_size: f64,
    /// A new metric at the end of a slow window.
    pub metric: Option<Metric>,
}

/// Step size and metric adaptation over a warm-up of fixed length.
#[derive(Clone, Debug)]
pub struct Warmup {
    schedule: WarmupSchedule,
    step: DualAveraging,
    estimator: Option<Estimator>,
    iteration: usize,
    frozen: bool,
    step_size_adaptation: StepSizeAdaptation,
}

impl Warmup {
    /// A warm-up of `iterations` steps starting from `initial_step`, aiming
    /// at mean acceptance `target_accept` (0.8 for HMC, 0.574 for MALA),
    /// estimating the metric of dimension `dim` as `metric` says.
    pub fn new(
        iterations: usize,
        initial_step: f64,
        target_accept: f64,
        metric: MetricAdaptation,
        dim: usize,
    ) -> Result<Self> {
        if !(initial_step.is_finite() && initial_step > 0.0) {
            return Err(invalid("step_size", "must be finite and positive"));
        }
        if !(target_accept > 0.0 && target_accept < 1.0) {
            return Err(invalid("target_accept", "must lie in (0, 1)"));
        }
        let estimator = match metric {
            MetricAdaptation::None => None,
            MetricAdaptation::Diagonal => Some(Estimator::Draws(MetricEstimator::diagonal(dim))),
            MetricAdaptation::Dense => Some(Estimator::Draws(MetricEstimator::dense(dim))),
            MetricAdaptation::DiagonalGradient => {
                Some(Estimator::Gradient(GradientMetricEstimator::new(dim)))
            }
        };
        Ok(Warmup {
            schedule: WarmupSchedule::stan(iterations),
            step: DualAveraging::new(initial_step, target_accept),
            estimator,
            iteration: 0,
            frozen: iterations == 0,
            step_size_adaptation: StepSizeAdaptation::Restart,
        })
    }

    /// Sets what the step size does at metric updates (default
    /// [`StepSizeAdaptation::Restart`], Stan's).
    pub fn with_step_size_adaptation(mut self, mode: StepSizeAdaptation) -> Self {
        self.step_size_adaptation = mode;
        self
    }

    /// What the step size does at metric updates.
    pub fn step_size_adaptation(&self) -> StepSizeAdaptation {
        self.step_size_adaptation
    }

    /// Replaces Stan's windows by `schedule` (e.g.
    /// [`WarmupSchedule::proportional`]); it must cover the same number of
    /// iterations and be set before the first observation.
    pub fn with_schedule(mut self, schedule: WarmupSchedule) -> Result<Self> {
        if schedule.iterations() != self.schedule.iterations() || self.iteration > 0 {
            return Err(invalid(
                "schedule",
                "must cover the warm-up's iterations and be set before it starts",
            ));
        }
        self.schedule = schedule;
        Ok(self)
    }

    /// True once warm-up is over.
    pub fn is_frozen(&self) -> bool {
        self.frozen
    }

    /// Iterations observed so far.
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Ends warm-up now; returns the final step size (the dual-averaging
    /// iterate average).
    pub fn freeze(&mut self) -> f64 {
        self.frozen = true;
        self.step.final_step_size()
    }

    /// Restarts dual averaging around `step` (`μ = ln 10·step`), as Stan
    /// does after its step-size heuristic.
    pub fn restart_step_size(&mut self, step: f64) {
        self.step.restart(step);
    }

    /// Records one iteration with acceptance probability `alpha` ending at
    /// `state`. `None` once frozen.
    pub fn observe(&mut self, alpha: f64, state: &[f64]) -> Option<WarmupUpdate> {
        self.observe_with_gradient(alpha, state, None)
    }

    /// [`Self::observe`] with the gradient of `ln π` at `state`, which
    /// [`MetricAdaptation::DiagonalGradient`] needs (without it the
    /// iteration adds nothing to that estimator).
    pub fn observe_with_gradient(
        &mut self,
        alpha: f64,
        state: &[f64],
        gradient: Option<&[f64]>,
    ) -> Option<WarmupUpdate> {
        if self.frozen {
            return None;
        }
        let i = self.iteration;
        self.iteration += 1;
        let mut step_size = self.step.update(if alpha.is_nan() { 0.0 } else { alpha });
        let mut metric = None;
        if let Some(est) = &mut self.estimator {
            if self.schedule.in_slow_window(i) {
                match (&mut *est, gradient) {
                    (Estimator::Draws(e), _) => e.add(state),
                    (Estimator::Gradient(e), Some(g)) => e.add(state, g),
                    (Estimator::Gradient(_), None) => {}
                }
            }
            if self.schedule.is_window_end(i) {
                match est {
                    Estimator::Draws(e) => {
                        metric = e.metric();
                        e.reset();
                    }
                    Estimator::Gradient(e) => {
                        metric = e.metric();
                        e.reset();
                    }
                }
                // Stan restarts dual averaging around the current step size
                // after every metric change.
                if self.step_size_adaptation == StepSizeAdaptation::Restart {
                    self.step.restart(step_size);
                }
            }
        }
        if self.iteration >= self.schedule.iterations() {
            self.frozen = true;
            step_size = self.step.final_step_size();
        }
        Some(WarmupUpdate { step_size, metric })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The step sizes a warm-up returns for a fixed acceptance sequence.
    fn steps(metric: MetricAdaptation, mode: StepSizeAdaptation) -> Vec<f64> {
        let mut w = Warmup::new(300, 0.5, 0.8, metric, 2)
            .unwrap()
            .with_step_size_adaptation(mode);
        (0..300)
            .map(|i| {
                let alpha = 0.5 + 0.45 * ((i as f64) * 0.7).sin();
                let x = [(i as f64 * 0.3).cos(), (i as f64 * 1.1).sin()];
                w.observe(alpha, &x).unwrap().step_size
            })
            .collect()
    }

    /// With `Continuous`, metric updates leave the step-size path alone: it
    /// is bit-identical to that of a warm-up with no metric at all. With
    /// `Restart` (the control) the first window end (iteration 99 of Stan's
    /// 300-iteration schedule, after 75 + 25) changes the path.
    #[test]
    fn continuous_step_size_ignores_metric_updates() {
        let none = steps(MetricAdaptation::None, StepSizeAdaptation::Restart);
        let cont = steps(MetricAdaptation::Diagonal, StepSizeAdaptation::Continuous);
        assert_eq!(none, cont);
        let restart = steps(MetricAdaptation::Diagonal, StepSizeAdaptation::Restart);
        assert_eq!(restart[..100], none[..100]);
        assert_ne!(restart[100], none[100]);
    }
}
