//! Tempered replica exchange light transport, MMLT variant (Šik's thesis
//! ch. 5, §5.4: "8 levels per path length"; spec `seed000-ch5-6.md`), on
//! the Markov-chain driver.
//!
//! - **Members**: one per (path depth `d`, level `k`), member `d·L + k`
//!   for `L` levels. Level `k` of depth `d` targets the luminance of
//!   MMLT's depth-`d` sample ([`crate::pss::MmltDepth`]) with the
//!   connection BSDFs roughened to `√T_k · max(ρ, ρ_reg)`
//!   ([`TemperedMmltDepth`]); the technique, both subpaths and the
//!   visibility are traced once for all levels.
//! - **Replica groups**: the `L` levels of one depth form a ladder
//!   ([`ChainFamily::replica_groups`]): replica sets hold one chain per
//!   level of one depth and exchange only among those, so exchanges trace
//!   nothing; sets go to depths in proportion to the `T = 1` level's
//!   bootstrap `b̂_d` (MMLT's allocation).
//! - **Image** (Eq. 5.13 within a depth): every level's samples, the
//!   `T = 1` splat weighted by the balance heuristic over that depth's
//!   levels ([`chain_mis_factors`] over the depth's `b̂`), each depth's
//!   image scaled by its own normalisation, the depths summed as in MMLT.
//!
//! With one level (and no regularisation) the family is plain MMLT with
//! the same mutation, bit for bit (tested). The MMLT variant is its own
//! file because its family (members per depth and level, grouped) and its
//! depth limit differ from the PSSMLT variant's; the ladder settings, the
//! exchange moves and the report are shared
//! ([`super::tempered_pssmlt::TemperedLadder`], [`super::tempered_pssmlt::report`]).

use super::registry::IntegratorSettings;
use super::tempered_pssmlt::{LevelTarget, TemperedLadder, report};
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::markov::{self, ChainFamily, ChainParams};
use crate::observer::Observer;
use crate::pss::{Mutation, MutationParams, PATH_CLASSES, PathSample, PssFamily};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::tempered::{TemperedMmltDepth, chain_mis_factors, level_density, log_of};
use mcmc_core::kernel::Mixture;
use mcmc_core::replica::ExchangeMove;
use mcmc_core::space::TorusPoint;
use std::ops::Range;
use std::sync::atomic::AtomicBool;

crate::settings! {
    /// Tempered MMLT settings: the ladder of `tempered-pssmlt`, MMLT's depths.
    pub struct TemperedMmlt {
        flatten {
            /// Levels, exchanges and regularisation.
            pub ladder: TemperedLadder = TemperedLadder::default();
            /// Path depth (a finite `max_depth` is needed, as for MMLT).
            pub depth: DepthParams = DepthParams::default();
            /// The mutation (Kelemen small step, large step 0.3, as the thesis).
            pub mutation: MutationParams = MutationParams::default();
            /// The driver (`kelemen_mis` only with one level).
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

impl TemperedMmlt {
    /// One tempered sampler per path depth `1..=max_depth` on `scene`, at
    /// the first stage's regularisation floor.
    pub fn samplers(&self, scene: &Scene) -> Vec<TemperedMmltDepth> {
        self.samplers_at(scene, 0)
    }

    /// The samplers of a stage that starts after `samples_per_pixel`
    /// samples per pixel.
    pub fn samplers_at(&self, scene: &Scene, samples_per_pixel: u64) -> Vec<TemperedMmltDepth> {
        let bsdfs = self.ladder.bsdfs_at(scene, samples_per_pixel);
        super::mmlt::depths(&self.depth)
            .into_iter()
            .map(|depth| TemperedMmltDepth {
                depth,
                bsdfs: bsdfs.clone(),
            })
            .collect()
    }
}

/// The tempered MMLT family: member `d·L + k` is level `k` of the depth
/// sampler `d`.
pub struct TemperedMmltFamily<'a> {
    targets: Vec<LevelTarget<'a, TemperedMmltDepth>>,
    levels: usize,
    ladder: TemperedLadder,
}

impl<'a> TemperedMmltFamily<'a> {
    /// The family of `samplers`' levels (every sampler with `ladder.levels`
    /// levels) on `scene`.
    pub fn new(scene: &'a Scene, samplers: &[TemperedMmltDepth], ladder: &TemperedLadder) -> Self {
        let levels = ladder.levels;
        TemperedMmltFamily {
            targets: samplers
                .iter()
                .flat_map(|s| (0..levels).map(move |k| LevelTarget::new(scene, s.clone(), k)))
                .collect(),
            levels,
            ladder: ladder.clone(),
        }
    }

    /// The level of member `member`.
    fn level(&self, member: usize) -> usize {
        member % self.levels
    }

    /// The members of `member`'s depth.
    fn group_of(&self, member: usize) -> Range<usize> {
        let first = member - self.level(member);
        first..first + self.levels
    }
}

impl<'a> ChainFamily for TemperedMmltFamily<'a> {
    type State = TorusPoint;
    type Target = LevelTarget<'a, TemperedMmltDepth>;
    type Mutation = Mutation;
    type Kernel = Mixture<TorusPoint, PathSample>;

    fn members(&self) -> usize {
        self.targets.len()
    }
    fn target(&self, member: usize) -> &Self::Target {
        &self.targets[member]
    }
    fn kernel(
        &self,
        mutation: &Mutation,
        _member: usize,
    ) -> Result<Self::Kernel, markov::MltError> {
        Ok(mutation.kernel()?)
    }
    fn independent_probability(&self, mutation: &Mutation) -> f64 {
        mutation.large_step_probability
    }
    fn checkpointable(&self, _mutation: &Mutation) -> bool {
        // Every small step: the adaptive one's state is saved per level
        // with the chain at that level (`ChainRecord::kernel`, session 21).
        true
    }
    crate::primary_sample_space_family!();
    fn exchange_move(&self) -> Option<Box<dyn ExchangeMove<TorusPoint, PathSample>>> {
        self.ladder.exchange.exchange_move(self.levels)
    }
    fn replica_groups(&self) -> Vec<Range<usize>> {
        (0..self.members())
            .step_by(self.levels)
            .map(|first| first..first + self.levels)
            .collect()
    }
    /// Valid for payloads of `member`'s own depth, the only ones the
    /// driver asks about (it shares evaluations within a replica group).
    fn member_log_density(&self, member: usize, payload: &PathSample) -> Option<f64> {
        Some(log_of(
            level_density(payload, self.level(member)).unwrap_or(f64::NAN),
        ))
    }
    fn class_weights(
        &self,
        member: usize,
        payload: &PathSample,
        b_hat: &[f64],
    ) -> Option<[f64; PATH_CLASSES]> {
        Some(chain_mis_factors(
            payload,
            self.level(member),
            &b_hat[self.group_of(member)],
        ))
    }
}

impl IntegratorSettings for TemperedMmlt {
    const NAME: &'static str = "tempered-mmlt";
    const DESCRIPTION: &'static str = "Tempered replica exchange MMLT (Šik's thesis ch. 5): per path depth, a ladder of levels with connection BSDFs roughened by √T, exchanges within a depth, levels combined by MIS.";

    fn validate(&self) -> Result<(), String> {
        if self.depth.max_depth < 1 {
            return Err("tempered-mmlt needs a finite max_depth ≥ 1 (give --max-depth)".into());
        }
        self.mutation.mutation()?;
        self.ladder.validate(Self::NAME, self.chain.kelemen_mis)
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
        let mutation = self.mutation.mutation().map_err(RenderError::Invalid)?;
        self.ladder.render_stages(
            scene,
            &self.chain,
            mutation,
            run,
            stop,
            observer,
            |settings, before, observer| {
                let samplers = self.samplers_at(scene, before);
                let result = if self.ladder.levels == 1 {
                    let family = PssFamily::new(scene, samplers.clone());
                    markov::run(scene, &family, settings, stop, observer)?
                } else {
                    let family = TemperedMmltFamily::new(scene, &samplers, &self.ladder);
                    markov::run(scene, &family, settings, stop, observer)?
                };
                let rendered =
                    markov::report::rendered(&result, DumpSampler::Mmlt, self.depth.limit(), true);
                let levels = self.ladder.levels;
                Ok(report(
                    rendered,
                    &result,
                    &self.ladder,
                    &samplers[0].bsdfs,
                    self.ladder.sample_index(before),
                    |m| format!("depth-{}-level-{}", m / levels + 1, m % levels),
                ))
            },
        )
    }
}
