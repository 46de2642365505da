//! The SD-tree: a binary k-d tree over a cube around the scene whose
//! leaves each hold two directional quadtrees, one to sample from and one
//! to record into (Müller, Gross, Novák 2017).

use super::quadtree::{self, QuadTree};
use super::{direction_to_square, square_to_direction};
use glam::Vec3;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Deepest level of the spatial tree: 16 halvings per axis (a leaf is then
/// 2⁻¹⁶ of the cube's edge), far below any sample-count threshold.
pub const MAX_SPATIAL_DEPTH: u32 = 48;

/// A node of the spatial tree: the index of its first child (0: a leaf;
/// the two children are consecutive, lower half first) and, for a leaf,
/// its index into the leaves.
#[derive(Clone, Copy, Debug)]
struct SpatialNode {
    first_child: u32,
    leaf: u32,
}

/// What a spatial leaf holds.
#[derive(Clone, Debug)]
struct Leaf {
    /// Read-only during an iteration; what [`SdTree::sample`] draws from.
    sampling: QuadTree,
    /// Receives this iteration's records.
    building: QuadTree,
    /// Records received (the statistical weight that drives spatial splits).
    samples: u64,
}

/// A spatial leaf, as returned by [`SdTree::leaf_at`]: valid until the
/// next [`SdTree::end_iteration`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct LeafId(u32);

/// One recorded radiance sample: the spatial leaf, the direction on the
/// unit square and the value added to the building quadtree.
#[derive(Clone, Copy, Debug)]
struct Record {
    leaf: u32,
    p: (f32, f32),
    value: f32,
}

/// Records gathered by one work unit, merged into the tree by
/// [`SdTree::merge`] in the order the units are given (which makes the
/// tree independent of the thread count).
#[derive(Clone, Debug, Default)]
pub struct RecordBuffer {
    records: Vec<Record>,
}

impl RecordBuffer {
    /// Records `value` (an estimate of the incident radiance in direction
    /// `dir` divided by the density with which `dir` was sampled, so that
    /// the sums over a quadtree node estimate the flux through it) in
    /// `leaf`. Non-finite and negative values count as a sample with no
    /// energy.
    pub fn push(&mut self, leaf: LeafId, dir: Vec3, value: f32) {
        let value = if value.is_finite() && value > 0.0 {
            value
        } else {
            0.0
        };
        self.records.push(Record {
            leaf: leaf.0,
            p: direction_to_square(dir),
            value,
        });
    }

    /// Number of records.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// True when nothing was recorded.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Forgets every record (keeping the allocation).
    pub fn clear(&mut self) {
        self.records.clear();
    }

    /// Appends the records to `out` as numbers (four per record, exact:
    /// the leaf, the direction's square coordinates and the value), for
    /// sending them to other processes.
    pub fn to_f64s(&self, out: &mut Vec<f64>) {
        for r in &self.records {
            out.extend([f64::from(r.leaf), f64::from(r.p.0), f64::from(r.p.1)]);
            out.push(f64::from(r.value));
        }
    }

    /// The buffer of `n` records [`RecordBuffer::to_f64s`] wrote at the
    /// front of `input` (advanced past them); `None` when too short.
    pub fn from_f64s(input: &mut &[f64], n: usize) -> Option<RecordBuffer> {
        let (head, rest) = input.split_at_checked(4 * n)?;
        *input = rest;
        let records = head
            .chunks_exact(4)
            .map(|r| Record {
                leaf: r[0] as u32,
                p: (r[1] as f32, r[2] as f32),
                value: r[3] as f32,
            })
            .collect();
        Some(RecordBuffer { records })
    }
}

/// Sizes of an SD-tree, for statistics.
/// Fixed-point scale of [`ExactRecords`]: a record is rounded to a
/// multiple of 2⁻⁴⁰ (about 1e−12, far below any flux that matters).
const EXACT_SCALE: f64 = (1u64 << 40) as f64;
/// Largest record value [`ExactRecords`] keeps (2⁶⁴; larger values are
/// clamped, so that a sum of 2²⁴ of them still fits in 128 bits).
const EXACT_MAX: f64 = 18_446_744_073_709_551_616.0;

/// Records summed per building quadtree leaf in fixed point, for
/// recorders that cannot fix the order of their records (the chains of
/// `mcmc-pg`'s online variant, spread over threads by the scheduler):
/// integer sums are exact, so merging them ([`SdTree::merge_exact`])
/// gives the same tree in any order, and memory is bounded by the tree's
/// leaves rather than by the number of records.
#[derive(Clone, Debug, Default)]
pub struct ExactRecords {
    /// Records per spatial leaf (all of them, zero-valued included).
    samples: Vec<u64>,
    /// Fixed-point energy per (spatial leaf, building quadtree node).
    energy: std::collections::HashMap<(u32, u32), u128>,
}

impl ExactRecords {
    /// Records accumulated so far.
    pub fn len(&self) -> u64 {
        self.samples.iter().sum()
    }

    /// Whether nothing was accumulated.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Appends the sums to `out` as words (exact), for sending them to
    /// other processes: the per-leaf counts after their number, then each
    /// energy entry (leaf, node, low and high word) after theirs.
    pub fn to_words(&self, out: &mut Vec<u64>) {
        out.push(self.samples.len() as u64);
        out.extend(&self.samples);
        out.push(self.energy.len() as u64);
        for (&(leaf, node), &e) in &self.energy {
            out.extend([u64::from(leaf), u64::from(node), e as u64, (e >> 64) as u64]);
        }
    }

    /// The sums [`ExactRecords::to_words`] wrote at the front of `input`
    /// (advanced past them); `None` when the words are not such sums.
    pub fn from_words(input: &mut &[u64]) -> Option<ExactRecords> {
        let (&n, rest) = input.split_first()?;
        let (samples, rest) = rest.split_at_checked(usize::try_from(n).ok()?)?;
        let (&m, rest) = rest.split_first()?;
        let (entries, rest) = rest.split_at_checked(usize::try_from(m).ok()?.checked_mul(4)?)?;
        *input = rest;
        let energy = entries
            .chunks_exact(4)
            .map(|e| {
                let key = (u32::try_from(e[0]).ok()?, u32::try_from(e[1]).ok()?);
                Some((key, u128::from(e[2]) | (u128::from(e[3]) << 64)))
            })
            .collect::<Option<_>>()?;
        Some(ExactRecords {
            samples: samples.to_vec(),
            energy,
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct TreeSize {
    /// Nodes of the spatial tree (interior and leaves).
    pub spatial_nodes: usize,
    /// Spatial leaves (each with two quadtrees).
    pub spatial_leaves: usize,
    /// Nodes of the sampling quadtrees, all leaves together.
    pub sampling_nodes: usize,
    /// Nodes of the building quadtrees, all leaves together.
    pub building_nodes: usize,
    /// Deepest sampling quadtree.
    pub max_quadtree_depth: u32,
    /// Bytes held by the node arrays of both trees.
    pub bytes: usize,
}

/// The spatio-directional tree (see the module documentation and
/// `docs/guiding.md`).
///
/// Use: [`SdTree::leaf_at`] a point, then [`SdTree::sample`] or
/// [`SdTree::pdf`] a direction there from the sampling quadtrees (read
/// only); record into a [`RecordBuffer`] per work unit, [`SdTree::merge`]
/// the buffers, and [`SdTree::end_iteration`] to make what was recorded the
/// new sampling distribution.
#[derive(Clone, Debug)]
pub struct SdTree {
    /// Lower corner of the cube.
    origin: Vec3,
    /// Edge of the cube.
    edge: f32,
    nodes: Vec<SpatialNode>,
    leaves: Vec<Leaf>,
}

impl SdTree {
    /// A tree over the cube that contains the box `(lo, hi)` (its longest
    /// edge, centred, grown by 1% so that no point lies on its faces), split
    /// into a full binary tree of `initial_depth` levels (axes x, y, z in
    /// turn), every leaf with empty quadtrees (sampling from it is
    /// uniform and [`SdTree::is_trained`] is false).
    pub fn new((lo, hi): (Vec3, Vec3), initial_depth: u32) -> SdTree {
        let extent = (hi - lo).max_element().max(1e-3) * 1.01;
        let center = (lo + hi) * 0.5;
        let mut tree = SdTree {
            origin: center - Vec3::splat(extent * 0.5),
            edge: extent,
            nodes: vec![SpatialNode {
                first_child: 0,
                leaf: 0,
            }],
            leaves: vec![Leaf {
                sampling: QuadTree::default(),
                building: QuadTree::default(),
                samples: 0,
            }],
        };
        let depth = initial_depth.min(MAX_SPATIAL_DEPTH);
        let mut stack = vec![(0usize, 0u32)];
        while let Some((n, d)) = stack.pop() {
            if d < depth {
                let first = tree.split(n);
                stack.push((first, d + 1));
                stack.push((first + 1, d + 1));
            }
        }
        tree
    }

    /// Splits the leaf node `n` in two: the first child keeps its leaf, the
    /// second gets a copy; each gets half its sample count. Returns the
    /// index of the first child.
    fn split(&mut self, n: usize) -> usize {
        let leaf = self.nodes[n].leaf as usize;
        self.leaves[leaf].samples /= 2;
        let copy = self.leaves[leaf].clone();
        let first = self.nodes.len();
        self.nodes.push(SpatialNode {
            first_child: 0,
            leaf: leaf as u32,
        });
        self.nodes.push(SpatialNode {
            first_child: 0,
            leaf: self.leaves.len() as u32,
        });
        self.leaves.push(copy);
        self.nodes[n].first_child = first as u32;
        first
    }

    /// The spatial leaf containing `p` (points outside the cube go to the
    /// nearest leaf).
    #[inline]
    pub fn leaf_at(&self, p: Vec3) -> LeafId {
        let q = ((p - self.origin) / self.edge).clamp(Vec3::ZERO, Vec3::ONE);
        let mut q = [q.x, q.y, q.z];
        let mut n = 0usize;
        let mut axis = 0usize;
        loop {
            let node = self.nodes[n];
            if node.first_child == 0 {
                return LeafId(node.leaf);
            }
            let upper = q[axis] >= 0.5;
            q[axis] = if upper {
                2.0 * q[axis] - 1.0
            } else {
                2.0 * q[axis]
            };
            n = node.first_child as usize + usize::from(upper);
            axis = (axis + 1) % 3;
        }
    }

    /// True when the leaf's sampling quadtree holds energy (after a
    /// training iteration recorded radiance there). Sampling an untrained
    /// leaf is uniform over the sphere; the guided tracer uses the BSDF
    /// alone there.
    #[inline]
    pub fn is_trained(&self, leaf: LeafId) -> bool {
        self.leaves[leaf.0 as usize].sampling.energy() > 0.0
    }

    /// A world-space direction drawn from the leaf's sampling quadtree with
    /// two uniform numbers, and its solid-angle density.
    #[inline]
    pub fn sample(&self, leaf: LeafId, u: (f32, f32)) -> (Vec3, f32) {
        let (p, density) = self.leaves[leaf.0 as usize].sampling.sample(u);
        (square_to_direction(p), (density / (4.0 * PI)) as f32)
    }

    /// Solid-angle density of [`SdTree::sample`] at the world-space unit
    /// direction `dir` (it integrates to 1 over the sphere).
    #[inline]
    pub fn pdf(&self, leaf: LeafId, dir: Vec3) -> f32 {
        let density = self.leaves[leaf.0 as usize]
            .sampling
            .density(direction_to_square(dir));
        (density / (4.0 * PI)) as f32
    }

    /// Moves the records of `buffer` into `into`, summed per building
    /// quadtree leaf in fixed point (see [`ExactRecords`]). The tree's
    /// shape must not change before [`SdTree::merge_exact`].
    pub fn accumulate(&self, buffer: &mut RecordBuffer, into: &mut ExactRecords) {
        if into.samples.len() < self.leaves.len() {
            into.samples.resize(self.leaves.len(), 0);
        }
        for r in buffer.records.drain(..) {
            into.samples[r.leaf as usize] += 1;
            if r.value > 0.0 {
                let node = self.leaves[r.leaf as usize].building.leaf_index(r.p);
                let fixed = (f64::from(r.value).min(EXACT_MAX) * EXACT_SCALE).round() as u128;
                let e = into.energy.entry((r.leaf, node as u32)).or_insert(0);
                *e = e.saturating_add(fixed);
            }
        }
    }

    /// Adds the exact sums of `parts` to the building quadtrees (and the
    /// leaves' record counts). Integer sums do not depend on the order of
    /// the parts or of the records in them, so the tree is the same
    /// whichever thread recorded what.
    pub fn merge_exact(&mut self, parts: impl IntoIterator<Item = ExactRecords>) {
        let mut samples = vec![0u64; self.leaves.len()];
        let mut energy: std::collections::BTreeMap<(u32, u32), u128> = Default::default();
        for part in parts {
            for (s, n) in samples.iter_mut().zip(&part.samples) {
                *s += n;
            }
            for (k, v) in part.energy {
                let e = energy.entry(k).or_insert(0);
                *e = e.saturating_add(v);
            }
        }
        for (leaf, n) in self.leaves.iter_mut().zip(samples) {
            leaf.samples += n;
        }
        for ((leaf, node), v) in energy {
            self.leaves[leaf as usize]
                .building
                .add_energy(node as usize, v as f64 / EXACT_SCALE);
        }
    }

    /// Adds the records of `buffers` to the building quadtrees, in the
    /// order given (buffer by buffer, each in recording order), so that
    /// the sums do not depend on which thread made which buffer. Leaves
    /// are filled in parallel (each leaf's records in that order).
    pub fn merge<'a>(&mut self, buffers: impl IntoIterator<Item = &'a RecordBuffer> + Clone) {
        // Counting sort by leaf, stable.
        let mut counts = vec![0usize; self.leaves.len()];
        for b in buffers.clone() {
            for r in &b.records {
                counts[r.leaf as usize] += 1;
            }
        }
        let mut start = Vec::with_capacity(counts.len() + 1);
        let mut total = 0usize;
        for &c in &counts {
            start.push(total);
            total += c;
        }
        start.push(total);
        let mut sorted = vec![((0.0f32, 0.0f32), 0.0f32); total];
        let mut next = start.clone();
        for b in buffers {
            for r in &b.records {
                let i = &mut next[r.leaf as usize];
                sorted[*i] = (r.p, r.value);
                *i += 1;
            }
        }
        self.leaves
            .par_iter_mut()
            .enumerate()
            .for_each(|(i, leaf)| {
                let mine = &sorted[start[i]..start[i + 1]];
                leaf.samples += mine.len() as u64;
                for &(p, value) in mine {
                    if value > 0.0 {
                        leaf.building.record(p, f64::from(value));
                    }
                }
            });
    }

    /// Ends training iteration `iteration` (1 for the first): leaves that
    /// received more than `c·√(2^iteration)` records are split (halving
    /// the axes in turn, recursively, each child with half the count and a
    /// copy of the quadtrees); then in every leaf the building quadtree,
    /// its energies summed, becomes the sampling quadtree, and the building
    /// quadtree is replaced by its refinement with threshold `rho`
    /// ([`QuadTree::refined`]), empty. Leaves that received no energy keep
    /// their previous sampling quadtree (no new information there).
    pub fn end_iteration(&mut self, iteration: u32, c: f64, rho: f64) {
        self.leaves.par_iter_mut().for_each(|l| l.building.sum_up());
        let threshold = c * 2f64.powi(iteration as i32).sqrt();
        let mut stack = vec![(0usize, 0u32)];
        while let Some((n, d)) = stack.pop() {
            let node = self.nodes[n];
            if node.first_child != 0 {
                let f = node.first_child as usize;
                stack.push((f, d + 1));
                stack.push((f + 1, d + 1));
            } else if d < MAX_SPATIAL_DEPTH
                && self.leaves[node.leaf as usize].samples as f64 > threshold
            {
                let f = self.split(n);
                stack.push((f, d + 1));
                stack.push((f + 1, d + 1));
            }
        }
        self.leaves.par_iter_mut().for_each(|l| {
            let refined = l.building.refined(rho, quadtree::MAX_DEPTH);
            let recorded = std::mem::replace(&mut l.building, refined);
            if recorded.energy() > 0.0 {
                l.sampling = recorded;
            }
            l.samples = 0;
        });
        self.nodes.shrink_to_fit();
        self.leaves.shrink_to_fit();
    }

    /// Node counts and memory.
    pub fn size(&self) -> TreeSize {
        let mut s = TreeSize {
            spatial_nodes: self.nodes.len(),
            spatial_leaves: self.leaves.len(),
            sampling_nodes: 0,
            building_nodes: 0,
            max_quadtree_depth: 0,
            bytes: self.nodes.capacity() * std::mem::size_of::<SpatialNode>()
                + self.leaves.capacity() * std::mem::size_of::<Leaf>(),
        };
        for l in &self.leaves {
            s.sampling_nodes += l.sampling.node_count();
            s.building_nodes += l.building.node_count();
            s.max_quadtree_depth = s.max_quadtree_depth.max(l.sampling.depth());
            s.bytes += l.sampling.bytes() + l.building.bytes();
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leaves_partition_the_cube_and_split_by_count() {
        let mut t = SdTree::new((Vec3::ZERO, Vec3::ONE), 3);
        assert_eq!(t.size().spatial_leaves, 8);
        // The eight octants get eight different leaves.
        let mut seen = std::collections::HashSet::new();
        for i in 0..8 {
            let p = Vec3::new(
                0.25 + 0.5 * (i & 1) as f32,
                0.25 + 0.5 * ((i >> 1) & 1) as f32,
                0.25 + 0.5 * (i >> 2) as f32,
            );
            seen.insert(t.leaf_at(p));
        }
        assert_eq!(seen.len(), 8);
        // 100 records in one leaf with threshold 10·√2: it splits until
        // each part holds at most 14 (100 → 50 → 25 → 12): 3 levels, 8 leaves.
        let leaf = t.leaf_at(Vec3::splat(0.1));
        let mut b = RecordBuffer::default();
        for _ in 0..100 {
            b.push(leaf, Vec3::Z, 1.0);
        }
        t.merge([&b]);
        t.end_iteration(1, 10.0, 0.01);
        assert_eq!(t.size().spatial_leaves, 8 - 1 + 8);
        let l = t.leaf_at(Vec3::splat(0.1));
        assert!(t.is_trained(l));
        assert!(!t.is_trained(t.leaf_at(Vec3::splat(0.9))));
        // The sampling quadtree is the initial one (root and four
        // quadrants) with all the energy in the quadrant of +z (cos θ ≥ 0,
        // φ < π): density 4 there on the square, 0 elsewhere.
        let uniform = 1.0 / (4.0 * std::f32::consts::PI);
        assert!((t.pdf(l, Vec3::Z) - 4.0 * uniform).abs() < 1e-6);
        assert_eq!(t.pdf(l, -Vec3::Z), 0.0);
    }
}
