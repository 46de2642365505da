//! Fused state spaces (Otsu et al. 2017; spec seed001) on the Markov-chain
//! driver: MMLT's per-depth chains over multiplexed primary sample space
//! whose steps are either primary-sample mutations (small step, large
//! step, change of technique; Eq. 11) or path-space mutations of the
//! cached path (the fixed-length bidirectional mutation, the lens
//! perturbation, and every other mutation of
//! [`crate::path_space::PathMutations`]; Eq. 24), mapped back by the
//! inverse path sampler. State, kernel and ratios: [`crate::fused_space`];
//! `docs/fused.md`.

use super::mmlt::Mmlt;
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::fused_space::{FusedFamily, FusedMutation};
use crate::markov::{self, ChainParams, MltResult};
use crate::observer::Observer;
use crate::path_space::{PathMutations, emitters_at_infinity_refusal};
use crate::pss::MutationParams;
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};

crate::settings! {
    /// Fused-space settings: MMLT's (the Gaussian small step) plus the
    /// path-space mutations and how often they run.
    pub struct Fused {
        /// Probability of a path-space mutation per step (the rest: primary-sample mutations).
        pub path_space_probability: f64 = 0.5, check check::probability;
        /// Probability of a change of technique per step (the authors' default: 0).
        pub technique_change_probability: f64 = 0.0, check check::probability;
        /// Relative weight of the fixed-length bidirectional mutation among the path-space mutations.
        pub bidirectional_mutation: f64 = 1.0, check check::non_negative;
        /// Relative weight of the lens perturbation among the path-space mutations.
        pub lens_perturbation: f64 = 1.0, check check::non_negative;
        /// Relative weight of the caustic perturbation (must be 0 until it is built).
        pub caustic_perturbation: f64 = 0.0, check check::non_negative;
        /// Relative weight of the multi-chain perturbation (must be 0 until it is built).
        pub multi_chain_perturbation: f64 = 0.0, check check::non_negative;
        /// Relative weight of the manifold perturbation (must be 0 until it is built).
        pub manifold_perturbation: f64 = 0.0, check check::non_negative;
        flatten {
            /// Path depth (a finite max_depth, as MMLT).
            pub depth: DepthParams = DepthParams::default();
            /// The primary-sample mutation.
            pub mutation: MutationParams = MutationParams::gaussian();
            /// The driver.
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

impl Fused {
    /// The fused kernel's settings.
    pub fn fused_mutation(&self) -> Result<FusedMutation, String> {
        let m = FusedMutation {
            pss: self.mutation.mutation()?,
            technique_change: self.technique_change_probability,
            path: PathMutations {
                bidirectional: self.bidirectional_mutation,
                fixed_length: true,
                lens_perturbation: self.lens_perturbation,
                caustic_perturbation: self.caustic_perturbation,
                multi_chain_perturbation: self.multi_chain_perturbation,
                manifold_perturbation: self.manifold_perturbation,
                independent: 0.0,
                // Mutations added to the mixture later keep their defaults.
                ..PathMutations::default()
            },
            path_probability: self.path_space_probability,
            drop_jacobian: false,
        };
        m.check()?;
        Ok(m)
    }

    /// MMLT with the same depth, mutation and driver settings.
    fn mmlt(&self) -> Mmlt {
        Mmlt {
            depth: self.depth.clone(),
            mutation: self.mutation.clone(),
            chain: self.chain.clone(),
        }
    }
}

impl IntegratorSettings for Fused {
    const NAME: &'static str = "fused";
    const DESCRIPTION: &'static str = "Fused state spaces (Otsu et al. 2017): MMLT chains that also take path-space mutations through inverse path samplers.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth < 1 {
            return Err("fused needs a finite max_depth ≥ 1 (give --max-depth)".into());
        }
        self.fused_mutation().map(|_| ())
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
        if scene.lights.has_emitter_at_infinity() {
            return Err(RenderError::Invalid(emitters_at_infinity_refusal(
                Self::NAME,
            )));
        }
        let mutation = self.fused_mutation().map_err(RenderError::Invalid)?;
        let family = FusedFamily::new(scene, self.mmlt().depths());
        let result = markov::run(
            scene,
            &family,
            &self.chain.chain_settings(mutation, run),
            stop,
            observer,
        )?;
        let mut out =
            markov::report::rendered(&result, DumpSampler::Mmlt, self.depth.limit(), true);
        out.statistics
            .insert("fused".into(), statistics(&family, &result));
        Ok(out)
    }
}

/// The sidecar's `fused` block: acceptance per mutation type, the expected
/// number of state-space transitions per mutation (accepted path-space
/// moves, the paper's 0.131 on its necklace scene), round-trip failures,
/// and the share of the kernel's time spent converting.
pub fn statistics(family: &FusedFamily<'_>, result: &MltResult) -> serde_json::Value {
    let cs = &result.chain_stats;
    let (mut pss, mut tech, mut path) = ([0u64; 2], [0u64; 2], [0u64; 2]);
    let mut failures = serde_json::Map::new();
    for c in &cs.components {
        let slot = if c.name.starts_with("path: ") {
            if c.name.starts_with("path: technique cannot")
                || c.name.starts_with("path: proposal not invertible")
                || c.name.starts_with("path: round trip")
                || c.name.starts_with("path: current path")
            {
                failures.insert(c.name.clone(), json!(c.proposed));
            }
            &mut path
        } else if c.name == "technique change" {
            &mut tech
        } else {
            &mut pss
        };
        slot[0] += c.proposed;
        slot[1] += c.accepted;
    }
    let rate = |s: [u64; 2]| {
        if s[0] > 0 {
            s[1] as f64 / s[0] as f64
        } else {
            f64::NAN
        }
    };
    let counters = &family.counters;
    let conversion = counters.conversion_nanos.load(Ordering::Relaxed) as f64;
    let propose = counters.propose_nanos.load(Ordering::Relaxed) as f64;
    let mutations = result.mutations.max(1) as f64;
    json!({
        "acceptance_pss": rate(pss),
        "acceptance_technique_change": rate(tech),
        "acceptance_path_space": rate(path),
        "proposals": { "pss": pss[0], "technique_change": tech[0], "path_space": path[0] },
        "transitions_per_mutation": path[1] as f64 / mutations,
        "inversions": counters.inversions.load(Ordering::Relaxed),
        "rejected_before_conversion": counters.rejected_before_conversion.load(Ordering::Relaxed),
        "round_trip_failures": failures,
        "conversion_seconds": conversion * 1e-9,
        "conversion_share_of_proposals": if propose > 0.0 { conversion / propose } else { f64::NAN },
    })
}
