//! Veach's Metropolis light transport (Veach & Guibas 1997; Mitsuba 0.6's
//! `mlt`) on the Markov-chain driver, in path space
//! ([`crate::path_space`]).
//!
//! - **State and target**: a path `x_0 … x_k` and `ln lum f(x)`.
//! - **Mutations**: `mcmc-core`'s mixture of the path-space mutations with
//!   the selection weights of the settings: Mitsuba 0.6's mutations by
//!   default, Veach's bidirectional mutation and the lens, caustic and
//!   multi-chain perturbations at weight 1 each (the last two since
//!   session 20, when their agreement with PT was resolved to 1%), the
//!   manifold perturbation off (on in `mept`); fixed weights unless
//!   `suitability` (Mitsuba's renormalisation over the mutations a path
//!   admits) is set.
//! - **Start-up and normalisation**: `bootstrap` candidates (Mitsuba's
//!   `luminanceSamples`; 2 000 000 here, 100 000 in Mitsuba), each one sample of a BDPT technique with
//!   its one-sample-MIS weight ([`crate::path_space::family`]), give `b`
//!   and the chains' start states. Veach's mutations are all local, so by
//!   default the running normalisation equals the bootstrap's (its
//!   standard error is reported as `scale_standard_error`);
//!   `independent_mutation > 0` adds a fresh start-up path as a large step
//!   (not in Mitsuba), which the running normalisation then counts.
//!   `bdpt_startup` (`mept`'s default) replaces the candidates by BDPT
//!   draws that count every technique of their two walks
//!   ([`crate::path_space::bdpt_startup`]).
//! - **Direct-lighting pass** (`direct_samples`, Mitsuba's `directSamples`;
//!   off by default here, 16 in Mitsuba): paths of one and two segments by
//!   path tracing, the chains on three segments or more
//!   ([`super::chain_passes`], shared with `erpt`).
//! - **Specular-chain pass** (`specular_samples`, default 16 spp; not in
//!   Mitsuba): the paths `L S* E` (emitters seen directly or through
//!   Dirac vertices only) are path traced
//!   ([`crate::path_space::specular_pass`]) and the chains leave them out:
//!   no bidirectional move keeps a vertex of such a path, so chains
//!   resampled onto a rare bright one never left it. With
//!   `unconnectable_pass` (the default since session 29, on scenes with
//!   Dirac lobes) it takes every path no connection can make,
//!   `L S+ (D S+)* E` too (session 23: their heavy-tailed start-up weights
//!   made `mlt` read low on the RELT scenes), and then a fifth of a time
//!   budget.
//! - **Snapshots** (previews, `convergence` checkpoints): the passes run
//!   first and show none; every snapshot of the chains has the passes'
//!   images added ([`WithPasses`]), so each is a whole estimate.
//! - Emitters at infinity (environment maps, `constant`, directional
//!   lights): `x_0` is then a vertex at infinity measured in solid angle
//!   (`path_space::state`; since session 19).
//! - **Checkpoints** (`--checkpoint`, session 20): the driver saves the
//!   chains between rounds with their paths encoded bit for bit
//!   ([`crate::path_space::state::Path::to_words`]); the passes are not
//!   saved but rendered again on resume, so with a checkpoint they run to
//!   their sample counts whatever the time budget.

use super::chain_passes::{
    WithPasses, add_pass, check_direct_depth, check_pass_samples, direct_pass, fixed_spp,
    pass_done, pass_samples,
};
use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::deadline::Deadline;
use crate::markov::{self, ChainParams, MltError, MltResult};
use crate::observer::Observer;
use crate::path_space::family::PerturbationSizes;
use crate::path_space::proposal_clock::{ProposalClock, mutation_types};
use crate::path_space::specular_pass::SpecularChains;
use crate::path_space::{PathFamily, PathMutations};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

crate::settings! {
    /// Path-space MLT settings (Mitsuba 0.6's `mlt` names, snake case).
    pub struct Mlt {
        /// Selection weight of Veach's bidirectional mutation.
        pub bidirectional_mutation: f64 = 1.0, check check::non_negative;
        /// Keep path lengths fixed in the bidirectional mutation (seed 001's variant).
        pub fixed_length: bool = false;
        /// Selection weight of an independent proposal (a fresh start-up path; not in Mitsuba): lets the running normalisation refine b.
        pub independent_mutation: f64 = 0.0, check check::non_negative;
        /// Selection weight of the lens perturbation (Mitsuba: on; 1 here since session 10: it cut door-ajar's relMSE at equal time in every seed, and agrees with PT to 1%).
        pub lens_perturbation: f64 = 1.0, check check::non_negative;
        /// Selection weight of the caustic perturbation (Mitsuba: on; 1 here since session 20, when the agreement with PT of the mixture with it resolved 1%).
        pub caustic_perturbation: f64 = 1.0, check check::non_negative;
        /// Selection weight of the multi-chain perturbation (Mitsuba: on; 1 here since session 20, as the caustic perturbation).
        pub multi_chain_perturbation: f64 = 1.0, check check::non_negative;
        /// Selection weight of the manifold perturbation (Jakob & Marschner 2012; Mitsuba: off; on in `mept`).
        pub manifold_perturbation: f64 = 0.0, check check::non_negative;
        /// Selection weight of Veach's lens subpath mutation (not in Mitsuba; 0 by default).
        pub lens_subpath_mutation: f64 = 0.0, check check::non_negative;
        /// Mitsuba 0.6's suitability selection: mutations whose pattern the path does not match are not selected, the others' weights renormalised (the selection ratio enters the acceptance); false: fixed weights.
        pub suitability: bool = false;
        /// Samples per pixel of the direct-lighting pass (path tracing of paths up to two segments; the chains take the rest); -1: off, the chains do everything (Mitsuba's default is 16).
        pub direct_samples: i64 = -1, check check_pass_samples;
        /// Samples per pixel of the specular-chain pass (path tracing of the paths L S* E, emitters seen directly or through mirrors and glass, which the chains then leave out: no bidirectional move keeps a vertex of them); -1: off, the chains do them (not in Mitsuba).
        pub specular_samples: i64 = 16, check check_pass_samples;
        /// The specular-chain pass (when it runs) also path traces the other unconnectable paths, `L S+ (D S+)* E` (seen and lit only through mirrors and glass: no edge joins two non-Dirac vertices, so only a camera walk that hits the emitter draws them), and the chains leave them out. On by default since session 29 (docs/path-space.md, Sessions 23, 28 and 29); a scene without Dirac lobes has no such paths and renders as with false.
        pub unconnectable_pass: bool = true;
        /// Chains of their own for the unconnectable paths through a non-Dirac vertex, `L S+ (D S+)* E` (a second member with its own b, refined by camera-walk draws as the chains run; path_space::unconnectable_chains; off by default: measured on caustic-sds, ring and mirror-balls only, docs/path-space.md Session 35), instead of the pass or the common chains; needs the specular-chain pass (which keeps `L S* E`) and a scene with Dirac lobes, and takes precedence over unconnectable_pass.
        pub unconnectable_chains: bool = false;
        /// Camera-walk draws (weighted as the BDPT start-up's) per mutation of the unconnectable chains that refine their b while they run (unconnectable_chains only; 0: the start-up's draws alone).
        pub unconnectable_search_rate: f64 = 1.0, check check::non_negative;
        /// With a time budget, the specular-chain pass runs for this share of it (at least specular_samples spp), so that its noise falls with the budget like the chains'; 0: specular_samples spp alone (the only rule without a time budget); -1 (default): 0.2 when the pass takes the unconnectable paths of a scene with Dirac lobes, else 0.05.
        pub specular_time_share: f64 = -1.0, check time_share;
        /// Smallest film offset of the lens perturbation (pixels; -1 with lens_perturbation_max = -1: Mitsuba's 0.1).
        pub lens_perturbation_min: f64 = -1.0;
        /// Largest film offset of the lens perturbation (pixels; -1: Mitsuba's √(0.05 · pixels / π)).
        pub lens_perturbation_max: f64 = -1.0;
        /// Smallest film offset the caustic perturbation's angles derive from (pixels; -1: Mitsuba's).
        pub caustic_perturbation_min: f64 = -1.0;
        /// Largest film offset the caustic perturbation's angles derive from (pixels; -1: Mitsuba's).
        pub caustic_perturbation_max: f64 = -1.0;
        /// Smallest film offset of the multi-chain perturbation (pixels; -1: Mitsuba's).
        pub multi_chain_perturbation_min: f64 = -1.0;
        /// Largest film offset of the multi-chain perturbation (pixels; -1: Mitsuba's).
        pub multi_chain_perturbation_max: f64 = -1.0;
        /// Smallest film offset of the manifold perturbation when it moves the camera end (pixels; -1: Mitsuba's).
        pub manifold_perturbation_min: f64 = -1.0;
        /// Largest film offset of the manifold perturbation when it moves the camera end (pixels; -1: Mitsuba's).
        pub manifold_perturbation_max: f64 = -1.0;
        /// Start-up by BDPT draws (path_space::bdpt_startup): each of the `bootstrap` draws traces a camera and a light walk and counts every technique (s, t) of them, MIS-weighted, for b and the chains' starts, instead of one technique per candidate; needs max_depth ≤ 62 (else the ordinary start-up).
        pub bdpt_startup: bool = false;
        flatten {
            /// Path depth (rr_depth applies to the direct pass only: path-space walks have exact lengths).
            pub depth: DepthParams = DepthParams::default();
            /// The driver (bootstrap = Mitsuba's luminanceSamples, 100 000 there; 2 000 000 here since session 29: `b`'s standard error was 5–22% on the interiors from 100 000, and 20× the candidates, about a second, cut interior-window's error at 60 s 5–7×; docs/path-space.md, Session 29).
            pub chain: ChainParams = ChainParams {
                bootstrap: 2_000_000,
                ..ChainParams::default()
            };
        }
    }
}

impl Mlt {
    /// The perturbations' sizes these settings give (an error names a
    /// pair that is neither both -1 nor `0 < min < max`).
    pub fn sizes(&self) -> Result<PerturbationSizes, String> {
        Ok(PerturbationSizes {
            lens: PerturbationSizes::from_setting(
                "lens_perturbation",
                self.lens_perturbation_min,
                self.lens_perturbation_max,
            )?,
            caustic: PerturbationSizes::from_setting(
                "caustic_perturbation",
                self.caustic_perturbation_min,
                self.caustic_perturbation_max,
            )?,
            multi_chain: PerturbationSizes::from_setting(
                "multi_chain_perturbation",
                self.multi_chain_perturbation_min,
                self.multi_chain_perturbation_max,
            )?,
            manifold: PerturbationSizes::from_setting(
                "manifold_perturbation",
                self.manifold_perturbation_min,
                self.manifold_perturbation_max,
            )?,
        })
    }

    /// The mutation mixture these settings select (Mitsuba's sizes where
    /// the size settings are invalid: [`IntegratorSettings::validate`]
    /// refuses those first).
    pub fn mutations(&self) -> PathMutations {
        PathMutations {
            bidirectional: self.bidirectional_mutation,
            fixed_length: self.fixed_length,
            lens_perturbation: self.lens_perturbation,
            caustic_perturbation: self.caustic_perturbation,
            multi_chain_perturbation: self.multi_chain_perturbation,
            manifold_perturbation: self.manifold_perturbation,
            lens_subpath: self.lens_subpath_mutation,
            independent: self.independent_mutation,
            suitability: self.suitability,
            sizes: self.sizes().unwrap_or_default(),
        }
    }

    /// Longest path in segments (`None`: unbounded).
    pub fn max_segments(&self) -> Option<usize> {
        (self.depth.max_depth >= 0).then_some(self.depth.max_depth as usize)
    }

    /// Samples per pixel of the direct-lighting pass, if it runs.
    pub fn direct_pass(&self) -> Option<u32> {
        pass_samples(self.direct_samples)
    }

    /// Whether the specular-chain pass takes the unconnectable paths
    /// `L S+ (D S+)* E` of `scene` (and the chains leave them out): with
    /// `unconnectable_pass`, when the pass runs and the scene has Dirac
    /// lobes. Without Dirac lobes the class is the emitters seen directly,
    /// which the plain pass takes, so its walks through diffuse vertices
    /// would only cost time.
    pub fn unconnectable_in(&self, scene: &Scene) -> bool {
        self.unconnectable_pass
            && !self.unconnectable_chains
            && self.specular_pass().is_some()
            && scene.has_dirac_lobes()
    }

    /// Whether the unconnectable paths through a non-Dirac vertex have
    /// chains of their own on `scene` (`unconnectable_chains`, with the
    /// specular-chain pass keeping `L S* E`, on a scene with Dirac lobes).
    pub fn unconnectable_chains_in(&self, scene: &Scene) -> bool {
        self.unconnectable_chains && self.specular_pass().is_some() && scene.has_dirac_lobes()
    }

    /// The specular-chain pass's share of a time budget on `scene`:
    /// `specular_time_share`, or with -1, 0.2 when the pass takes the
    /// unconnectable paths ([`Mlt::unconnectable_in`]) and 0.05 otherwise.
    /// Why 0.2: the pass's noise in the class falls only with its own
    /// time, which must grow with the class's share of the light. At 60 s
    /// on the RELT scenes 0.2 beat 0.05 by 3.7× and 3.2× (at 0.05 the
    /// water box was 1.8× worse than with no such pass); see
    /// docs/path-space.md, Sessions 28 and 29, for the other scenes.
    /// Without those paths the pass renders only the emitters seen
    /// through Dirac chains, for which 0.05 was chosen (session 12).
    pub fn specular_share_in(&self, scene: &Scene) -> f64 {
        match self.specular_time_share {
            s if s >= 0.0 => s,
            _ if self.unconnectable_in(scene) => 0.2,
            _ => 0.05,
        }
    }

    /// Samples per pixel of the specular-chain pass, if it runs.
    pub fn specular_pass(&self) -> Option<u32> {
        pass_samples(self.specular_samples)
    }

    /// Shortest path the chains sample: 3 segments with the direct pass.
    pub fn min_segments(&self) -> usize {
        super::chain_passes::min_segments(self.direct_samples)
    }
}

/// `specular_time_share`: in `[0, 1)`, or -1 (the scene decides).
fn time_share(v: &f64) -> Result<(), String> {
    if (0.0..1.0).contains(v) || *v == -1.0 {
        Ok(())
    } else {
        Err("must be in [0, 1), or -1 (0.2 with unconnectable paths, else 0.05)".into())
    }
}

impl IntegratorSettings for Mlt {
    const NAME: &'static str = "mlt";
    const DESCRIPTION: &'static str = "Path-space Metropolis light transport (Veach 1997): the bidirectional mutation and the lens, caustic and multi-chain perturbations (Mitsuba 0.6's selection) on the Markov-chain driver.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth == 0 {
            return Err("mlt needs max_depth ≥ 1 or -1 (unbounded)".into());
        }
        check_direct_depth(Self::NAME, self.direct_samples, self.depth.max_depth)?;
        self.sizes()?;
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
        let start = Instant::now();
        let deadline = Deadline::new(start, run.time_budget);
        // With a checkpoint the passes are not saved: a resumed run renders
        // them again and must get the saved run's images, so they run to
        // their sample counts whatever the clock (no time share, no cut).
        let checkpointed = run.checkpoint.is_some();
        let pass_deadline = markov::startup_deadline(deadline, checkpointed);
        // A pass alone is not an estimate of the image: its snapshots are
        // not passed on; the chains' snapshots carry the passes' images.
        let quiet = WithPasses::progress_only(observer);
        let direct = self.direct_pass().map(|spp| {
            direct_pass(
                scene,
                run,
                (spp, self.depth.rr_depth),
                pass_deadline,
                stop,
                &quiet,
            )
        });
        // The specular chains of the lengths the chains would sample
        // (the direct pass has those of one and two segments).
        let specular = self.specular_pass().map(|spp| {
            let pass = SpecularChains {
                min_depth: self.min_segments() as u32,
                max_depth: self.max_segments().map_or(u32::MAX, |m| m as u32),
                through_diffuse: self.unconnectable_in(scene),
            };
            specular_chains_pass(
                scene,
                &pass,
                (run, pass_deadline),
                spp,
                if checkpointed {
                    0.0
                } else {
                    self.specular_share_in(scene)
                },
                stop,
                &quiet,
            )
        });
        let chains_run = RunSettings {
            time_budget: deadline.time_left(),
            ..run.clone()
        };
        let clock = ProposalClock::new();
        // In add_pass's order (specular, then direct), so that the last
        // snapshot is the final image to the bit.
        let passes = [&specular, &direct]
            .into_iter()
            .flatten()
            .map(|(_, pass)| pass.image.as_slice());
        let observer = WithPasses::new(observer, passes);
        let result = render_mlt(self, scene, &chains_run, stop, &observer, &clock)?;
        let mut out = markov::report::rendered(
            &result,
            // Path states have no primary-sample coordinates: no dump.
            DumpSampler::Bdpt,
            self.depth.limit(),
            false,
        );
        let components = result
            .chain_stats
            .components
            .iter()
            .map(|c| (c.name.clone(), c.proposed, c.accepted));
        out.statistics.insert(
            "mutation_types".into(),
            mutation_types(
                components,
                &clock,
                result.seconds - result.bootstrap_seconds,
            ),
        );
        if let Some((spp, pass)) = specular {
            add_pass(
                &mut out,
                &pass,
                "specular_pass",
                "specular-chain pass",
                spp,
                start,
            );
            // What the defaults resolved to on this scene.
            if let Some(stats) = out.statistics.get_mut("specular_pass") {
                stats["unconnectable"] = self.unconnectable_in(scene).into();
                stats["unconnectable_chains"] = self.unconnectable_chains_in(scene).into();
                stats["time_share"] = self.specular_share_in(scene).into();
            }
        }
        if let Some((spp, pass)) = direct {
            add_pass(&mut out, &pass, "direct_pass", "direct pass", spp, start);
        }
        Ok(out)
    }
}

/// The specular-chain pass: with a time budget and a positive `share`,
/// path tracing for `share` of the budget (passes of 1, 2, 4, … spp; the
/// one cut by the deadline is discarded), else, or when that gave fewer
/// than `min_spp`, `min_spp` samples per pixel (fewer if the run's
/// `deadline` comes first). Returns the samples per pixel done and the
/// image.
///
/// Why the time share: at a fixed 16 spp the pass's noise on the emitters
/// seen through glass and mirrors does not fall with the budget. On
/// caustic-sds (128×96) it was the whole of `mept`'s RMSE, flat at
/// 0.21–0.37 over every checkpoint of 60 s runs, and up to 0.017 of its
/// relMSE (seed 3); see docs/path-space.md.
fn specular_chains_pass(
    scene: &Scene,
    pass: &SpecularChains,
    (run, deadline): (&RunSettings, Deadline),
    min_spp: u32,
    share: f64,
    stop: &AtomicBool,
    observer: &dyn Observer,
) -> (u32, Rendered) {
    if let Some(budget) = run.time_budget.filter(|_| share > 0.0) {
        let timed = RunSettings {
            spp: None,
            time_budget: Some(budget.mul_f64(share)),
            ..run.clone()
        };
        let r = crate::render::run_per_pixel(scene, pass, &timed, stop, observer);
        let (done, r) = pass_done(r, stop);
        if done >= min_spp {
            return (done, r);
        }
    }
    let fixed = fixed_spp(run, min_spp, deadline);
    pass_done(
        crate::render::run_per_pixel(scene, pass, &fixed, stop, observer),
        stop,
    )
}

/// Bytes a BDPT start-up keeps per draw, at least: its entry (the weighted
/// techniques' vector and the draw's total, 32 B), the total kept for `b̂`
/// (8 B), one weighted technique of the start states (16 B) and its image
/// splat (20 B, `Search::image_splats`).
const BDPT_STARTUP_BYTES_PER_DRAW: u128 = 76;

/// Renders `scene` with path-space MLT as `settings` say, timing each
/// mutation type's proposals into `clock`.
pub fn render_mlt(
    settings: &Mlt,
    scene: &Scene,
    run: &RunSettings,
    stop: &AtomicBool,
    observer: &dyn Observer,
    clock: &Arc<ProposalClock>,
) -> Result<MltResult, MltError> {
    let mut family = PathFamily::between(scene, settings.min_segments(), settings.max_segments())
        .timed(clock.clone());
    if settings.specular_pass().is_some() {
        family = family.without_specular_chains();
        if settings.unconnectable_in(scene) {
            family = family.without_unconnectable();
        }
        if settings.unconnectable_chains_in(scene) {
            family = family.with_unconnectable_chains(settings.unconnectable_search_rate);
        }
    }
    let mut chain = settings.chain.chain_settings(settings.mutations(), run);
    if settings.bdpt_startup {
        let draws = settings.chain.bootstrap as u64;
        family = family.with_bdpt_startup(draws);
        if family.has_bdpt_startup() {
            // The search keeps every draw's weights until it ends (the
            // driver's estimate below then counts one candidate): 10^15
            // draws aborted on a 32 PB allocation.
            crate::resources::check_memory(
                &format!("mlt: a BDPT start-up of {draws} draws"),
                u128::from(draws) * BDPT_STARTUP_BYTES_PER_DRAW,
            )
            .map_err(MltError::Setting)?;
            // The family's search replaces the driver's bootstrap, which
            // still needs one candidate.
            chain.bootstrap = 1;
        }
    }
    markov::run(scene, &family, &chain, stop, observer)
}
