//! Scene geometry: triangles, analytic spheres and disks in one BVH (built
//! by obvhs, traversed as a four-wide BVH, see [`bvh4`]), with closest-hit
//! and occlusion queries.
//!
//! Self-intersection is avoided the pbrt-v4 way, without any scene-scale
//! epsilon: every hit point carries a conservative bound on its floating-
//! point error, and rays leave a surface from a point pushed along the
//! geometric normal just past that bound ([`offset_ray_origin`]).

mod bvh4;
mod tri_pack;

use bvh4::Bvh4;
use glam::{Mat4, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use std::time::{Duration, Instant};
use tri_pack::TriPack;

/// A ray with origin, unit direction and a maximum distance.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Origin.
    pub o: Vec3,
    /// Unit direction.
    pub d: Vec3,
    /// Smallest accepted hit distance.
    pub tmin: f32,
    /// Largest accepted hit distance.
    pub tmax: f32,
}

impl Ray {
    /// A ray from `o` along the unit direction `d`.
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray {
            o,
            d,
            tmin: 0.0,
            tmax: f32::INFINITY,
        }
    }

    /// Point at distance `t`.
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// `γ(n)` of pbrt: bound on the relative error of `n` floating-point operations.
pub fn gamma(n: i32) -> f32 {
    let e = f32::EPSILON * 0.5;
    n as f32 * e / (1.0 - n as f32 * e)
}

/// pbrt-v4's `OffsetRayOrigin`: moves `p` along `n` by the error bound
/// projected on the normal, to the side `w` leaves through, then rounds
/// away from the surface so the new origin is provably off it.
#[inline]
pub fn offset_ray_origin(p: Vec3, p_err: Vec3, n: Vec3, w: Vec3) -> Vec3 {
    let d = n.abs().dot(p_err);
    let mut offset = n * d;
    if w.dot(n) < 0.0 {
        offset = -offset;
    }
    let po = p + offset;
    Vec3::new(
        ulp_step(po.x, offset.x),
        ulp_step(po.y, offset.y),
        ulp_step(po.z, offset.z),
    )
}

/// `x` moved one ulp towards +∞ when `dir > 0` and towards −∞ when
/// `dir < 0` (pbrt's `NextFloatUp`/`NextFloatDown`, as `f32::next_up` and
/// `next_down`); unchanged when `dir` is zero or `x` is not finite. Written
/// on the bits directly: ray spawning calls it three times per ray.
#[inline(always)]
fn ulp_step(x: f32, dir: f32) -> f32 {
    if dir == 0.0 || !x.is_finite() {
        return x;
    }
    let bits = x.to_bits();
    if bits & 0x7fff_ffff == 0 {
        // ±0 steps to the smallest subnormal of `dir`'s sign.
        return f32::from_bits(1).copysign(dir);
    }
    // Same signs: the magnitude grows (one more ulp); else it shrinks.
    let away = (bits >> 31) == (dir.to_bits() >> 31);
    f32::from_bits(if away { bits + 1 } else { bits - 1 })
}

/// `Geometry::leaf_pack` entry of a leaf without a triangle pack.
const NO_PACK: u32 = u32::MAX;

/// One primitive as stored in BVH order.
#[derive(Clone, Copy, Debug)]
enum Prim {
    /// Vertices in SIMD vectors (the test then needs about half the
    /// instructions of the scalar form); 64 bytes, one cache line.
    Triangle {
        v0: Vec3A,
        e1: Vec3A,
        e2: Vec3A,
        shape: u32,
        /// Index of the triangle in its mesh.
        tri: u32,
    },
    Sphere {
        center: Vec3,
        radius: f32,
        shape: u32,
    },
    Disk {
        shape: u32,
    },
}

/// A triangle mesh in world space, for shading-normal interpolation and
/// emitter sampling.
#[derive(Clone, Debug)]
pub struct MeshData {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (`None`: flat shading).
    pub normals: Option<Vec<Vec3>>,
    /// Triangles.
    pub indices: Vec<[u32; 3]>,
}

/// The analytic surface a shape is made of.
#[derive(Clone, Debug)]
pub enum Surface {
    /// Triangle mesh.
    Mesh(MeshData),
    /// Sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius.
        radius: f32,
    },
    /// Mitsuba's disk: the unit disk in z = 0 mapped by `to_world`.
    Disk {
        /// Object to world.
        to_world: Mat4,
        /// World to object.
        to_local: Mat4,
        /// Unit world-space normal (of object +z).
        normal: Vec3,
    },
}

impl Surface {
    /// Total surface area.
    pub fn area(&self) -> f32 {
        match self {
            Surface::Mesh(m) => m.indices.iter().map(|t| triangle_area(m, t)).sum(),
            Surface::Sphere { radius, .. } => 4.0 * std::f32::consts::PI * radius * radius,
            Surface::Disk { to_world, .. } => {
                std::f32::consts::PI
                    * to_world
                        .x_axis
                        .truncate()
                        .cross(to_world.y_axis.truncate())
                        .length()
            }
        }
    }
}

/// Area of one triangle of a mesh.
pub fn triangle_area(m: &MeshData, t: &[u32; 3]) -> f32 {
    let [a, b, c] = t.map(|i| m.positions[i as usize]);
    0.5 * (b - a).cross(c - a).length()
}

/// A geometric shape with its orientation flag.
#[derive(Clone, Debug)]
pub struct GeoShape {
    /// The surface.
    pub surface: Surface,
    /// Mitsuba's `flip_normals`.
    pub flip_normals: bool,
}

/// A point on a surface with its local geometry.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// Position.
    pub p: Vec3,
    /// Conservative absolute error bound of `p`, per axis.
    pub p_err: Vec3,
    /// Unit geometric normal (oriented as the shape's normals, after `flip_normals`).
    pub ng: Vec3,
    /// Unit shading normal, on the same side as `ng`.
    pub ns: Vec3,
    /// Index of the shape.
    pub shape: u32,
}

impl SurfacePoint {
    /// Ray leaving this point in unit direction `d`.
    pub fn spawn_ray(&self, d: Vec3) -> Ray {
        Ray::new(offset_ray_origin(self.p, self.p_err, self.ng, d), d)
    }

    /// Origin for a segment leaving towards `target`.
    pub fn spawn_origin(&self, target: Vec3) -> Vec3 {
        offset_ray_origin(self.p, self.p_err, self.ng, target - self.p)
    }
}

/// A closest-hit result: distance and where on which primitive.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    prim: u32,
    u: f32,
    v: f32,
}

/// Shapes plus their BVH.
pub struct Geometry {
    /// Shapes, indexed by shape id.
    pub shapes: Vec<GeoShape>,
    prims: Vec<Prim>,
    bvh: Bvh4,
    /// Unit face normal of every mesh triangle, per shape (empty for
    /// non-meshes): computed once instead of a square root and a division
    /// at every hit.
    face_normals: Vec<Vec<Vec3>>,
    /// Triangles of the leaves made only of (at most four) triangles.
    packs: Vec<TriPack>,
    /// Index into `packs` of the leaf starting at each primitive index
    /// (`NO_PACK`: the leaf is tested primitive by primitive).
    leaf_pack: Vec<u32>,
    /// Wall-clock time of the BVH build.
    pub build_time: Duration,
    /// Total triangle count.
    pub triangles: usize,
}

impl Geometry {
    /// Builds the BVH over all shapes (parallel build through rayon).
    pub fn build(shapes: Vec<GeoShape>) -> Geometry {
        let mut prims = Vec::new();
        let mut aabbs = Vec::new();
        let mut triangles = 0;
        for (s, shape) in shapes.iter().enumerate() {
            let s = s as u32;
            match &shape.surface {
                Surface::Mesh(m) => {
                    triangles += m.indices.len();
                    for (i, t) in m.indices.iter().enumerate() {
                        let [a, b, c] = t.map(|k| m.positions[k as usize]);
                        let mut bb = Aabb::from_point(a.into());
                        bb.extend(b.into()).extend(c.into());
                        aabbs.push(bb);
                        prims.push(Prim::Triangle {
                            v0: a.into(),
                            e1: (b - a).into(),
                            e2: (c - a).into(),
                            shape: s,
                            tri: i as u32,
                        });
                    }
                }
                Surface::Sphere { center, radius } => {
                    let r = Vec3::splat(*radius);
                    aabbs.push(Aabb::new((*center - r).into(), (*center + r).into()));
                    prims.push(Prim::Sphere {
                        center: *center,
                        radius: *radius,
                        shape: s,
                    });
                }
                Surface::Disk { to_world, .. } => {
                    let mut bb = Aabb::empty();
                    for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                        bb.extend(to_world.transform_point3(Vec3::new(x, y, 0.0)).into());
                    }
                    aabbs.push(bb);
                    prims.push(Prim::Disk { shape: s });
                }
            }
        }
        // Small scenes afford the slowest, best-quality build (it takes
        // milliseconds there); large ones use obvhs's balanced preset.
        let mut params = if aabbs.len() < 10_000 {
            BvhBuildParams::very_slow_build()
        } else {
            BvhBuildParams::medium_build()
        };
        // Small leaves: the four-wide box test is cheaper than a triangle
        // test, so splitting down to one or two primitives per leaf pays
        // (obvhs's presets aim at eight-primitive leaves). On the Cornell
        // box this halves the instructions per closest-hit ray.
        params.max_prims_per_leaf = 4;
        params.collapse_traversal_cost = 1.0;
        let start = Instant::now();
        let (bvh, order) = Bvh4::build(&aabbs, params);
        // Store primitives in BVH order so leaves index them directly.
        let prims: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
        let face_normals = shapes
            .iter()
            .map(|s| match &s.surface {
                Surface::Mesh(m) => m
                    .indices
                    .iter()
                    .map(|t| {
                        let [p0, p1, p2] = t.map(|i| m.positions[i as usize]);
                        (p1 - p0).cross(p2 - p0).normalize()
                    })
                    .collect(),
                _ => Vec::new(),
            })
            .collect();
        let mut packs = Vec::new();
        let mut leaf_pack = vec![NO_PACK; prims.len()];
        for leaf in bvh.leaves() {
            let tris: Option<Vec<(Vec3, Vec3, Vec3)>> = prims[leaf.clone()]
                .iter()
                .map(|p| match *p {
                    Prim::Triangle { v0, e1, e2, .. } => Some((v0.into(), e1.into(), e2.into())),
                    _ => None,
                })
                .collect();
            if let Some(tris) = tris
                && tris.len() <= tri_pack::LANES
            {
                leaf_pack[leaf.start] = packs.len() as u32;
                packs.push(TriPack::new(&tris));
            }
        }
        Geometry {
            shapes,
            prims,
            bvh,
            face_normals,
            packs,
            leaf_pack,
            build_time: start.elapsed(),
            triangles,
        }
    }

    /// Bytes used by the BVH nodes, the primitive array and the index array.
    pub fn bvh_bytes(&self) -> usize {
        self.bvh.bytes()
            + std::mem::size_of_val(self.prims.as_slice())
            + std::mem::size_of_val(self.packs.as_slice())
            + std::mem::size_of_val(self.leaf_pack.as_slice())
    }

    /// Number of primitives in the BVH.
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
    }

    #[inline(always)]
    fn intersect_prim(
        &self,
        prim: &Prim,
        o: Vec3A,
        d: Vec3A,
        tmin: f32,
        tmax: f32,
    ) -> (f32, f32, f32) {
        const MISS: (f32, f32, f32) = (f32::INFINITY, 0.0, 0.0);
        match *prim {
            Prim::Triangle { v0, e1, e2, .. } => {
                // Möller–Trumbore, with the barycentric tests done on the
                // unnormalised values (scaled by |det|) so that the
                // division, a long-latency operation, is only paid by rays
                // that pass them.
                let pv = d.cross(e2);
                let det = e1.dot(pv);
                if det == 0.0 || !det.is_finite() {
                    return MISS;
                }
                let tv = o - v0;
                let qv = tv.cross(e1);
                let (su, sv) = (tv.dot(pv), d.dot(qv));
                let (au, av, adet) = if det > 0.0 {
                    (su, sv, det)
                } else {
                    (-su, -sv, -det)
                };
                if !(au >= 0.0 && av >= 0.0 && au + av <= adet) {
                    return MISS;
                }
                let inv = 1.0 / det;
                let (u, v) = (su * inv, sv * inv);
                let t = e2.dot(qv) * inv;
                if t > tmin && t < tmax {
                    (t, u, v)
                } else {
                    MISS
                }
            }
            Prim::Sphere { center, radius, .. } => {
                let (o, d) = (Vec3::from(o), Vec3::from(d));
                // In f64: `o − center` loses all precision of a small sphere
                // far from the origin in f32, and a spawned ray could then
                // find its own surface again. The Hearn–Baker discriminant
                // (from the perpendicular distance) avoids cancellation.
                let oc = o.as_dvec3() - center.as_dvec3();
                let d = d.as_dvec3();
                let r = radius as f64;
                let b = oc.dot(d);
                let perp = oc - d * b;
                let disc = r * r - perp.length_squared();
                if disc < 0.0 {
                    return MISS;
                }
                let c = oc.length_squared() - r * r;
                let sq = disc.sqrt();
                let q = if b > 0.0 { -b - sq } else { -b + sq };
                let (mut t0, mut t1) = if q == 0.0 { (0.0, 0.0) } else { (c / q, q) };
                if t0 > t1 {
                    std::mem::swap(&mut t0, &mut t1);
                }
                let (t0, t1) = (t0 as f32, t1 as f32);
                if t0 > tmin && t0 < tmax {
                    (t0, 0.0, 0.0)
                } else if t1 > tmin && t1 < tmax {
                    (t1, 0.0, 0.0)
                } else {
                    MISS
                }
            }
            Prim::Disk { shape } => {
                let Surface::Disk { to_local, .. } = &self.shapes[shape as usize].surface else {
                    return MISS;
                };
                let lo = to_local.transform_point3(o.into());
                let ld = to_local.transform_vector3(d.into());
                if ld.z == 0.0 {
                    return MISS;
                }
                let t = -lo.z / ld.z;
                if !(t > tmin && t < tmax) {
                    return MISS;
                }
                let x = lo.x + t * ld.x;
                let y = lo.y + t * ld.y;
                if x * x + y * y > 1.0 {
                    return MISS;
                }
                (t, x, y)
            }
        }
    }

    /// Closest hit along `ray`, if any.
    pub fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let (o, d, tmin) = (ray.o, ray.d, ray.tmin);
        let mut uv = (0.0, 0.0);
        // The leaf test is inlined into the traversal loop (a call per leaf
        // and the ray kept in memory for it cost more than the test).
        let (prim, t) = self.bvh.closest(
            o,
            d,
            tmin,
            ray.tmax,
            #[inline(always)]
            |ray4, leaf, tmax| {
                let (prim, t, u, v) = if let Some(pack) = self.leaf_pack_of(&leaf) {
                    let (lane, t, u, v) = pack.intersect(ray4, tmin, tmax)?;
                    (leaf.start + lane, t, u, v)
                } else {
                    self.leaf_closest(leaf, ray, tmax)?
                };
                // The traversal keeps the last hit returned, so `uv` is its.
                uv = (u, v);
                Some((prim, t))
            },
        )?;
        Some(Hit {
            t,
            prim: prim as u32,
            u: uv.0,
            v: uv.1,
        })
    }

    /// The triangle pack of a BVH leaf, if it has one.
    #[inline(always)]
    fn leaf_pack_of(&self, leaf: &std::ops::Range<usize>) -> Option<&TriPack> {
        // SAFETY: BVH leaves are non-empty ranges of `prims`, and
        // `leaf_pack` has one entry per primitive (both set in `build`).
        let pack = unsafe { *self.leaf_pack.get_unchecked(leaf.start) };
        // SAFETY: entries other than `NO_PACK` index `packs` (`build`).
        (pack != NO_PACK).then(|| unsafe { self.packs.get_unchecked(pack as usize) })
    }

    /// Closest hit `(prim, t, u, v)` with `tmin < t < tmax` among a leaf's
    /// primitives, one by one. Kept out of line so that the set-up of the
    /// sphere and disk tests is not hoisted into every ray's traversal.
    #[inline(never)]
    fn leaf_closest(
        &self,
        leaf: std::ops::Range<usize>,
        ray: &Ray,
        tmax: f32,
    ) -> Option<(usize, f32, f32, f32)> {
        // The ray is passed by reference: values passed here would be kept
        // (spilled) through the whole traversal.
        let (oa, da, tmin) = (Vec3A::from(ray.o), Vec3A::from(ray.d), ray.tmin);
        let mut best = None;
        let mut tmax = tmax;
        for id in leaf {
            let (t, u, v) = self.intersect_prim(&self.prims[id], oa, da, tmin, tmax);
            if t < tmax {
                tmax = t;
                best = Some((id, t, u, v));
            }
        }
        best
    }

    /// True when something blocks `ray` strictly before `ray.tmax`.
    pub fn occluded(&self, ray: &Ray) -> bool {
        let (o, d, tmin, tmax) = (ray.o, ray.d, ray.tmin, ray.tmax);
        self.bvh.any(
            o,
            d,
            tmin,
            tmax,
            #[inline(always)]
            |ray4, leaf| {
                if let Some(pack) = self.leaf_pack_of(&leaf) {
                    pack.occludes(ray4, tmin, tmax)
                } else {
                    self.leaf_blocks(leaf, ray)
                }
            },
        )
    }

    /// True when a primitive of the leaf is hit with `tmin < t < tmax`;
    /// out of line for the same reason as [`Self::leaf_closest`].
    #[inline(never)]
    fn leaf_blocks(&self, leaf: std::ops::Range<usize>, ray: &Ray) -> bool {
        let (oa, da) = (Vec3A::from(ray.o), Vec3A::from(ray.d));
        let (tmin, tmax) = (ray.tmin, ray.tmax);
        leaf.into_iter()
            .any(|id| self.intersect_prim(&self.prims[id], oa, da, tmin, tmax).0 < tmax)
    }

    /// True when the segment between two surface points (each offset off
    /// its own surface) is unobstructed.
    pub fn visible(&self, a: &SurfacePoint, b: &SurfacePoint) -> bool {
        let pa = a.spawn_origin(b.p);
        let pb = b.spawn_origin(pa);
        self.segment_clear(pa, pb)
    }

    /// True when nothing lies strictly between the two points.
    pub fn segment_clear(&self, from: Vec3, to: Vec3) -> bool {
        let delta = to - from;
        let dist = delta.length();
        if !(dist > 0.0) || !dist.is_finite() {
            return dist == 0.0;
        }
        let mut ray = Ray::new(from, delta / dist);
        // Stop short of the target point by a relative margin (pbrt's
        // ShadowEpsilon), so the far surface itself never counts as a blocker.
        ray.tmax = dist * (1.0 - 1e-4);
        !self.occluded(&ray)
    }

    /// The surface point of a hit, with its error bound and normals.
    pub fn surface_point(&self, ray: &Ray, hit: &Hit) -> SurfacePoint {
        match self.prims[hit.prim as usize] {
            Prim::Triangle { shape, tri, .. } => {
                self.triangle_point(shape, tri, 1.0 - hit.u - hit.v, hit.u, hit.v)
            }
            Prim::Sphere { shape, .. } => self.sphere_point(shape, ray.at(hit.t)),
            Prim::Disk { shape } => self.disk_point(shape, hit.u, hit.v),
        }
    }

    /// Point of a mesh triangle at barycentrics (b0, b1, b2).
    pub fn triangle_point(&self, shape: u32, tri: u32, b0: f32, b1: f32, b2: f32) -> SurfacePoint {
        let gs = &self.shapes[shape as usize];
        let Surface::Mesh(m) = &gs.surface else {
            unreachable!("triangle primitive on a non-mesh shape")
        };
        let idx = m.indices[tri as usize];
        let [p0, p1, p2] = idx.map(|i| m.positions[i as usize]);
        let p = p0 * b0 + p1 * b1 + p2 * b2;
        let p_err = ((p0 * b0).abs() + (p1 * b1).abs() + (p2 * b2).abs()) * gamma(7);
        let mut ng = self.face_normals[shape as usize][tri as usize];
        let mut ns = match &m.normals {
            Some(n) => {
                let [n0, n1, n2] = idx.map(|i| n[i as usize]);
                (n0 * b0 + n1 * b1 + n2 * b2).try_normalize().unwrap_or(ng)
            }
            None => ng,
        };
        if m.normals.is_some() && ng.dot(ns) < 0.0 {
            // Keep the geometric normal on the side the file's normals choose.
            ng = -ng;
        }
        if gs.flip_normals {
            ng = -ng;
            ns = -ns;
        }
        SurfacePoint {
            p,
            p_err,
            ng,
            ns,
            shape,
        }
    }

    /// Point on a sphere near `p_guess` (reprojected onto the surface).
    pub fn sphere_point(&self, shape: u32, p_guess: Vec3) -> SurfacePoint {
        let gs = &self.shapes[shape as usize];
        let Surface::Sphere { center, radius } = gs.surface else {
            unreachable!("sphere primitive on a non-sphere shape")
        };
        let local = p_guess - center;
        let len = local.length();
        let local = if len > 0.0 {
            local * (radius / len)
        } else {
            Vec3::new(0.0, 0.0, radius)
        };
        let p = center + local;
        // Object-space reprojection error plus the translation by the centre
        // (pbrt's transform bound).
        let p_err = local.abs() * gamma(5) + (center.abs() + local.abs()) * gamma(3);
        let mut n = (local / radius).normalize();
        if gs.flip_normals {
            n = -n;
        }
        SurfacePoint {
            p,
            p_err,
            ng: n,
            ns: n,
            shape,
        }
    }

    /// Point on a disk at object-space (x, y).
    pub fn disk_point(&self, shape: u32, x: f32, y: f32) -> SurfacePoint {
        let gs = &self.shapes[shape as usize];
        let Surface::Disk {
            to_world, normal, ..
        } = &gs.surface
        else {
            unreachable!("disk primitive on a non-disk shape")
        };
        let p = to_world.transform_point3(Vec3::new(x, y, 0.0));
        let p_err = ((to_world.x_axis.truncate() * x).abs()
            + (to_world.y_axis.truncate() * y).abs()
            + to_world.w_axis.truncate().abs())
            * gamma(4);
        let n = if gs.flip_normals { -*normal } else { *normal };
        SurfacePoint {
            p,
            p_err,
            ng: n,
            ns: n,
            shape,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::Frame;
    use crate::warp::uniform_sphere;

    fn lcg(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*state >> 40) as f32) / (1u64 << 24) as f32
    }

    /// The bit-level ulp step equals the standard library's `next_up` /
    /// `next_down` on zeros, subnormals, normals of both signs and the
    /// largest finite values.
    #[test]
    fn ulp_step_matches_next_up_and_next_down() {
        let xs = [
            0.0f32,
            -0.0,
            f32::from_bits(1),
            -f32::from_bits(1),
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1.0,
            -1.0,
            0.3,
            -123.456,
            f32::MAX,
            f32::MIN,
        ];
        for x in xs {
            for dir in [1.0f32, -1e-30, 0.0, -0.0] {
                let want = if dir > 0.0 {
                    x.next_up()
                } else if dir < 0.0 {
                    x.next_down()
                } else {
                    x
                };
                assert_eq!(
                    ulp_step(x, dir).to_bits(),
                    want.to_bits(),
                    "x={x} dir={dir}"
                );
            }
        }
    }

    /// Rays from inside a closed sphere must always hit it, and a ray
    /// spawned from the hit point back inside must hit the far side (never
    /// its own origin), at every scale.
    #[test]
    fn rays_inside_a_sphere_always_hit_it_at_any_scale() {
        for (center, radius) in [
            (Vec3::ZERO, 1.0e-4),
            (Vec3::new(1e-3, 2e-3, -1e-3), 1.0e-4),
            (Vec3::ZERO, 1.0),
            (Vec3::new(3e4, -2e4, 1e4), 5e3),
        ] {
            let g = Geometry::build(vec![GeoShape {
                surface: Surface::Sphere { center, radius },
                flip_normals: true,
            }]);
            let mut s = 1u64;
            for _ in 0..20_000 {
                let o = center
                    + uniform_sphere((lcg(&mut s), lcg(&mut s))) * radius * 0.5 * lcg(&mut s);
                let d = uniform_sphere((lcg(&mut s), lcg(&mut s)));
                let ray = Ray::new(o, d);
                let hit = g
                    .intersect(&ray)
                    .unwrap_or_else(|| panic!("r={radius}: ray escaped"));
                let sp = g.surface_point(&ray, &hit);
                assert!(
                    ((sp.p - center).length() - radius).abs() <= 1e-5 * radius.max(center.length())
                );
                let d2 = Frame::from_normal(sp.ng)
                    .to_world(uniform_sphere((lcg(&mut s), lcg(&mut s))).abs());
                let ray2 = sp.spawn_ray(d2);
                let hit2 = g
                    .intersect(&ray2)
                    .unwrap_or_else(|| panic!("r={radius}: bounce escaped"));
                assert!(
                    hit2.t > 1e-3 * radius * d2.dot(sp.ng),
                    "r={radius}: self-hit at t={}",
                    hit2.t
                );
            }
        }
    }
}
