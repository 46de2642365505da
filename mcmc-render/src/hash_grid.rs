//! Fixed-radius range search over a set of points: a hashed uniform grid
//! (the structure photon mappers and SmallVCM use for vertex merging).
//!
//! Cells are cubes of edge `2r`, so the ball of radius `r` around a query
//! point meets at most the 2 × 2 × 2 cells nearest to it. Cells are hashed
//! into a table of about as many buckets as points (Teschner et al. 2003's
//! prime multipliers); the points are sorted by bucket with a stable
//! counting sort, so a bucket holds its points in their original order and
//! the grid, and the order in which a query visits points, depend only on
//! the input (never on threads or timing). Two of the eight cells may share
//! a bucket: the query visits each bucket once.

use glam::Vec3;

/// A hashed grid over points for queries with one fixed radius.
#[derive(Clone, Debug, Default)]
pub struct HashGrid {
    radius2: f32,
    inv_cell: f32,
    origin: Vec3,
    /// `starts[b]..starts[b + 1]` indexes `entries` for bucket `b`.
    starts: Vec<u32>,
    /// (position, caller's index), sorted by bucket.
    entries: Vec<(Vec3, u32)>,
}

impl HashGrid {
    /// Builds the grid over `points` (the caller's index of a point is its
    /// position in the slice) for queries of radius `radius`.
    pub fn build(&mut self, points: impl ExactSizeIterator<Item = Vec3> + Clone, radius: f32) {
        self.radius2 = radius * radius;
        self.inv_cell = 0.5 / radius;
        self.entries.clear();
        let n = points.len();
        let buckets = n.max(1);
        self.starts.clear();
        self.starts.resize(buckets + 1, 0);
        if n == 0 {
            return;
        }
        self.origin = points
            .clone()
            .fold(Vec3::splat(f32::INFINITY), |lo, p| lo.min(p));
        // Counting sort by bucket: counts, prefix sums, stable placement.
        let bucket_of: Vec<u32> = points.clone().map(|p| self.bucket(self.cell(p))).collect();
        for &b in &bucket_of {
            self.starts[b as usize + 1] += 1;
        }
        for b in 0..buckets {
            self.starts[b + 1] += self.starts[b];
        }
        let mut next = self.starts.clone();
        self.entries.resize(n, (Vec3::ZERO, 0));
        for (i, (p, &b)) in points.zip(&bucket_of).enumerate() {
            let slot = &mut next[b as usize];
            self.entries[*slot as usize] = (p, i as u32);
            *slot += 1;
        }
    }

    /// Calls `visit(index, distance²)` for every point within the radius
    /// of `p` (distance² ≤ r²), bucket by bucket in a fixed order.
    pub fn query(&self, p: Vec3, mut visit: impl FnMut(u32, f32)) {
        if self.entries.is_empty() {
            return;
        }
        // The cell of p and, per axis, the neighbour on the side of the
        // nearer half: these 2×2×2 cells cover the ball.
        let c = (p - self.origin) * self.inv_cell;
        let base = c.floor();
        let frac = c - base;
        let lo = [0, 1, 2].map(|k| base[k] as i32 - i32::from(frac[k] < 0.5));
        let mut buckets = [0u32; 8];
        for (k, b) in buckets.iter_mut().enumerate() {
            let cell = [
                lo[0] + (k & 1) as i32,
                lo[1] + ((k >> 1) & 1) as i32,
                lo[2] + ((k >> 2) & 1) as i32,
            ];
            *b = self.bucket(cell);
        }
        buckets.sort_unstable();
        let mut prev = u32::MAX;
        for &b in &buckets {
            if b == prev {
                continue;
            }
            prev = b;
            let range = self.starts[b as usize] as usize..self.starts[b as usize + 1] as usize;
            for &(q, i) in &self.entries[range] {
                let d2 = (q - p).length_squared();
                if d2 <= self.radius2 {
                    visit(i, d2);
                }
            }
        }
    }

    /// Integer cell coordinates of `p`.
    fn cell(&self, p: Vec3) -> [i32; 3] {
        let c = ((p - self.origin) * self.inv_cell).floor();
        [c.x as i32, c.y as i32, c.z as i32]
    }

    /// The bucket of a cell.
    fn bucket(&self, cell: [i32; 3]) -> u32 {
        let h = (cell[0] as u32).wrapping_mul(73_856_093)
            ^ (cell[1] as u32).wrapping_mul(19_349_663)
            ^ (cell[2] as u32).wrapping_mul(83_492_791);
        h % (self.starts.len() as u32 - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::{IndependentSource, RandomSource};
    use rand::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// Every query returns exactly the points a linear scan finds, each once.
    #[test]
    fn queries_match_a_linear_scan() {
        let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(3));
        let mut point = || Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d());
        for &(n, r) in &[
            (0usize, 0.1f32),
            (1, 0.5),
            (500, 0.05),
            (5000, 0.02),
            (300, 2.0),
        ] {
            let pts: Vec<Vec3> = (0..n).map(|_| point() * 2.0 - 1.0).collect();
            let mut grid = HashGrid::default();
            grid.build(pts.iter().copied(), r);
            for _ in 0..300 {
                let q = point() * 2.4 - 1.2;
                let mut found = Vec::new();
                grid.query(q, |i, d2| {
                    assert_eq!(d2, (pts[i as usize] - q).length_squared());
                    found.push(i);
                });
                found.sort_unstable();
                let expected: Vec<u32> = (0..n as u32)
                    .filter(|&i| (pts[i as usize] - q).length_squared() <= r * r)
                    .collect();
                assert_eq!(found, expected, "n {n}, r {r}, q {q}");
            }
        }
    }
}
