//! A start-up in which every technique of a draw's two walks counts (the
//! `bdpt_startup` setting of `mlt`/`mept`), as BDPT's estimator counts
//! them.
//!
//! # Why
//!
//! The driver's ordinary start-up draws one path per candidate: a length
//! `k`, one split `s` of its `#s` techniques, and the weight
//! `I(x) / (P(k)/#s · Σ_s p_s(x))`. A path that only one technique can
//! produce (an `L S D S E` caustic seen through glass: only the camera walk
//! that hits the lamp) is then drawn by one candidate in `#s/P(k)` (56 on
//! caustic-sds, `max_depth` 8) and carries that factor in its weight: the
//! estimate of `b` and the share of chains started on such paths are
//! heavy-tailed (session 10: seed 2 of caustic-sds drew `b` = 0.32 ± 0.18
//! against ≈ 0.16).
//!
//! # What
//!
//! A draw `j` traces one camera walk of `max + 1` vertices and one light
//! walk of `max` vertices (stream `CANDIDATE_STREAM + SEARCH_INDEX + j`)
//! and forms the path of every split `(s, t)` with `s + t − 1 = k` in
//! `min..=max` that the walks reach, joined as a start-up candidate is
//! joined (a connection at two connectible vertices, visible). Path `x`
//! of split `s` weighs `w = I(x) / Σ_{s'} p_{s'}(x)` (the balance
//! heuristic over the same techniques as the ordinary start-up's
//! reference density, so `w = e^{candidate weight} · P(k)/#s`); for each
//! `k`, `Σ_s w` is BDPT's unbiased estimate of `∫_{P_k} I dμ`, and the
//! draw's total over `k` is an unbiased estimate of `b`. The driver's
//! running estimate takes the mean of the draws' totals
//! ([`Search::per_draw`]); the chains start from paths resampled over all
//! techniques of all draws in proportion to `w`. The search replaces the
//! driver's bootstrap ([`Search::replaces_bootstrap`]).
//!
//! It needs a bounded depth of at most [`MAX_SEARCH_SEGMENTS`] segments
//! (the split is packed into the candidate index); with an unbounded depth
//! `mlt` keeps the ordinary start-up.

use super::family::PathFamily;
use super::state::Path;
use super::walk::{ChainSource, camera_walk, light_walk};
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::markov::{CANDIDATE_STREAM, Search, StartupCut, draw_in_rounds};
use mcmc_core::rng::stream_rng;
use rayon::prelude::*;

/// Candidate indices from here on are the search's paths: `SEARCH_INDEX +
/// (j << 12) + (s << 6) + t` for split `(s, t)` of draw `j`.
pub const SEARCH_INDEX: u64 = 1 << 39;

/// Longest path the search handles (`s` and `t` take 6 bits each).
pub const MAX_SEARCH_SEGMENTS: usize = 62;

/// One draw of the search: its splits' `(index, ln w)`, `ln` of its total
/// and its image splats `(x, y, r, g, b)`.
pub(super) type SearchDraw = (Vec<(u64, f64)>, f64, Vec<[f32; 5]>);

/// The index of split `(s, t)` of draw `j`.
fn index(j: u64, s: usize, t: usize) -> u64 {
    SEARCH_INDEX + (j << 12) + ((s as u64) << 6) + t as u64
}

/// The two walks of draw `j`: the camera walk of `max + 1` vertices, then
/// the light walk of `max` vertices, from the draw's own stream. Without
/// `light_walk` (member 1's draws, which use only the camera walk), the
/// light walk is empty: the camera walk is the same either way.
fn walks(
    family: &PathFamily<'_>,
    (seed, j): (u64, u64),
    max: usize,
    with_light_walk: bool,
) -> (Vec<Vertex>, Vec<Vertex>) {
    let mut rng = stream_rng(seed, CANDIDATE_STREAM + SEARCH_INDEX + j);
    let mut source = ChainSource::new(&mut rng);
    let (mut light, mut camera) = (Vec::new(), Vec::new());
    camera_walk(family.scene, &mut source, max + 1, &mut camera);
    if with_light_walk {
        light_walk(family.scene, &mut source, max, &mut light);
    }
    (light, camera)
}

/// The first `n` vertices of a walk, its last one (a connection end)
/// marked as not scattering through a Dirac lobe: in the walk it may have
/// gone on through one, but the path ends there or connects through the
/// BSDF's other part ([`Path::connectible`] refuses a purely Dirac BSDF).
fn prefix(walk: &[Vertex], n: usize) -> Vec<Vertex> {
    let mut v = walk[..n].to_vec();
    if let Some(last) = v.last_mut()
        && last.kind == VertexKind::Surface
    {
        last.delta = false;
    }
    v
}

impl<'s> PathFamily<'s> {
    /// The path of split `(s, t)` from the given walks, joined as a
    /// start-up candidate is joined; `None` beyond the walks and for a
    /// split that cannot carry light (a camera walk that did not end on
    /// an emitter, a connection at a Dirac vertex or occluded), decided
    /// before the path is evaluated (most of a draw's splits; evaluation
    /// is the search's main cost).
    fn live_split_path(
        &self,
        light: &[Vertex],
        camera: &[Vertex],
        s: usize,
        t: usize,
    ) -> Option<Path<'s>> {
        if s > light.len() || t > camera.len() || t == 0 {
            return None;
        }
        if s == 0 && !camera[t - 1].is_light() {
            return None;
        }
        let mut path = Path::new(self.scene);
        path.vertices.extend(prefix(light, s));
        path.vertices.extend(prefix(camera, t).into_iter().rev());
        path.normalize_ends();
        if s > 0 && !(path.connectible(s - 1) && path.connectible(s) && path.edge_visible(s - 1)) {
            return None;
        }
        path.evaluate();
        Some(path)
    }

    /// The search's path of candidate `index` (≥ [`SEARCH_INDEX`]).
    pub(crate) fn search_candidate(&self, seed: u64, index: u64) -> Path<'s> {
        let i = index - SEARCH_INDEX;
        let (j, s, t) = (i >> 12, ((i >> 6) & 63) as usize, (i & 63) as usize);
        let max = self.max_segments.unwrap_or(0);
        let (light, camera) = walks(self, (seed, j), max, s > 0);
        self.live_split_path(&light, &camera, s, t)
            .unwrap_or_else(|| Path::new(self.scene))
    }

    /// `ln w` of every split of draw `j` that carries light under member
    /// `member`'s target, `ln` of the draw's total (−∞ for none; NaN
    /// weights count as zero, as the running normalisation counts them),
    /// and the splits' image splats `f(x)/Σ_s p_s(x)`
    /// ([`Search::image_splats`]). Member 1's paths (the unconnectable
    /// ones, [`PathFamily::with_unconnectable_chains`]) are drawn by the
    /// camera walk alone, `s = 0`.
    pub(super) fn search_draw(
        &self,
        member: usize,
        (seed, j): (u64, u64),
        max: usize,
    ) -> SearchDraw {
        let (light, camera) = walks(self, (seed, j), max, member != 1);
        let mut weighted = Vec::new();
        let mut splats = Vec::new();
        for k in self.min_segments..=max {
            let last_s = if member == 1 { self.s_min() } else { k };
            for s in self.s_min()..=last_s {
                let t = k + 1 - s;
                let Some(path) = self.live_split_path(&light, &camera, s, t) else {
                    continue;
                };
                let log_i = self.target_log_density(member, &path);
                if !log_i.is_finite() {
                    // Zero, or NaN: counted as zero, as the running
                    // normalisation counts it.
                    continue;
                }
                let log_sum = self.log_technique_sum(&path);
                let log_w = log_i - log_sum;
                if log_w.is_finite() {
                    weighted.push((index(j, s, t), log_w));
                    let l = path.contribution * (-log_sum).exp() as f32;
                    if l.is_finite() {
                        splats.push([path.raster.x, path.raster.y, l.r, l.g, l.b]);
                    }
                }
            }
        }
        let terms: Vec<f64> = weighted.iter().map(|w| w.1).collect();
        let total = if terms.is_empty() {
            f64::NEG_INFINITY
        } else {
            mcmc_core::math::log_sum_exp(&terms)
        };
        (weighted, total, splats)
    }

    /// Member `member`'s search of `draws` BDPT draws (module docs), or
    /// `None` when the depth is unbounded or longer than
    /// [`MAX_SEARCH_SEGMENTS`]. It
    /// stops short at the start-up's `cut` once some draw carried light
    /// (`draw_in_rounds`); its `draws` are then those made (a prefix:
    /// each depends on its index alone, so uncut it is the whole search).
    pub fn bdpt_search(
        &self,
        member: usize,
        seed: u64,
        draws: u64,
        cut: &StartupCut,
    ) -> Option<Search> {
        let max = self.max_segments.filter(|&m| m <= MAX_SEARCH_SEGMENTS)?;
        let mut search = Search {
            replaces_bootstrap: true,
            ..Search::default()
        };
        let lit = |s: &Search| !s.per_draw.is_empty();
        let made = draw_in_rounds(&mut search, draws as usize, cut, lit, |range, search| {
            let per: Vec<SearchDraw> = range
                .into_par_iter()
                .map(|j| self.search_draw(member, (seed, j as u64), max))
                .collect();
            for (weighted, total, splats) in per {
                if total.is_finite() {
                    search.per_draw.push(total);
                }
                search.weighted.extend(weighted);
                search.image_splats.extend(splats);
            }
        });
        search.draws = made as u64;
        Some(search)
    }
}
