use super::{Kernel, Proposal, StepObservation};
use crate::error::{Result, invalid};
use crate::rng::{ChainRng, child_rng};
use crate::sample::Sample;
use crate::space::{SmallStep, TorusPoint};

/// A small step on the torus: every coordinate moves by one [`SmallStep`],
/// wrapping around. Symmetric.
///
/// On fixed-dimension states (`Vec<f64>` in `[0,1)^d`) all coordinates move
/// at once; on [`TorusPoint`]s they move lazily when read.
#[derive(Clone, Debug)]
pub struct TorusStep {
    step: SmallStep,
}

impl TorusStep {
    /// A kernel with the given step law.
    pub fn new(step: SmallStep) -> Result<Self> {
        step.validate()?;
        Ok(TorusStep { step })
    }

    /// Kelemen et al.'s step with `s1 = 1/1024`, `s2 = 1/64`.
    pub fn kelemen() -> Self {
        TorusStep {
            step: SmallStep::KELEMEN,
        }
    }

    /// pbrt's Gaussian step with `σ = 0.01`.
    pub fn gaussian() -> Self {
        TorusStep {
            step: SmallStep::GAUSSIAN,
        }
    }

    /// The step law.
    pub fn step(&self) -> SmallStep {
        self.step
    }
}

fn name_of(step: SmallStep) -> String {
    match step {
        SmallStep::Kelemen { .. } => "kelemen small step".into(),
        SmallStep::Gaussian { .. } => "gaussian small step".into(),
        SmallStep::Power { .. } => "adaptive small step".into(),
    }
}

fn eager_step<P>(
    step: SmallStep,
    current: &Sample<Vec<f64>, P>,
    proposal: &mut Sample<Vec<f64>, P>,
    rng: &mut ChainRng,
) {
    proposal.state.clear();
    proposal
        .state
        .extend(current.state.iter().map(|&u| step.apply(u, rng)));
}

fn eager_log_density(step: SmallStep, from: &[f64], to: &[f64]) -> f64 {
    from.iter()
        .zip(to)
        .map(|(&a, &b)| step.density(a, b).ln())
        .sum()
}

impl<P> Kernel<Vec<f64>, P> for TorusStep {
    #[inline]
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, P>,
        proposal: &mut Sample<Vec<f64>, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        eager_step(self.step, current, proposal, rng);
        Proposal::symmetric(0)
    }

    fn log_proposal_density(&self, from: &Sample<Vec<f64>, P>, to: &Vec<f64>) -> Option<f64> {
        Some(eager_log_density(self.step, &from.state, to))
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn component_names(&self) -> Vec<String> {
        vec![name_of(self.step)]
    }
}

impl<P> Kernel<TorusPoint, P> for TorusStep {
    #[inline]
    fn propose(
        &mut self,
        current: &Sample<TorusPoint, P>,
        proposal: &mut Sample<TorusPoint, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        proposal
            .state
            .set_small_step_of(&current.state, self.step, child_rng(rng));
        Proposal::symmetric(0)
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn component_names(&self) -> Vec<String> {
        vec![name_of(self.step)]
    }
}

/// Hachisuka & Jensen's (2011) adaptive small step (spec Eqs. 6.8 and 4.10):
/// a [`SmallStep::Power`] step whose shape `θ` follows
/// `θ_{i+1} = θ_i + (A_i − A*)/i`, where `A_i` is the running acceptance
/// rate of this kernel's proposals and `A* = 0.234`.
///
/// `θ` is clamped to `[θ_min, 1]` (`θ_min = 1e-4`). The gain `1/i`
/// diminishes, so the chain converges; [`Kernel::freeze`] stops adaptation
/// altogether. Symmetric for every fixed `θ`.
#[derive(Clone, Debug)]
pub struct AdaptiveTorusStep {
    theta: f64,
    target_acceptance: f64,
    proposals: u64,
    accepted: u64,
    frozen: bool,
}

/// Smallest `θ` the adaptation may reach.
const THETA_MIN: f64 = 1e-4;

impl AdaptiveTorusStep {
    /// Starts at `theta` and aims at acceptance `target_acceptance`.
    pub fn new(theta: f64, target_acceptance: f64) -> Result<Self> {
        if !(theta > 0.0 && theta <= 1.0) {
            return Err(invalid("theta", format!("{theta} must lie in (0, 1]")));
        }
        if !(target_acceptance > 0.0 && target_acceptance < 1.0) {
            return Err(invalid("target_acceptance", "must lie in (0, 1)"));
        }
        Ok(AdaptiveTorusStep {
            theta,
            target_acceptance,
            proposals: 0,
            accepted: 0,
            frozen: false,
        })
    }

    /// `θ = 0.5`, target acceptance 0.234.
    pub fn standard() -> Self {
        AdaptiveTorusStep::new(0.5, 0.234).expect("valid constants")
    }

    /// The current `θ`.
    pub fn theta(&self) -> f64 {
        self.theta
    }

    fn step(&self) -> SmallStep {
        SmallStep::Power { theta: self.theta }
    }

    /// The adaptation's state: `θ` (bits), the proposals and acceptances
    /// it has counted, and whether it is frozen.
    fn words(&self, out: &mut Vec<u64>) {
        out.extend([
            self.theta.to_bits(),
            self.proposals,
            self.accepted,
            u64::from(self.frozen),
        ]);
    }

    /// Restores [`AdaptiveTorusStep::words`] from the front of `input`:
    /// false unless `θ` lies in `(0, 1]` (as [`AdaptiveTorusStep::new`]
    /// takes it), at most as many acceptances as proposals, and a frozen
    /// flag of 0 or 1.
    fn restore(&mut self, input: &mut &[u64]) -> bool {
        let Some((&[theta, proposals, accepted, frozen], rest)) = input.split_first_chunk::<4>()
        else {
            return false;
        };
        let theta = f64::from_bits(theta);
        if !(theta > 0.0 && theta <= 1.0 && accepted <= proposals && frozen <= 1) {
            return false;
        }
        (self.theta, self.proposals, self.accepted) = (theta, proposals, accepted);
        self.frozen = frozen == 1;
        *input = rest;
        true
    }

    fn adapt<S>(&mut self, obs: &StepObservation<'_, S>) {
        if self.frozen || !obs.own {
            return;
        }
        self.proposals += 1;
        self.accepted += obs.accepted as u64;
        let rate = self.accepted as f64 / self.proposals as f64;
        let next = self.theta + (rate - self.target_acceptance) / self.proposals as f64;
        self.theta = next.clamp(THETA_MIN, 1.0);
    }
}

impl<P> Kernel<Vec<f64>, P> for AdaptiveTorusStep {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, P>,
        proposal: &mut Sample<Vec<f64>, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        eager_step(self.step(), current, proposal, rng);
        Proposal::symmetric(0)
    }

    fn log_proposal_density(&self, from: &Sample<Vec<f64>, P>, to: &Vec<f64>) -> Option<f64> {
        Some(eager_log_density(self.step(), &from.state, to))
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn observe(&mut self, obs: &StepObservation<'_, Vec<f64>>) {
        self.adapt(obs);
    }

    fn freeze(&mut self) {
        self.frozen = true;
    }

    fn state_words(&self, out: &mut Vec<u64>) {
        self.words(out);
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        self.restore(input)
    }

    fn component_names(&self) -> Vec<String> {
        vec![name_of(self.step())]
    }
}

impl<P> Kernel<TorusPoint, P> for AdaptiveTorusStep {
    fn propose(
        &mut self,
        current: &Sample<TorusPoint, P>,
        proposal: &mut Sample<TorusPoint, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        proposal
            .state
            .set_small_step_of(&current.state, self.step(), child_rng(rng));
        Proposal::symmetric(0)
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn observe(&mut self, obs: &StepObservation<'_, TorusPoint>) {
        self.adapt(obs);
    }

    fn freeze(&mut self) {
        self.frozen = true;
    }

    fn state_words(&self, out: &mut Vec<u64>) {
        self.words(out);
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        self.restore(input)
    }

    fn component_names(&self) -> Vec<String> {
        vec![name_of(self.step())]
    }
}
