//! Veach's bidirectional mutation (Veach 1997 §11.4.2; Mitsuba 0.6's
//! `BidirectionalMutator`): delete a subpath, regrow it from both ends,
//! connect.
//!
//! # The move
//!
//! Indices are those of the path with two virtual end nodes added: `z_0`
//! before the emitter point, `z_j = x_{j−1}`, `z_n` after the camera, with
//! `n = k + 2` edges.
//!
//! 1. The proposal's length `n'`: fixed (`n' = n`, the variant seed 001
//!    needs) or drawn from the two-tailed geometric pmf `∝ 2^{−|n'−n|}` on
//!    `[min, max]` segments (+2).
//! 2. The number of edges deleted, `k_d`, from `∝ 2^{−|k_d−2|}` on
//!    `[max(1 or 2, n − n' + 1), n]` (at least 2 when the length is kept, so
//!    that something changes): Veach's deletion pmf, whose mass sits at
//!    one deleted vertex. `k_a = n' − n + k_d` edges are added.
//! 3. The deletion's start `l`, uniform over the valid ones: `z_l` and
//!    `z_{l+k_d}` must be keepable (a virtual node, the emitter point, or a
//!    surface vertex that does not scatter through a Dirac lobe; the camera
//!    vertex is never kept as a walk's start, so camera-side regrowth
//!    starts at the camera), and when `k_d = 1` or `k_a = 1` the virtual
//!    nodes' edges are left alone (Mitsuba's rule).
//! 4. The split: `s` of the `k_a − 1` new vertices grown from `z_l` by a
//!    light walk, `t = k_a − 1 − s` from `z_{l+k_d}` by a camera walk, `s`
//!    uniform over `[s_min, s_max]` (`t ≥ 1` when the camera is regrown:
//!    light walks never hit the camera; `s ≥ 1` when the emitter point is
//!    regrown and the scene has no area light or environment to hit), then
//!    the two walks' ends are connected (visibility tested).
//!
//! # Emitters at infinity
//!
//! `x_0` at infinity (measured in solid angle, `path_space::state`) is
//! regrown as any emitter vertex: by a light walk (the environment's
//! direction sampling, or a directional light's one direction) or by a
//! camera walk that escapes into the environment; its `pdf_fwd` and
//! `pdf_rev` are solid-angle densities, so the sum over splits stays a sum
//! of densities in one measure. Kept, it starts a light walk from its disk
//! (`pdf_fwd(x_1) = |ng_1·ω|/(πR²)`). A camera walk that escapes anywhere
//! but at `x_0` ended early ([`Invalid::WalkEnded`]).
//!
//! # Transition density
//!
//! ```text
//! T(x→y) = P(n'|n) · P(k_d|n, n') · 1/#l(x) · 1/#s · Σ_{s'} p_{s'}(y)
//! ```
//!
//! summed over every split `s'` the move could have drawn: a proposal can
//! be produced by any of them ([`Path::log_regrowth_density`]; a split whose
//! connection would touch a Dirac vertex contributes 0). The reverse move
//! deletes the `k_a` new edges of `y` from the same `l` and adds `k_d`;
//! the kernel reports `ln T(y→x) − ln T(x→y)`.
//!
//! # Invalid proposals
//!
//! A proposal that cannot be made is a failed `mcmc-core` proposal whose
//! component names the reason, so the run's per-component statistics count
//! them: no valid deletion, a walk that escaped or was absorbed, a
//! connection at a Dirac vertex, an occluded connection, a zero
//! contribution (zero BSDF, off the image, a camera walk that missed the
//! emitters).

use super::retrace::component_names;
use super::state::Path;
use super::walk::{ChainSource, camera_walk, camera_walks_reach_emitters, extend_walk, light_walk};
use crate::bsdf::TransportMode;
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::pss::PathSample;
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::math::log_sum_exp;
use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;

/// The pmf `∝ base^{−|i − center|}` on `[lo, hi]` (`hi = None`: unbounded),
/// Mitsuba's `TwoTailedGeoDistr` with base 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoTailedGeometric {
    /// Centre (the mode).
    pub center: i64,
    /// Smallest value.
    pub lo: i64,
    /// Largest value, if bounded.
    pub hi: Option<i64>,
}

impl TwoTailedGeometric {
    /// `Σ_{j=a}^{b} 2^{−j}` for `0 ≤ a`, `b ≥ a − 1` (`None`: infinite).
    fn tail(a: i64, b: Option<i64>) -> f64 {
        let upper = b.map_or(0.0, |b| 0.5f64.powi((b + 1) as i32) * 2.0);
        if b.is_some_and(|b| b < a) {
            return 0.0;
        }
        0.5f64.powi(a as i32) * 2.0 - upper
    }

    /// The normalising sum `Σ_{i=lo}^{hi} 2^{−|i−center|}` (0 when empty).
    fn total(&self) -> f64 {
        if self.hi.is_some_and(|h| h < self.lo) {
            return 0.0;
        }
        let c = self.center;
        // i ≤ c: j = c − i from max(c − hi, 0) to c − lo.
        let left = if self.lo <= c {
            let hi_left = self.hi.map_or(c, |h| h.min(c));
            Self::tail(c - hi_left, Some(c - self.lo))
        } else {
            0.0
        };
        // i > c: j = i − c from max(lo − c, 1) to hi − c.
        let right = if self.hi.is_none_or(|h| h > c) {
            Self::tail((self.lo - c).max(1), self.hi.map(|h| h - c))
        } else {
            0.0
        };
        left + right
    }

    /// `P(i)` (0 outside the support or for an empty one).
    pub fn pmf(&self, i: i64) -> f64 {
        if i < self.lo || self.hi.is_some_and(|h| i > h) {
            return 0.0;
        }
        0.5f64.powi((i - self.center).unsigned_abs() as i32) / self.total()
    }

    /// The value of `u ∈ [0, 1)` by inversion; `None` for an empty support.
    pub fn sample(&self, u: f64) -> Option<i64> {
        let total = self.total();
        if !(total > 0.0) {
            return None;
        }
        let target = u * total;
        let mut acc = 0.0;
        let mut i = self.lo;
        loop {
            acc += 0.5f64.powi((i - self.center).unsigned_abs() as i32);
            // Unbounded: the mass beyond 60 steps is below 2⁻⁶⁰ (rounding).
            let last = self.hi.is_some_and(|h| i >= h) || i > self.center.max(self.lo) + 60;
            if target < acc || last {
                return Some(i);
            }
            i += 1;
        }
    }
}

/// Why a bidirectional proposal could not be made (its component offset
/// after the mutation's own component 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invalid {
    /// No deletion range is valid for the drawn lengths.
    NoDeletion = 1,
    /// A walk escaped the scene or was absorbed before its length.
    WalkEnded = 2,
    /// The connection would end at a Dirac vertex (pattern mismatch).
    NotConnectible = 3,
    /// The connecting segment is occluded.
    Occluded = 4,
    /// The proposal carries nothing (zero BSDF, off the image, a camera
    /// walk that missed the emitters).
    ZeroContribution = 5,
    /// The proposal's own density evaluated to zero (rounding at a
    /// grazing or Dirac vertex).
    ZeroDensity = 6,
}

impl Invalid {
    /// Every reason, in component order.
    pub const ALL: [Invalid; 6] = [
        Invalid::NoDeletion,
        Invalid::WalkEnded,
        Invalid::NotConnectible,
        Invalid::Occluded,
        Invalid::ZeroContribution,
        Invalid::ZeroDensity,
    ];

    /// The reason's name in the statistics.
    pub fn name(self) -> &'static str {
        match self {
            Invalid::NoDeletion => "no valid deletion",
            Invalid::WalkEnded => "walk ended",
            Invalid::NotConnectible => "connection at a Dirac vertex",
            Invalid::Occluded => "occluded",
            Invalid::ZeroContribution => "zero contribution",
            Invalid::ZeroDensity => "zero proposal density",
        }
    }
}

/// What one bidirectional proposal did: enough to evaluate its transition
/// density both ways.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MutationRecord {
    /// Start of the deleted range (virtual-node indexing, see the module docs).
    pub l: usize,
    /// Edges deleted.
    pub deleted: usize,
    /// Edges added.
    pub added: usize,
    /// Light-walk vertices of the drawn split.
    pub s: usize,
}

impl MutationRecord {
    /// The record of the reverse move (from the proposal back).
    pub fn reverse(&self) -> MutationRecord {
        MutationRecord {
            l: self.l,
            deleted: self.added,
            added: self.deleted,
            s: 0,
        }
    }
}

/// Veach's bidirectional mutation as an `mcmc-core` kernel over
/// [`Path`]s: component 0 is the mutation, components 1–6 its failed
/// proposals by [`Invalid`] reason.
#[derive(Clone, Debug)]
pub struct Bidirectional {
    /// Shortest path in segments (≥ 1).
    pub min_segments: usize,
    /// Longest path in segments (`None`: unbounded).
    pub max_segments: Option<usize>,
    /// Keep the path's length (seed 001's variant) instead of Veach's
    /// length-changing move.
    pub fixed_length: bool,
    /// The statistics' name of component 0.
    pub name: String,
    light: Vec<Vertex>,
    camera: Vec<Vertex>,
    last: Option<MutationRecord>,
}

impl Bidirectional {
    /// The mutation on paths of `min_segments ..= max_segments` segments.
    pub fn new(min_segments: usize, max_segments: Option<usize>, fixed_length: bool) -> Self {
        Bidirectional {
            min_segments: min_segments.max(1),
            max_segments,
            fixed_length,
            name: if fixed_length {
                "bidirectional (fixed length)".into()
            } else {
                "bidirectional".into()
            },
            light: Vec::new(),
            camera: Vec::new(),
            last: None,
        }
    }

    /// The record of the last proposal that got as far as drawing its
    /// deletion (tests read it to evaluate densities).
    pub fn last_record(&self) -> Option<MutationRecord> {
        self.last
    }

    /// `P(n' | n)` over edge counts (virtual nodes included).
    fn length_pmf(&self, n: usize) -> TwoTailedGeometric {
        TwoTailedGeometric {
            center: n as i64,
            lo: self.min_segments as i64 + 2,
            hi: self.max_segments.map(|m| m as i64 + 2),
        }
    }

    /// `P(k_d | n, n')`.
    fn deletion_pmf(n: usize, n_new: usize) -> TwoTailedGeometric {
        let (n, n_new) = (n as i64, n_new as i64);
        let least = if n == n_new { 2 } else { 1 };
        TwoTailedGeometric {
            center: 2,
            lo: least.max(n - n_new + 1),
            hi: Some(n),
        }
    }

    /// `ln P(n', k_d | n)`: the length and deletion-size choices.
    fn log_size_pmf(&self, n: usize, deleted: usize, added: usize) -> f64 {
        let n_new = (n + added).saturating_sub(deleted);
        let p_len = if self.fixed_length {
            if n_new == n { 1.0 } else { 0.0 }
        } else {
            self.length_pmf(n).pmf(n_new as i64)
        };
        (p_len * Self::deletion_pmf(n, n_new).pmf(deleted as i64)).ln()
    }

    /// `ln` of the probability that a proposal from `from` draws the
    /// discrete choices of `record` (length, deletion size, start, split):
    /// `P(n'|n) · P(k_d|n, n') · 1/#l · 1/#s`; `−∞` when it cannot.
    pub fn log_record_probability(&self, from: &Path, record: &MutationRecord) -> f64 {
        let n = from.segments() + 2;
        let MutationRecord {
            l,
            deleted,
            added,
            s,
        } = *record;
        if from.len() < 2 || added == 0 {
            return f64::NEG_INFINITY;
        }
        let starts = deletion_starts(from, deleted, added);
        if !starts.clone().any(|start| start == l) {
            return f64::NEG_INFINITY;
        }
        let Some((s_lo, s_hi)) = split_range(from, l, l + deleted, added) else {
            return f64::NEG_INFINITY;
        };
        if !(s_lo..=s_hi).contains(&s) {
            return f64::NEG_INFINITY;
        }
        self.log_size_pmf(n, deleted, added)
            - (starts.count() as f64).ln()
            - ((s_hi - s_lo + 1) as f64).ln()
    }

    /// `ln T(from → to)` for the move `record` (its `s` is ignored: every
    /// split is summed), `−∞` when the move cannot produce `to`.
    pub fn log_transition_density(&self, from: &Path, to: &Path, record: &MutationRecord) -> f64 {
        let MutationRecord {
            l, deleted, added, ..
        } = *record;
        if from.len() < 2 || to.len() + deleted != from.len() + added || added == 0 {
            return f64::NEG_INFINITY;
        }
        let Some((s_lo, s_hi)) = split_range(from, l, l + deleted, added) else {
            return f64::NEG_INFINITY;
        };
        let choice = self.log_record_probability(from, &MutationRecord { s: s_lo, ..*record });
        if choice == f64::NEG_INFINITY {
            return choice;
        }
        // New vertices of `to`: z_{l+1} … z_{l+added−1} = x'_l … x'_{l+added−2}
        // (none when `added = 1`, which needs `l ≥ 1`).
        let Some(last) = (l + added).checked_sub(2) else {
            return f64::NEG_INFINITY;
        };
        let terms: Vec<f64> = (s_lo..=s_hi)
            .map(|s| to.log_regrowth_density(l, last, s))
            .collect();
        choice + log_sum_exp(&terms)
    }

    /// Draws a proposal into `y`; `Err` names why it failed.
    fn mutate<'s>(
        &mut self,
        x: &Path<'s>,
        y: &mut Path<'s>,
        rng: &mut ChainRng,
    ) -> Result<(), Invalid> {
        self.last = None;
        let k = x.segments();
        if x.len() < 2 {
            return Err(Invalid::NoDeletion);
        }
        let n = k + 2;
        let n_new = if self.fixed_length {
            n
        } else {
            self.length_pmf(n)
                .sample(uniform(rng))
                .ok_or(Invalid::NoDeletion)? as usize
        };
        let deleted = Self::deletion_pmf(n, n_new)
            .sample(uniform(rng))
            .ok_or(Invalid::NoDeletion)? as usize;
        let added = n_new + deleted - n;
        let mut starts = deletion_starts(x, deleted, added);
        let count = starts.clone().count();
        if count == 0 {
            return Err(Invalid::NoDeletion);
        }
        let l = (starts.nth(((uniform(rng) * count as f64) as usize).min(count - 1)))
            .expect("index below the count");
        let m = l + deleted;
        let (s_lo, s_hi) = split_range(x, l, m, added).ok_or(Invalid::NoDeletion)?;
        let s = s_lo + ((uniform(rng) * (s_hi - s_lo + 1) as f64) as usize).min(s_hi - s_lo);
        let t = added - 1 - s;
        self.last = Some(MutationRecord {
            l,
            deleted,
            added,
            s,
        });
        let scene = x.scene;
        let mut source = ChainSource::new(rng);
        // Light side: kept x_0 … x_{l−1}, then s new vertices.
        if s > 0 {
            let made = if l == 0 {
                light_walk(scene, &mut source, s, &mut self.light)
            } else {
                let behind = (l >= 2).then(|| &x.vertices[l - 2]);
                extend_walk(
                    scene,
                    &x.vertices[l - 1],
                    behind,
                    s,
                    TransportMode::Importance,
                    &mut source,
                    &mut self.light,
                ) + 1
            };
            if made != s + usize::from(l > 0) {
                return Err(Invalid::WalkEnded);
            }
        } else {
            self.light.clear();
        }
        // Camera side: t new vertices, then kept x_{m−1} … x_k.
        if t > 0 {
            let made = if m == n {
                camera_walk(scene, &mut source, t, &mut self.camera)
            } else {
                extend_walk(
                    scene,
                    &x.vertices[m - 1],
                    Some(&x.vertices[m]),
                    t,
                    TransportMode::Radiance,
                    &mut source,
                    &mut self.camera,
                ) + 1
            };
            if made != t + usize::from(m < n) {
                return Err(Invalid::WalkEnded);
            }
        } else {
            self.camera.clear();
        }
        let vs = &mut y.vertices;
        vs.clear();
        if s > 0 && l > 0 {
            vs.extend_from_slice(&x.vertices[..l - 1]);
            vs.extend_from_slice(&self.light);
        } else {
            vs.extend_from_slice(&x.vertices[..l]);
            vs.extend_from_slice(&self.light);
        }
        vs.extend(self.camera.iter().rev());
        if t > 0 && m < n {
            vs.extend_from_slice(&x.vertices[m..]);
        } else {
            vs.extend_from_slice(&x.vertices[m - 1..]);
        }
        // A camera walk that escaped into the environment ends at infinity:
        // a path's x_0 (l = s = 0), a walk that ended anywhere else.
        if vs[1..].iter().any(|v| v.kind == VertexKind::Infinite) {
            return Err(Invalid::WalkEnded);
        }
        y.normalize_ends();
        y.evaluate();
        // The connection joins y_{l+s−1} and y_{l+s}; with l + s = 0 the
        // camera walk itself reached the emitter.
        let join = l + s;
        if join == 0 {
            if !matches!(y.vertices[0].kind, VertexKind::Light | VertexKind::Infinite) {
                return Err(Invalid::ZeroContribution);
            }
        } else {
            if !(y.connectible(join - 1) && y.connectible(join)) {
                return Err(Invalid::NotConnectible);
            }
            if !y.edge_visible(join - 1) {
                return Err(Invalid::Occluded);
            }
        }
        if y.contribution.is_black() {
            return Err(Invalid::ZeroContribution);
        }
        Ok(())
    }
}

/// True when virtual-node vertex `z_j` of `x` may stay as a regrowth's
/// start: a virtual node, the emitter point (at infinity too: a light walk
/// continues from its disk), or a surface vertex that does not scatter
/// through a Dirac lobe.
fn keepable(x: &Path, j: usize) -> bool {
    let n = x.segments() + 2;
    if j == 0 || j == n {
        return true;
    }
    let v = &x.vertices[j - 1];
    match v.kind {
        VertexKind::Light | VertexKind::Infinite => true,
        VertexKind::Surface => !v.delta,
        VertexKind::Camera => false,
    }
}

/// The valid starts `l` of a deletion of `deleted` edges followed by
/// `added` new ones, in increasing order (an iterator, not a vector: each
/// proposal walks them three times, and allocating them each time was a
/// measurable share of a step).
fn deletion_starts(x: &Path, deleted: usize, added: usize) -> impl Iterator<Item = usize> + Clone {
    let n = x.segments() + 2;
    let (mut lo, mut hi) = (0i64, n as i64 - deleted as i64);
    if deleted == 0 || deleted > n {
        // Empty.
        (lo, hi) = (1, 0);
    }
    if deleted == 1 || added == 1 {
        lo += 1;
        hi -= 1;
    }
    (lo..=hi)
        .map(|l| l as usize)
        .filter(move |&l| keepable(x, l) && keepable(x, l + deleted))
}

/// The splits `s ∈ [s_lo, s_hi]` a regrowth of `added` edges between
/// `z_l` and `z_m` draws from, `None` when there is none.
fn split_range(x: &Path, l: usize, m: usize, added: usize) -> Option<(usize, usize)> {
    let n = x.segments() + 2;
    let mut hi = added.checked_sub(1)?;
    if m == n {
        // The camera is regrown by the camera walk (t ≥ 1).
        hi = hi.checked_sub(1)?;
    }
    let lo = usize::from(l == 0 && !camera_walks_reach_emitters(x.scene));
    (lo <= hi).then_some((lo, hi))
}

impl<'s> Kernel<Path<'s>, PathSample> for Bidirectional {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let y = &mut proposal.state;
        if let Err(reason) = self.mutate(x, y, rng) {
            return Proposal::failed(reason as usize);
        }
        let record = self.last.expect("a successful proposal has a record");
        let forward = self.log_transition_density(x, y, &record);
        if !(forward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::ZeroDensity as usize);
        }
        let backward = self.log_transition_density(y, x, &record.reverse());
        Proposal::with_ratio(backward - forward, 0)
    }

    fn component_names(&self) -> Vec<String> {
        component_names(&self.name, Invalid::ALL.iter().map(|r| r.name()))
    }
}
