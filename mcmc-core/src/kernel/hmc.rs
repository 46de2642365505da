//! Hamiltonian Monte Carlo as a Metropolis–Hastings kernel (spec
//! seed000-ch5-6 App. 4.A, Eqs. 4.17–4.19).
//!
//! One proposal: draw `p ~ N(0, M)`, run `L` leapfrog steps of size `ε` on
//! `H(x, p) = −ln π(x) + ½ pᵀ M⁻¹ p`, and propose the end point `y`. The map
//! `(x, p) → (y, −p_L)` is a volume-preserving involution, so the kernel
//! reports `log_q_ratio = K(p₀) − K(p_L)` and the standard MH test
//! `ln π(y) − ln π(x) + log_q_ratio = −ΔH` is exact. Momentum is drawn afresh
//! for every proposal, so nothing but the state and its gradient
//! ([`GradientPayload`]) persists between steps, and replica swaps need no
//! extra care.
//!
//! The kernel evaluates the target itself (`Proposal::evaluated`), reusing
//! the gradient cached in the current sample's payload: one gradient
//! evaluation per leapfrog step.
//!
//! **Failures** (never a panic): a trajectory that reaches `ln π = −∞` stops
//! and the proposal is rejected as outside the support; a NaN or infinite
//! gradient or density stops it and the proposal is rejected as invalid;
//! an energy error `ΔH` above the divergence threshold (default 1000) or not
//! finite is a **divergence**, rejected. All are counted in
//! [`GradientKernelStatistics`].
//!
//! **With multiple-try Metropolis**: HMC has no proposal density in `x`
//! (only in the extended space), so `log_proposal_density` is `None` and
//! [`MultipleTry`](crate::mtm::MultipleTry) refuses it for every λ. Use
//! [`Mala`](super::Mala) or [`H2mc`](super::H2mc), which have densities.
//!
//! **Torus** ([`Boundary::Wrap`]): positions are wrapped into `[0, 1)^d`
//! after every drift. The drift (a translation of the torus) and the kick
//! (a shear in `p` at fixed `x`) are each volume preserving, and the
//! leapfrog composed with a momentum flip is still an involution, so the
//! move is exact for any target on the torus; a target that is not periodic
//! merely has larger energy errors across the seam.

use super::phase_pool::PhasePoint;
use super::{Kernel, Metric, Proposal, StepObservation};
use crate::adaptation::{
    AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation, Warmup, WarmupSchedule,
};
use crate::error::{Result, invalid};
use crate::gradient::{
    GradientPayload, GradientTarget, all_finite, check_dimension, check_state_dimension,
    evaluate_checked,
};
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;

/// How positions are kept in the domain.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Boundary {
    /// `R^d`: no boundary.
    Unbounded,
    /// The unit torus `[0, 1)^d`: coordinates wrap around after each drift.
    Wrap,
}

/// What a gradient kernel counts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GradientKernelStatistics {
    /// Proposals (trajectories) made.
    pub trajectories: u64,
    /// Leapfrog steps taken.
    pub leapfrog_steps: u64,
    /// Gradient evaluations (one per leapfrog step; more for H²MC's Hessian).
    pub gradient_evaluations: u64,
    /// Proposals rejected because the energy error exceeded the threshold
    /// (or was not finite).
    pub divergences: u64,
    /// Trajectories stopped by a NaN/infinite density or gradient.
    pub invalid: u64,
    /// Trajectories stopped outside the support (`ln π = −∞`).
    pub outside_support: u64,
}

/// The number of leapfrog steps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trajectory {
    /// A fixed number of steps.
    Steps(usize),
    /// A fixed integration time `T`: `max(1, round(T/ε))` steps, so the
    /// trajectory length follows the adapted step size.
    Time(f64),
}

/// Hamiltonian Monte Carlo kernel over `Vec<f64>` with gradient payloads.
///
/// ```
/// use mcmc_core::prelude::*;
/// use mcmc_core::gradient::{Differentiable, FiniteDifference};
/// use mcmc_core::kernel::Hmc;
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * (x[0] * x[0] + x[1] * x[1]), 2);
/// let target = Differentiable(g);
/// let hmc = Hmc::new(g, 0.3, 10).unwrap();
/// let mut chain = Chain::new(&target, vec![0.0, 0.0], MetropolisHastings::new(hmc), stream_rng(1, 0)).unwrap();
/// for _ in 0..100 { chain.step(&target); }
/// assert!(chain.stats().acceptance_rate() > 0.5);
/// ```
#[derive(Clone, Debug)]
pub struct Hmc<G> {
    target: G,
    dim: usize,
    step_size: f64,
    trajectory: Trajectory,
    jitter: f64,
    metric: Metric,
    boundary: Boundary,
    divergence_threshold: f64,
    warmup: Option<Warmup>,
    stats: GradientKernelStatistics,
    momentum: Vec<f64>,
    velocity: Vec<f64>,
    name: &'static str,
}

impl<G: GradientTarget> Hmc<G> {
    /// HMC with step size `step_size`, `steps` leapfrog steps and the unit
    /// metric.
    pub fn new(target: G, step_size: f64, steps: usize) -> Result<Self> {
        if steps == 0 {
            return Err(invalid("steps", "must be at least 1"));
        }
        Self::with_trajectory(target, step_size, Trajectory::Steps(steps))
    }

    /// HMC with the given trajectory length rule.
    pub fn with_trajectory(target: G, step_size: f64, trajectory: Trajectory) -> Result<Self> {
        check_dimension(&target)?;
        if !(step_size.is_finite() && step_size > 0.0) {
            return Err(invalid(
                "step_size",
                format!("{step_size} must be finite and positive"),
            ));
        }
        match trajectory {
            Trajectory::Steps(0) => return Err(invalid("steps", "must be at least 1")),
            Trajectory::Time(t) if !(t.is_finite() && t > 0.0) => {
                return Err(invalid("integration_time", "must be finite and positive"));
            }
            _ => {}
        }
        let dim = target.dim();
        Ok(Hmc {
            target,
            dim,
            step_size,
            trajectory,
            jitter: 0.0,
            metric: Metric::identity(dim),
            boundary: Boundary::Unbounded,
            divergence_threshold: 1000.0,
            warmup: None,
            stats: GradientKernelStatistics::default(),
            momentum: vec![0.0; dim],
            velocity: vec![0.0; dim],
            name: "hmc",
        })
    }

    /// Uses mass matrix `metric` (given by `M⁻¹`).
    pub fn with_metric(mut self, metric: Metric) -> Result<Self> {
        if metric.dim() != self.dim {
            return Err(crate::CoreError::DimensionMismatch {
                expected: self.dim,
                got: metric.dim(),
            });
        }
        self.metric = metric;
        Ok(self)
    }

    /// Draws each trajectory's step size uniformly from `ε·[1 − j, 1 + j]`
    /// (`0 ≤ j < 1`), which breaks resonances with periodic orbits.
    pub fn with_jitter(mut self, jitter: f64) -> Result<Self> {
        if !(0.0..1.0).contains(&jitter) {
            return Err(invalid("jitter", "must lie in [0, 1)"));
        }
        self.jitter = jitter;
        Ok(self)
    }

    /// Wraps positions on the unit torus (see the module docs).
    pub fn with_boundary(mut self, boundary: Boundary) -> Self {
        self.boundary = boundary;
        self
    }

    /// Energy error above which a trajectory is a divergence (default 1000).
    pub fn with_divergence_threshold(mut self, threshold: f64) -> Result<Self> {
        if threshold.is_nan() || threshold <= 0.0 {
            return Err(invalid("divergence_threshold", "must be positive"));
        }
        self.divergence_threshold = threshold;
        Ok(self)
    }

    /// Adapts the step size (dual averaging towards mean acceptance
    /// `target_accept`, 0.8 is Stan's default) and the metric over the first
    /// `iterations` steps, with Stan's windows; then stops by itself.
    pub fn with_warmup(
        mut self,
        iterations: usize,
        target_accept: f64,
        metric: MetricAdaptation,
    ) -> Result<Self> {
        self.warmup = Some(Warmup::new(
            iterations,
            self.step_size,
            target_accept,
            metric,
            self.dim,
        )?);
        Ok(self)
    }

    /// Sets what the warm-up's step size does at metric updates (no effect
    /// without a warm-up).
    pub(crate) fn set_step_size_adaptation(&mut self, mode: StepSizeAdaptation) {
        if let Some(w) = self.warmup.take() {
            self.warmup = Some(w.with_step_size_adaptation(mode));
        }
    }

    /// Which acceptance statistic the warm-up's dual averaging steers
    /// ([`Warmup::with_acceptance_statistic`]).
    pub(crate) fn set_acceptance_statistic(&mut self, statistic: AcceptanceStatistic) {
        if let Some(w) = self.warmup.take() {
            self.warmup = Some(w.with_acceptance_statistic(statistic));
        }
    }

    /// Replaces the windows of the warm-up set by [`Self::with_warmup`].
    pub(crate) fn with_warmup_schedule(mut self, schedule: WarmupSchedule) -> Result<Self> {
        let w = self
            .warmup
            .take()
            .ok_or_else(|| invalid("schedule", "needs a warm-up"))?;
        self.warmup = Some(w.with_schedule(schedule)?);
        Ok(self)
    }

    /// Current step size.
    pub fn step_size(&self) -> f64 {
        self.step_size
    }

    /// Current metric.
    pub fn metric(&self) -> &Metric {
        &self.metric
    }

    /// True while warm-up adaptation is running.
    pub fn is_adapting(&self) -> bool {
        self.warmup.as_ref().is_some_and(|w| !w.is_frozen())
    }

    /// Divergences, invalid and outside-support trajectories, gradient
    /// evaluations.
    pub fn statistics(&self) -> &GradientKernelStatistics {
        &self.stats
    }

    /// The gradient target.
    pub fn target(&self) -> &G {
        &self.target
    }

    /// One warm-up iteration with acceptance statistic `alpha` ending at
    /// `state`; returns true when the metric changed.
    pub(crate) fn adapt(&mut self, alpha: f64, state: &[f64]) -> bool {
        self.adapt_with_statistics(alpha, alpha, state, None)
    }

    /// [`Self::adapt`] with the symmetrised acceptance statistic as well
    /// ([`Warmup::observe_with_statistics`]) and the gradient of `ln π` at
    /// `state` (for [`MetricAdaptation::DiagonalGradient`]).
    pub(crate) fn adapt_with_statistics(
        &mut self,
        alpha: f64,
        symmetric_alpha: f64,
        state: &[f64],
        gradient: Option<&[f64]>,
    ) -> bool {
        if let Some(w) = &mut self.warmup
            && let Some(update) = w.observe_with_statistics(alpha, symmetric_alpha, state, gradient)
        {
            self.step_size = update.step_size;
            if let Some(m) = update.metric {
                self.metric = m;
                return true;
            }
        }
        false
    }

    /// Sets the step size and restarts dual averaging around it (after
    /// Stan's step-size heuristic); no effect on the warm-up once frozen.
    pub(crate) fn restart_step_size(&mut self, step_size: f64) {
        self.step_size = step_size;
        if let Some(w) = &mut self.warmup
            && !w.is_frozen()
        {
            w.restart_step_size(step_size);
        }
    }

    /// Appends the kernel's state for checkpoints: step size, counters,
    /// metric and warm-up (its settings are not saved: the kernel it is
    /// restored into is built with the same).
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        let s = &self.stats;
        out.push(self.step_size.to_bits());
        out.extend([
            s.trajectories,
            s.leapfrog_steps,
            s.gradient_evaluations,
            s.divergences,
            s.invalid,
            s.outside_support,
        ]);
        self.metric.words(out);
        if let Some(w) = &self.warmup {
            w.words(out);
        }
    }

    /// Restores [`Self::words`] from the front of `input`; false when cut
    /// or inconsistent (the kernel is then not to be used).
    pub(crate) fn restore(&mut self, input: &mut &[u64]) -> bool {
        let Some(w) = crate::checkpoint::take_words(input, 7) else {
            return false;
        };
        let step_size = f64::from_bits(w[0]);
        let Some(metric) = Metric::from_words(input, self.dim) else {
            return false;
        };
        if !(step_size.is_finite() && step_size > 0.0) {
            return false;
        }
        self.step_size = step_size;
        self.stats = GradientKernelStatistics {
            trajectories: w[1],
            leapfrog_steps: w[2],
            gradient_evaluations: w[3],
            divergences: w[4],
            invalid: w[5],
            outside_support: w[6],
        };
        self.metric = metric;
        self.warmup.as_mut().is_none_or(|w| w.restore(input))
    }

    pub(crate) fn statistics_mut(&mut self) -> &mut GradientKernelStatistics {
        &mut self.stats
    }

    pub(crate) fn set_name(&mut self, name: &'static str) {
        self.name = name;
    }

    pub(crate) fn boundary(&self) -> Boundary {
        self.boundary
    }

    pub(crate) fn has_jitter(&self) -> bool {
        self.jitter > 0.0
    }

    fn steps(&self, eps: f64) -> usize {
        match self.trajectory {
            Trajectory::Steps(n) => n,
            Trajectory::Time(t) => ((t / eps).round() as usize).clamp(1, 100_000),
        }
    }

    #[inline]
    fn wrap(&self, x: &mut [f64]) {
        if self.boundary == Boundary::Wrap {
            for v in x.iter_mut() {
                let w = v.rem_euclid(1.0);
                // rem_euclid of a tiny negative number rounds to 1.0.
                *v = if w >= 1.0 { 0.0 } else { w };
            }
        }
    }

    /// Runs `steps` leapfrog steps of size `eps` from `(x, p)` with gradient
    /// `grad` at `x`, in place. Returns `ln π` at the end (or the first
    /// non-finite value met, where it stops) and the steps taken.
    pub fn leapfrog(
        &mut self,
        eps: f64,
        steps: usize,
        x: &mut [f64],
        p: &mut [f64],
        grad: &mut [f64],
    ) -> (f64, usize) {
        let mut v = std::mem::take(&mut self.velocity);
        v.resize(self.dim, 0.0);
        let mut lp = f64::NAN;
        let mut taken = 0;
        for _ in 0..steps {
            taken += 1;
            for (pi, gi) in p.iter_mut().zip(grad.iter()) {
                *pi += 0.5 * eps * gi;
            }
            self.metric.velocity(p, &mut v);
            for (xi, vi) in x.iter_mut().zip(&v) {
                *xi += eps * vi;
            }
            self.wrap(x);
            lp = self.evaluate_at(x, grad);
            if !lp.is_finite() {
                break;
            }
            for (pi, gi) in p.iter_mut().zip(grad.iter()) {
                *pi += 0.5 * eps * gi;
            }
        }
        self.velocity = v;
        (lp, taken)
    }

    /// `ln π(x)` and its gradient, counted; NaN for a non-finite `x`.
    #[inline]
    fn evaluate_at(&mut self, x: &[f64], grad: &mut [f64]) -> f64 {
        self.stats.gradient_evaluations += 1;
        if all_finite(x) {
            evaluate_checked(&self.target, x, grad)
        } else {
            f64::NAN
        }
    }

    /// One leapfrog step of size `eps` from `from` into `to` (out of place:
    /// NUTS keeps every point it may still select), the same arithmetic as
    /// [`Self::leapfrog`] with one step. Sets `to.x`, `to.p`, `to.grad`,
    /// `to.lp`, the velocity `to.v = M⁻¹ to.p` and `to.h = −ln π + ½ pᵀv`
    /// (`+∞` when not finite); the second half kick is skipped, as there,
    /// when `ln π` is not finite.
    pub(crate) fn leapfrog_into(&mut self, eps: f64, from: &PhasePoint, to: &mut PhasePoint) {
        let half = 0.5 * eps;
        if let Some(m) = self.metric.diagonal_inverse_mass() {
            // Kick, velocity and drift fused: `v = m p` element by element.
            for i in 0..self.dim {
                let p = from.p[i] + half * from.grad[i];
                to.p[i] = p;
                to.x[i] = from.x[i] + eps * (m[i] * p);
            }
        } else {
            for i in 0..self.dim {
                to.p[i] = from.p[i] + half * from.grad[i];
            }
            self.metric.velocity(&to.p, &mut to.v);
            for i in 0..self.dim {
                to.x[i] = from.x[i] + eps * to.v[i];
            }
        }
        self.wrap(&mut to.x);
        let lp = self.evaluate_at(&to.x, &mut to.grad);
        let k = match self.metric.diagonal_inverse_mass() {
            Some(m) if lp.is_finite() => {
                // Second kick, velocity and kinetic energy fused. The sum
                // stays one left-to-right chain, as `Metric::kinetic` sums
                // (so every Hamiltonian keeps its bits); the kick and the
                // velocity run in the shadow of its latency instead of in
                // two more passes.
                let mut sum = 0.0;
                for i in 0..self.dim {
                    let p = to.p[i] + half * to.grad[i];
                    let v = m[i] * p;
                    to.p[i] = p;
                    to.v[i] = v;
                    sum += p * v;
                }
                0.5 * sum
            }
            _ => {
                if lp.is_finite() {
                    for (pi, gi) in to.p.iter_mut().zip(&to.grad) {
                        *pi += half * gi;
                    }
                }
                self.metric.kinetic(&to.p, &mut to.v)
            }
        };
        to.lp = lp;
        let h = if lp.is_finite() {
            -lp + k
        } else {
            f64::INFINITY
        };
        to.h = if h.is_nan() { f64::INFINITY } else { h };
    }

    /// Kinetic energy `½ pᵀ M⁻¹ p` under the current metric.
    pub fn kinetic_energy(&mut self, p: &[f64]) -> f64 {
        let mut v = std::mem::take(&mut self.velocity);
        v.resize(self.dim, 0.0);
        let k = self.metric.kinetic(p, &mut v);
        self.velocity = v;
        k
    }

    /// `ln q(from → to)` of a one-step (MALA) move:
    /// `to ~ N(from + ε²/2 M⁻¹∇ln π(from), ε² M⁻¹)`.
    pub(crate) fn one_step_log_density(
        &self,
        from: &Sample<Vec<f64>, GradientPayload>,
        to: &[f64],
    ) -> Option<f64> {
        if from.payload.gradient.len() != self.dim || to.len() != self.dim {
            return None;
        }
        let eps = self.step_size;
        let mut drift = vec![0.0; self.dim];
        self.metric.velocity(&from.payload.gradient, &mut drift);
        let r: Vec<f64> = (0..self.dim)
            .map(|i| (to[i] - from.state[i] - 0.5 * eps * eps * drift[i]) / eps)
            .collect();
        Some(self.metric.log_normal(&r) - self.dim as f64 * eps.ln())
    }
}

impl<G: GradientTarget> Kernel<Vec<f64>, GradientPayload> for Hmc<G> {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, GradientPayload>,
        proposal: &mut Sample<Vec<f64>, GradientPayload>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let d = self.dim;
        if current.state.len() != d || current.payload.gradient.len() != d {
            return Proposal::failed(0);
        }
        self.stats.trajectories += 1;
        let eps = if self.jitter > 0.0 {
            self.step_size * (1.0 + self.jitter * (2.0 * uniform(rng) - 1.0))
        } else {
            self.step_size
        };
        let steps = self.steps(eps);

        let mut p = std::mem::take(&mut self.momentum);
        p.resize(d, 0.0);
        self.metric.sample_momentum(rng, &mut p);
        let k0 = self.kinetic_energy(&p);

        proposal.state.clear();
        proposal.state.extend_from_slice(&current.state);
        proposal.payload.gradient.clear();
        proposal
            .payload
            .gradient
            .extend_from_slice(&current.payload.gradient);
        let (lp, taken) = self.leapfrog(
            eps,
            steps,
            &mut proposal.state,
            &mut p,
            &mut proposal.payload.gradient,
        );
        self.stats.leapfrog_steps += taken as u64;
        proposal.log_density = lp;
        let mut result = Proposal {
            log_q_ratio: 0.0,
            component: 0,
            evaluated: true,
            failed: false,
        };
        if lp == f64::NEG_INFINITY {
            self.stats.outside_support += 1;
        } else if !lp.is_finite() {
            self.stats.invalid += 1;
            proposal.log_density = f64::NAN;
        } else {
            let k1 = self.kinetic_energy(&p);
            let log_q = k0 - k1;
            let energy_error = -(lp - current.log_density + log_q);
            if energy_error.is_nan() || energy_error > self.divergence_threshold {
                self.stats.divergences += 1;
                result.log_q_ratio = f64::NEG_INFINITY;
            } else {
                result.log_q_ratio = log_q;
            }
        }
        self.momentum = p;
        result
    }

    fn observe(&mut self, observation: &StepObservation<'_, Vec<f64>>) {
        if observation.own {
            self.adapt(observation.alpha, observation.state);
        }
    }

    fn freeze(&mut self) {
        if let Some(w) = &mut self.warmup
            && !w.is_frozen()
        {
            self.step_size = w.freeze();
        }
    }

    fn component_names(&self) -> Vec<String> {
        vec![self.name.to_string()]
    }

    fn state_words(&self, out: &mut Vec<u64>) {
        self.words(out);
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        self.restore(input)
    }

    fn check_state(&self, state: &Vec<f64>) -> Result<()> {
        check_state_dimension(self.dim, state)
    }
}
