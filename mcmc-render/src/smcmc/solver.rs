//! Tile alignment (spec seed003 §8.4, Eq. 3.38): the normalisations `b_s`
//! of all tiles from their unscaled histograms `G_s(j)` (luminance) and an
//! independent per-pixel estimate `Ĩ(j)` from the large steps, so that
//! neighbouring tiles agree on the pixels they share (`b_s G_s(j) ≈
//! b_t G_t(j)`) and each tile stays attached to `Ĩ` with weight `α`.
//!
//! The sweeps are the \[EXT\] Jacobi-type update of Gruson's reference code
//! (spec §8.4) with unit pair weights (its 20 outer L1 reweighting passes
//! are not done): with `v_s = G_s(j)` at a pixel `j` that tile `s` shares
//! with tile `t`, `Ḡ_s`, `Ĩ̄_s` the means of `G_s` and `Ĩ` over the pixels
//! of tile `s` where `G_s > 0`,
//!
//! ```text
//! b_s ← b_s − [Σ_pairs ½(v_s b_s − v_t b_t) + α(b_s Ḡ_s − Ĩ̄_s)] / [Σ_pairs v_s + α Ḡ_s]
//! ```
//!
//! Its fixed point solves `Σ_pairs ½(v_s b_s − v_t b_t) + α(b_s Ḡ_s − Ĩ̄_s) = 0`
//! for every tile: equations *linear* in the noisy `G`, whose expectation
//! vanishes at the true `b` (`E[b_s G_s(j)] = I(j)`), so noise in the
//! histograms does not bias the solution. The least-squares normal
//! equations of Eq. 3.38 as literally written weight each difference by
//! `G_s(j)` once more, and `E[G²] > E[G]²` makes them shrink every `b_s`:
//! measured on the 16×16 Cornell box after 256 iterations, 200 sweeps of
//! them darkened the image by 11% (and more with more sweeps), while this
//! update leaves the mean where `b⁰` put it. The update is a damped Jacobi
//! step of an M-matrix-like system (diagonal `½Σ v_s + αḠ_s`, damping
//! between ½ and 1); its slowest modes (image-wide brightness) contract by
//! about `α/(Σ v + α)` per sweep, so with 200 sweeps they stay where `b⁰`
//! (the large-step estimate) put them, and the sweeps remove the seams
//! between neighbouring tiles (the thesis's Fig. 3.9).

use super::tile::Tiling;
use rayon::prelude::*;

/// Tiles from which a Jacobi sweep runs on the thread pool.
const PARALLEL_SWEEP_TILES: usize = 4096;

/// The result of an alignment of `N` lanes (one per colour channel, or
/// one for luminance).
#[derive(Clone, Debug, PartialEq)]
pub struct Alignment<const N: usize = 1> {
    /// `b_s` per tile and lane (`b⁰_s` for inactive tiles).
    pub b: Vec<[f64; N]>,
    /// Per lane, `‖r(b⁰)‖/‖c‖` with `r` the residuals of the tiles'
    /// equations and `c` their constant part (0 for an empty system).
    pub initial_residual: [f64; N],
    /// Per lane, `‖r(b)‖/‖c‖` after the sweeps.
    pub residual: [f64; N],
    /// Sweeps run.
    pub iterations: usize,
}

impl<const N: usize> Alignment<N> {
    /// `b_s` of lane `lane`, per tile.
    pub fn lane(&self, lane: usize) -> Vec<f64> {
        self.b.iter().map(|b| b[lane]).collect()
    }

    /// The lane furthest from converged (the largest final residual).
    pub fn worst_lane(&self) -> usize {
        (0..N)
            .max_by(|&x, &y| self.residual[x].total_cmp(&self.residual[y]))
            .expect("an alignment has one lane at least")
    }
}

/// The alignment problem of one image, for `N` independent lanes that
/// share the tiling (the colour channels): each lane is the problem of the
/// module's comment on its own, and one sweep updates all lanes in one
/// pass over the tiles' neighbourhoods, which costs little more than one
/// lane's.
pub struct AlignmentProblem<'a, const N: usize = 1> {
    /// The tiles.
    pub tiling: &'a Tiling,
    /// `G_s` per tile and slot (`tiles × slots`, row-major), per lane.
    pub g: &'a [[f64; N]],
    /// Whether each tile takes part (initialised, with samples).
    pub active: &'a [bool],
    /// `Ĩ(j)` per pixel and lane.
    pub i_tilde: &'a [[f64; N]],
    /// Weight `α` of the attachment to `Ĩ`.
    pub alpha: f64,
}

/// Per lane, the residual of a tile's equation, its step's denominator
/// and the equation's constant part.
struct Terms<const N: usize> {
    residual: [f64; N],
    denominator: [f64; N],
    constant: [f64; N],
}

impl<const N: usize> AlignmentProblem<'_, N> {
    /// Residual `r_s` of tile `s`'s equation, its step's denominator and
    /// the constant part `α Ĩ̄_s`, per lane. (Each lane's arithmetic is in
    /// the order of a one-lane problem: the same bits as solving the lanes
    /// one by one.)
    fn terms(&self, s: usize, b: &[[f64; N]]) -> Terms<N> {
        let slots = self.tiling.slots();
        let (mut pairs, mut den) = ([0.0; N], [0.0; N]);
        let (mut g_sum, mut i_sum, mut count) = ([0.0; N], [0.0; N], [0.0; N]);
        for (k, j) in self.tiling.pixels(s) {
            let g = self.g[s * slots + k];
            for c in 0..N {
                if g[c] > 0.0 {
                    g_sum[c] += g[c];
                    i_sum[c] += self.i_tilde[j][c];
                    count[c] += 1.0;
                }
            }
            for (t, kt) in self.tiling.covering(j) {
                if t != s && self.active[t] {
                    let g_t = self.g[t * slots + kt];
                    for c in 0..N {
                        pairs[c] += 0.5 * (g[c] * b[s][c] - g_t[c] * b[t][c]);
                        den[c] += g[c];
                    }
                }
            }
        }
        let mut terms = Terms {
            residual: [0.0; N],
            denominator: [0.0; N],
            constant: [0.0; N],
        };
        for c in 0..N {
            if count[c] > 0.0 {
                let (g_mean, i_mean) = (g_sum[c] / count[c], i_sum[c] / count[c]);
                terms.residual[c] = pairs[c] + self.alpha * (b[s][c] * g_mean - i_mean);
                terms.denominator[c] = den[c] + self.alpha * g_mean;
                terms.constant[c] = self.alpha * i_mean;
            }
        }
        terms
    }

    /// Per lane, `‖r(b)‖/‖c‖`, with `c_s = α Ĩ̄_s` the part of the
    /// equations that does not depend on `b`.
    fn residual(&self, b: &[[f64; N]]) -> [f64; N] {
        // Terms in parallel, summed in tile order (the same bits on any
        // thread count).
        let terms: Vec<([f64; N], [f64; N])> = (0..self.tiling.tiles())
            .into_par_iter()
            .map(|s| {
                if self.active[s] {
                    let t = self.terms(s, b);
                    (t.residual.map(|r| r * r), t.constant.map(|c| c * c))
                } else {
                    ([0.0; N], [0.0; N])
                }
            })
            .collect();
        let (mut r2, mut c2) = ([0.0; N], [0.0; N]);
        for (r, c) in terms {
            for l in 0..N {
                r2[l] += r[l];
                c2[l] += c[l];
            }
        }
        std::array::from_fn(|l| {
            if c2[l] > 0.0 {
                (r2[l] / c2[l]).sqrt()
            } else {
                0.0
            }
        })
    }

    /// One Jacobi sweep: `next` from `b`. On the thread pool only for
    /// films with many tiles: below [`PARALLEL_SWEEP_TILES`] handing a
    /// sweep to the pool costs more than the sweep (40 000 sweeps of 108
    /// tiles took 14 s, 5 s of it user CPU, in parallel). Each update
    /// reads only `b`, so both ways give the same bits.
    fn sweep(&self, b: &[[f64; N]], next: &mut [[f64; N]]) {
        let update = |(s, next): (usize, &mut [f64; N])| {
            *next = b[s];
            if self.active[s] {
                let t = self.terms(s, b);
                for (lane, (r, den)) in next.iter_mut().zip(t.residual.iter().zip(t.denominator)) {
                    // A tile whose histogram is black keeps b⁰.
                    if den > 0.0 {
                        *lane -= r / den;
                    }
                }
            }
        };
        if next.len() >= PARALLEL_SWEEP_TILES {
            next.par_iter_mut()
                .enumerate()
                .with_min_len(PARALLEL_SWEEP_TILES / 4)
                .for_each(update);
        } else {
            next.iter_mut().enumerate().for_each(update);
        }
    }

    /// `iterations` Jacobi sweeps from `b0` (every update reads only the
    /// previous sweep, so the result does not depend on the thread count).
    pub fn solve(&self, b0: &[[f64; N]], iterations: usize) -> Alignment<N> {
        self.solve_while(b0, iterations, &|_| true)
    }

    /// [`solve`](Self::solve), stopping before the first sweep `i` (from
    /// 0) for which `more(i)` is false: a run's deadline cuts the sweeps
    /// short ([`Alignment::iterations`] counts those run).
    pub fn solve_while(
        &self,
        b0: &[[f64; N]],
        iterations: usize,
        more: &dyn Fn(usize) -> bool,
    ) -> Alignment<N> {
        let initial_residual = self.residual(b0);
        let mut b = b0.to_vec();
        let mut next = b.clone();
        let mut done = 0;
        while done < iterations && more(done) {
            self.sweep(&b, &mut next);
            std::mem::swap(&mut b, &mut next);
            done += 1;
        }
        Alignment {
            initial_residual,
            residual: self.residual(&b),
            b,
            iterations: done,
        }
    }
}
