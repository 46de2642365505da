//! Up to four triangles of one BVH leaf tested against a ray at once.
//!
//! The triangles are stored as structure-of-arrays lanes (glam `Vec4`, SSE2
//! on x86-64) and run through the same Möller–Trumbore arithmetic as the
//! scalar test in [`super`], one triangle per lane: a leaf costs about as
//! many instructions as one scalar triangle test.

use glam::{BVec4A, Vec3, Vec4};

/// Lanes of a pack.
pub const LANES: usize = 4;

/// A ray splatted across the lanes.
pub struct Ray4 {
    pub(super) o: [Vec4; 3],
    pub(super) d: [Vec4; 3],
}

impl Ray4 {
    /// The ray with origin `o` and direction `d`.
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> Ray4 {
        Ray4 {
            o: [Vec4::splat(o.x), Vec4::splat(o.y), Vec4::splat(o.z)],
            d: [Vec4::splat(d.x), Vec4::splat(d.y), Vec4::splat(d.z)],
        }
    }
}

/// Up to four triangles `v0 + u·e1 + v·e2`, with their unnormalised
/// normals `n = e2 × e1`; unused lanes hold a degenerate triangle (all
/// zero), which the determinant test rejects.
#[derive(Clone, Copy, Debug)]
pub struct TriPack {
    v0: [Vec4; 3],
    e1: [Vec4; 3],
    e2: [Vec4; 3],
    n: [Vec4; 3],
}

#[inline(always)]
fn cross(a: &[Vec4; 3], b: &[Vec4; 3]) -> [Vec4; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline(always)]
fn dot(a: &[Vec4; 3], b: &[Vec4; 3]) -> Vec4 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl TriPack {
    /// Packs up to four triangles given as `(v0, e1, e2)`.
    pub fn new(tris: &[(Vec3, Vec3, Vec3)]) -> TriPack {
        debug_assert!(tris.len() <= LANES);
        let mut p = TriPack {
            v0: [Vec4::ZERO; 3],
            e1: [Vec4::ZERO; 3],
            e2: [Vec4::ZERO; 3],
            n: [Vec4::ZERO; 3],
        };
        for (lane, &(v0, e1, e2)) in tris.iter().enumerate() {
            let n = e2.cross(e1);
            for axis in 0..3 {
                p.v0[axis][lane] = v0[axis];
                p.e1[axis][lane] = e1[axis];
                p.e2[axis][lane] = e2[axis];
                p.n[axis][lane] = n[axis];
            }
        }
        p
    }

    /// The lanes hit with `tmin < t < tmax` (a non-zero bit mask) with
    /// every lane's `t`, unnormalised barycentrics and `1 / det`.
    #[inline(always)]
    fn hits(&self, ray: &Ray4, tmin: f32, tmax: f32) -> Option<(u32, Vec4, Vec4, Vec4, Vec4)> {
        // Möller–Trumbore rewritten by the scalar triple product around
        // the stored normal (one cross product per ray instead of two):
        // with w = v0 − o and c = d × w,
        //   det = e1·(d × e2) = d·n,   det·u = e2·c,   det·v = −e1·c,
        //   det·t = e2·((o − v0) × e1) = w·n.
        let w = [
            self.v0[0] - ray.o[0],
            self.v0[1] - ray.o[1],
            self.v0[2] - ray.o[2],
        ];
        let c = cross(&ray.d, &w);
        let det = dot(&ray.d, &self.n);
        let su = dot(&self.e2, &c);
        let sv_neg = dot(&self.e1, &c);
        // Barycentric tests scaled by |det| (as the scalar test does), so
        // the division is paid once for the four lanes. Multiplying by ±1
        // with det's sign bit negates exactly where `det < 0`, in fewer
        // operations than a select; where the two differ (det = −0 or
        // NaN) `adet > 0` fails anyway.
        let s = Vec4::ONE.copysign(det);
        let (au, av) = (su * s, sv_neg * -s);
        let adet = det.abs();
        let finite = adet.cmplt(Vec4::INFINITY);
        let inside: BVec4A = adet.cmpgt(Vec4::ZERO)
            & finite
            & au.cmpge(Vec4::ZERO)
            & av.cmpge(Vec4::ZERO)
            & (au + av).cmple(adet);
        if !inside.any() {
            return None;
        }
        let inv = Vec4::ONE / det;
        let t = dot(&w, &self.n) * inv;
        let hit = inside & t.cmpgt(Vec4::splat(tmin)) & t.cmplt(Vec4::splat(tmax));
        let mask = hit.bitmask();
        (mask != 0).then_some((mask, t, su, -sv_neg, inv))
    }

    /// The nearest triangle hit with `tmin < t < tmax`: `(lane, t, u, v)`.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray4, tmin: f32, tmax: f32) -> Option<(usize, f32, f32, f32)> {
        let (mut mask, t, su, sv, inv) = self.hits(ray, tmin, tmax)?;
        let ts = t.to_array();
        let mut lane = mask.trailing_zeros() as usize;
        mask &= mask - 1;
        while mask != 0 {
            let l = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            if ts[l] < ts[lane] {
                lane = l;
            }
        }
        // Barycentrics of all lanes (the same products lane by lane), then
        // one load each: picking single lanes out of three vectors took a
        // jump table on the lane and three shuffles.
        let (u, v) = ((su * inv).to_array(), (sv * inv).to_array());
        Some((lane, ts[lane], u[lane], v[lane]))
    }

    /// True when some triangle is hit with `tmin < t < tmax` (the same
    /// arithmetic as [`Self::intersect`], without choosing the nearest).
    #[inline(always)]
    pub fn occludes(&self, ray: &Ray4, tmin: f32, tmax: f32) -> bool {
        self.hits(ray, tmin, tmax).is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The packed test finds the same nearest triangle, distance and
    /// barycentrics as a plain scalar Möller–Trumbore, lane by lane, for
    /// random rays through random triangles (both orientations).
    #[test]
    fn pack_matches_scalar_moller_trumbore() {
        let mut s = 9u64;
        let mut u = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let scalar = |o: Vec3, d: Vec3, (v0, e1, e2): (Vec3, Vec3, Vec3)| {
            let pv = d.cross(e2);
            let det = e1.dot(pv);
            if det == 0.0 {
                return None;
            }
            let inv = 1.0 / det;
            let tv = o - v0;
            let uu = tv.dot(pv) * inv;
            let qv = tv.cross(e1);
            let vv = d.dot(qv) * inv;
            let t = e2.dot(qv) * inv;
            (uu >= 0.0 && vv >= 0.0 && uu + vv <= 1.0 && t > 0.0).then_some((t, uu, vv))
        };
        let mut hits = 0;
        // About 8% of the rays hit a triangle of their pack.
        for _ in 0..40_000 {
            let n = 1 + (u().abs() * 3.99) as usize;
            let tris: Vec<_> = (0..n)
                .map(|_| {
                    let v0 = Vec3::new(u(), u(), u() + 3.0);
                    (v0, Vec3::new(u(), u(), u()), Vec3::new(u(), u(), u()))
                })
                .collect();
            let o = Vec3::new(u() * 0.2, u() * 0.2, 0.0);
            let d = (Vec3::new(u() * 0.3, u() * 0.3, 1.0)).normalize();
            let pack = TriPack::new(&tris);
            let got = pack.intersect(&Ray4::new(o, d), 0.0, f32::INFINITY);
            let want = tris
                .iter()
                .enumerate()
                .filter_map(|(i, &t)| scalar(o, d, t).map(|h| (i, h)))
                .min_by(|a, b| a.1.0.total_cmp(&b.1.0));
            match (got, want) {
                (None, None) => {}
                (Some((l, t, uu, vv)), Some((i, (t2, u2, v2)))) => {
                    hits += 1;
                    assert_eq!(l, i);
                    assert!((t - t2).abs() <= 1e-5 * t2, "t {t} vs {t2}");
                    assert!((uu - u2).abs() <= 1e-5 && (vv - v2).abs() <= 1e-5);
                }
                // Rays within rounding of an edge may fall either way.
                (g, w) => {
                    let edge = |(tt, uu, vv): (f32, f32, f32)| {
                        let _ = tt;
                        uu.abs() < 1e-5 || vv.abs() < 1e-5 || (1.0 - uu - vv).abs() < 1e-5
                    };
                    let near_edge = g.is_some_and(|(_, t, uu, vv)| edge((t, uu, vv)))
                        || w.is_some_and(|(_, h)| edge(h));
                    assert!(near_edge, "pack {g:?} vs scalar {w:?}");
                }
            }
        }
        assert!(hits > 2_000, "too few hits to test: {hits}");
    }
}
