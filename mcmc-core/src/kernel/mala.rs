//! The Metropolis-adjusted Langevin algorithm: one leapfrog step.

use super::{Boundary, GradientKernelStatistics, Hmc, Kernel, Metric, Proposal, StepObservation};
use crate::adaptation::{MetricAdaptation, WarmupSchedule};
use crate::error::Result;
use crate::gradient::{GradientPayload, GradientTarget};
use crate::rng::ChainRng;
use crate::sample::Sample;

/// MALA: `y ~ N(x + ε²/2 M⁻¹∇ln π(x), ε² M⁻¹)`, i.e. HMC with one leapfrog
/// step. The MH ratio uses the asymmetric proposal density (reported as the
/// kinetic-energy difference, which is the same number); the density is
/// also available through [`Kernel::log_proposal_density`], so MALA works
/// in multiple-try Metropolis with `Lambda::One` or `Lambda::InverseProduct`
/// (on `R^d`; on the torus the wrapped density is not provided).
///
/// ```
/// use mcmc_core::prelude::*;
/// use mcmc_core::gradient::{Differentiable, FiniteDifference};
/// use mcmc_core::kernel::Mala;
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let target = Differentiable(g);
/// let mut chain = Chain::new(&target, vec![0.0], MetropolisHastings::new(Mala::new(g, 0.9).unwrap()), stream_rng(1, 0)).unwrap();
/// for _ in 0..100 { chain.step(&target); }
/// ```
#[derive(Clone, Debug)]
pub struct Mala<G>(Hmc<G>);

impl<G: GradientTarget> Mala<G> {
    /// MALA with step size `ε` and the unit metric.
    pub fn new(target: G, step_size: f64) -> Result<Self> {
        let mut h = Hmc::new(target, step_size, 1)?;
        h.set_name("mala");
        Ok(Mala(h))
    }

    /// Uses preconditioner `metric` (`M⁻¹`, the proposal covariance up to ε²).
    pub fn with_metric(self, metric: Metric) -> Result<Self> {
        Ok(Mala(self.0.with_metric(metric)?))
    }

    /// Wraps on the unit torus (then no proposal density is reported).
    pub fn with_boundary(self, boundary: Boundary) -> Self {
        Mala(self.0.with_boundary(boundary))
    }

    /// Warm-up adaptation as for [`Hmc::with_warmup`] (dual averaging of
    /// the step size towards mean acceptance `target_accept`; 0.574 is the
    /// optimal mean acceptance of MALA, Roberts & Rosenthal 1998), but with
    /// windows that grow with the warm-up
    /// ([`WarmupSchedule::proportional`]): MALA moves diffusively, so its
    /// variance estimates need long windows and its step size a long final
    /// buffer. In 100 dimensions MALA needs about 10⁴ warm-up iterations
    /// (`examples/hmc_vs_nuts`, `docs/performance.md`).
    pub fn with_warmup(
        self,
        iterations: usize,
        target_accept: f64,
        metric: MetricAdaptation,
    ) -> Result<Self> {
        Ok(Mala(
            self.0
                .with_warmup(iterations, target_accept, metric)?
                .with_warmup_schedule(WarmupSchedule::proportional(iterations))?,
        ))
    }

    /// Current step size.
    pub fn step_size(&self) -> f64 {
        self.0.step_size()
    }

    /// Current metric.
    pub fn metric(&self) -> &Metric {
        self.0.metric()
    }

    /// Divergences, invalid proposals, gradient evaluations.
    pub fn statistics(&self) -> &GradientKernelStatistics {
        self.0.statistics()
    }
}

impl<G: GradientTarget> Kernel<Vec<f64>, GradientPayload> for Mala<G> {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, GradientPayload>,
        proposal: &mut Sample<Vec<f64>, GradientPayload>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.0.propose(current, proposal, rng)
    }

    fn log_proposal_density(
        &self,
        from: &Sample<Vec<f64>, GradientPayload>,
        to: &Vec<f64>,
    ) -> Option<f64> {
        if self.0.boundary() == Boundary::Wrap || self.0.has_jitter() {
            return None;
        }
        self.0.one_step_log_density(from, to)
    }

    fn observe(&mut self, observation: &StepObservation<'_, Vec<f64>>) {
        self.0.observe(observation)
    }

    fn freeze(&mut self) {
        self.0.freeze()
    }

    fn component_names(&self) -> Vec<String> {
        self.0.component_names()
    }

    fn check_state(&self, state: &Vec<f64>) -> crate::Result<()> {
        self.0.check_state(state)
    }
}
