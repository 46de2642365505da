use super::{Kernel, Proposal};
use crate::rng::ChainRng;
use crate::sample::Sample;
use crate::space::ReferenceMeasure;

/// Independent proposals from a space's reference measure (the "large
/// step"): `y ~ p`, with `ln q(y→x) − ln q(x→y) = ln p(x) − ln p(y)`.
#[derive(Clone, Debug)]
pub struct Independent<Sp> {
    space: Sp,
}

impl<Sp> Independent<Sp> {
    /// Proposals from `space`'s reference measure.
    pub fn new(space: Sp) -> Self {
        Independent { space }
    }
}

impl<Sp: ReferenceMeasure, P> Kernel<Sp::State, P> for Independent<Sp> {
    fn propose(
        &mut self,
        current: &Sample<Sp::State, P>,
        proposal: &mut Sample<Sp::State, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.space.sample_reference_into(rng, &mut proposal.state);
        let ratio = self.space.log_reference_density(&current.state)
            - self.space.log_reference_density(&proposal.state);
        Proposal::with_ratio(ratio, 0)
    }

    fn log_proposal_density(&self, _from: &Sample<Sp::State, P>, to: &Sp::State) -> Option<f64> {
        Some(self.space.log_reference_density(to))
    }

    fn component_names(&self) -> Vec<String> {
        vec!["independent (large step)".into()]
    }
}
