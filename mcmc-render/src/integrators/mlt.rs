//! Veach's Metropolis light transport (Veach & Guibas 1997; Mitsuba 0.6's
//! `mlt`) on the Markov-chain driver, in path space
//! ([`crate::path_space`]).
//!
//! - **State and target**: a path `x_0 … x_k` and `ln lum f(x)`.
//! - **Mutations**: `mcmc-core`'s mixture of the path-space mutations with
//!   the selection weights of the settings. Only Veach's bidirectional
//!   mutation exists so far; the lens, caustic and multi-chain
//!   perturbations (on in Mitsuba 0.6) and the manifold perturbation (off
//!   in Mitsuba 0.6) have their settings, which must stay 0 until they are
//!   built.
//! - **Start-up and normalisation**: `bootstrap` candidates (Mitsuba's
//!   `luminanceSamples`, 100 000), each one sample of a BDPT technique with
//!   its one-sample-MIS weight ([`crate::path_space::family`]), give `b`
//!   and the chains' start states; no mutation is an independent proposal,
//!   so the running normalisation equals the bootstrap's (its standard
//!   error is reported as `scale_standard_error`).
//! - Emitters at infinity (environment maps, directional lights) are not
//!   supported yet; such scenes are refused.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::light::Light;
use crate::markov::{self, ChainParams, MltError, MltResult};
use crate::observer::Observer;
use crate::path_space::{PathFamily, PathMutations};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use std::sync::atomic::AtomicBool;

crate::settings! {
    /// Path-space MLT settings (Mitsuba 0.6's `mlt` names, snake case).
    pub struct Mlt {
        /// Selection weight of Veach's bidirectional mutation.
        pub bidirectional_mutation: f64 = 1.0, check check::non_negative;
        /// Keep path lengths fixed in the bidirectional mutation (seed 001's variant).
        pub fixed_length: bool = false;
        /// Selection weight of the lens perturbation (Mitsuba: on; 0 here until the agreement test with it exists).
        pub lens_perturbation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the caustic perturbation (Mitsuba: on; not implemented yet, must be 0).
        pub caustic_perturbation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the multi-chain perturbation (Mitsuba: on; not implemented yet, must be 0).
        pub multi_chain_perturbation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the manifold perturbation (Mitsuba: off; not implemented yet, must be 0).
        pub manifold_perturbation: f64 = 0.0, check check::non_negative;
        flatten {
            /// Path depth (rr_depth is unused: path-space walks have exact lengths).
            pub depth: DepthParams = DepthParams::default();
            /// The driver (bootstrap = Mitsuba's luminanceSamples).
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

impl Mlt {
    /// The mutation mixture these settings select.
    pub fn mutations(&self) -> PathMutations {
        PathMutations {
            bidirectional: self.bidirectional_mutation,
            fixed_length: self.fixed_length,
            lens_perturbation: self.lens_perturbation,
            caustic_perturbation: self.caustic_perturbation,
            multi_chain_perturbation: self.multi_chain_perturbation,
            manifold_perturbation: self.manifold_perturbation,
        }
    }

    /// Longest path in segments (`None`: unbounded).
    pub fn max_segments(&self) -> Option<usize> {
        (self.depth.max_depth >= 0).then_some(self.depth.max_depth as usize)
    }
}

impl IntegratorSettings for Mlt {
    const NAME: &'static str = "mlt";
    const DESCRIPTION: &'static str = "Path-space Metropolis light transport (Veach 1997): the bidirectional mutation on the Markov-chain driver.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth == 0 {
            return Err("mlt needs max_depth ≥ 1 or -1 (unbounded)".into());
        }
        self.mutations().check()
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
        let result = render_mlt(self, scene, run, stop, observer)?;
        Ok(markov::report::rendered(
            &result,
            // Path states have no primary-sample coordinates: no dump.
            DumpSampler::Bdpt,
            self.depth.limit(),
            false,
        ))
    }
}

/// Renders `scene` with path-space MLT as `settings` say.
pub fn render_mlt(
    settings: &Mlt,
    scene: &Scene,
    run: &RunSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> Result<MltResult, MltError> {
    if scene
        .lights
        .lights
        .iter()
        .any(|l| matches!(l, Light::Directional { .. } | Light::Environment(_)))
    {
        return Err(MltError::Setting(
            "mlt does not support emitters at infinity (environment, directional) yet".into(),
        ));
    }
    let family = PathFamily::new(scene, settings.max_segments());
    markov::run(
        scene,
        &family,
        &settings.chain.chain_settings(settings.mutations(), run),
        stop,
        observer,
    )
}
