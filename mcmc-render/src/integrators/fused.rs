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
use crate::fused_space::kernel::{CONVERSION_FAILURE, MUTATION_COST, MoveTotals, ROUND_TRIP_COST};
use crate::fused_space::{Conversion, FusedFamily, FusedMutation};
use crate::markov::{self, ChainParams, MltResult};
use crate::observer::{NoObserver, Observer};
use crate::path_space::PathMutations;
use crate::pss::MutationParams;
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use mcmc_core::rng::splitmix64;
use serde::Serialize;
use serde_json::json;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

crate::settings! {
    /// Fused-space settings: MMLT's (the Gaussian small step) plus the
    /// path-space mutations and how often they run.
    pub struct Fused {
        /// Probability of a path-space mutation per step (the rest: primary-sample mutations); auto (the default): chosen per path depth by a pilot run, then fixed (docs/fused.md).
        pub path_space_probability: Option<f64> = None, check probability_or_auto;
        /// Mutations per pixel of the pilot run that path_space_probability=auto chooses from (not in the image).
        pub adaptation_mutations_per_pixel: usize = 4, check check::count;
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
        /// When an accepted path-space proposal is mapped back to primary samples: eager (at once, with the current path's round trip; exact up to f32 rounding) or lazy (only before the next primary-sample move, the paper's; docs/fused.md, Session 22).
        pub conversion: Conversion = Conversion::Eager;
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

/// `path_space_probability`'s check: a probability or `auto`.
fn probability_or_auto(v: &Option<f64>) -> Result<(), String> {
    v.as_ref().map_or(Ok(()), check::probability)
}

/// Path-space probability of the pilot run of `path_space_probability=auto`
/// (the fixed default before Session 19, so the pilot sees both kinds of
/// move equally).
pub const PILOT_PATH_PROBABILITY: f64 = 0.5;
/// Bounds of `auto`'s choice: each kind keeps at least 5% of the steps, so
/// the chain stays a mixture (large steps for ergodicity and the running
/// normalisation, path-space moves where primary samples mix badly).
pub const AUTO_BOUNDS: (f64, f64) = (0.05, 0.95);
/// Pilot proposals of each kind a depth needs for its own choice; with
/// fewer it keeps [`PILOT_PATH_PROBABILITY`].
pub const MIN_PILOT_PROPOSALS: u64 = 200;
/// Mixed into the run's seed for the pilot's, so the pilot's streams are
/// not the run's (the run's chains then depend on the pilot only through
/// the probabilities it fixes).
const PILOT_SEED_SALT: u64 = 0x9110_7f05_ed00_0019;

/// `path_space_probability=auto`'s choice for a depth from its pilot
/// tallies: with `e_pss` and `e_path` the expected squared image jump per
/// unit of cost of each kind ([`MoveTotals::efficiencies`]), the
/// probability `e_path² / (e_path² + e_pss²)` within [`AUTO_BOUNDS`];
/// `fallback` when the pilot made fewer than [`MIN_PILOT_PROPOSALS`] of
/// either kind or neither moved.
///
/// Why this rule: per step, a mixture with probability `p` has expected
/// jump and cost both linear in `p`, so their ratio is monotone in `p` and
/// the best `p` is a corner (all steps of the more efficient kind). The
/// square is a smoothed corner (a 3× efficiency ratio gives 0.9, equal
/// ones 0.5) that does not stake everything on a short pilot's estimate.
pub fn choose_path_probability(t: &MoveTotals, fallback: f64) -> f64 {
    let (e_pss, e_path) = t.efficiencies();
    let enough = t.pss_proposals >= MIN_PILOT_PROPOSALS && t.path_proposals >= MIN_PILOT_PROPOSALS;
    if !enough || !(e_pss + e_path > 0.0) {
        return fallback;
    }
    let p = e_path * e_path / (e_path * e_path + e_pss * e_pss);
    p.clamp(AUTO_BOUNDS.0, AUTO_BOUNDS.1)
}

/// One depth's pilot tallies and the probability chosen from them.
#[derive(Clone, Debug, Serialize)]
pub struct DepthChoice {
    /// The path depth.
    pub depth: usize,
    /// Primary-sample proposals of the pilot.
    pub pss_proposals: u64,
    /// Path-space proposals of the pilot.
    pub path_proposals: u64,
    /// Expected squared image jump per cost unit of the primary-sample moves.
    pub pss_efficiency: f64,
    /// The same for the path-space moves.
    pub path_efficiency: f64,
    /// The probability of a path-space move chosen for the run.
    pub path_space_probability: f64,
}

/// The pilot run of `path_space_probability=auto`.
#[derive(Clone, Debug, Serialize)]
pub struct Adaptation {
    /// Mutations the pilot made (not in the image).
    pub pilot_mutations: u64,
    /// Wall-clock seconds of the pilot, its bootstrap included.
    pub pilot_seconds: f64,
    /// Whether the time budget or a stop cut the pilot short (its choice
    /// then depends on timing).
    pub pilot_interrupted: bool,
    /// The path-space probability the pilot ran with.
    pub pilot_path_space_probability: f64,
    /// Per family member (depths in order), the choice.
    pub per_depth: Vec<DepthChoice>,
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
            path_probability: self
                .path_space_probability
                .unwrap_or(PILOT_PATH_PROBABILITY),
            drop_jacobian: false,
            conversion: self.conversion,
        };
        m.check()?;
        Ok(m)
    }

    /// `path_space_probability=auto`'s pilot: a run of `mutation` (the
    /// pilot probability) with its own seed, a tenth of the bootstrap and
    /// [`Fused::adaptation_mutations_per_pixel`], whose image is dropped;
    /// each depth's probability is chosen from its tallies
    /// ([`choose_path_probability`]). The tallies are integers summed in
    /// any order and the pilot's work is fixed, so the choice is the same
    /// for any thread count (unless `run`'s time budget cuts the pilot).
    /// The run's chains then use fixed probabilities: adapting from an
    /// independent pilot keeps them exact, where adapting from their own
    /// past would not.
    pub fn adapt(
        &self,
        scene: &Scene,
        mutation: FusedMutation,
        run: &RunSettings,
        stop: &AtomicBool,
    ) -> Result<Adaptation, RenderError> {
        let start = Instant::now();
        let family = FusedFamily::new(scene, self.mmlt().depths());
        let mut pilot = self.chain.chain_settings(mutation, run);
        pilot.mutations_per_pixel = Some(self.adaptation_mutations_per_pixel as u64);
        pilot.bootstrap = (self.chain.bootstrap / 10).max(self.chain.bootstrap.min(1000));
        pilot.seed = splitmix64(run.seed ^ PILOT_SEED_SALT);
        // With a checkpoint the pilot is not saved but made again on
        // resume, so it must choose the same: the time budget does not
        // cut it (as the driver's start-up, `markov::startup_deadline`).
        if run.checkpoint.is_some() {
            pilot.time_budget = None;
        }
        pilot.checkpoint = None;
        let result = markov::run(scene, &family, &pilot, stop, &NoObserver)?;
        // On a cluster each rank ran some of the pilot's chains: every
        // rank sums all ranks' tallies (integers, so the sums are a single
        // process's) and so chooses what a single process would.
        let local: Vec<u64> = (family.targets.iter())
            .flat_map(|t| family.counters.per_depth[t.depth.depth].words())
            .collect();
        let gathered = crate::cluster::all_gather_words(local.clone());
        let summed: Vec<u64> = (0..local.len())
            .map(|i| {
                (gathered.iter().skip(i).step_by(local.len()))
                    .fold(0, |a: u64, w| a.wrapping_add(*w))
            })
            .collect();
        let per_depth = family
            .targets
            .iter()
            .zip(summed.chunks_exact(5))
            .map(|(t, words)| {
                let depth = t.depth.depth;
                let totals = MoveTotals::from_words(words.try_into().expect("five words a depth"));
                let (pss_efficiency, path_efficiency) = totals.efficiencies();
                DepthChoice {
                    depth,
                    pss_proposals: totals.pss_proposals,
                    path_proposals: totals.path_proposals,
                    pss_efficiency,
                    path_efficiency,
                    path_space_probability: choose_path_probability(
                        &totals,
                        mutation.path_probability,
                    ),
                }
            })
            .collect();
        Ok(Adaptation {
            pilot_mutations: result.mutations,
            pilot_seconds: start.elapsed().as_secs_f64(),
            pilot_interrupted: result.interrupted,
            pilot_path_space_probability: mutation.path_probability,
            per_depth,
        })
    }

    /// The fused chains with `mutation` (the settings' own, or a test's
    /// variant of it) under `run`: with `path_space_probability=auto`
    /// first the pilot ([`Fused::adapt`]), whose time counts against the
    /// budget, then the run with the probabilities it chose.
    pub fn run_chains<'s>(
        &self,
        scene: &'s Scene,
        mutation: FusedMutation,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<(FusedFamily<'s>, MltResult, Option<Adaptation>), RenderError> {
        let mut family = FusedFamily::new(scene, self.mmlt().depths());
        let mut main = run.clone();
        let adaptation = match self.path_space_probability {
            Some(_) => None,
            None => {
                let a = self.adapt(scene, mutation, run, stop)?;
                family.path_probabilities = a
                    .per_depth
                    .iter()
                    .map(|c| c.path_space_probability)
                    .collect();
                main.time_budget = run
                    .time_budget
                    .map(|t| t.saturating_sub(Duration::from_secs_f64(a.pilot_seconds)));
                // A pilot cut short (by a stop: with a checkpoint the budget
                // does not cut it) chose from fewer moves than a resumed
                // run's would: its chains are not saved, nor is the file
                // resumed from (it stays as it was).
                if a.pilot_interrupted {
                    main.checkpoint = None;
                }
                Some(a)
            }
        };
        let settings = self.chain.chain_settings(mutation, &main);
        let result = markov::run(scene, &family, &settings, stop, observer)?;
        Ok((family, result, adaptation))
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
        if self.path_space_probability.is_none() && self.chain.kelemen_mis {
            return Err("path_space_probability=auto chooses a probability per depth, which kelemen_mis (one large-step probability for all) cannot use: give a number or kelemen_mis=false".into());
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
        let mutation = self.fused_mutation().map_err(RenderError::Invalid)?;
        let (family, result, adaptation) = self.run_chains(scene, mutation, run, stop, observer)?;
        let mut out =
            markov::report::rendered(&result, DumpSampler::Mmlt, self.depth.limit(), true);
        out.statistics.insert(
            "fused".into(),
            statistics(&family, &result, &mutation, adaptation.as_ref()),
        );
        Ok(out)
    }
}

/// The sidecar's `fused` block: acceptance per mutation type, the expected
/// number of state-space transitions per mutation (accepted path-space
/// moves, the paper's 0.131 on its necklace scene), round-trip failures,
/// the share of the kernel's time spent converting, per depth the
/// path-space probability used and what each kind of move achieved, and
/// `auto`'s pilot (`null` with a fixed probability).
pub fn statistics(
    family: &FusedFamily<'_>,
    result: &MltResult,
    mutation: &FusedMutation,
    adaptation: Option<&Adaptation>,
) -> serde_json::Value {
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
        } else if c.name == CONVERSION_FAILURE {
            failures.insert(c.name.clone(), json!(c.proposed));
            &mut pss
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
    let nanos = |a: &std::sync::atomic::AtomicU64| a.load(Ordering::Relaxed) as f64;
    let (pss_nanos, path_nanos) = (nanos(&counters.pss_nanos), nanos(&counters.path_nanos));
    let mut all = MoveTotals::default();
    let per_depth: Vec<serde_json::Value> = (family.targets.iter().enumerate())
        .map(|(member, t)| {
            let depth = t.depth.depth;
            let totals = counters.per_depth[depth].totals();
            all.pss_proposals += totals.pss_proposals;
            all.path_proposals += totals.path_proposals;
            all.path_inversions += totals.path_inversions;
            let (pss_efficiency, path_efficiency) = totals.efficiencies();
            json!({
                "depth": depth,
                "path_space_probability": family.member_mutation(mutation, member).path_probability,
                "pss_proposals": totals.pss_proposals,
                "path_proposals": totals.path_proposals,
                "path_inversions": totals.path_inversions,
                "pss_efficiency": pss_efficiency,
                "path_efficiency": path_efficiency,
            })
        })
        .collect();
    // A path-space step's cost in primary-sample steps, by the model that
    // `auto` uses and by the clock (summed over threads), to check the model.
    let (n_pss, n_path) = (all.pss_proposals as f64, all.path_proposals as f64);
    let model = (MUTATION_COST * n_path + ROUND_TRIP_COST * all.path_inversions as f64) / n_path;
    let measured = (path_nanos / n_path) / (pss_nanos / n_pss);
    json!({
        "per_depth": per_depth,
        "adaptation": adaptation,
        "seconds_pss_moves": pss_nanos * 1e-9,
        "seconds_path_space_moves": path_nanos * 1e-9,
        "path_step_cost_model": model,
        "path_step_cost_measured": measured,
        "acceptance_pss": rate(pss),
        "acceptance_technique_change": rate(tech),
        "acceptance_path_space": rate(path),
        "proposals": { "pss": pss[0], "technique_change": tech[0], "path_space": path[0] },
        "transitions_per_mutation": path[1] as f64 / mutations,
        "inversions": counters.inversions.load(Ordering::Relaxed),
        "rejected_before_conversion": counters.rejected_before_conversion.load(Ordering::Relaxed),
        "round_trip_failures": failures,
        "conversion": mutation.conversion.name(),
        "deferred_conversions": counters.deferred_conversions.load(Ordering::Relaxed),
        "deferred_conversion_failures": counters.deferred_conversion_failures.load(Ordering::Relaxed),
        "conversion_seconds": conversion * 1e-9,
        "conversion_share_of_proposals": if propose > 0.0 { conversion / propose } else { f64::NAN },
    })
}
