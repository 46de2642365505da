//! Multiplexed Metropolis light transport (Hachisuka et al. 2014) on the
//! Markov-chain driver: one primary-sample-space target per path depth
//! `d`, whose path picks one BDPT technique `(s, t)` with `s + t = d + 1`
//! and weights it by MIS over that depth's techniques
//! ([`crate::pss::MmltDepth`]). Each depth is a member of the family with
//! its own normalisation `b_d` and chains (see [`crate::markov`] for why
//! per member).

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::markov::{self, ChainParams, MltError, MltResult};
use crate::observer::Observer;
use crate::pss::{MmltDepth, MutationParams, PssFamily, PssPathSampler, PssmltSettings};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use std::sync::atomic::AtomicBool;

crate::settings! {
    /// MMLT settings (pbrt-v4's `mlt`: the Gaussian small step).
    ///
    /// The Gaussian step is the default because a lazily updated
    /// coordinate that missed `n` small steps costs one draw with it but
    /// `n` with Kelemen's, and MMLT's chains leave many coordinates unread
    /// for long stretches (e.g. the light subpath while `s = 0`).
    pub struct Mmlt {
        flatten {
            /// Path depth (MMLT needs a finite `max_depth`).
            pub depth: DepthParams = DepthParams::default();
            /// The mutation.
            pub mutation: MutationParams = MutationParams::gaussian();
            /// The driver.
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

/// Longest `max_depth` MMLT takes: one family member (and one replay
/// trace) per depth, so the depth sizes allocations (real scenes use
/// depths below 100; 4294967294 asked for 240 GB, found by fuzzing).
pub const MAX_DEPTH: u32 = 1024;

impl Mmlt {
    /// One target per path depth `1..=max_depth`.
    pub fn depths(&self) -> Vec<MmltDepth> {
        depths(&self.depth)
    }
}

/// MMLT's targets, one per path depth `1..=max_depth` of `depth`.
pub fn depths(depth: &DepthParams) -> Vec<MmltDepth> {
    let bdpt = Bdpt {
        max_depth: depth.limit(),
        rr_depth: depth.rr_depth,
        heuristic: MisHeuristic::Power,
    };
    (1..=depth.limit() as usize)
        .map(|depth| MmltDepth { bdpt, depth })
        .collect()
}

impl IntegratorSettings for Mmlt {
    const NAME: &'static str = "mmlt";
    const DESCRIPTION: &'static str = "Multiplexed MLT (Hachisuka et al. 2014): one chain family member per path depth over BDPT techniques.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth < 1 {
            return Err("mmlt needs a finite max_depth ≥ 1 (give --max-depth)".into());
        }
        if self.depth.limit() > MAX_DEPTH {
            return Err(format!(
                "mmlt: max_depth must be at most {MAX_DEPTH} (one chain family member per depth), got {}",
                self.depth.limit()
            ));
        }
        self.mutation.mutation().map(|_| ())
    }

    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        self.chain.planned_mutations(scene, run)
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        IntegratorSettings::validate(self).map_err(RenderError::Invalid)?;
        let settings = self
            .chain
            .chain_settings(self.mutation.mutation().map_err(RenderError::Invalid)?, run);
        let result = render_family(scene, self.depths(), &settings, stop, observer)?;
        let rendered =
            markov::report::rendered(&result, DumpSampler::Mmlt, self.depth.limit(), true);
        Ok(markov::report::with_sample_counts(&result, rendered))
    }
}

/// Renders `scene` with a family of PSS targets (one per sampler; MMLT:
/// one per path depth), each with its own normalisation.
pub fn render_family<F: PssPathSampler>(
    scene: &Scene,
    samplers: Vec<F>,
    settings: &PssmltSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<MltResult, MltError> {
    markov::run(
        scene,
        &PssFamily::new(scene, samplers),
        settings,
        stop,
        observer,
    )
}
