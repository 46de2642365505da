//! A four-wide BVH for CPU traversal, collapsed from the binary BVH that
//! obvhs builds.
//!
//! obvhs builds the tree (PLOC plus reinsertion, in parallel); this module
//! only re-lays it out for one ray at a time on a CPU: every node holds the
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
/// A child slot without a child.
const EMPTY: u32 = u32::MAX;
/// Capacity of the fixed traversal stack. Each level of the tree pushes at
/// most three entries, so trees up to 42 levels deep (PLOC trees over
/// millions of primitives stay far below) use it; deeper ones fall back to
/// a heap stack.
const STACK: usize = 128;

/// Push/pop storage of a traversal.
trait PushPop<T> {
    fn push(&mut self, x: T);
    fn pop(&mut self) -> Option<T>;
}

/// A fixed-capacity stack left uninitialised up front: zeroing a
/// kilobyte-sized array per ray cost more than the traversal of a small
/// scene. The caller guarantees it never holds more than `N` items.
struct ArrayStack<T: Copy, const N: usize> {
    items: [MaybeUninit<T>; N],
    len: usize,
}

impl<T: Copy, const N: usize> ArrayStack<T, N> {
    #[inline(always)]
    fn new() -> Self {
        ArrayStack {
            items: [const { MaybeUninit::uninit() }; N],
            len: 0,
        }
    }
}

impl<T: Copy, const N: usize> PushPop<T> for ArrayStack<T, N> {
    #[inline(always)]
    fn push(&mut self, x: T) {
        // Indexing keeps an overflow a panic rather than memory corruption.
        self.items[self.len].write(x);
        self.len += 1;
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        // SAFETY: every slot below `len` was written by `push`.
        Some(unsafe { self.items[self.len].assume_init() })
    }
}

impl<T> PushPop<T> for Vec<T> {
    #[inline(always)]
    fn push(&mut self, x: T) {
        Vec::push(self, x);
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        Vec::pop(self)
    }
}

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

/// A ray prepared for box tests: origin and reciprocal direction per axis
/// splatted to four lanes, and which bound of each axis is met first.
struct BoxRay {
    o: [Vec4; 3],
    inv: [Vec4; 3],
    /// `bounds` index of the near plane per axis (the far one is `near ^ 1`).
    near: [usize; 3],
}

impl BoxRay {
    #[inline(always)]
    fn new(o: Vec3, d: Vec3) -> BoxRay {
        // A zero component would give 0·∞ = NaN on a box face through the
        // origin; a tiny same-signed value gives the right ±huge slabs.
        let d = Vec3A::from(d);
        let tiny = Vec3A::splat(1e-30);
        let d = Vec3A::select(d.abs().cmplt(tiny), tiny.copysign(d), d);
        // One SIMD division for the three reciprocals.
        let inv = Vec3A::ONE / d;
        BoxRay {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            inv: [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)],
            near: [
                usize::from(d.x < 0.0),
                usize::from(d.y < 0.0),
                usize::from(d.z < 0.0),
            ],
        }
    }

    /// Entry distances of the four children and the mask of those the ray
    /// crosses within `[tmin, tmax]`.
    #[inline(always)]
    fn test(&self, node: &Node, tmin: f32, tmax: f32) -> (Vec4, u32) {
        let b = &node.bounds;
        let [nx, ny, nz] = self.near;
        let t0x = (b[nx] - self.o[0]) * self.inv[0];
        let t1x = (b[nx ^ 1] - self.o[0]) * self.inv[0];
        let t0y = (b[2 + ny] - self.o[1]) * self.inv[1];
        let t1y = (b[2 + (ny ^ 1)] - self.o[1]) * self.inv[1];
        let t0z = (b[4 + nz] - self.o[2]) * self.inv[2];
        let t1z = (b[4 + (nz ^ 1)] - self.o[2]) * self.inv[2];
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
        let mut nodes = Vec::with_capacity(bvh2.nodes.len() / 3 + 1);
        let mut depth = 1;
        if bvh2.nodes[0].is_leaf() {
            // A single leaf: a root with one child.
            let mut root = Node::EMPTY;
            root.set_box(0, bvh2.nodes[0].aabb());
            root.child[0] = leaf_ref(&bvh2, 0);
            nodes.push(root);
        } else {
            collapse(&bvh2, 0, 1, &mut nodes, &mut depth);
        }
        (Bvh4 { nodes, depth }, bvh2.primitive_indices.clone())
    }

    /// Bytes used by the nodes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
    }

    /// True when the fixed traversal stack is deep enough for this tree.
    #[inline(always)]
    fn fits_array_stack(&self) -> bool {
        3 * self.depth < STACK
    }

    /// Primitive ranges of all leaves.
    pub fn leaves(&self) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
        self.nodes
            .iter()
            .flat_map(|n| n.child)
            .filter(|&c| c != EMPTY && c & LEAF_BIT != 0)
            .map(leaf_range)
    }

    /// Closest hit: calls `hit(leaf, tmax)` for candidate leaves (primitive
    /// ranges), which returns the closest `(prim, t)` of the leaf with `t`
    /// below `tmax` (else `None`); the interval shrinks with every hit.
    /// Returns the closest `(prim, t)`.
    #[inline(always)]
    pub fn closest<F: FnMut(std::ops::Range<usize>, f32) -> Option<(usize, f32)>>(
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
        if self.fits_array_stack() {
            let mut stack = ArrayStack::<(u32, f32), STACK>::new();
            self.closest_with(&mut stack, o, d, tmin, tmax, hit)
        } else {
            self.closest_with(&mut Vec::new(), o, d, tmin, tmax, hit)
        }
    }

    #[inline(always)]
    fn closest_with<
        S: PushPop<(u32, f32)>,
        F: FnMut(std::ops::Range<usize>, f32) -> Option<(usize, f32)>,
    >(
        &self,
        stack: &mut S,
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
        loop {
            if cur & LEAF_BIT != 0 {
                if let Some((prim, t)) = hit(leaf_range(cur), tmax) {
                    tmax = t;
                    best = Some((prim, t));
                }
            } else {
                let node = &self.nodes[cur as usize];
                let (tnear, mut mask) = ray.test(node, tmin, tmax);
                if mask != 0 {
                    // Push the crossed children farthest first, so the
                    // nearest is popped next.
                    let tn = tnear.to_array();
                    let mut kids = [(0u32, 0.0f32); 4];
                    let mut n = 0;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        // Insertion by entry distance, descending.
                        let entry = (node.child[i], tn[i]);
                        let mut k = n;
                        while k > 0 && kids[k - 1].1 < entry.1 {
                            kids[k] = kids[k - 1];
                            k -= 1;
                        }
                        kids[k] = entry;
                        n += 1;
                    }
                    // The nearest is visited now; the others wait.
                    for &kid in &kids[..n - 1] {
                        stack.push(kid);
                    }
                    cur = kids[n - 1].0;
                    continue;
                }
            }
            // Next pending child still nearer than the closest hit so far.
            loop {
                let Some((r, t)) = stack.pop() else {
                    return best;
                };
                if t <= tmax {
                    cur = r;
                    break;
                }
            }
        }
    }

    /// Any hit: true as soon as `blocks(leaf)` says a primitive of a leaf
    /// (primitive range) blocks the ray within `[tmin, tmax]`.
    #[inline(always)]
    pub fn any<F: FnMut(std::ops::Range<usize>) -> bool>(
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
        if self.fits_array_stack() {
            let mut stack = ArrayStack::<u32, STACK>::new();
            self.any_with(&mut stack, o, d, tmin, tmax, blocks)
        } else {
            self.any_with(&mut Vec::new(), o, d, tmin, tmax, blocks)
        }
    }

    #[inline(always)]
    fn any_with<S: PushPop<u32>, F: FnMut(std::ops::Range<usize>) -> bool>(
        &self,
        stack: &mut S,
        o: Vec3,
        d: Vec3,
        tmin: f32,
        tmax: f32,
        mut blocks: F,
    ) -> bool {
        let ray = BoxRay::new(o, d);
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT != 0 {
                if blocks(leaf_range(cur)) {
                    return true;
                }
            } else {
                let node = &self.nodes[cur as usize];
                let (_, mut mask) = ray.test(node, tmin, tmax);
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        stack.push(node.child[i]);
                    }
                    cur = node.child[first];
                    continue;
                }
            }
            match stack.pop() {
                Some(r) => cur = r,
                None => return false,
            }
        }
    }
}

/// The child reference of a binary leaf.
fn leaf_ref(bvh2: &Bvh2, i: usize) -> u32 {
    let n = &bvh2.nodes[i];
    debug_assert!(n.prim_count >= 1 && n.prim_count <= MAX_LEAF_PRIMS);
    LEAF_BIT | ((n.prim_count - 1) << FIRST_BITS) | n.first_index
}

/// Appends the four-wide node for the binary inner node `i` (and, after
/// it, its subtree); returns its index. The binary node's children are
/// opened, largest surface first, until four remain or all are leaves.
/// `level` is the new node's depth (root = 1); `depth` tracks the deepest.
fn collapse(bvh2: &Bvh2, i: usize, level: usize, nodes: &mut Vec<Node>, depth: &mut usize) -> u32 {
    *depth = (*depth).max(level);
    let first = bvh2.nodes[i].first_index as usize;
    let mut kids = vec![first, first + 1];
    while kids.len() < 4 {
        let widest = kids
            .iter()
            .enumerate()
            .filter(|(_, k)| !bvh2.nodes[**k].is_leaf())
            .max_by(|a, b| {
                let ha = bvh2.nodes[*a.1].aabb().half_area();
                let hb = bvh2.nodes[*b.1].aabb().half_area();
                ha.total_cmp(&hb)
            })
            .map(|(slot, _)| slot);
        let Some(slot) = widest else { break };
        let open = bvh2.nodes[kids[slot]].first_index as usize;
        kids[slot] = open;
        kids.push(open + 1);
    }
    let me = nodes.len();
    nodes.push(Node::EMPTY);
    let mut node = Node::EMPTY;
    for (slot, &k) in kids.iter().enumerate() {
        node.set_box(slot, bvh2.nodes[k].aabb());
        node.child[slot] = if bvh2.nodes[k].is_leaf() {
            leaf_ref(bvh2, k)
        } else {
            collapse(bvh2, k, level + 1, nodes, depth)
        };
    }
    nodes[me] = node;
    me as u32
}
