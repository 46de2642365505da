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
    /// Draw by the camera walk alone ([`PathFamily::draw_camera_candidate`]),
    /// the only technique that draws the unconnectable paths: the
    /// independent proposal of `mlt`'s unconnectable chains.
    pub camera_walks: bool,
}

impl<'s> Kernel<Path<'s>, PathSample> for IndependentPath {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let family = PathFamily::between(current.state.scene, self.min_segments, self.max_segments);
        let log_density = |path: &Path<'_>| match self.camera_walks {
            true => family.log_camera_candidate_density(path),
            false => family.log_candidate_density(path),
        };
        proposal.state = match self.camera_walks {
            true => family.draw_camera_candidate(rng),
            false => family.draw_candidate(rng),
        };
        // A draw that carries nothing is still a proposal: the running
        // normalisation must count it as a zero (the target rejects it).
        let ratio = if proposal.state.luminance() > 0.0 {
            log_density(&current.state) - log_density(&proposal.state)
        } else {
            0.0
        };
        Proposal::with_ratio(ratio, 0)
    }

    fn component_names(&self) -> Vec<String> {
        vec!["independent".into()]
    }
}
