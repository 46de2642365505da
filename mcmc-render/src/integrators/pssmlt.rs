//! Primary sample space Metropolis light transport (Kelemen et al. 2002)
//! over the path tracer or BDPT, on the Markov-chain driver.
//!
//! - **State and target**: a primary-sample point `u` and `ln I(u)`, the
//!   log luminance of the path traced from it ([`crate::pss::PssTarget`]).
//! - **Mutation**: `mcmc-core`'s mixture of a torus small step (Kelemen's
//!   by default) and an independent large step ([`crate::pss::Mutation`]).
//! - **Family**: one member; start-up, estimator, normalisation, budgets
//!   and statistics are the driver's ([`crate::markov`]).

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::markov::{self, ChainParams, MltError, MltResult};
use crate::observer::Observer;
use crate::pss::{MutationParams, PssFamily, PssPathSampler, PssTarget, PssmltSettings};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use mcmc_core::startup::Bootstrap;
use std::sync::atomic::AtomicBool;

crate::choice! {
    /// The path sampler PSSMLT runs over.
    pub enum MltBase {
        /// Path tracing.
        Pt = "pt",
        /// Bidirectional path tracing, all techniques of one sample.
        Bdpt = "bdpt",
    }
}

crate::settings! {
    /// PSSMLT settings (Kelemen's small step, as Kelemen et al. 2002).
    pub struct Pssmlt {
        /// Path sampler under the chains: pt or bdpt.
        pub base: MltBase = MltBase::Pt;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
            /// The mutation.
            pub mutation: MutationParams = MutationParams::default();
            /// The driver.
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

impl IntegratorSettings for Pssmlt {
    const NAME: &'static str = "pssmlt";
    const DESCRIPTION: &'static str =
        "Primary sample space MLT (Kelemen et al. 2002) over pt or bdpt (parameter `base`).";

    fn validate(&self) -> Result<(), String> {
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
        let settings = self
            .chain
            .chain_settings(self.mutation.mutation().map_err(RenderError::Invalid)?, run);
        let (max_depth, rr_depth) = (self.depth.limit(), self.depth.rr_depth);
        let (result, sampler) = match self.base {
            MltBase::Pt => {
                let pt = super::pt::PathTracer {
                    max_depth,
                    rr_depth,
                };
                (
                    render_pssmlt(scene, pt, &settings, stop, observer)?,
                    DumpSampler::Pt,
                )
            }
            MltBase::Bdpt => {
                let bdpt = Bdpt {
                    max_depth,
                    rr_depth,
                    heuristic: MisHeuristic::Power,
                };
                (
                    render_pssmlt(scene, bdpt, &settings, stop, observer)?,
                    DumpSampler::Bdpt,
                )
            }
        };
        let rendered = markov::report::rendered(&result, sampler, max_depth, false);
        Ok(markov::report::with_sample_counts(&result, rendered))
    }
}

/// Renders `scene` with PSSMLT over `sampler`.
pub fn render_pssmlt<F: PssPathSampler>(
    scene: &Scene,
    sampler: F,
    settings: &PssmltSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<MltResult, MltError> {
    markov::run(
        scene,
        &PssFamily::new(scene, vec![sampler]),
        settings,
        stop,
        observer,
    )
}

/// The start-up bootstrap of PSSMLT over `target`'s sampler: `count`
/// candidates, and their `ln I`.
pub fn bootstrap<F: PssPathSampler + Copy>(
    target: &PssTarget<'_, F>,
    count: usize,
    seed: u64,
) -> Result<(Bootstrap<usize, ()>, Vec<f64>), MltError> {
    markov::bootstrap(
        &PssFamily::new(target.scene, vec![target.sampler]),
        count,
        seed,
    )
}
