//! A four-wide BVH for CPU traversal, collapsed from the binary BVH that
//! obvhs builds.
//!
//! obvhs builds the tree (PLOC plus reinsertion, in parallel); this module
//! re-lays it out for one ray at a time on a CPU (which binary subtrees
//! become four-wide nodes, which become leaves, chosen by the surface-area
//! heuristic over the whole binary tree, see [`plan`]): every node holds the
//! boxes of its four children as structure-of-arrays lanes, so one ray
//! tests all four with a handful of 4-wide SIMD operations (glam's `Vec4`
//! is SSE2 on x86-64), and children are visited nearest first so the
//! closest-hit search shrinks its interval early. For the small scenes of
//! this project (tens to thousands of primitives) that is several times
//! faster than obvhs's compressed eight-wide BVH, whose per-node decoding
//! of quantised boxes dominates there.
//!
//! Robustness: box tests follow pbrt-v4 (`Bounds3::IntersectP`): the far
//! distance is enlarged by `1 + 2γ(3)` so rounding never culls a box the
//! ray really crosses, and zero direction components are replaced by a tiny
//! value of the same sign so no `0 · ∞ = NaN` can arise.

use super::tri_pack::Ray4;
use glam::{Vec3, Vec3A, Vec4};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use std::mem::MaybeUninit;

/// Most primitives one leaf may hold (three bits of a child reference).
pub const MAX_LEAF_PRIMS: u32 = 8;
/// Top bit of a child reference: the child is a leaf.
const LEAF_BIT: u32 = 1 << 31;
/// Bits of a leaf reference holding its first primitive.
const FIRST_BITS: u32 = 28;
/// Cost of a node test relative to a leaf test, for the collapse's
/// surface-area heuristic (≈ 45 against ≈ 115–160 instructions in callgrind
/// profiles of the Cornell box; 0.4 was worse there when leaves were merged
/// by a local rule).
const NODE_COST: f32 = 0.3;
/// A child slot without a child.
const EMPTY: u32 = u32::MAX;
/// Capacity of the fixed traversal stack. Each level of the tree leaves at
/// most three entries on it (siblings of the current path's node), so
/// trees up to 42 levels deep (PLOC trees over millions of primitives stay
/// far below) use it; deeper ones get a heap stack of their own size.
const STACK: usize = 128;

/// One node: the boxes of up to four children and their references.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct Node {
    /// Children's boxes as lanes: min x, max x, min y, max y, min z, max z.
    /// Empty slots hold the inverted box (+∞, −∞), which no ray hits.
    bounds: [Vec4; 6],
    /// Child references: a node index, a leaf (`LEAF_BIT | (count − 1) <<
    /// FIRST_BITS | first`), or `EMPTY`.
    child: [u32; 4],
}

impl Node {
    const EMPTY: Node = Node {
        bounds: [
            Vec4::INFINITY,
            Vec4::NEG_INFINITY,
            Vec4::INFINITY,
            Vec4::NEG_INFINITY,
            Vec4::INFINITY,
            Vec4::NEG_INFINITY,
        ],
        child: [EMPTY; 4],
    };

    fn set_box(&mut self, slot: usize, b: &Aabb) {
        for axis in 0..3 {
            self.bounds[2 * axis][slot] = b.min[axis];
            self.bounds[2 * axis + 1][slot] = b.max[axis];
        }
    }
}

/// The primitive range `first..first + count` of a leaf reference.
#[inline(always)]
fn leaf_range(r: u32) -> std::ops::Range<usize> {
    let first = (r & ((1 << FIRST_BITS) - 1)) as usize;
    let count = (((r >> FIRST_BITS) & 7) + 1) as usize;
    first..first + count
}

/// A ray prepared for box tests: origin and direction splatted to four
/// lanes (shared with the leaves' triangle packs), the reciprocal direction
/// per axis, and which bound of each axis is met first.
struct BoxRay {
    simd: Ray4,
    inv: [Vec4; 3],
    /// Byte offsets in `Node::bounds` of the near and far planes of x, y
    /// and z: byte offsets rather than indices save two instructions per
    /// offset and node (no scaling, no reload of the index for it).
    planes: [usize; 6],
}

/// `PLANES[signs]`: [`BoxRay::planes`] for the direction whose sign bits
/// (x in bit 0) are `signs`; a negative direction meets the maximum (the
/// second plane of the axis) first.
const PLANES: [[usize; 6]; 8] = {
    const V: usize = std::mem::size_of::<Vec4>();
    let mut t = [[0; 6]; 8];
    let mut signs = 0;
    while signs < 8 {
        let mut axis = 0;
        while axis < 3 {
            let neg = (signs >> axis) & 1;
            t[signs][2 * axis] = (2 * axis + neg) * V;
            t[signs][2 * axis + 1] = (2 * axis + (neg ^ 1)) * V;
            axis += 1;
        }
        signs += 1;
    }
    t
};

impl BoxRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> BoxRay {
        let simd = Ray4::new(o, d);
        // A zero component would give 0·∞ = NaN on a box face through the
        // origin; a tiny same-signed value gives the right ±huge slabs
        // (`max` then the sign back: fewer operations than a select, and
        // the same values for every non-NaN component).
        let d = Vec3A::from(d);
        let d = d.abs().max(Vec3A::splat(1e-30)).copysign(d);
        // One SIMD division for the three reciprocals.
        let inv = Vec3A::ONE / d;
        BoxRay {
            simd,
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            // The sign bits in one `movmskps` (`d` has no zero left, so
            // they agree with `d < 0`) select a row of precomputed plane
            // offsets: six loads instead of a dozen bit operations.
            planes: PLANES[(d.is_negative_bitmask() & 7) as usize],
        }
    }

    /// Entry distances of the four children and the mask of those the ray
    /// crosses within `[tmin, tmax]`.
    #[inline(always)]
    fn test(&self, node: &Node, tmin: f32, tmax: f32) -> (Vec4, u32) {
        let b = &node.bounds;
        let p = |k: usize| {
            let off = self.planes[k];
            debug_assert!(
                off.is_multiple_of(std::mem::size_of::<Vec4>()) && off < std::mem::size_of_val(b)
            );
            // SAFETY: `planes` holds offsets of whole `Vec4`s inside
            // `bounds` (set in `new`), so the read is in bounds and aligned.
            unsafe { *b.as_ptr().cast::<u8>().add(off).cast::<Vec4>() }
        };
        let o = &self.simd.o;
        let t0x = (p(0) - o[0]) * self.inv[0];
        let t1x = (p(1) - o[0]) * self.inv[0];
        let t0y = (p(2) - o[1]) * self.inv[1];
        let t1y = (p(3) - o[1]) * self.inv[1];
        let t0z = (p(4) - o[2]) * self.inv[2];
        let t1z = (p(5) - o[2]) * self.inv[2];
        let tnear = t0x.max(t0y).max(t0z).max(Vec4::splat(tmin));
        // pbrt-v4's conservative far distance: 1 + 2γ(3).
        let tfar = t1x.min(t1y).min(t1z) * (1.0 + 2.0 * super::gamma(3));
        let tfar = tfar.min(Vec4::splat(tmax));
        (tnear, tnear.cmple(tfar).bitmask())
    }
}

/// The four-wide BVH: nodes only; leaves index the caller's primitive
/// array, which must be stored in [`Bvh4::build`]'s returned order.
#[derive(Clone, Debug, Default)]
pub struct Bvh4 {
    nodes: Vec<Node>,
    /// Levels of nodes on the longest root-to-leaf path.
    depth: usize,
}

impl Bvh4 {
    /// Builds the BVH over primitive boxes. Returns it with the order in
    /// which the primitives must be stored (`order[k]` = input index of the
    /// `k`-th stored primitive).
    ///
    /// # Panics
    /// With 2²⁸ or more primitives (the leaf encoding's limit; such a
    /// scene would need tens of gigabytes).
    pub fn build(aabbs: &[Aabb], params: BvhBuildParams) -> (Bvh4, Vec<u32>) {
        assert!(
            aabbs.len() < 1 << FIRST_BITS,
            "at most 2^28 primitives are supported"
        );
        if aabbs.is_empty() {
            return (Bvh4::default(), Vec::new());
        }
        let mut params = params;
        params.max_prims_per_leaf = params.max_prims_per_leaf.clamp(1, MAX_LEAF_PRIMS);
        let bvh2 = obvhs::bvh2::builder::build_bvh2(aabbs, params, &mut Default::default());
        let mut c = Collapser {
            plans: plan(&bvh2, params.max_prims_per_leaf),
            bvh2: &bvh2,
            nodes: Vec::with_capacity(bvh2.nodes.len() / 3 + 1),
            order: Vec::with_capacity(aabbs.len()),
            depth: 1,
        };
        if c.is_leaf(0) {
            // A single leaf: a root with one child.
            let mut root = Node::EMPTY;
            root.set_box(0, bvh2.nodes[0].aabb());
            root.child[0] = c.leaf(0);
            c.nodes.push(root);
        } else {
            c.node(0, 1);
        }
        debug_assert_eq!(c.order.len(), aabbs.len());
        let (nodes, depth, order) = (c.nodes, c.depth, c.order);
        (Bvh4 { nodes, depth }, order)
    }

    /// Bytes used by the nodes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
    }

    /// Entries the traversal stack must hold for this tree.
    #[inline(always)]
    fn stack_need(&self) -> usize {
        3 * self.depth
    }

    /// Primitive ranges of all leaves.
    pub fn leaves(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.nodes
            .iter()
            .flat_map(|n| n.child)
            .filter(|&c| c != EMPTY && c & LEAF_BIT != 0)
            .map(leaf_range)
    }

    /// Closest hit: calls `hit(ray, leaf, tmax)` for candidate leaves
    /// (primitive ranges; `ray` is the query ray splatted to four lanes),
    /// which returns the closest `(prim, t)` of the leaf with `t` below
    /// `tmax` (else `None`); the interval shrinks with every hit. Returns
    /// the closest `(prim, t)`.
    #[inline(always)]
    pub fn closest<F: FnMut(&Ray4, std::ops::Range<usize>, f32) -> Option<(usize, f32)>>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: f32,
        hit: F,
    ) -> Option<(usize, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        // Left uninitialised: zeroing a kilobyte per ray cost more than the
        // traversal of a small scene.
        let mut local = [const { MaybeUninit::uninit() }; STACK];
        let mut heap;
        let stack: &mut [MaybeUninit<(u32, f32)>] = if self.stack_need() <= STACK {
            &mut local
        } else {
            heap = vec![MaybeUninit::uninit(); self.stack_need()];
            &mut heap
        };
        self.closest_in(stack, o, d, tmin, tmax, hit)
    }

    /// The closest-hit traversal on a stack of at least
    /// [`Self::stack_need`] entries.
    #[inline(always)]
    fn closest_in<F: FnMut(&Ray4, std::ops::Range<usize>, f32) -> Option<(usize, f32)>>(
        &self,
        stack: &mut [MaybeUninit<(u32, f32)>],
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: f32,
        mut hit: F,
    ) -> Option<(usize, f32)> {
        let ray = BoxRay::new(o, d);
        let mut tmax = tmax;
        let mut best = None;
        let mut cur = 0u32;
        // Entries below `sp` are initialised.
        let mut sp = 0usize;
        loop {
            if cur & LEAF_BIT != 0 {
                if let Some((prim, t)) = hit(&ray.simd, leaf_range(cur), tmax) {
                    tmax = t;
                    best = Some((prim, t));
                }
            } else {
                // SAFETY: inner-node references are indices into `nodes`,
                // written by `Collapser::node` and never changed after.
                let node = unsafe { self.nodes.get_unchecked(cur as usize) };
                let (tnear, mask) = ray.test(node, tmin, tmax);
                if mask != 0 {
                    // One or two crossed children (the common cases) need
                    // no sort: descend into the only one, or push the
                    // farther of two. Ties go to the later slot, as in the
                    // general case below.
                    let a = mask.trailing_zeros() as usize;
                    let rest = mask & (mask - 1);
                    if rest == 0 {
                        cur = node.child[a];
                        continue;
                    }
                    let tn = tnear.to_array();
                    if rest & (rest - 1) == 0 {
                        let b = rest.trailing_zeros() as usize;
                        let (near, far) = if tn[b] <= tn[a] { (b, a) } else { (a, b) };
                        debug_assert!(sp < stack.len());
                        // SAFETY: `sp < 3 · depth <= stack.len()`: at most three pending
                        // siblings per level of the current path (see `STACK`).
                        unsafe { stack.get_unchecked_mut(sp) }.write((node.child[far], tn[far]));
                        sp += 1;
                        cur = node.child[near];
                        continue;
                    }
                    // Three or four: insertion by entry distance,
                    // descending; the nearest is visited now and the others
                    // wait, farthest deepest.
                    let mut mask = mask;
                    let mut kids = [(0u32, 0.0f32); 4];
                    let mut n = 0;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let entry = (node.child[i], tn[i]);
                        let mut k = n;
                        while k > 0 && kids[k - 1].1 < entry.1 {
                            kids[k] = kids[k - 1];
                            k -= 1;
                        }
                        kids[k] = entry;
                        n += 1;
                    }
                    for &kid in &kids[..n - 1] {
                        debug_assert!(sp < stack.len());
                        // SAFETY: `sp < 3 · depth <= stack.len()`: at most three pending
                        // siblings per level of the current path (see `STACK`).
                        unsafe { stack.get_unchecked_mut(sp) }.write(kid);
                        sp += 1;
                    }
                    cur = kids[n - 1].0;
                    continue;
                }
            }
            // Next pending child still nearer than the closest hit so far.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                // SAFETY: every entry below the old `sp` was written (and
                // lies in `stack`).
                let (r, t) = unsafe { stack.get_unchecked(sp).assume_init() };
                if t <= tmax {
                    cur = r;
                    break;
                }
            }
        }
    }

    /// Any hit: true as soon as `blocks(ray, leaf)` says a primitive of a
    /// leaf (primitive range; `ray` is the query ray splatted to four
    /// lanes) blocks the ray within `[tmin, tmax]`.
    #[inline(always)]
    pub fn any<F: FnMut(&Ray4, std::ops::Range<usize>) -> bool>(
        &self,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: f32,
        blocks: F,
    ) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let mut local = [const { MaybeUninit::uninit() }; STACK];
        let mut heap;
        let stack: &mut [MaybeUninit<u32>] = if self.stack_need() <= STACK {
            &mut local
        } else {
            heap = vec![MaybeUninit::uninit(); self.stack_need()];
            &mut heap
        };
        self.any_in(stack, o, d, tmin, tmax, blocks)
    }

    /// The any-hit traversal on a stack of at least [`Self::stack_need`]
    /// entries.
    #[inline(always)]
    fn any_in<F: FnMut(&Ray4, std::ops::Range<usize>) -> bool>(
        &self,
        stack: &mut [MaybeUninit<u32>],
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: f32,
        mut blocks: F,
    ) -> bool {
        let ray = BoxRay::new(o, d);
        let mut cur = 0u32;
        let mut sp = 0usize;
        loop {
            if cur & LEAF_BIT != 0 {
                if blocks(&ray.simd, leaf_range(cur)) {
                    return true;
                }
            } else {
                // SAFETY: inner-node references are indices into `nodes`,
                // written by `Collapser::node` and never changed after.
                let node = unsafe { self.nodes.get_unchecked(cur as usize) };
                let (_, mut mask) = ray.test(node, tmin, tmax);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        debug_assert!(sp < stack.len());
                        // SAFETY: `sp < 3 · depth <= stack.len()`: at most three pending
                        // siblings per level of the current path (see `STACK`).
                        unsafe { stack.get_unchecked_mut(sp) }.write(node.child[i]);
                        sp += 1;
                    }
                    cur = node.child[first];
                    continue;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            // SAFETY: every entry below the old `sp` was written (and lies
            // in `stack`).
            cur = unsafe { stack.get_unchecked(sp).assume_init() };
        }
    }
}

/// How the collapse lays out one binary subtree (surface-area costs: a
/// leaf test costs 1 per unit of box area, a node test `NODE_COST`).
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// The subtree becomes one leaf (else a four-wide node).
    leaf: bool,
    /// Primitives in the subtree.
    count: u32,
    /// `best[k]`: least cost of the subtree spread over at most `k` slots
    /// of its parent (`k` = 1..4; `best[1]` = the subtree as one child).
    best: [f32; 5],
    /// `split[k]`: slots given to the left child for `best[k]` (0: the
    /// subtree takes one slot).
    split: [u8; 5],
    /// Slots of the left child when the subtree is a node of its own.
    node_split: u8,
}

/// Chooses, bottom-up, which binary nodes become four-wide nodes and
/// which become leaves, and which descendants fill each node's four slots,
/// minimising the surface-area cost (dynamic programming over the binary
/// tree, as in Ylitie et al. 2017 for eight-wide trees). A subtree of at
/// most `max_leaf` primitives may become one leaf: a leaf of up to four
/// triangles costs one SIMD test whatever their number.
fn plan(bvh2: &Bvh2, max_leaf: u32) -> Vec<Plan> {
    // Pre-order without recursion, then children before parents.
    let mut pre = Vec::with_capacity(bvh2.nodes.len());
    let mut stack = vec![0usize];
    while let Some(i) = stack.pop() {
        pre.push(i);
        let n = &bvh2.nodes[i];
        if !n.is_leaf() {
            stack.push(n.first_index as usize);
            stack.push(n.first_index as usize + 1);
        }
    }
    let none = Plan {
        leaf: true,
        count: 0,
        best: [f32::INFINITY; 5],
        split: [0; 5],
        node_split: 0,
    };
    let mut plans = vec![none; bvh2.nodes.len()];
    for &i in pre.iter().rev() {
        let n = &bvh2.nodes[i];
        let area = n.aabb().half_area().max(0.0);
        let mut p = none;
        if n.is_leaf() {
            p.count = n.prim_count;
            p.best = [area; 5];
        } else {
            let f = n.first_index as usize;
            let (l, r) = (plans[f], plans[f + 1]);
            p.count = l.count.saturating_add(r.count);
            // As a node: its four slots shared between the two children.
            let (mut node_cost, mut node_split) = (f32::INFINITY, 1);
            for j in 1..4 {
                let c = l.best[j] + r.best[4 - j];
                if c < node_cost {
                    (node_cost, node_split) = (c, j as u8);
                }
            }
            let node_cost = area * NODE_COST + node_cost;
            let leaf_cost = if p.count <= max_leaf {
                area
            } else {
                f32::INFINITY
            };
            p.leaf = leaf_cost <= node_cost;
            p.node_split = node_split;
            let one = leaf_cost.min(node_cost);
            for k in 1..5 {
                p.best[k] = one;
                for j in 1..k {
                    let c = l.best[j] + r.best[k - j];
                    if c < p.best[k] {
                        p.best[k] = c;
                        p.split[k] = j as u8;
                    }
                }
            }
        }
        plans[i] = p;
    }
    plans
}

/// Re-lays a binary BVH out as four-wide nodes following [`plan`].
struct Collapser<'a> {
    bvh2: &'a Bvh2,
    plans: Vec<Plan>,
    nodes: Vec<Node>,
    /// Input primitive indices in leaf order.
    order: Vec<u32>,
    /// Levels of nodes on the longest root-to-leaf path so far.
    depth: usize,
}

impl Collapser<'_> {
    /// True when the binary node `i` becomes one leaf rather than a node.
    fn is_leaf(&self, i: usize) -> bool {
        self.plans[i].leaf
    }

    /// The leaf reference for the binary subtree `i`, whose primitives are
    /// appended to `order`.
    fn leaf(&mut self, i: usize) -> u32 {
        let first = self.order.len() as u32;
        let mut stack = vec![i];
        while let Some(k) = stack.pop() {
            let n = &self.bvh2.nodes[k];
            if n.is_leaf() {
                let range = n.first_index as usize..(n.first_index + n.prim_count) as usize;
                self.order
                    .extend_from_slice(&self.bvh2.primitive_indices[range]);
            } else {
                // Right pushed first so that the left one is gathered first.
                stack.push(n.first_index as usize + 1);
                stack.push(n.first_index as usize);
            }
        }
        let count = self.order.len() as u32 - first;
        debug_assert!((1..=MAX_LEAF_PRIMS).contains(&count));
        LEAF_BIT | ((count - 1) << FIRST_BITS) | first
    }

    /// Appends to `out` the binary subtrees that fill `k` slots for `i`.
    fn pieces(&self, i: usize, k: usize, out: &mut Vec<usize>) {
        let j = self.plans[i].split[k] as usize;
        if j == 0 {
            out.push(i);
        } else {
            let f = self.bvh2.nodes[i].first_index as usize;
            self.pieces(f, j, out);
            self.pieces(f + 1, k - j, out);
        }
    }

    /// Appends the four-wide node for the binary inner node `i` (and, after
    /// it, its subtree); returns its index. `level` is the new node's depth
    /// (root = 1).
    fn node(&mut self, i: usize, level: usize) -> u32 {
        self.depth = self.depth.max(level);
        let f = self.bvh2.nodes[i].first_index as usize;
        let j = self.plans[i].node_split as usize;
        let mut kids = Vec::with_capacity(4);
        self.pieces(f, j, &mut kids);
        self.pieces(f + 1, 4 - j, &mut kids);
        debug_assert!((2..=4).contains(&kids.len()));
        let me = self.nodes.len();
        self.nodes.push(Node::EMPTY);
        let mut node = Node::EMPTY;
        for (slot, &k) in kids.iter().enumerate() {
            node.set_box(slot, self.bvh2.nodes[k].aabb());
            node.child[slot] = if self.is_leaf(k) {
                self.leaf(k)
            } else {
                self.node(k, level + 1)
            };
        }
        self.nodes[me] = node;
        me as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(s: &mut u64) -> f32 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*s >> 40) as f32) / (1u64 << 24) as f32
    }

    /// Möller–Trumbore hit distance in `(tmin, tmax)`, if any.
    fn tri_hit(o: Vec3, d: Vec3, [a, b, c]: [Vec3; 3], tmin: f32, tmax: f32) -> Option<f32> {
        let (e1, e2) = (b - a, c - a);
        let pv = d.cross(e2);
        let det = e1.dot(pv);
        if det == 0.0 {
            return None;
        }
        let inv = 1.0 / det;
        let tv = o - a;
        let u = tv.dot(pv) * inv;
        let qv = tv.cross(e1);
        let v = d.dot(qv) * inv;
        let t = e2.dot(qv) * inv;
        (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > tmin && t < tmax).then_some(t)
    }

    /// The traversals find exactly what a brute-force loop over all
    /// primitives finds (same closest primitive and distance, same any-hit
    /// answer) for random triangles and rays, from a single primitive to
    /// trees several levels deep, with leaves merged or not.
    #[test]
    fn traversals_match_brute_force() {
        let mut s = 3u64;
        for (n, leaf) in [
            (1, 4),
            (3, 4),
            (5, 4),
            (37, 4),
            (37, 1),
            (2000, 4),
            (2000, 8),
        ] {
            let tris: Vec<[Vec3; 3]> = (0..n)
                .map(|_| {
                    let c = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 10.0;
                    [0, 1, 2].map(|_| {
                        c + Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) - Vec3::splat(0.5)
                    })
                })
                .collect();
            let aabbs: Vec<Aabb> = tris
                .iter()
                .map(|t| {
                    let mut b = Aabb::from_point(t[0].into());
                    b.extend(t[1].into()).extend(t[2].into());
                    b
                })
                .collect();
            let mut params = BvhBuildParams::very_slow_build();
            params.max_prims_per_leaf = leaf;
            let (bvh, order) = Bvh4::build(&aabbs, params);
            let mut sorted = order.clone();
            sorted.sort_unstable();
            assert!(
                sorted.iter().copied().eq(0..n as u32),
                "order is a permutation"
            );
            let stored: Vec<[Vec3; 3]> = order.iter().map(|&i| tris[i as usize]).collect();
            let mut hits = 0;
            for k in 0..3000 {
                let o = Vec3::new(lcg(&mut s), lcg(&mut s), lcg(&mut s)) * 12.0 - Vec3::ONE;
                // Aimed near a random triangle (slightly beyond its edges
                // too), so that most rays hit something.
                let [a, b, c] = tris[(lcg(&mut s) * n as f32) as usize % n];
                let (u, v) = (lcg(&mut s) * 1.4 - 0.2, lcg(&mut s) * 1.4 - 0.2);
                let mut d = a + (b - a) * u + (c - a) * v - o;
                // Some axis-parallel rays (zero direction components).
                if k % 7 == 0 {
                    d.x = 0.0;
                }
                if k % 11 == 0 {
                    d.y = 0.0;
                }
                let d = d.normalize();
                let (tmin, tmax) = (0.0, if k % 2 == 0 { f32::INFINITY } else { 8.0 });
                let want = stored
                    .iter()
                    .enumerate()
                    .filter_map(|(i, &t)| tri_hit(o, d, t, tmin, tmax).map(|h| (i, h)))
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                let got = bvh.closest(o, d, tmin, tmax, |_, leaf, tmax| {
                    leaf.filter_map(|i| tri_hit(o, d, stored[i], tmin, tmax).map(|h| (i, h)))
                        .min_by(|a, b| a.1.total_cmp(&b.1))
                });
                assert_eq!(got, want, "n={n} ray {k}");
                let blocked = bvh.any(o, d, tmin, tmax, |_, mut leaf| {
                    leaf.any(|i| tri_hit(o, d, stored[i], tmin, tmax).is_some())
                });
                assert_eq!(blocked, want.is_some(), "n={n} ray {k}");
                hits += usize::from(want.is_some());
            }
            assert!(hits > 300, "n={n}: too few hits to test ({hits})");
        }
    }
}
