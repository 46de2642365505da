//! Replica exchange light transport (Kitaoka, Kitamura and Kishino 2009)
//! on the Markov-chain driver; spec `seed002-relt.md`.
//!
//! - **State**: a primary-sample point; one BDPT evaluation gives every
//!   technique's splat tagged by its path class `L0 … L5`
//!   ([`crate::path_classes`]), kept with the state, so that every
//!   replica's density comes from it without tracing.
//! - **Replicas** (family members, ordered easy to hard): *uniform*
//!   (`q = 1`, independent proposals, always accepted), *full*
//!   (`L0 + L2 + L3 + L4 + L5`), *indirect* (`L0 + L3 + L4 + L5`) and
//!   *specific* (`L0 + δ·L5`), each value measured by `X + Y + Z` (or
//!   luminance). Replicas 2–4 take Kelemen small steps with their own
//!   sizes and no large step.
//! - **Exchanges**: `mcmc-core`'s moves between the replicas of each set
//!   (neighbour swaps by default; `none` is the paper's Fig. 8).
//! - **Estimator** (the paper's §5.1.4 form of Eq. 23): `L0` only from the
//!   specific replica (`b_4 · L0/q_4`), the rest by the power heuristic
//!   over the other replicas with the start-up `b̂_k`
//!   (`(q_k/b̂_k)^{β−1} / (b̂_k Σ_l (q_l/b̂_l)^β)` per state, times the
//!   running `b_k`). Every uniform draw updates every replica's running
//!   `b_k`. `mis_classes=per_class` runs each class's sum only over the
//!   replicas whose target holds the class (`L1`: the uniform replica,
//!   and the full one under `full_l1`).
//! - **Start-up**: one shared pool of uniform candidates gives every
//!   replica's initial running `b_k`; population annealing (Algorithm 2,
//!   `mcmc_core::replica::population_annealing`) from the uniform replica
//!   through full, indirect and specific gives the chains' start states
//!   and the `b̂_k` of the MIS weights (`annealing_particles = 0`: each
//!   replica resamples its start from the pool instead). A replica whose
//!   bootstrap `b̂` is zero is dropped and reported.

use super::registry::IntegratorSettings;
use super::{DepthParams, RenderError, Rendered, RunSettings};
use crate::integrators::bdpt::{Bdpt, MisHeuristic};
use crate::markov::{
    self, Annealing, ChainFamily, ChainParams, ContinuedSearch, MltError, MltResult, Normalization,
    Search, StartupCut,
};
use crate::observer::Observer;
use crate::path_classes::{ClassScalar, ClassifiedBdpt, class_values};
use crate::pss::{Mutation, PATH_CLASSES, PathSample, PssTarget, SmallStepKind};
use crate::pss_dump::DumpSampler;
use crate::scene::Scene;
use crate::settings::check;
use mcmc_core::kernel::Mixture;
use mcmc_core::replica::{
    EvenOdd, ExchangeMove, IsPermutation, IsSwap, NeighbourSwap, RandomNeighbour,
};
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
use rayon::prelude::*;
use serde_json::json;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

crate::choice! {
    /// The exchange move between replicas.
    pub enum ReltExchange {
        /// Swap every neighbouring pair after the hotter one mutated.
        Neighbour = "neighbour",
        /// Even or odd neighbour pairs, alternately.
        EvenOdd = "even_odd",
        /// Importance-sampled permutation of all replicas.
        IsPermutation = "is_permutation",
        /// Importance-sampled swap of one pair.
        IsSwap = "is_swap",
        /// No exchanges: every replica mixes alone (the paper's Fig. 8).
        None = "none",
        /// One neighbouring pair per sweep, drawn uniformly, after all
        /// replicas mutated (the paper's Algorithm 1).
        RandomNeighbour = "random_neighbour",
    }
}

crate::choice! {
    /// Which replicas share the MIS weights of a class (`L0` aside while
    /// the specific replica runs: it films `L0` alone, §5.1.4).
    pub enum ReltMisClasses {
        /// Every class over all the other replicas (the paper's §5.1.4).
        All = "all",
        /// Each class over the replicas whose target holds it (the uniform
        /// replica holds every class): `L1` is then filmed by the uniform
        /// replica alone, or with the full one under `full_l1`.
        PerClass = "per_class",
    }
}

crate::settings! {
    /// RELT settings (defaults from spec seed002 §11).
    pub struct Relt {
        /// Scalar of a class contribution: xyz_sum (the paper's X+Y+Z) or luminance.
        pub target: ClassScalar = ClassScalar::XyzSum;
        /// δ, the weight of indirect paths (L5) in the specific replica's target (the paper gives none).
        pub delta: f64 = 0.01, check check::positive;
        /// Run the specific (L0 + δ·L5) replica.
        pub specific_replica: bool = true;
        /// Largest Kelemen step of the full-path replica (smallest: s2/16).
        pub s2_full: f64 = 1.0 / 64.0, check check::probability;
        /// Largest Kelemen step of the indirect-path replica.
        pub s2_indirect: f64 = 1.0 / 64.0, check check::probability;
        /// Largest Kelemen step of the specific-path replica.
        pub s2_specific: f64 = 1.0 / 96.0, check check::probability;
        /// Exchange move: neighbour, even_odd, is_permutation, is_swap, none or random_neighbour.
        pub exchange: ReltExchange = ReltExchange::Neighbour;
        /// Share of the sweeps in which the uniform replica draws (1: every sweep, as in the paper).
        pub uniform_share: f64 = 1.0, check share;
        /// Exponent β ≥ 1 of the power heuristic over replicas (1: balance).
        pub mis_power: f64 = 1.0, check check::at_least_one;
        /// Replicas a class's MIS weights run over: all, or per_class (only those whose target holds the class).
        pub mis_classes: ReltMisClasses = ReltMisClasses::All;
        /// Put L1 (implicit lighting without a specular vertex) into the full replica's target.
        pub full_l1: bool = false;
        /// Particles of the population-annealing start-up (0: start every replica from its own bootstrap).
        pub annealing_particles: usize = 10_000;
        /// Metropolis–Hastings steps per particle and replica in the annealing.
        pub annealing_sweeps: usize = 1;
        /// Uniform draws screened for L0 paths to start the specific replica (0: no search, neither at start-up nor during the run; docs/relt.md).
        pub l0_search: usize = 4_000_000;
        /// Further search draws per chain mutation, made while the chains run and merged into the specific replica's b_4 (0: start-up search only; normalization=running or filmed only; docs/relt.md session 16).
        pub l0_search_rate: f64 = 0.0, check check::non_negative;
        flatten {
            /// Path depth.
            pub depth: DepthParams = DepthParams::default();
            /// The driver (`kelemen_mis` does not apply; `depth_allocation`
            /// only without exchanges; `normalization=ratios` is the
            /// paper's Eq. 10 chain; the default `filmed` scales the full
            /// and indirect replicas, whose `L0` their chains rarely
            /// reach, by their filmed part: docs/relt.md, session 24).
            pub chain: ChainParams = ChainParams {
                normalization: Normalization::Filmed,
                ..ChainParams::default()
            };
        }
    }
}

/// A share of the sweeps: in `(0, 1]`.
fn share(v: &f64) -> Result<(), String> {
    if *v > 0.0 && *v <= 1.0 {
        Ok(())
    } else {
        Err("must lie in (0, 1]".into())
    }
}

/// One replica: its name and how its density weighs the classes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Replica {
    /// Name in statistics and layer files.
    pub name: &'static str,
    /// `d_k` over `(L0 … L5)`; `None`: the uniform replica (`q = 1`).
    pub weights: Option<[f64; PATH_CLASSES]>,
    /// Largest Kelemen step (unused by the uniform replica).
    pub s2: f64,
    /// Share of the sweeps in which the replica mutates.
    pub share: f64,
}

impl Replica {
    /// `q_k` of a state with class values `v` (NaN stays NaN).
    fn density(&self, v: &[f64; PATH_CLASSES]) -> f64 {
        match self.weights {
            None if v[0].is_nan() => f64::NAN,
            None => 1.0,
            Some(d) => d.iter().zip(v).map(|(d, l)| d * l).sum(),
        }
    }

    /// Whether the replica's target holds class `c` (the uniform replica's
    /// holds every class).
    fn holds(&self, c: usize) -> bool {
        self.weights.is_none_or(|d| d[c] > 0.0)
    }

    /// The replica's kernel configuration.
    fn mutation(&self) -> Mutation {
        let small = SmallStepKind::Kelemen {
            s1: self.s2 / 16.0,
            s2: self.s2,
        };
        Mutation {
            small,
            large_step_probability: if self.weights.is_none() { 1.0 } else { 0.0 },
        }
    }
}

impl Relt {
    /// The replicas, easy to hard (the specific one last, if on).
    pub fn replicas(&self) -> Vec<Replica> {
        let full_l1 = if self.full_l1 { 1.0 } else { 0.0 };
        let mut r = vec![
            Replica {
                name: "uniform",
                weights: None,
                s2: self.s2_full,
                share: self.uniform_share,
            },
            Replica {
                name: "full",
                weights: Some([1.0, full_l1, 1.0, 1.0, 1.0, 1.0]),
                s2: self.s2_full,
                share: 1.0,
            },
            Replica {
                name: "indirect",
                weights: Some([1.0, 0.0, 0.0, 1.0, 1.0, 1.0]),
                s2: self.s2_indirect,
                share: 1.0,
            },
        ];
        if self.specific_replica {
            r.push(Replica {
                name: "specific",
                weights: Some([1.0, 0.0, 0.0, 0.0, 0.0, self.delta]),
                s2: self.s2_specific,
                share: 1.0,
            });
        }
        r
    }
}

/// One replica's target: `ln q_k` of the classified BDPT sample.
pub struct ReplicaTarget<'a> {
    pss: PssTarget<'a, ClassifiedBdpt>,
    replica: Replica,
    scalar: ClassScalar,
}

fn log_of(q: f64) -> f64 {
    if q > 0.0 && q.is_finite() {
        q.ln()
    } else if q == 0.0 {
        f64::NEG_INFINITY
    } else {
        f64::NAN
    }
}

impl Target<TorusPoint> for ReplicaTarget<'_> {
    type Payload = PathSample;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<PathSample> {
        let e = self.pss.trace(state);
        let v = class_values(&e.payload.splats, self.scalar);
        Evaluation::new(log_of(self.replica.density(&v)), e.payload)
    }
}

/// The RELT family: one member per replica.
pub struct ReltFamily<'a> {
    targets: Vec<ReplicaTarget<'a>>,
    scalar: ClassScalar,
    exchange: ReltExchange,
    mis_power: f64,
    /// Which replicas share a class's MIS weights.
    mis_classes: ReltMisClasses,
    /// Index of the specific replica, whose member alone films `L0`.
    specific: Option<usize>,
    /// A custom exchange move in place of `exchange`.
    custom_exchange: Option<MakeExchange>,
    /// The start-up's population annealing.
    annealing: Option<Annealing>,
    /// Draws of the specific replica's search for `L0` paths.
    l0_search: u64,
    /// Search draws per chain mutation made while the chains run.
    l0_search_rate: f64,
}

/// First start-up candidate index of the specific replica's search (the
/// bootstrap's are `0 .. bootstrap · members`).
const SEARCH_OFFSET: u64 = 1 << 39;

/// Draws of the search traced in full whatever their camera subpath
/// (every `stride`-th): they estimate the `δ·L5` part of `b_4`.
const SEARCH_FULL_DRAWS: u64 = 10_000;

/// Draws of the search between two looks at the start-up's cut (in parallel
/// within a block; the blocks in order, so the draws kept are a prefix).
const SEARCH_BLOCK: u64 = 1 << 14;

/// First candidate index of the search continued during the run: after
/// the start-up search's (disjoint from them for `l0_search < 2^38`).
const CONTINUED_SEARCH_OFFSET: u64 = SEARCH_OFFSET + (1 << 38);

/// Makes a fresh exchange move for one replica set.
pub type MakeExchange = fn(usize) -> Box<dyn ExchangeMove<TorusPoint, PathSample>>;

impl<'a> ReltFamily<'a> {
    /// The family of `replicas` over BDPT on `scene`.
    pub fn new(scene: &'a Scene, bdpt: Bdpt, replicas: &[Replica], settings: &Relt) -> Self {
        ReltFamily {
            targets: replicas
                .iter()
                .map(|&replica| ReplicaTarget {
                    pss: PssTarget {
                        scene,
                        sampler: ClassifiedBdpt(bdpt),
                    },
                    replica,
                    scalar: settings.target,
                })
                .collect(),
            scalar: settings.target,
            exchange: settings.exchange,
            mis_power: settings.mis_power,
            mis_classes: settings.mis_classes,
            specific: replicas.iter().position(|r| r.name == "specific"),
            custom_exchange: None,
            annealing: (settings.annealing_particles > 0).then_some(Annealing {
                particles: settings.annealing_particles,
                sweeps: settings.annealing_sweeps,
            }),
            l0_search: settings.l0_search as u64,
            // Only the running normalisation pools the draws into the
            // image's b_4 (the others scale by the bootstrap's or by
            // the chain of ratios): elsewhere they would be wasted.
            l0_search_rate: match settings.chain.normalization {
                Normalization::Running | Normalization::Filmed => settings.l0_search_rate,
                _ => 0.0,
            },
        }
    }

    /// The specific replica's search for `L0` paths: `l0_search` uniform
    /// draws (rounded up to a multiple of the stride), each screened by its
    /// camera subpath alone
    /// ([`ClassifiedBdpt::may_carry_specular_implicit`]). A draw that
    /// passes is traced in full with weight `q_4`; of the others (whose
    /// `L0` is exactly 0, so `q_4 = δ·L5`), every `stride`-th by index is
    /// traced with weight `stride · q_4`, the rest get 0. Membership of
    /// the subsample depends on the index only, so the mean weight over
    /// all draws is an unbiased estimate of `b_4 = ∫ q_4`, and the
    /// weighted draws are an importance sample of `q_4` to start from.
    ///
    /// At the start-up's `cut` (the run's deadline or Ctrl-C; on a
    /// cluster: any rank's) the search stops after
    /// its current block of [`SEARCH_BLOCK`] draws; `draws` is then the
    /// number made. A cut that ends inside a stride of `m < stride` draws
    /// gives that stride's subsampled draw the weight `m · q_4` in place of
    /// `stride · q_4`, so the mean over the draws made stays unbiased.
    /// Uncut, the draws and weights are exactly those of the whole search.
    fn search_specific(&self, member: usize, seed: u64, cut: &StartupCut) -> Search {
        let stride = self.search_stride();
        let planned = self.l0_search.div_ceil(stride) * stride;
        let draw = |j: u64| {
            let index = SEARCH_OFFSET + j;
            self.screened_draw(member, seed, index, j.is_multiple_of(stride))
                .map(|(log_q, subsampled)| (index, log_q, subsampled))
        };
        let mut kept: Vec<(u64, f64, bool)> = Vec::new();
        let mut draws = 0;
        // Every rank of a cluster searches: they agree before each block
        // whether the cut is due (collective), so all keep the same draws.
        while draws < planned && !cut.due() {
            let end = (draws + SEARCH_BLOCK).min(planned);
            kept.par_extend((draws..end).into_par_iter().filter_map(draw));
            draws = end;
        }
        // The last stride's length among the draws made (`stride` unless
        // the cut ended it).
        let last = draws - (draws.max(1) - 1) / stride * stride;
        let weighted = kept
            .into_iter()
            .map(|(index, log_q, subsampled)| {
                let j = index - SEARCH_OFFSET;
                let scale = match subsampled {
                    false => 1,
                    true if j + last == draws => last,
                    true => stride,
                };
                (index, log_q + (scale as f64).ln())
            })
            .collect();
        Search {
            draws,
            weighted,
            ..Search::default()
        }
    }

    /// Every `stride`-th draw of the search is traced whatever its camera
    /// subpath: [`SEARCH_FULL_DRAWS`] of them in a search of `l0_search`.
    fn search_stride(&self) -> u64 {
        (self.l0_search / SEARCH_FULL_DRAWS).max(1)
    }

    /// One draw of the specific replica's search, candidate `index`,
    /// screened by its camera subpath alone
    /// ([`ClassifiedBdpt::may_carry_specular_implicit`]): `None` (weight
    /// 0) for a draw that fails the screen unless it is its stride's
    /// `representative`, and for one whose `q_4` is 0 or NaN; else `ln
    /// q_4` and whether it failed the screen (it then stands for its
    /// stride's unscreened draws).
    fn screened_draw(
        &self,
        member: usize,
        seed: u64,
        index: u64,
        representative: bool,
    ) -> Option<(f64, bool)> {
        let target = &self.targets[member];
        let x = self.candidate(seed, index);
        let subsampled = !target
            .pss
            .sampler
            .may_carry_specular_implicit(target.pss.scene, &x);
        if subsampled && !representative {
            return None;
        }
        let log_q = target.evaluate(&x).log_density;
        // Zero and NaN weigh nothing (NaN as in the running
        // normalisation: counted as a zero).
        log_q.is_finite().then_some((log_q, subsampled))
    }

    /// The family with the exchange move `make(replicas)` (any move of
    /// `mcmc-core`'s, or a user's own) in place of the settings' choice.
    pub fn with_exchange(mut self, make: MakeExchange) -> Self {
        self.custom_exchange = Some(make);
        self
    }

    /// The replicas of the family.
    pub fn replicas(&self) -> Vec<Replica> {
        self.targets.iter().map(|t| t.replica).collect()
    }
}

impl<'a> ChainFamily for ReltFamily<'a> {
    type State = TorusPoint;
    type Target = ReplicaTarget<'a>;
    type Mutation = ();
    type Kernel = Mixture<TorusPoint, PathSample>;

    fn members(&self) -> usize {
        self.targets.len()
    }
    fn target(&self, member: usize) -> &ReplicaTarget<'a> {
        &self.targets[member]
    }
    fn kernel(&self, _mutation: &(), member: usize) -> Result<Self::Kernel, MltError> {
        Ok(self.targets[member].replica.mutation().kernel()?)
    }
    fn independent_probability(&self, _mutation: &()) -> f64 {
        // Only for Kelemen's MIS, which RELT does not use.
        0.0
    }
    crate::primary_sample_space_family!();
    /// Checkpoints hold every replica set as the driver saves them: the
    /// Kelemen small steps and the uniform replica's independent draws
    /// keep no state of their own, and the start-up (bootstrap,
    /// annealing, search) is made again on resume, uncut by the budget
    /// (`markov::startup_deadline`), so `b̂` and the replica set are the
    /// saved run's; the continued search's draws are in each task's
    /// running `b_4` (saved) and follow from its mutation count.
    fn checkpointable(&self, _mutation: &()) -> bool {
        true
    }
    /// Every replica but the uniform one (member 0) can be dropped when
    /// no bootstrap path reaches it (spec seed002 §5).
    fn droppable(&self, member: usize) -> bool {
        member > 0
    }
    fn exchange_move(&self) -> Option<Box<dyn ExchangeMove<TorusPoint, PathSample>>> {
        let m = self.members();
        if let Some(make) = self.custom_exchange {
            return Some(make(m));
        }
        match self.exchange {
            ReltExchange::Neighbour => Some(Box::new(NeighbourSwap::new())),
            ReltExchange::EvenOdd => Some(Box::new(EvenOdd::new())),
            // At most four replicas: well within the permutation DP's limit.
            ReltExchange::IsPermutation => Some(Box::new(
                IsPermutation::new(m).expect("IS permutations of at most 4 replicas"),
            )),
            ReltExchange::IsSwap => Some(Box::new(IsSwap::new())),
            ReltExchange::None => None,
            ReltExchange::RandomNeighbour => Some(Box::new(RandomNeighbour::new())),
        }
    }
    fn annealing(&self) -> Option<Annealing> {
        self.annealing
    }
    fn search(&self, member: usize, seed: u64, cut: &StartupCut) -> Option<Search> {
        (Some(member) == self.specific && self.l0_search > 0)
            .then(|| self.search_specific(member, seed, cut))
    }
    fn continued_search(&self, member: usize) -> Option<ContinuedSearch> {
        (Some(member) == self.specific && self.l0_search > 0 && self.l0_search_rate > 0.0).then(
            || ContinuedSearch {
                per_mutation: self.l0_search_rate,
                unit: self.search_stride(),
                first_index: CONTINUED_SEARCH_OFFSET,
            },
        )
    }
    /// One stride of the search, screened as at start-up: its first draw
    /// is the representative of the unscreened ones (weight `stride ·
    /// q_4` if it fails the screen), the others weigh `q_4` if they pass
    /// it and 0 if not, so the stride's weights sum to `stride · b_4` in
    /// expectation.
    fn search_unit(&self, member: usize, seed: u64, first: u64) -> Vec<f64> {
        let stride = self.search_stride();
        (0..stride)
            .filter_map(|j| self.screened_draw(member, seed, first + j, j == 0))
            .map(|(log_q, subsampled)| match subsampled {
                true => log_q + (stride as f64).ln(),
                false => log_q,
            })
            .collect()
    }
    fn sweep_share(&self, member: usize) -> f64 {
        self.targets[member].replica.share
    }
    fn member_log_density(&self, member: usize, payload: &PathSample) -> Option<f64> {
        let v = class_values(&payload.splats, self.scalar);
        Some(log_of(self.targets[member].replica.density(&v)))
    }
    /// The full and indirect replicas' targets hold `L0`, which the
    /// specific replica alone films: their filmed part is `q_k − d_k[0]·L0`.
    fn filmed_log_density(&self, member: usize, payload: &PathSample) -> Option<f64> {
        let d = self.targets[member].replica.weights?;
        if self.specific.is_none() || Some(member) == self.specific || d[0] == 0.0 {
            return None;
        }
        let mut v = class_values(&payload.splats, self.scalar);
        v[0] = 0.0;
        Some(log_of(self.targets[member].replica.density(&v)))
    }
    fn class_weights(
        &self,
        member: usize,
        payload: &PathSample,
        b_hat: &[f64],
    ) -> Option<[f64; PATH_CLASSES]> {
        let v = class_values(&payload.splats, self.scalar);
        let q = |k: usize| self.targets[k].replica.density(&v);
        let mut w = [0.0; PATH_CLASSES];
        if Some(member) == self.specific {
            // L0 from the specific replica alone: b_4 · L0 / q_4.
            w[0] = 1.0 / q(member);
            return Some(w);
        }
        // The power heuristic with sample counts: replica l draws in a
        // share f_l of the sweeps, so w_k = (f_k q_k/b̂_k)^β / Σ_l (f_l
        // q_l/b̂_l)^β, and the factor is w_k/q_k (its film is over its own
        // mutations). With every f_l = 1 this is the paper's Eq. 22. The
        // sum runs over the replicas that film the class: all but the
        // specific one, or (`per_class`) those of them whose target holds
        // it. Holding c, replica k has q_k > 0 wherever L_c > 0, so the
        // weights still sum to 1 there; the uniform replica holds every
        // class, so no sum is empty.
        let beta = self.mis_power;
        let f = |k: usize| self.targets[k].replica.share;
        let films = |k: usize, c: usize| {
            Some(k) != self.specific
                && (self.mis_classes == ReltMisClasses::All || self.targets[k].replica.holds(c))
        };
        let mut denominators = [0.0; PATH_CLASSES];
        for l in (0..self.members()).filter(|&l| Some(l) != self.specific) {
            let term = (f(l) * q(l) / b_hat[l]).powf(beta);
            for (c, d) in denominators.iter_mut().enumerate() {
                if films(l, c) {
                    *d += term;
                }
            }
        }
        let own = f(member) * (f(member) * q(member) / b_hat[member]).powf(beta - 1.0);
        for (c, w) in w.iter_mut().enumerate() {
            // L0 is the specific replica's alone (§5.1.4).
            if !(c == 0 && self.specific.is_some()) && films(member, c) {
                *w = own / (b_hat[member] * denominators[c]);
            }
        }
        Some(w)
    }
}

impl IntegratorSettings for Relt {
    const NAME: &'static str = "relt";
    const DESCRIPTION: &'static str = "Replica exchange light transport (Kitaoka et al. 2009): PSS replicas over BDPT path classes, exchanged and combined by MIS.";

    fn validate(&self) -> Result<(), String> {
        if self.chain.kelemen_mis {
            return Err(
                "relt combines its replicas by its own MIS; kelemen_mis does not apply".into(),
            );
        }
        for r in self.replicas() {
            r.mutation()
                .kernel::<()>()
                .map_err(|e| format!("relt {} replica: {e}", r.name))?;
        }
        Ok(())
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
        let bdpt = Bdpt {
            max_depth: self.depth.limit(),
            rr_depth: self.depth.rr_depth,
            heuristic: MisHeuristic::Power,
        };
        let mut settings = self.chain.chain_settings((), run);
        // The driver stops the start-up's search at the budget (not with a
        // checkpoint: `markov::StartupCut`), then the annealing and the
        // chains.
        let mut replicas = self.replicas();
        let mut dropped = Vec::new();
        let result = loop {
            let family = ReltFamily::new(scene, bdpt, &replicas, self);
            let attempt = Instant::now();
            match markov::run(scene, &family, &settings, stop, observer) {
                // A replica no bootstrap path reached cannot start: drop
                // it (spec seed002 §5) and run the others, on the first
                // run's clock: its budget and `seconds` count both runs
                // (the budget had restarted: up to 2× --time).
                Err(MltError::EmptyMember { member }) if family.droppable(member) => {
                    dropped.push(replicas.remove(member).name);
                    settings.clock_started.get_or_insert(attempt);
                }
                other => break other?,
            }
        };
        Ok(report(&result, &replicas, &dropped, self.depth.limit()))
    }
}

/// The registry's report of a RELT run, with each replica's statistics
/// and image.
fn report(result: &MltResult, replicas: &[Replica], dropped: &[&str], max_depth: u32) -> Rendered {
    let mut rendered = markov::report::rendered(result, DumpSampler::Bdpt, max_depth, false);
    rendered.statistics.insert(
        "replicas".into(),
        json!(replicas.iter().map(|r| r.name).collect::<Vec<_>>()),
    );
    rendered
        .statistics
        .insert("dropped_replicas".into(), json!(dropped));
    rendered.layers = replicas
        .iter()
        .zip(&result.families)
        .map(|(r, f)| (format!("replica-{}", r.name), f.image()))
        .collect();
    rendered
}
