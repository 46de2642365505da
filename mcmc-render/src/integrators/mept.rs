//! Manifold exploration path-space MLT (Jakob & Marschner 2012; Mitsuba
//! 0.6's "MEMLT"/"MEPT" images): [`crate::integrators::mlt`] with the
//! manifold perturbation ([`crate::path_space::manifold_perturbation`])
//! switched on.
//!
//! Mitsuba 0.6 has no `mept` plugin: manifold exploration is the
//! `manifoldPerturbation` switch of `mlt` (and `erpt`). Here `mept` is a
//! registered name of its own rather than an alias of `mlt`, because an
//! alias shares `mlt`'s defaults and the point of the name is a different
//! defaults: the settings are exactly `mlt`'s (every parameter, same
//! names), with `manifold_perturbation` = 1 instead of 0,
//! `independent_mutation` = 0.3 instead of 0, `lens_perturbation` = 0
//! instead of 1 (`mept` was measured on caustic-sds without it),
//! `caustic_perturbation` = `multi_chain_perturbation` = 0 instead of 1
//! (`mlt`'s defaults since session 20; `mept`'s mixture, its agreement
//! tests and its caustic-sds figures are the ones without them) and the
//! BDPT start-up (`bdpt_startup` = true, `bootstrap` = 200 000 draws)
//! instead of `mlt`'s 2 000 000 one-technique candidates. `--integrator mlt --set
//! manifold_perturbation=1 --set independent_mutation=0.3 --set
//! lens_perturbation=0 --set caustic_perturbation=0 --set
//! multi_chain_perturbation=0 --set bdpt_startup=true --set bootstrap=200000
//! --set normalization=bootstrap` runs the same thing.
//!
//! Why the independent proposal (a fresh start-up path as a large step)
//! is on here and not in `mlt`: measured at equal time (60 s, seeds 1–3,
//! `docs/path-space.md`), on caustic-sds it lowered `mept`'s relMSE in
//! every seed, while on door-ajar it raised `mlt`'s in both seeds.
//!
//! Why the BDPT start-up ([`crate::path_space::bdpt_startup`]): the
//! ordinary start-up's estimate of `b` on the SDS scene is heavy-tailed
//! (`L S D S E` paths come from one technique of the `k + 1`; session
//! 10's seed 2 drew `b` = 0.32 ± 0.18 against ≈ 0.16, and even with
//! 1 000 000 candidates that seed stayed 2.9× `pssmlt`'s relMSE). Counting
//! every technique of each draw's walks lowered `b`'s variance tenfold at
//! half the start-up time (`docs/path-space.md`).
//!
//! Why `normalization` = bootstrap (session 12): the running estimate
//! merges the independent proposals, one-technique candidates whose
//! weights are heavy-tailed on scenes with specular paths, sample for
//! sample with the BDPT draws. A run's `b` then typically reads a few
//! per cent low and now and then far high (ring, 128×96, seed 1: +15% and
//! +34% of the draws' `b` at 7.4 M and 3.1 M mutations, the whole image
//! scaled with it; caustic-sds: −4%, −5%, +9% in session 11), while the
//! 200 000 draws alone are within about 2.5% (`docs/path-space.md`).

use super::mlt::Mlt;
use super::registry::IntegratorSettings;
use super::{RenderError, Rendered, RunSettings};
use crate::markov::{ChainParams, Normalization};
use crate::observer::Observer;
use crate::scene::Scene;
use std::sync::atomic::AtomicBool;

crate::settings! {
    /// `mlt`'s settings with the manifold perturbation on.
    pub struct Mept {
        flatten {
            /// Every `mlt` parameter (manifold_perturbation defaults to 1, independent_mutation to 0.3, lens_perturbation, caustic_perturbation and multi_chain_perturbation to 0, bdpt_startup to true with bootstrap 200 000 draws, normalization to bootstrap: the draws' b alone).
            pub mlt: Mlt = Mlt {
                manifold_perturbation: 1.0,
                independent_mutation: 0.3,
                lens_perturbation: 0.0,
                caustic_perturbation: 0.0,
                multi_chain_perturbation: 0.0,
                bdpt_startup: true,
                chain: ChainParams {
                    bootstrap: 200_000,
                    normalization: Normalization::Bootstrap,
                    ..ChainParams::default()
                },
                ..Mlt::default()
            };
        }
    }
}

impl IntegratorSettings for Mept {
    const NAME: &'static str = "mept";
    const DESCRIPTION: &'static str = "Path-space MLT with the manifold perturbation on (manifold exploration, Jakob & Marschner 2012): mlt with manifold_perturbation = 1, independent_mutation = 0.3, lens_perturbation = caustic_perturbation = multi_chain_perturbation = 0 and the BDPT start-up (bdpt_startup, 200 000 draws) giving b alone (normalization = bootstrap).";

    fn validate(&self) -> Result<(), String> {
        IntegratorSettings::validate(&self.mlt)
    }

    fn planned_samples(&self, scene: &Scene, run: &RunSettings) -> Option<u64> {
        IntegratorSettings::planned_samples(&self.mlt, scene, run)
    }

    fn render(
        &self,
        scene: &Scene,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
    ) -> Result<Rendered, RenderError> {
        IntegratorSettings::render(&self.mlt, scene, run, stop, observer)
    }
}
