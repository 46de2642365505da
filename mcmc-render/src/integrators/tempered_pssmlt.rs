//! Tempered replica exchange light transport, PSSMLT variant (Šik's thesis
//! ch. 5; spec `seed000-ch5-6.md` §5.2–§5.4), on the Markov-chain driver.
//!
//! - **Levels**: `levels` replicas over one primary-sample state space,
//!   temperatures log-evenly spaced from 1 to `t_max`; level `k` roughens
//!   the BSDFs at the connecting vertices of every BDPT technique to
//!   `√T_k · max(ρ, ρ_reg)` ([`crate::tempered`]). One evaluation of a
//!   state gives every level's density (subpaths and visibility traced
//!   once), so exchange moves trace nothing.
//! - **Mutation**: every level's chain takes Kelemen's small step and a
//!   large step (probability 0.3 by default).
//! - **Exchanges**: `mcmc-core`'s moves between the levels of each replica
//!   set, importance-sampled permutations by default (§5.3.2, §5.4).
//! - **Start-up**: one shared pool of BDPT candidates, each traced once
//!   and weighed by every level's (tempered) density, starts each level's
//!   chains and gives its bootstrap `b̂_k`; every large step then updates
//!   every level's running normalisation.
//! - **Image** (Eq. 5.13): every level's samples, the `T = 1` contribution
//!   `C(u)` weighted by the balance heuristic over chains,
//!   `C(u) / (N Σ_j π_j(u)/b̂_j)` per sample, scaled by the level's `b`.
//! - **Regularisation**: the schedule of [`Regularization`], evaluated at
//!   sample index `regularization_n` and held for the run, or, with
//!   `regularization_stages` K > 1, held within each of K stages of
//!   doubling budget and evaluated at the samples per pixel before it
//!   ([`crate::staged`]; the driver's targets are stationary, see
//!   docs/tempered-replica-exchange.md).
//!
//! With one level (and no regularisation) the family is plain PSSMLT over
//! BDPT ([`PssFamily`]), bit for bit.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::markov::{self, ChainFamily, ChainParams, ChainSettings, MltResult};
use crate::observer::Observer;
use crate::pss::{
    Mutation, MutationParams, PATH_CLASSES, PathSample, PssFamily, PssPathSampler, PssTarget,
};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use crate::staged::{MAX_STAGES, Stage, render_in_stages, stage_checkpoint};
use crate::tempered::{
    MAX_LEVELS, Regularization, RegularizationSchedule, ScheduleKind, TemperedBdpt, TemperedBsdfs,
    chain_mis_factors, ladder_json, level_density, log_of, temperatures,
};
use mcmc_core::kernel::Mixture;
use mcmc_core::replica::{EvenOdd, ExchangeMove, IsPermutation, IsSwap, NeighbourSwap};
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
use serde_json::{Value, json};
use std::sync::atomic::AtomicBool;

crate::choice! {
    /// The exchange move between levels.
    pub enum TemperedExchange {
        /// Importance-sampled permutation of all levels, after every level mutated (§5.3.2).
        IsPermutation = "is_permutation",
        /// Swap every neighbouring pair after the hotter one mutated (§5.3.1).
        Neighbour = "neighbour",
        /// Even or odd neighbour pairs, alternately.
        EvenOdd = "even_odd",
        /// Importance-sampled swap of one pair (§5.3.3).
        IsSwap = "is_swap",
        /// No exchanges: every level mixes alone.
        None = "none",
    }
}

fn level_count(v: &usize) -> Result<(), String> {
    if (1..=MAX_LEVELS).contains(v) {
        Ok(())
    } else {
        Err(format!("must lie in 1..={MAX_LEVELS}"))
    }
}

crate::settings! {
    /// The temperature ladder, exchanges and regularisation of a tempered
    /// integrator (defaults from spec seed000 §5.4, §5.5), shared by
    /// `tempered-pssmlt` and `tempered-mmlt`.
    pub struct TemperedLadder {
        /// Number of levels (replicas), temperatures log-spaced from 1 to t_max.
        pub levels: usize = 8, check level_count;
        /// Hottest temperature T_max (roughness scale √T at the hottest level).
        pub t_max: f64 = 2500.0, check check::at_least_one;
        /// Exchange move: is_permutation, neighbour, even_odd, is_swap or none.
        pub exchange: TemperedExchange = TemperedExchange::IsPermutation;
        /// Regularisation schedule: off, constant (ρ0), geometric (ρ0·γ^n) or power (ρ0·(n+1)^-γ).
        pub regularization: ScheduleKind = ScheduleKind::Off;
        /// Initial regularisation roughness ρ0.
        pub rho0: f64 = 4e-3, check check::non_negative;
        /// Regularisation decline rate γ.
        pub gamma: f64 = 1e-5, check check::non_negative;
        /// Sample index n at which the schedule is evaluated (the first stage's; held within a stage).
        pub regularization_n: usize = 0;
        /// Stages of doubling budget, each at the floor of the samples per pixel before it (decaying schedules only; 1: one floor for the run).
        pub regularization_stages: usize = 1, check stage_count;
        /// Roughness smooth BSDFs stand in with at T > 1 (before the √T scale; thesis 1e-4); T = 1 stays smooth.
        pub specular_roughness: f64 = crate::tempered::SPECULAR_STAND_IN, check check::non_negative;
    }
}

fn stage_count(v: &usize) -> Result<(), String> {
    if (1..=MAX_STAGES).contains(v) {
        Ok(())
    } else {
        Err(format!("must lie in 1..={MAX_STAGES}"))
    }
}

crate::settings! {
    /// Tempered PSSMLT settings.
    pub struct TemperedPssmlt {
        flatten {
            /// Levels, exchanges and regularisation.
            pub ladder: TemperedLadder = TemperedLadder::default();
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
            /// The mutation (Kelemen small step, large step 0.3).
            pub mutation: MutationParams = MutationParams::default();
            /// The driver (`kelemen_mis` only with one level).
            pub chain: ChainParams = ChainParams::default();
        }
    }
}

impl TemperedLadder {
    /// The regularisation schedule of these settings.
    pub fn schedule(&self) -> Regularization {
        Regularization {
            kind: self.regularization,
            rho0: self.rho0,
            gamma: self.gamma,
        }
    }

    /// The ladder's roughened BSDFs on `scene` at the first stage's floor.
    pub fn bsdfs(&self, scene: &Scene) -> TemperedBsdfs {
        self.bsdfs_at(scene, 0)
    }

    /// The sample index of a stage that starts after `samples_per_pixel`
    /// samples per pixel: `regularization_n` plus those.
    pub fn sample_index(&self, samples_per_pixel: u64) -> u64 {
        self.regularization_n as u64 + samples_per_pixel
    }

    /// The ladder's roughened BSDFs on `scene` for a stage that starts
    /// after `samples_per_pixel` samples per pixel.
    pub fn bsdfs_at(&self, scene: &Scene, samples_per_pixel: u64) -> TemperedBsdfs {
        TemperedBsdfs::with_stand_in(
            scene,
            &temperatures(self.levels, self.t_max),
            self.schedule().floor(self.sample_index(samples_per_pixel)),
            self.specular_roughness,
        )
    }

    /// Renders the stages of a tempered integrator (one stage unless
    /// `regularization_stages` says more; see [`crate::staged`]) and adds
    /// each stage's regularisation floor to the `stages` statistics: the
    /// regularised roughness over the run. `render_stage` gets the
    /// stage's driver settings (`chain` and `mutation` under the stage's
    /// budget and seed) and the samples per pixel before the stage.
    #[allow(clippy::too_many_arguments)]
    pub fn render_stages(
        &self,
        scene: &Scene,
        chain: &ChainParams,
        mutation: Mutation,
        run: &RunSettings,
        stop: &AtomicBool,
        observer: &dyn Observer,
        mut render_stage: impl FnMut(
            &ChainSettings<Mutation>,
            u64,
            &dyn Observer,
        ) -> Result<Rendered, RenderError>,
    ) -> Result<Rendered, RenderError> {
        // Each stage is a run of its own with a checkpoint of its own
        // (`staged::stage_checkpoint`); their `checkpoint` statistics are
        // summed below.
        let stages = self.regularization_stages;
        let mut stage_checkpoints = Vec::new();
        let pixels = u64::from(scene.film.width) * u64::from(scene.film.height);
        let mut rendered = render_in_stages(
            stages,
            pixels,
            chain.mutations_per_pixel(run),
            run,
            stop,
            observer,
            |stage: &Stage, observer: &dyn Observer| {
                let mut stage_run = stage.run.clone();
                if let (Some(c), true) = (&run.checkpoint, stages > 1) {
                    stage_run.checkpoint = Some(
                        stage_checkpoint(c, stage.index, scene).map_err(RenderError::Invalid)?,
                    );
                }
                let settings = ChainSettings {
                    mutations_per_pixel: stage.samples_per_pixel,
                    ..chain.chain_settings(mutation, &stage_run)
                };
                let r = render_stage(&settings, stage.samples_per_pixel_before, observer)?;
                stage_checkpoints.extend(r.statistics.get("checkpoint").cloned());
                Ok(r)
            },
        )?;
        if let (Some(c), true) = (&run.checkpoint, stages > 1) {
            let sum = |key: &str| -> u64 {
                (stage_checkpoints.iter())
                    .filter_map(|s| s[key].as_u64())
                    .sum()
            };
            let error = (stage_checkpoints.iter()).find(|s| !s["error"].is_null());
            rendered.statistics.insert(
                "checkpoint".into(),
                json!({
                    "path": c.path.display().to_string(),
                    "resumed_from_mutations": sum("resumed_from_mutations"),
                    "total_mutations": sum("total_mutations"),
                    "error": error.map(|s| s["error"].clone()),
                    // Per stage, under other keys than the sums' (`.ci/run`
                    // greps for `resumed_from_<unit>`).
                    "stages": stage_checkpoints.iter().map(|s| json!({
                        "resumed_from": s["resumed_from_mutations"],
                        "total": s["total_mutations"],
                        "error": s["error"],
                    })).collect::<Vec<_>>(),
                }),
            );
        }
        if let Some(Value::Array(stages)) = rendered.statistics.get_mut("stages") {
            for stage in stages {
                let n = self.sample_index(stage["n"].as_u64().unwrap_or(0));
                stage["floor"] = json!(self.schedule().floor(n));
            }
        }
        Ok(rendered)
    }

    /// The checks a tempered integrator's settings need beyond each
    /// field's own (`kelemen_mis`: whether the driver's Kelemen MIS is on).
    pub fn validate(&self, name: &str, kelemen_mis: bool) -> Result<(), String> {
        if self.levels > 1 && kelemen_mis {
            return Err(format!(
                "{name} combines its levels by its own MIS; kelemen_mis needs levels=1"
            ));
        }
        if self.regularization != ScheduleKind::Off && !(self.rho0 > 0.0) {
            return Err("regularization needs rho0 > 0".into());
        }
        if self.regularization_stages > 1
            && !matches!(
                self.regularization,
                ScheduleKind::Geometric | ScheduleKind::Power
            )
        {
            return Err(format!(
                "regularization_stages={} needs a decaying schedule (regularization=geometric or power)",
                self.regularization_stages
            ));
        }
        Ok(())
    }
}

impl TemperedExchange {
    /// The exchange move between the `levels` levels of one replica set
    /// (`None`: no exchanges).
    pub fn exchange_move<S: 'static, P: Clone + 'static>(
        self,
        levels: usize,
    ) -> Option<Box<dyn ExchangeMove<S, P>>> {
        match self {
            TemperedExchange::IsPermutation => Some(Box::new(
                IsPermutation::new(levels).expect("IS permutations of at most 16 levels"),
            )),
            TemperedExchange::Neighbour => Some(Box::new(NeighbourSwap::new())),
            TemperedExchange::EvenOdd => Some(Box::new(EvenOdd::new())),
            TemperedExchange::IsSwap => Some(Box::new(IsSwap::new())),
            TemperedExchange::None => None,
        }
    }
}

impl TemperedPssmlt {
    /// The ladder's roughened BSDFs on `scene`.
    pub fn ladder(&self, scene: &Scene) -> TemperedBsdfs {
        self.ladder.bsdfs(scene)
    }

    /// The BDPT under the chains.
    pub fn bdpt(&self) -> Bdpt {
        Bdpt {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
            heuristic: MisHeuristic::Power,
        }
    }
}

/// One level's target: `ln π_k` of a tempered sample (of BDPT, or of one
/// MMLT depth).
pub struct LevelTarget<'a, S = TemperedBdpt> {
    pss: PssTarget<'a, S>,
    level: usize,
}

impl<'a, S> LevelTarget<'a, S> {
    /// Level `level` of `sampler`'s tempered samples on `scene`.
    pub fn new(scene: &'a Scene, sampler: S, level: usize) -> Self {
        LevelTarget {
            pss: PssTarget { scene, sampler },
            level,
        }
    }
}

impl<S: PssPathSampler> Target<TorusPoint> for LevelTarget<'_, S> {
    type Payload = PathSample;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<PathSample> {
        let e = self.pss.trace(state);
        let pi = level_density(&e.payload, self.level).unwrap_or(f64::NAN);
        Evaluation::new(log_of(pi), e.payload)
    }
}

/// The tempered family: one member per level (at least two).
pub struct TemperedFamily<'a> {
    targets: Vec<LevelTarget<'a>>,
    exchange: TemperedExchange,
}

impl<'a> TemperedFamily<'a> {
    /// The family of `sampler`'s levels on `scene`.
    pub fn new(scene: &'a Scene, sampler: &TemperedBdpt, exchange: TemperedExchange) -> Self {
        let levels = sampler.bsdfs.temperatures().len();
        TemperedFamily {
            targets: (0..levels)
                .map(|level| LevelTarget::new(scene, sampler.clone(), level))
                .collect(),
            exchange,
        }
    }
}

impl<'a> ChainFamily for TemperedFamily<'a> {
    type State = TorusPoint;
    type Target = LevelTarget<'a>;
    type Mutation = Mutation;
    type Kernel = Mixture<TorusPoint, PathSample>;

    fn members(&self) -> usize {
        self.targets.len()
    }
    fn target(&self, member: usize) -> &LevelTarget<'a> {
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
        self.exchange.exchange_move(self.members())
    }
    fn member_log_density(&self, member: usize, payload: &PathSample) -> Option<f64> {
        Some(log_of(level_density(payload, member).unwrap_or(f64::NAN)))
    }
    fn class_weights(
        &self,
        member: usize,
        payload: &PathSample,
        b_hat: &[f64],
    ) -> Option<[f64; PATH_CLASSES]> {
        Some(chain_mis_factors(payload, member, b_hat))
    }
}

impl IntegratorSettings for TemperedPssmlt {
    const NAME: &'static str = "tempered-pssmlt";
    const DESCRIPTION: &'static str = "Tempered replica exchange PSSMLT over BDPT (Šik's thesis ch. 5): connection BSDFs roughened by √T per level, IS permutations, all levels combined by MIS.";

    fn validate(&self) -> Result<(), String> {
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
                let sampler = TemperedBdpt {
                    bdpt: self.bdpt(),
                    bsdfs: self.ladder.bsdfs_at(scene, before),
                };
                let result = if self.ladder.levels == 1 {
                    let family = PssFamily::new(scene, vec![sampler.clone()]);
                    markov::run(scene, &family, settings, stop, observer)?
                } else {
                    let family = TemperedFamily::new(scene, &sampler, self.ladder.exchange);
                    markov::run(scene, &family, settings, stop, observer)?
                };
                let rendered =
                    markov::report::rendered(&result, DumpSampler::Bdpt, self.depth.limit(), false);
                Ok(report(
                    rendered,
                    &result,
                    &self.ladder,
                    &sampler.bsdfs,
                    self.ladder.sample_index(before),
                    |k| format!("level-{k}"),
                ))
            },
        )
    }
}

/// The registry's report of a tempered run: the driver's statistics (per
/// member: `families[k]` acceptance, image share; `exchange`: pairs, round
/// trips) plus the ladder, the swap acceptance matrix (summed over replica
/// sets) and round trips per hour, and each member's image as a layer
/// named by `layer`. `n` is the sample index the floor was evaluated at.
pub fn report(
    mut rendered: Rendered,
    result: &MltResult,
    settings: &TemperedLadder,
    bsdfs: &TemperedBsdfs,
    n: u64,
    layer: impl Fn(usize) -> String,
) -> Rendered {
    let schedule = settings.schedule();
    let mut ladder = ladder_json(bsdfs, &schedule, n);
    if let Some(ex) = &result.exchange {
        let m = settings.levels;
        let mut matrix = vec![vec![f64::NAN; m]; m];
        for p in &ex.pairs {
            if p.attempted > 0 {
                let rate = p.accepted as f64 / p.attempted as f64;
                matrix[p.i][p.j] = rate;
                matrix[p.j][p.i] = rate;
            }
        }
        let hours = result.seconds / 3600.0;
        ladder["swap_acceptance_matrix"] = json!(matrix);
        ladder["round_trips_per_hour"] = json!(if hours > 0.0 {
            ex.round_trips as f64 / hours
        } else {
            0.0
        });
    }
    ladder["level_acceptance"] = json!(
        result
            .member_stats
            .iter()
            .map(|s| s.as_ref().map(|s| s.acceptance_rate()))
            .collect::<Vec<_>>()
    );
    rendered.statistics.insert("tempering".into(), ladder);
    rendered.layers = result
        .families
        .iter()
        .enumerate()
        .map(|(k, f)| (layer(k), f.image()))
        .collect();
    rendered
}
