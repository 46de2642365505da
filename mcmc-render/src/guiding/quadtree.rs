//! The directional quadtree of one spatial leaf: a piecewise-constant
//! density over the unit square `[0, 1)²` of the cylindrical map
//! ([`super::direction_to_square`]), refined where the recorded energy is.
//!
//! Each node stores the energy (flux estimate) recorded inside its square;
//! an interior node has four children, its quadrants, stored consecutively
//! in the order `(x, y) = (0, 0), (1, 0), (0, 1), (1, 1)` (child index
//! `x + 2y`, `x` = the upper half of the first coordinate). The root always
//! has children, as in Müller et al.'s implementation.

/// Deepest level of a quadtree (Müller et al.: 20; a leaf at level 20 is
/// 2⁻²⁰ of the square's edge).
pub const MAX_DEPTH: u32 = 20;

/// A node: its energy and the index of its first child (0: a leaf; the
/// root, index 0, is nobody's child).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Node {
    energy: f64,
    first_child: u32,
}

/// A directional quadtree (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct QuadTree {
    nodes: Vec<Node>,
}

impl Default for QuadTree {
    /// The root split once, no energy: the uniform density.
    fn default() -> Self {
        let mut nodes = vec![Node::default(); 5];
        nodes[0].first_child = 1;
        QuadTree { nodes }
    }
}

/// The quadrant of `p` in a node's square scaled to `[0, 1)²`: the child
/// index and `p` rescaled to the child's square.
#[inline]
fn quadrant(p: (f64, f64)) -> (usize, (f64, f64)) {
    let (x, y) = p;
    let (cx, x) = if x < 0.5 {
        (0, 2.0 * x)
    } else {
        (1, 2.0 * x - 1.0)
    };
    let (cy, y) = if y < 0.5 {
        (0, 2.0 * y)
    } else {
        (1, 2.0 * y - 1.0)
    };
    (cx + 2 * cy, (x, y))
}

impl QuadTree {
    /// Total recorded energy (the root's).
    pub fn energy(&self) -> f64 {
        self.nodes[0].energy
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Bytes held by the node array.
    pub fn bytes(&self) -> usize {
        self.nodes.capacity() * std::mem::size_of::<Node>()
    }

    /// Depth of the deepest leaf (the root alone is depth 0).
    pub fn depth(&self) -> u32 {
        let mut deepest = 0;
        let mut stack = vec![(0usize, 0u32)];
        while let Some((n, d)) = stack.pop() {
            deepest = deepest.max(d);
            let c = self.nodes[n].first_child as usize;
            if c != 0 {
                stack.extend((c..c + 4).map(|c| (c, d + 1)));
            }
        }
        deepest
    }

    /// Adds `value` to the leaf containing `p` (a point of `[0, 1)²`).
    /// Interior energies are left stale until [`QuadTree::sum_up`].
    pub fn record(&mut self, p: (f32, f32), value: f64) {
        let n = self.leaf_index(p);
        self.add_energy(n, value);
    }

    /// The index of the leaf containing `p` (a point of `[0, 1)²`).
    pub fn leaf_index(&self, p: (f32, f32)) -> usize {
        let mut p = (f64::from(p.0), f64::from(p.1));
        let mut n = 0usize;
        loop {
            let c = self.nodes[n].first_child as usize;
            if c == 0 {
                return n;
            }
            let (q, rest) = quadrant(p);
            n = c + q;
            p = rest;
        }
    }

    /// Adds `value` to node `n`'s energy (a leaf from
    /// [`QuadTree::leaf_index`]; interior energies are left stale until
    /// [`QuadTree::sum_up`]).
    pub fn add_energy(&mut self, n: usize, value: f64) {
        self.nodes[n].energy += value;
    }

    /// Sets every interior node's energy to the sum of its children's
    /// (children always have larger indices than their parent).
    pub fn sum_up(&mut self) {
        for n in (0..self.nodes.len()).rev() {
            let c = self.nodes[n].first_child as usize;
            if c != 0 {
                self.nodes[n].energy = self.nodes[c..c + 4].iter().map(|k| k.energy).sum();
            }
        }
    }

    /// Density on the unit square at `p` (it integrates to 1 over the
    /// square): the product over the levels of `4·E_child/E_node`, or 1
    /// (uniform) when the tree holds no energy. Requires summed energies
    /// ([`QuadTree::sum_up`]).
    pub fn density(&self, p: (f32, f32)) -> f64 {
        if !(self.energy() > 0.0) {
            return 1.0;
        }
        let mut p = (f64::from(p.0), f64::from(p.1));
        let mut n = 0usize;
        let mut density = 1.0f64;
        loop {
            let c = self.nodes[n].first_child as usize;
            if c == 0 {
                return density;
            }
            let (q, rest) = quadrant(p);
            let e = self.nodes[c + q].energy;
            if !(e > 0.0) {
                return 0.0;
            }
            density *= 4.0 * e / self.nodes[n].energy;
            n = c + q;
            p = rest;
        }
    }

    /// A point of `[0, 1)²` with density [`QuadTree::density`], from the
    /// uniform `u` (a hierarchical warp: at each level the column is chosen
    /// with `u.0` and the row with `u.1`, each rescaled to `[0, 1)` for the
    /// next level, then the point is uniform in the leaf). Uniform when the
    /// tree holds no energy. Returns the point and its density.
    pub fn sample(&self, u: (f32, f32)) -> ((f32, f32), f64) {
        let (mut ux, mut uy) = (f64::from(u.0), f64::from(u.1));
        if !(self.energy() > 0.0) {
            return (u, 1.0);
        }
        let (mut x0, mut y0, mut size) = (0.0f64, 0.0f64, 1.0f64);
        let mut n = 0usize;
        let mut density = 1.0f64;
        loop {
            let c = self.nodes[n].first_child as usize;
            if c == 0 {
                break;
            }
            let e = |k: usize| self.nodes[c + k].energy.max(0.0);
            let total = e(0) + e(1) + e(2) + e(3);
            // Column: x = 0 holds children 0 and 2.
            let left = e(0) + e(2);
            let p_left = left / total;
            let cx = if ux < p_left {
                ux /= p_left;
                0
            } else {
                ux = (ux - p_left) / (1.0 - p_left);
                1
            };
            let col = if cx == 0 { left } else { e(1) + e(3) };
            let p_low = e(cx) / col;
            let cy = if uy < p_low {
                uy /= p_low;
                0
            } else {
                uy = (uy - p_low) / (1.0 - p_low);
                1
            };
            // Rounding may push a rescaled number to 1: keep it inside.
            ux = ux.min(1.0 - f64::EPSILON);
            uy = uy.min(1.0 - f64::EPSILON);
            let k = cx + 2 * cy;
            density *= 4.0 * e(k) / total;
            size *= 0.5;
            x0 += cx as f64 * size;
            y0 += cy as f64 * size;
            n = c + k;
        }
        let x = (x0 + ux * size) as f32;
        let y = (y0 + uy * size) as f32;
        let below_one = |v: f32| v.min(crate::sampling::ONE_MINUS_EPSILON);
        ((below_one(x), below_one(y)), density)
    }

    /// The refined structure for the next iteration, with zero energy
    /// (Müller et al., Alg. 12): a node of the refined tree has children
    /// when its share of the total energy exceeds `rho` (the root always
    /// has), and `depth < max_depth`. Children of a node that had none
    /// inherit a quarter of its energy, so a bright leaf may split several
    /// levels at once; nodes at or below the share lose their children.
    /// With no energy at all, shares are `4^-depth`.
    pub fn refined(&self, rho: f64, max_depth: u32) -> QuadTree {
        let total = self.energy();
        let mut nodes = vec![Node::default()];
        // (new node, old node if it has a counterpart, energy, depth).
        let mut stack = vec![(0usize, Some(0usize), total, 0u32)];
        while let Some((n, old, energy, depth)) = stack.pop() {
            let share = if total > 0.0 {
                energy / total
            } else {
                0.25f64.powi(depth as i32)
            };
            if depth > 0 && !(depth < max_depth && share > rho) {
                continue;
            }
            let first = nodes.len();
            nodes[n].first_child = first as u32;
            nodes.extend([Node::default(); 4]);
            let old_first = old.map(|o| self.nodes[o].first_child as usize);
            for k in 0..4 {
                let child = match old_first {
                    Some(c) if c != 0 => (Some(c + k), self.nodes[c + k].energy),
                    _ => (None, energy / 4.0),
                };
                stack.push((first + k, child.0, child.1, depth + 1));
            }
        }
        nodes.shrink_to_fit();
        QuadTree { nodes }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tree with energy only in the quadrant `x ≥ ½, y < ½`, refined
    /// there: densities are exact products of `4·E_child/E_node`.
    #[test]
    fn density_follows_the_energy_and_sampling_agrees() {
        let mut t = QuadTree::default();
        for _ in 0..3 {
            t.record((0.7, 0.2), 3.0);
        }
        t.record((0.2, 0.8), 1.0);
        t.sum_up();
        assert_eq!(t.energy(), 10.0);
        assert!((t.density((0.7, 0.2)) - 4.0 * 9.0 / 10.0).abs() < 1e-12);
        assert!((t.density((0.2, 0.8)) - 4.0 * 1.0 / 10.0).abs() < 1e-12);
        assert_eq!(t.density((0.2, 0.2)), 0.0);
        for u in [(0.0, 0.0), (0.3, 0.9), (0.999, 0.5), (0.95, 0.05)] {
            let (p, d) = t.sample(u);
            assert!((d - t.density(p)).abs() < 1e-9, "{u:?} -> {p:?}");
            assert!(d > 0.0);
        }
    }

    #[test]
    fn refinement_follows_the_energy_share() {
        let mut t = QuadTree::default();
        t.record((0.1, 0.1), 1.0);
        t.sum_up();
        // All energy in one quadrant: it splits, and its children inherit
        // quarters (shares 1/4, 1/16, 1/64 > 0.01 split again, 1/256 does
        // not): a full subtree of depth 5 under it, the three empty
        // quadrants stay leaves.
        let r = t.refined(0.01, MAX_DEPTH);
        assert_eq!(r.depth(), 5);
        assert_eq!(r.node_count(), 1 + 4 + 4 + 16 + 64 + 256);
        assert_eq!(r.energy(), 0.0);
        // The depth limit stops it.
        let r = t.refined(0.01, 3);
        assert_eq!((r.depth(), r.node_count()), (3, 1 + 4 + 4 + 16));
        // No energy: shares 4^-d, so with rho = 0.01 every node down to
        // depth 3 splits (4^-3 = 0.0156 > 0.01 > 4^-4): a full tree of depth 4.
        let u = QuadTree::default().refined(0.01, MAX_DEPTH);
        assert_eq!(u.depth(), 4);
        assert_eq!(u.node_count(), 1 + 4 + 16 + 64 + 256);
    }
}
