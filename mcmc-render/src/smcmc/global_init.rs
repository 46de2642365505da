//! Start-up by global chains (spec seed003 §8.7, "global chains + RE"):
//! a few PSSMLT chains over the whole film find the light for the tiles.
//!
//! Each global chain targets `lum f` of one path per state, the shift's
//! own evaluation with the state's sub-pixel offset read as a position on
//! the whole film ([`TileShift::evaluate_film`]), so its states are in the
//! tiles' coordinate layout. The chains start from a bootstrap population
//! (`bootstrap` uniform states, each chain resampling one `∝ π`, spec
//! eq. 2.105–2.108) instead of the thesis's 100 000 burn-in mutations, run
//! `mutations_per_pixel × pixels / chains` mutations each, and record the
//! first state they hold in every pixel. A tile then starts from the state
//! recorded for its centre pixel (or, failing that, for another of its
//! pixels in slot order, the chains in index order), its offset moved into
//! the pixel: the start state is not drawn from the tile's target (start-up
//! bias, consistent as for the naive start), but it carries light where
//! uniform candidates rarely do, at the price of one path per global
//! mutation instead of one per tile pixel per candidate.
//!
//! Deviations from the thesis: the number of chains is a setting, not the
//! thread count (so the image does not depend on the threads); a tile that
//! a chain revisits is not swapped with it (Gruson's code swaps
//! unconditionally); the walk does not stop at a share of started tiles
//! (`percentageInit`), it runs its mutations.

use super::TileShift;
use crate::markov::STARTUP_ROUND;
use crate::pss::Mutation;
use crate::scene::Scene;
use mcmc_core::chain::Chain;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::rng::{ChainRng, splitmix64, stream_rng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::TorusPoint;
use mcmc_core::stats::ChainStatistics;
use mcmc_core::target::{Evaluation, Target};
use rayon::prelude::*;

/// `ln lum f` of a state's path on the whole film; the payload is the
/// index of the pixel it lands in (row-major).
pub struct FilmTarget<'a, S> {
    /// The scene.
    pub scene: &'a Scene,
    /// The shift whose film evaluation is the target.
    pub shift: &'a S,
}

impl<S: TileShift> Target<TorusPoint> for FilmTarget<'_, S> {
    type Payload = usize;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<usize> {
        let (raster, f) = self.shift.evaluate_film(self.scene, state);
        let (w, h) = (self.scene.film.width, self.scene.film.height);
        // The offsets are in [0, 1), but f32 rounding can reach the far edge.
        let x = (raster.x.max(0.0) as u32).min(w - 1);
        let y = (raster.y.max(0.0) as u32).min(h - 1);
        let l = f64::from(f.luminance());
        let log_density = if !f.is_finite() || !l.is_finite() {
            f64::NAN
        } else if l > 0.0 {
            l.ln()
        } else {
            f64::NEG_INFINITY
        };
        Evaluation::new(log_density, (y * w + x) as usize)
    }
}

/// The global start-up's settings.
#[derive(Clone, Copy, Debug)]
pub struct GlobalInit {
    /// Global chains.
    pub chains: usize,
    /// Uniform states of the bootstrap population.
    pub bootstrap: usize,
    /// Global mutations per pixel (all chains together).
    pub mutations_per_pixel: f64,
}

/// What the global start-up found.
pub struct Visits {
    /// Per pixel, the coordinates of the first state a chain held there
    /// (chains in index order), its offset coordinates moved into that
    /// pixel; [`Visits::state`] makes a point of them.
    pub states: Vec<Option<Vec<f64>>>,
    /// Pixels visited.
    pub visited: usize,
    /// Mutations run (all chains).
    pub mutations: u64,
    /// Uniform states of the bootstrap that carried light.
    pub lit_bootstrap: usize,
    /// Uniform states of the bootstrap drawn: `bootstrap`, or fewer when a
    /// stop or the start-up's share of the time budget cut it (in rounds
    /// of `markov::STARTUP_ROUND`).
    pub drawn_bootstrap: usize,
    /// The chains' statistics, merged.
    pub stats: Option<ChainStatistics>,
}

impl Visits {
    /// The state recorded for pixel `p` (later coordinates fresh uniforms
    /// drawn from `rng`).
    pub fn state(&self, p: usize, rng: ChainRng) -> Option<TorusPoint> {
        self.states[p]
            .as_ref()
            .map(|v| TorusPoint::from_values(v, rng))
    }
}

/// One global chain's walk: the pixels it visited first with their
/// states, its mutations and statistics.
struct Walk {
    found: Vec<(usize, Vec<f64>)>,
    mutations: u64,
    stats: ChainStatistics,
}

/// Stream offset of the start-up's random streams.
const GLOBAL_STREAM: u64 = 1 << 45;

impl GlobalInit {
    /// Runs the global chains of `shift` on `scene` with `mutation`;
    /// `halt()` ends the walk early.
    pub fn run<S: TileShift>(
        &self,
        scene: &Scene,
        shift: &S,
        mutation: &Mutation,
        seed: u64,
        halt: &(dyn Fn() -> bool + Sync),
    ) -> Visits {
        let (w, h) = (scene.film.width as usize, scene.film.height as usize);
        let pixels = w * h;
        let seed = splitmix64(seed ^ GLOBAL_STREAM);
        let target = FilmTarget { scene, shift };
        // Bootstrap state `i` (re-created, not stored: points are not `Sync`).
        let candidate =
            |i: usize| Sample::evaluate(&target, TorusPoint::fresh(stream_rng(seed, 1 + i as u64)));
        // In rounds, so that `halt()` (Ctrl-C, the time budget) ends the
        // bootstrap within a round's time: drawn all at once, 50 million
        // states held a Ctrl-C for 17 s (session 33). Uncut, the weights are
        // those of one pass (each depends on its index alone).
        let mut weights: Vec<f64> = Vec::new();
        while weights.len() < self.bootstrap {
            let end = (weights.len() + STARTUP_ROUND).min(self.bootstrap);
            weights.par_extend((weights.len()..end).into_par_iter().map(|i| {
                let x = candidate(i);
                if x.log_density.is_finite() {
                    x.log_density.exp()
                } else {
                    0.0
                }
            }));
            if halt() {
                break;
            }
        }
        let total: f64 = weights.iter().sum();
        let lit_bootstrap = weights.iter().filter(|&&w| w > 0.0).count();
        let mut visits = Visits {
            states: vec![None; pixels],
            visited: 0,
            mutations: 0,
            lit_bootstrap,
            drawn_bootstrap: weights.len(),
            stats: None,
        };
        if total <= 0.0 || self.chains == 0 {
            return visits;
        }
        let steps = (self.mutations_per_pixel * pixels as f64 / self.chains as f64).ceil() as u64;
        let offsets = shift.offset_coordinates();
        let walks: Vec<Walk> = (0..self.chains)
            .into_par_iter()
            .map(|c| {
                let mut rng: ChainRng = stream_rng(seed, u64::MAX - c as u64);
                let mut u = uniform(&mut rng) * total;
                let mut pick = 0;
                for (i, &wi) in weights.iter().enumerate() {
                    if wi > 0.0 {
                        pick = i;
                        if u < wi {
                            break;
                        }
                        u -= wi;
                    }
                }
                let mut chain = Chain::from_sample(
                    candidate(pick),
                    MetropolisHastings::new(
                        mutation
                            .kernel()
                            .expect("the mutation was checked by validate"),
                    ),
                    rng,
                )
                .expect("a lit state starts a chain");
                let mut seen = vec![false; pixels];
                let mut found = Vec::new();
                let mut done = 0;
                let mut record = |x: &Sample<TorusPoint, usize>, found: &mut Vec<_>| {
                    let p = x.payload;
                    if !seen[p] {
                        seen[p] = true;
                        found.push((p, into_pixel(&x.state, (w, h), offsets)));
                    }
                };
                record(chain.current(), &mut found);
                while done < steps && !halt() {
                    chain.step(&target);
                    done += 1;
                    record(chain.current(), &mut found);
                }
                Walk {
                    found,
                    mutations: done,
                    stats: chain.stats().clone(),
                }
            })
            .collect();
        for Walk {
            found,
            mutations,
            stats,
        } in walks
        {
            visits.mutations += mutations;
            match visits.stats.as_mut() {
                Some(s) => s.merge(&stats),
                None => visits.stats = Some(stats),
            }
            for (p, state) in found {
                if visits.states[p].is_none() {
                    visits.states[p] = Some(state);
                    visits.visited += 1;
                }
            }
        }
        visits
    }
}

/// The coordinates of `state` (on a `w × h` film) with its offset
/// coordinates replaced by the position inside the pixel it lands in, so a
/// tile evaluates it there.
fn into_pixel(state: &TorusPoint, (w, h): (usize, usize), offsets: [usize; 2]) -> Vec<f64> {
    let mut values = state.materialize();
    for (i, n) in offsets.into_iter().zip([w, h]) {
        if i < values.len() {
            let v = values[i] * n as f64;
            values[i] = v - v.floor();
        }
    }
    values
}
