//! Warm-up adaptation for gradient kernels, following Stan:
//!
//! - [`DualAveraging`]: the step size by Nesterov dual averaging (Hoffman &
//!   Gelman 2014, §3.2; constants γ = 0.05, t₀ = 10, κ = 0.75, μ = ln 10ε₀);
//! - [`WarmupSchedule`]: Stan's windows — an initial fast buffer (75
//!   iterations), slow windows that double in length from 25 in which the
//!   metric is estimated, and a final fast buffer (50);
//! - [`MetricEstimator`]: Welford estimates of the variances (diagonal) or
//!   covariance (dense), regularised towards `10⁻³ I` like Stan;
//! - [`AcceptanceStatistic`]: Stan's acceptance statistic throughout, or
//!   nuts-rs's symmetrised one from the last metric window on;
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

/// Which per-transition acceptance statistic dual averaging steers
/// towards the target (`adapt_delta`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AcceptanceStatistic {
    /// Stan's: the mean over the trajectory's new points of
    /// `min(1, e^{dᵢ})`, `dᵢ = H₀ − Hᵢ`, throughout the warm-up.
    #[default]
    Stan,
    /// nuts-rs's late warm-up: Stan's statistic until the last metric
    /// window starts, then the symmetrised mean of
    /// `2·min(1, e^{dᵢ})/(1 + e^{dᵢ}) = 2/(1 + e^{|dᵢ|})`. It is even in
    /// `dᵢ`, so it does not depend on whether the start sits high or low
    /// in the trajectory's energy oscillation; with less noise in the
    /// feedback the dual-averaging iterates scatter less (100-d Gaussian:
    /// standard deviation of `ln ε` 0.08–0.10 instead of 0.15–0.18), and
    /// fewer warm-up trees cross into the next doubling
    /// (`docs/performance.md`, "NUTS vs nuts-rs, session 16"). Not from the
    /// start: on the way into the posterior the energy falls, the
    /// symmetrised statistic reads that as rejection and drives the step
    /// towards 0 (on `arma-arma11` a chain started at |θ| > 1 then never
    /// moved).
    SymmetricLate,
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
    /// [`Self::DiagonalGradient`] in every slow window but the last two,
    /// then [`Self::Diagonal`] (the variances) in the last two, whose
    /// estimate the chain keeps. The short early windows (25, 50, 100
    /// draws of Stan's schedule) give the variances alone a noisy metric
    /// and the warm-up long trees; the gradient-based estimate settles from
    /// few draws. The final metric is still Stan's variances, which sample
    /// arK better than the gradient-based one; switching one window before
    /// the end leaves continuous dual averaging 550 iterations to follow
    /// the change (switching at the last update left arK's final step too
    /// large: 65 divergences, half the ESS). `docs/performance.md`, "Eight
    /// schools' warm-up, session 17". Falls back to the variances where the
    /// kernel passes no gradient.
    DiagonalGradientEarly,
}

/// The estimator behind a [`MetricAdaptation`].
#[derive(Clone, Debug)]
enum Estimator {
    Draws(MetricEstimator),
    Gradient(GradientMetricEstimator),
    /// Gradient-based before the last two slow windows, variances in them.
    GradientEarly(GradientMetricEstimator, MetricEstimator),
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
    acceptance: AcceptanceStatistic,
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
            MetricAdaptation::DiagonalGradientEarly => Some(Estimator::GradientEarly(
                GradientMetricEstimator::new(dim),
                MetricEstimator::diagonal(dim),
            )),
        };
        Ok(Warmup {
            schedule: WarmupSchedule::stan(iterations),
            step: DualAveraging::new(initial_step, target_accept),
            estimator,
            iteration: 0,
            frozen: iterations == 0,
            step_size_adaptation: StepSizeAdaptation::Restart,
            acceptance: AcceptanceStatistic::Stan,
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

    /// Which acceptance statistic dual averaging steers (default
    /// [`AcceptanceStatistic::Stan`]); the symmetrised one comes from
    /// [`Self::observe_with_statistics`].
    pub fn with_acceptance_statistic(mut self, statistic: AcceptanceStatistic) -> Self {
        self.acceptance = statistic;
        self
    }

    /// True once warm-up is over.
    pub fn is_frozen(&self) -> bool {
        self.frozen
    }

    /// Iterations observed so far.
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Appends what the warm-up has learnt and where it is (iteration,
    /// frozen, dual averaging, the metric estimator's sums) for
    /// checkpoints; its schedule and options are settings, not saved.
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        out.extend([self.iteration as u64, u64::from(self.frozen)]);
        self.step.words(out);
        match &self.estimator {
            None => {}
            Some(Estimator::Draws(e)) => e.words(out),
            Some(Estimator::Gradient(e)) => e.words(out),
            Some(Estimator::GradientEarly(g, v)) => {
                g.words(out);
                v.words(out);
            }
        }
    }

    /// Restores [`Self::words`] into a warm-up made with the same settings,
    /// from the front of `input`; false when cut or inconsistent (an
    /// iteration beyond the schedule, a frozen flag not 0 or 1).
    pub(crate) fn restore(&mut self, input: &mut &[u64]) -> bool {
        let Some(&[iteration, frozen]) = crate::checkpoint::take_words(input, 2) else {
            return false;
        };
        if iteration > self.schedule.iterations() as u64 || frozen > 1 {
            return false;
        }
        (self.iteration, self.frozen) = (iteration as usize, frozen == 1);
        self.step.restore(input)
            && match &mut self.estimator {
                None => true,
                Some(Estimator::Draws(e)) => e.restore(input),
                Some(Estimator::Gradient(e)) => e.restore(input),
                Some(Estimator::GradientEarly(g, v)) => g.restore(input) && v.restore(input),
            }
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
        self.observe_with_statistics(alpha, alpha, state, gradient)
    }

    /// [`Self::observe_with_gradient`] with, beside the acceptance
    /// statistic `alpha` (the mean of `min(1, e^{H₀ − Hᵢ})` over a
    /// trajectory's points), its symmetrised form `symmetric_alpha`, the
    /// mean of `2·min(1, e^{dᵢ})/(1 + e^{dᵢ}) = 2/(1 + e^{|dᵢ|})` with
    /// `dᵢ = H₀ − Hᵢ`, which does not depend on the sign of the energy
    /// error and so not on where in the trajectory's energy oscillation the
    /// start sits; the warm-up steers it as
    /// [`Self::with_acceptance_statistic`] says.
    pub fn observe_with_statistics(
        &mut self,
        alpha: f64,
        symmetric_alpha: f64,
        state: &[f64],
        gradient: Option<&[f64]>,
    ) -> Option<WarmupUpdate> {
        if self.frozen {
            return None;
        }
        let i = self.iteration;
        self.iteration += 1;
        let late = self.schedule.last_window_start().is_some_and(|s| i >= s);
        let a = match self.acceptance {
            AcceptanceStatistic::SymmetricLate if late => symmetric_alpha,
            _ => alpha,
        };
        let mut step_size = self.step.update(if a.is_nan() { 0.0 } else { a });
        let mut metric = None;
        if let Some(est) = &mut self.estimator {
            // `DiagonalGradientEarly` estimates the variances in the last two
            // windows (all windows when there are fewer than three).
            let variances = self.schedule.early_windows_end().is_none_or(|e| i > e);
            if self.schedule.in_slow_window(i) {
                match (&mut *est, gradient) {
                    (Estimator::Draws(e), _) => e.add(state),
                    (Estimator::Gradient(e), Some(g)) => e.add(state, g),
                    (Estimator::Gradient(_), None) => {}
                    (Estimator::GradientEarly(e, _), Some(g)) if !variances => e.add(state, g),
                    (Estimator::GradientEarly(_, e), _) => e.add(state),
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
                    // Without gradients the early windows fed the variances.
                    Estimator::GradientEarly(g, v) => {
                        metric = if g.count() > 0 {
                            g.metric()
                        } else {
                            v.metric()
                        };
                        g.reset();
                        v.reset();
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

    /// The step sizes of a 300-iteration warm-up (no metric) fed the
    /// statistics `alpha_i` and `symmetric_i`.
    fn steps_with(statistic: AcceptanceStatistic, feed: impl Fn(usize) -> (f64, f64)) -> Vec<f64> {
        let mut w = Warmup::new(300, 0.5, 0.8, MetricAdaptation::None, 2)
            .unwrap()
            .with_acceptance_statistic(statistic);
        (0..300)
            .map(|i| {
                let (a, s) = feed(i);
                w.observe_with_statistics(a, s, &[0.0, 0.0], None)
                    .unwrap()
                    .step_size
            })
            .collect()
    }

    /// `SymmetricLate` steers Stan's statistic before the last slow window
    /// (Stan's 300-iteration schedule: windows end at 99, 149, 249, so the
    /// last starts at 150) and the symmetrised one from there: its step
    /// path is that of a plain warm-up fed `alpha` up to 149 and
    /// `symmetric` after. Control: `Stan` ignores `symmetric` and departs
    /// from that path at iteration 150.
    #[test]
    fn symmetric_late_steers_the_symmetrised_statistic_from_the_last_window() {
        let alpha = |i: usize| 0.5 + 0.45 * ((i as f64) * 0.7).sin();
        let symmetric = |i: usize| 0.6 + 0.3 * ((i as f64) * 1.3).cos();
        let late = steps_with(AcceptanceStatistic::SymmetricLate, |i| {
            (alpha(i), symmetric(i))
        });
        let spliced = steps_with(AcceptanceStatistic::Stan, |i| {
            let a = if i < 150 { alpha(i) } else { symmetric(i) };
            (a, f64::NAN)
        });
        assert_eq!(late, spliced);
        let stan = steps_with(AcceptanceStatistic::Stan, |i| (alpha(i), symmetric(i)));
        assert_eq!(stan[..150], late[..150]);
        assert_ne!(stan[150], late[150]);
    }

    /// The metric at each window end of a 1000-iteration warm-up (windows
    /// 75 / 25 / 150: ends 99, 149, 249, 449, 849) fed draws `x ~ N(0, 1)`
    /// with gradients `−4x` (`with_gradient`) or none: the gradient-based
    /// estimate is `√(var x / var g) = 1/4` exactly, the variances' ≈ 1.
    fn window_metrics(metric: MetricAdaptation, with_gradient: bool) -> Vec<f64> {
        let mut w = Warmup::new(1000, 0.5, 0.8, metric, 1)
            .unwrap()
            .with_schedule(WarmupSchedule::new(1000, 75, 25, 150))
            .unwrap();
        let mut rng = crate::rng::stream_rng(3, 0);
        let mut out = Vec::new();
        for _ in 0..1000 {
            let x = [crate::rng::standard_normal(&mut rng)];
            let g = [-4.0 * x[0]];
            let u = w
                .observe_with_gradient(0.8, &x, with_gradient.then_some(&g[..]))
                .unwrap();
            if let Some(m) = u.metric {
                out.push(m.inverse_mass_diagonal()[0]);
            }
        }
        out
    }

    /// `DiagonalGradientEarly`: the gradient-based estimate at the first
    /// three window ends, the variances at the last two (the metric the
    /// chain keeps); without gradients, the variances throughout.
    /// Controls: `DiagonalGradient` is gradient-based at every end,
    /// `Diagonal` nowhere.
    #[test]
    fn gradient_early_metric_switches_to_the_variances_for_the_last_two_windows() {
        let early = window_metrics(MetricAdaptation::DiagonalGradientEarly, true);
        assert_eq!(early.len(), 5);
        for m in &early[..3] {
            assert!((m - 0.25).abs() < 1e-12, "{early:?}");
        }
        for m in &early[3..] {
            assert!((m - 1.0).abs() < 0.3, "{early:?}");
        }
        let plain = window_metrics(MetricAdaptation::Diagonal, true);
        assert_eq!(
            window_metrics(MetricAdaptation::DiagonalGradientEarly, false),
            plain
        );
        assert_eq!(early[3..], plain[3..]);
        assert!(plain.iter().all(|m| (m - 1.0).abs() < 0.4), "{plain:?}");
        let gradient = window_metrics(MetricAdaptation::DiagonalGradient, true);
        assert!(
            gradient.iter().all(|m| (m - 0.25).abs() < 1e-12),
            "{gradient:?}"
        );
    }
}
