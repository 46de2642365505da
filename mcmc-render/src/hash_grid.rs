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
//! a bucket: the query visits each bucket once, in increasing order.
//!
//! Two things keep a query cheap without changing which points it reports
//! or their order: cells of the 2 × 2 × 2 block that the ball does not
//! reach (on average 1.1 of the 8) are not looked up, and the bucket of a
//! cell is reduced modulo the table size by Lemire's multiply-based
//! `fastmod` instead of an integer division (eight per query).

use glam::Vec3;

/// A hashed grid over points for queries with one fixed radius.
#[derive(Clone, Debug, Default)]
pub struct HashGrid {
    radius2: f32,
    inv_cell: f32,
    origin: Vec3,
    /// Number of buckets (`starts.len() − 1`).
    buckets: u32,
    /// Lemire's `fastmod` multiplier for `buckets`: `⌊(2⁶⁴ − 1)/buckets⌋ + 1`.
    mod_m: u64,
    /// `starts[b]..starts[b + 1]` indexes `entries` for bucket `b`.
    starts: Vec<u32>,
    /// (position, caller's index), sorted by bucket.
    entries: Vec<(Vec3, u32)>,
}

/// `h mod d` for the `m = fastmod_multiplier(d)` of `d ≥ 1` (Lemire, Kaser
/// & Kurz 2019, "Faster remainder by direct computation": exact for every
/// 32-bit `h` and `d` with a 64-bit `m`).
fn fastmod(h: u32, m: u64, d: u32) -> u32 {
    let low = m.wrapping_mul(u64::from(h));
    ((u128::from(low) * u128::from(d)) >> 64) as u32
}

/// The multiplier of [`fastmod`] for divisor `d ≥ 1`.
fn fastmod_multiplier(d: u32) -> u64 {
    (u64::MAX / u64::from(d)).wrapping_add(1)
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
        self.buckets = buckets as u32;
        self.mod_m = fastmod_multiplier(self.buckets);
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
    /// of `p` (distance² ≤ r²), bucket by bucket in increasing bucket
    /// order, each bucket's points in their original order.
    pub fn query(&self, p: Vec3, mut visit: impl FnMut(u32, f32)) {
        if self.entries.is_empty() {
            return;
        }
        // The cell of p and, per axis, the neighbour on the side of the
        // nearer half: these 2×2×2 cells cover the ball. In cell units the
        // radius is 1/2, and the neighbour along axis k is `near[k]` away.
        let c = (p - self.origin) * self.inv_cell;
        let base = c.floor();
        let frac = c - base;
        let lower = frac.cmplt(Vec3::splat(0.5));
        let near = Vec3::select(lower, frac, Vec3::ONE - frac);
        // Rounding of the cell coordinates (of p and of a stored point, each
        // within a few ulps of |c|) must never skip a cell that holds a point
        // within the radius: shrink the distances by a margin well above it.
        let slack = 16.0 * f32::EPSILON * (c.abs().max_element() + 2.0);
        let near2 = (near - Vec3::splat(slack)).max(Vec3::ZERO);
        let near2 = near2 * near2;
        let reach = 0.25 * (1.0 + 1e-4);
        let lo = [0, 1, 2].map(|k| base[k] as i32 - i32::from(lower.test(k)));
        // Offset (0 or 1) of p's own cell in the block, per axis.
        let own = [0, 1, 2].map(|k| usize::from(lower.test(k)));
        let mut buckets = [0u32; 8];
        let mut count = 0;
        for k in 0..8usize {
            let bits = [k & 1, (k >> 1) & 1, (k >> 2) & 1];
            let mut d2 = 0.0;
            for a in 0..3 {
                if bits[a] != own[a] {
                    d2 += near2[a];
                }
            }
            if d2 > reach {
                continue;
            }
            let cell = [
                lo[0] + bits[0] as i32,
                lo[1] + bits[1] as i32,
                lo[2] + bits[2] as i32,
            ];
            buckets[count] = self.bucket(cell);
            count += 1;
        }
        let buckets = &mut buckets[..count];
        buckets.sort_unstable();
        let mut prev = u32::MAX;
        for &b in buckets.iter() {
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
        fastmod(h, self.mod_m, self.buckets)
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

    /// The visit order of the query before cells were skipped: all eight
    /// cells of the block, buckets sorted and deduplicated, `%` for the
    /// table size. The order fixes the order of floating-point sums in
    /// `vcm`, so it must not change. `corner = false` leaves out the block's
    /// cell diagonally opposite p's (the control).
    fn query_every_cell(grid: &HashGrid, p: Vec3, corner: bool) -> Vec<(u32, f32)> {
        let mut out = Vec::new();
        let c = (p - grid.origin) * grid.inv_cell;
        let base = c.floor();
        let frac = c - base;
        let lo = [0, 1, 2].map(|k| base[k] as i32 - i32::from(frac[k] < 0.5));
        let opposite = (0..3).fold(0, |k, a| k | (usize::from(frac[a] >= 0.5) << a));
        let mut buckets: Vec<u32> = (0..8usize)
            .filter(|&k| corner || k != opposite)
            .map(|k| {
                let cell = [
                    lo[0] + (k & 1) as i32,
                    lo[1] + ((k >> 1) & 1) as i32,
                    lo[2] + ((k >> 2) & 1) as i32,
                ];
                let h = (cell[0] as u32).wrapping_mul(73_856_093)
                    ^ (cell[1] as u32).wrapping_mul(19_349_663)
                    ^ (cell[2] as u32).wrapping_mul(83_492_791);
                h % grid.buckets
            })
            .collect();
        buckets.sort_unstable();
        buckets.dedup();
        for b in buckets {
            let range = grid.starts[b as usize] as usize..grid.starts[b as usize + 1] as usize;
            for &(q, i) in &grid.entries[range] {
                let d2 = (q - p).length_squared();
                if d2 <= grid.radius2 {
                    out.push((i, d2));
                }
            }
        }
        out
    }

    /// Skipping unreachable cells and `fastmod` leave the visit sequence
    /// exactly as it was, also for points and queries placed on and next
    /// to cell faces (where a wrong skip would show), far from the origin
    /// and for tiny radii. Control: leaving out the diagonally opposite
    /// cell (which the new query skips most often) must change some
    /// results, or the lattice would not test the skipping.
    #[test]
    fn visit_order_is_unchanged_by_cell_skipping() {
        let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(11));
        for &(r, offset, n) in &[
            (0.05f32, 0.0f32, 4000usize),
            (0.003, 100.0, 4000),
            (1e-4, -37.5, 3000),
            (0.5, 0.0, 3000),
        ] {
            let cell = 2.0 * r;
            // Points on a lattice of cell faces, each coordinate jittered by
            // a few ulps or up to a fifth of a cell, and uniform ones.
            let mut pts = Vec::with_capacity(n);
            for i in 0..n {
                let p = if i % 2 == 0 {
                    let mut c = [0.0f32; 3];
                    for x in &mut c {
                        let k = (rng.next_1d() * 8.0).floor();
                        let jitter = if rng.next_1d() < 0.5 {
                            (rng.next_1d() - 0.5) * 1e-6 * cell
                        } else {
                            (rng.next_1d() - 0.5) * 0.4 * cell
                        };
                        *x = k * cell + jitter;
                    }
                    Vec3::from(c)
                } else {
                    Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 8.0 * cell
                };
                pts.push(p + Vec3::splat(offset));
            }
            let mut grid = HashGrid::default();
            grid.build(pts.iter().copied(), r);
            let (mut hits, mut control_differs) = (0, 0);
            for i in 0..2000 {
                // Queries at the points themselves and at face-lattice spots.
                let q = if i % 2 == 0 {
                    pts[(rng.next_1d() * n as f32) as usize % n]
                } else {
                    Vec3::new(rng.next_1d(), rng.next_1d(), rng.next_1d()) * 8.0 * cell
                        + Vec3::splat(offset)
                };
                let mut got = Vec::new();
                grid.query(q, |i, d2| got.push((i, d2)));
                let expected = query_every_cell(&grid, q, true);
                hits += expected.len();
                control_differs += usize::from(query_every_cell(&grid, q, false) != expected);
                assert_eq!(got, expected, "r {r}, offset {offset}, q {q}");
            }
            assert!(hits > 1000, "the lattice must make many hits ({hits})");
            assert!(
                control_differs > 0,
                "r {r}: no query needs the opposite cell"
            );
        }
    }

    /// `fastmod` is `%` for every divisor size the grid uses.
    #[test]
    fn fastmod_is_the_remainder() {
        let mut rng = IndependentSource::new(Xoshiro256PlusPlus::seed_from_u64(5));
        for d in [
            1u32,
            2,
            3,
            7,
            1000,
            65_536,
            65_537,
            1 << 20,
            3_000_017,
            u32::MAX,
        ] {
            let m = fastmod_multiplier(d);
            for h in [0u32, 1, d - 1, d, u32::MAX, u32::MAX - 1] {
                assert_eq!(fastmod(h, m, d), h % d, "h {h}, d {d}");
            }
            for _ in 0..10_000 {
                let h = (rng.next_1d() as f64 * 4_294_967_296.0) as u32 ^ (rng.next_1d().to_bits());
                assert_eq!(fastmod(h, m, d), h % d, "h {h}, d {d}");
            }
        }
    }
}
