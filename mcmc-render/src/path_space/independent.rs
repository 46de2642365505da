//! The independent proposal: a fresh start-up candidate
//! ([`super::PathFamily::draw_candidate`]) as a large step, with
//! `ln T(y→x) − ln T(x→y) = ln p₀(x) − ln p₀(y)`. Not one of Veach's or
//! Mitsuba's mutations: it is PSSMLT's large step carried over, so that the
//! driver's running normalisation can refine `b` past the start-up (the
//! driver treats it as its independent component), and it lets chains
//! jump between regions no local mutation connects.

use super::family::PathFamily;
use super::state::Path;
use crate::pss::PathSample;
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::ChainRng;
use mcmc_core::sample::Sample;

/// The independent proposal as an `mcmc-core` kernel (one component).
#[derive(Clone, Copy, Debug)]
pub struct IndependentPath {
    /// Shortest path in segments.
    pub min_segments: usize,
    /// Longest path in segments (`None`: unbounded).
    pub max_segments: Option<usize>,
}

impl<'s> Kernel<Path<'s>, PathSample> for IndependentPath {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let family = PathFamily::between(current.state.scene, self.min_segments, self.max_segments);
        proposal.state = family.draw_candidate(rng);
        // A draw that carries nothing is still a proposal: the running
        // normalisation must count it as a zero (the target rejects it).
        let ratio = if proposal.state.luminance() > 0.0 {
            family.log_candidate_density(&current.state)
                - family.log_candidate_density(&proposal.state)
        } else {
            0.0
        };
        Proposal::with_ratio(ratio, 0)
    }

    fn component_names(&self) -> Vec<String> {
        vec!["independent".into()]
    }
}
