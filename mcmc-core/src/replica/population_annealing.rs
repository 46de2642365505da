//! Population annealing (Iba 2001; Kitaoka et al. 2009, Algorithm 2):
//! sequential Monte Carlo over the levels of a [`ReplicaFamily`] rather
//! than over time. It starts each level's chains near equilibrium and
//! estimates the ratios of the levels' normalisers.
//!
//! `N` particles are exact draws of level 0. Then, for each level `k ≥ 1`:
//!
//! 1. weights `c_i = π_k(x_i) / π_{k−1}(x_i)`; their mean estimates
//!    `b_k / b_{k−1}` (Eq. 21), with relative standard error
//!    `sd(c) / (√N · mean(c))`;
//! 2. systematic resampling of `N` particles `∝ c_i` (one uniform number,
//!    `(j + ξ)/N` through the weights' cumulative sum);
//! 3. `sweeps` steps of the level's Metropolis–Hastings algorithm on every
//!    particle (each particle draws from its own stream, in chunks of a
//!    fixed size, so the result does not depend on the thread count).
//!
//! The printed Algorithm 2 tests "k = K" where it means `k < K`; the
//! author code's retry of zero-density proposals is not used (a proposal
//! is made once and rejected if it has zero density).

use super::family::{LevelTarget, ReplicaFamily};
use crate::chain::{Algorithm, ChainState};
use crate::error::{Result, invalid};
use crate::rng::{stream_rng, uniform};
use crate::sample::Sample;
use crate::stats::ChainStatistics;
use rayon::prelude::*;

/// Particles per work unit of the MH sweeps (fixed, so the split does not
/// depend on the thread count).
const CHUNK: usize = 256;

/// Stream offset of the resampling draws (particle `i` of level `k` moves
/// with stream `k·N + i`).
const RESAMPLE_STREAM: u64 = 0x5A5A_0000_0000_0000;

/// `xs` in owned chunks of [`CHUNK`].
fn chunks<T>(xs: Vec<T>) -> Vec<Vec<T>> {
    let mut out = Vec::with_capacity(xs.len().div_ceil(CHUNK));
    let mut it = xs.into_iter().peekable();
    while it.peek().is_some() {
        out.push(it.by_ref().take(CHUNK).collect());
    }
    out
}

/// A chunk of particles after its sweeps, with its steps and acceptances.
type MovedChunk<S, P> = (Vec<Sample<S, P>>, u64, u64);

/// One annealed level.
#[derive(Clone, Debug)]
pub struct AnnealedLevel<S, P> {
    /// The particles after resampling and the MH sweeps (level 0: the
    /// initial draws).
    pub particles: Vec<Sample<S, P>>,
    /// `ln(b_k / b_{k−1})` (0 at level 0).
    pub log_ratio: f64,
    /// The relative standard error of `b_k / b_{k−1}` (0 at level 0).
    pub ratio_relative_error: f64,
    /// Acceptance rate of the level's MH sweeps (NaN at level 0).
    pub acceptance: f64,
    /// MH steps made at the level over all particles (0 at level 0):
    /// `particles · sweeps` unless [`anneal_until`]'s `stop` cut them.
    pub steps: u64,
}

/// The outcome of population annealing over every level of a family.
#[derive(Clone, Debug)]
pub struct PopulationAnnealing<S, P> {
    /// One entry per level.
    pub levels: Vec<AnnealedLevel<S, P>>,
}

impl<S, P> PopulationAnnealing<S, P> {
    /// `ln(b_level / b_0)`: the sum of the ratio estimates up to `level`.
    pub fn log_b(&self, level: usize) -> f64 {
        self.levels[..=level].iter().map(|l| l.log_ratio).sum()
    }

    /// The relative standard error of `b_level / b_0` (the ratios' errors
    /// in quadrature).
    pub fn relative_error(&self, level: usize) -> f64 {
        self.levels[..=level]
            .iter()
            .map(|l| l.ratio_relative_error.powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

/// Anneals `initial` (exact draws of level 0, at least one) through every
/// level of `family`, with `sweeps` steps per particle and level of
/// `algorithm(level)` (one instance per chunk of particles), drawing from
/// the streams of `seed`. Fails with a clear error when every particle's
/// weight towards some level is zero.
pub fn anneal<S, F, A>(
    family: &F,
    initial: Vec<Sample<S, F::Payload>>,
    algorithm: impl Fn(usize) -> A + Sync,
    sweeps: usize,
    seed: u64,
) -> Result<PopulationAnnealing<S, F::Payload>>
where
    S: Clone + Send,
    F: ReplicaFamily<S> + Sync,
    F::Payload: Send,
    A: Algorithm<S, F::Payload>,
{
    anneal_until(family, initial, algorithm, sweeps, seed, &|| false)
}

/// [`anneal`], with the MH sweeps cut once `stop()` holds (a time budget):
/// each particle checks it before every step and makes no more once it
/// holds. The weights, resampling and ratio estimates of every level are
/// still computed (they trace nothing); a particle that made fewer steps
/// is still a draw of its level (resampled from it and moved only by
/// kernels that leave it invariant), so the estimates keep their meaning
/// and only the particles' diversity suffers. [`AnnealedLevel::steps`]
/// counts the steps made.
pub fn anneal_until<S, F, A>(
    family: &F,
    initial: Vec<Sample<S, F::Payload>>,
    algorithm: impl Fn(usize) -> A + Sync,
    sweeps: usize,
    seed: u64,
    stop: &(dyn Fn() -> bool + Sync),
) -> Result<PopulationAnnealing<S, F::Payload>>
where
    S: Clone + Send,
    F: ReplicaFamily<S> + Sync,
    F::Payload: Send,
    A: Algorithm<S, F::Payload>,
{
    let n = initial.len();
    if n == 0 {
        return Err(invalid(
            "initial",
            "population annealing needs at least one particle",
        ));
    }
    let mut levels = vec![AnnealedLevel {
        particles: initial,
        log_ratio: 0.0,
        ratio_relative_error: 0.0,
        acceptance: f64::NAN,
        steps: 0,
    }];
    for k in 1..family.levels() {
        let previous = &levels[k - 1].particles;
        // ln c_i = ln π_k(x_i) − ln π_{k−1}(x_i); NaN weighs nothing.
        // Owned chunks: the states need only be `Send`.
        let log_pi: Vec<f64> = chunks(previous.clone())
            .into_par_iter()
            .map(|xs| {
                xs.iter()
                    .map(|x| family.log_density_of(k, x))
                    .collect::<Vec<_>>()
            })
            .collect::<Vec<_>>()
            .concat();
        let log_c: Vec<f64> = log_pi
            .iter()
            .zip(previous)
            .map(|(&lp, x)| {
                let lc = lp - x.log_density;
                if lc.is_nan() { f64::NEG_INFINITY } else { lc }
            })
            .collect();
        let shift = log_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if shift.is_infinite() {
            return Err(invalid(
                "family",
                format!(
                    "population annealing: every one of the {n} particles has {} weight towards level {k}",
                    if shift == f64::INFINITY {
                        "an infinite"
                    } else {
                        "zero"
                    }
                ),
            ));
        }
        let c: Vec<f64> = log_c.iter().map(|&l| (l - shift).exp()).collect();
        let mean = c.iter().sum::<f64>() / n as f64;
        let var = c.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n as f64 - 1.0).max(1.0);
        let ratio_relative_error = (var / n as f64).sqrt() / mean;

        // Systematic resampling ∝ c.
        let mut rng = stream_rng(seed, RESAMPLE_STREAM + k as u64);
        let xi = uniform(&mut rng);
        let total = mean * n as f64;
        let mut particles = Vec::with_capacity(n);
        let (mut i, mut cumulative) = (0usize, c[0]);
        for j in 0..n {
            let u = (j as f64 + xi) / n as f64 * total;
            while cumulative < u && i + 1 < n {
                i += 1;
                cumulative += c[i];
            }
            let mut x = previous[i].clone();
            family.retarget(k, &mut x, log_pi[i]);
            particles.push(x);
        }

        // MH sweeps at level k, chunk by chunk.
        let target = LevelTarget { family, level: k };
        let moved: Vec<MovedChunk<S, F::Payload>> = chunks(particles)
            .into_par_iter()
            .enumerate()
            .map(|(chunk, xs)| {
                let mut alg = algorithm(k);
                let (mut steps, mut accepted) = (0, 0);
                let out = xs
                    .into_iter()
                    .enumerate()
                    .map(|(i, x)| {
                        let stream = (k * n + chunk * CHUNK + i) as u64;
                        let mut state = ChainState {
                            current: x,
                            rng: stream_rng(seed, stream),
                            stats: ChainStatistics::new(alg.component_names()),
                        };
                        for _ in 0..sweeps {
                            if stop() {
                                break;
                            }
                            alg.step(&mut state, &target, &mut |_| {});
                        }
                        steps += state.stats.steps;
                        accepted += state.stats.accepted;
                        state.current
                    })
                    .collect();
                (out, steps, accepted)
            })
            .collect();
        let (steps, accepted) = moved.iter().fold((0, 0), |(s, a), m| (s + m.1, a + m.2));
        levels.push(AnnealedLevel {
            particles: moved.into_iter().flat_map(|m| m.0).collect(),
            log_ratio: mean.ln() + shift,
            ratio_relative_error,
            acceptance: accepted as f64 / steps as f64,
            steps,
        });
    }
    Ok(PopulationAnnealing { levels })
}
