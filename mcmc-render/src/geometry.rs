//! Scene geometry: triangles, analytic spheres and disks in one BVH (built
//! by obvhs, traversed as a four-wide BVH, see the `bvh4` module), with closest-hit
//! and occlusion queries.
//!
//! Self-intersection is avoided the pbrt-v4 way, without any scene-scale
//! epsilon: every hit point carries a conservative bound on its floating-
//! point error, and rays leave a surface from a point pushed along the
//! geometric normal just past that bound ([`offset_ray_origin`]).

mod bvh4;
pub mod differential;
mod tri_pack;

use bvh4::Bvh4;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec3A};
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
    // The side is chosen on the scalar (exact: n·(−d) = −(n·d)).
    let offset = n * if w.dot(n) < 0.0 { -d } else { d };
    let po = p + offset;
    ulp_step3(po.into(), offset.into()).into()
}

/// [`ulp_step`] on the three lanes at once (SSE2, part of the x86-64
/// baseline: about a third of the instructions of three scalar steps).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn ulp_step3(x: Vec3A, dir: Vec3A) -> Vec3A {
    // SAFETY: the intrinsics only need SSE2, which every x86-64 CPU has
    // (it is enabled in the target's baseline features).
    unsafe {
        use std::arch::x86_64::*;
        // `mask ? a : b` lane by lane (all-ones or all-zero masks).
        let select = |mask: __m128i, a: __m128i, b: __m128i| {
            _mm_or_si128(_mm_and_si128(mask, a), _mm_andnot_si128(mask, b))
        };
        let (xf, df): (__m128, __m128) = (x.into(), dir.into());
        let (bits, dbits) = (_mm_castps_si128(xf), _mm_castps_si128(df));
        let sign = _mm_set1_epi32(i32::MIN);
        let mag = _mm_andnot_si128(sign, bits);
        let is_zero = _mm_cmpeq_epi32(mag, _mm_setzero_si128());
        let base = select(is_zero, _mm_and_si128(dbits, sign), bits);
        // −1 where the signs differ, else 0; the step is then −1 or +1.
        let differ = _mm_srai_epi32::<31>(_mm_xor_si128(base, dbits));
        let step = _mm_or_si128(_mm_slli_epi32::<1>(differ), _mm_set1_epi32(1));
        let keep = _mm_or_si128(
            _mm_castps_si128(_mm_cmpeq_ps(df, _mm_setzero_ps())),
            _mm_cmpgt_epi32(mag, _mm_set1_epi32(0x7f7f_ffff)),
        );
        let out = select(keep, bits, _mm_add_epi32(base, step));
        Vec3A::from(_mm_castsi128_ps(out))
    }
}

/// [`ulp_step`] on the three lanes.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn ulp_step3(x: Vec3A, dir: Vec3A) -> Vec3A {
    Vec3A::new(
        ulp_step(x.x, dir.x),
        ulp_step(x.y, dir.y),
        ulp_step(x.z, dir.z),
    )
}

/// `x` moved one ulp towards +∞ when `dir > 0` and towards −∞ when
/// `dir < 0` (pbrt's `NextFloatUp`/`NextFloatDown`, as `f32::next_up` and
/// `next_down`); unchanged when `dir` is zero or `x` is not finite. Written
/// on the bits directly and without branches (selects only): ray spawning
/// calls it three times per ray.
#[cfg(any(test, not(target_arch = "x86_64")))]
#[inline(always)]
fn ulp_step(x: f32, dir: f32) -> f32 {
    const SIGN: u32 = 0x8000_0000;
    let (bits, dbits) = (x.to_bits(), dir.to_bits());
    let mag = bits & !SIGN;
    // ±0 is first given `dir`'s sign, so that one step away from it is the
    // smallest subnormal of that sign.
    let base = if mag == 0 { dbits & SIGN } else { bits };
    // Same signs: the magnitude grows (one more ulp); else it shrinks.
    let step = if (base ^ dbits) & SIGN == 0 {
        1
    } else {
        u32::MAX
    };
    let keep = dir == 0.0 || mag >= 0x7f80_0000;
    f32::from_bits(if keep { bits } else { base.wrapping_add(step) })
}

/// Relative length by which shadow rays stop short of their target
/// (pbrt's `ShadowEpsilon`): covers the rounding of computed hit distances.
const SHADOW_EPSILON: f32 = 1e-4;

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
    /// Vertex UVs (`None`: a point's UV is its barycentrics `(b1, b2)`,
    /// as Mitsuba 3 gives meshes without texture coordinates).
    pub uvs: Option<Vec<Vec2>>,
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
        /// Rotation from object to world space (the orthonormal part of
        /// `to_world`): UVs are spherical coordinates in object space.
        frame: Mat3,
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
    /// Surface UV as Mitsuba 3 defines it for the shape: interpolated
    /// vertex UVs on meshes that have them, barycentrics `(b1, b2)` on
    /// those that do not, polar (disk) or spherical (sphere) coordinates.
    pub uv: Vec2,
    /// Index of the shape.
    pub shape: u32,
    /// The BVH primitive of a hit point ([`NO_PRIM`] for points not found
    /// by a ray, such as light samples): what [`Geometry::tangents`] needs
    /// to find the triangle, for normal and bump maps.
    pub prim: u32,
}

/// [`SurfacePoint::prim`] of a point that no ray hit.
pub const NO_PRIM: u32 = u32::MAX;

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

/// A mesh triangle without vertex normals, holding what a point on it
/// needs: its vertices and its unit geometric normal, already oriented
/// (`flip_normals` applied). Cached per triangle so that hit points and
/// light samples skip the mesh look-ups of [`Geometry::triangle_point`],
/// whose result [`FlatTriangle::point`] reproduces bit for bit.
///
/// Its UV is the barycentric pair of a mesh without vertex UVs; meshes
/// with UVs keep theirs in [`Geometry`]'s per-primitive `flat_uv` (apart,
/// so that this stays one cache line), which [`Geometry::surface_point`]
/// interpolates.
///
/// The vertices are SIMD vectors (one instruction per operation on all
/// three axes, the same arithmetic lane by lane): 64 bytes, one cache line.
#[derive(Clone, Copy, Debug)]
pub struct FlatTriangle {
    p: [Vec3A; 3],
    ng: Vec3,
    shape: u32,
}

impl FlatTriangle {
    /// Point at barycentrics (b0, b1, b2) (same arithmetic as
    /// [`Geometry::triangle_point`]).
    #[inline(always)]
    pub fn point(&self, b0: f32, b1: f32, b2: f32) -> SurfacePoint {
        let [p0, p1, p2] = self.p;
        let (q0, q1, q2) = (p0 * b0, p1 * b1, p2 * b2);
        SurfacePoint {
            p: (q0 + q1 + q2).into(),
            p_err: ((q0.abs() + q1.abs() + q2.abs()) * gamma(7)).into(),
            ng: self.ng,
            ns: self.ng,
            uv: Vec2::new(b1, b2),
            shape: self.shape,
            prim: NO_PRIM,
        }
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
    /// Per primitive (BVH order): the cached flat triangle, or one with
    /// shape `u32::MAX` for primitives that are not flat triangles.
    flat: Vec<FlatTriangle>,
    /// Per primitive (BVH order): the vertex UVs of flat triangles of
    /// meshes with UVs (zeros elsewhere); empty when no such mesh exists.
    flat_uv: Vec<[Vec2; 3]>,
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
                Surface::Sphere { center, radius, .. } => {
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
        let mut geometry = Geometry {
            shapes,
            prims,
            bvh,
            face_normals,
            flat: Vec::new(),
            flat_uv: Vec::new(),
            packs,
            leaf_pack,
            build_time: start.elapsed(),
            triangles,
        };
        geometry.flat = geometry.flat_per_prim();
        geometry.flat_uv = geometry.flat_uv_per_prim();
        geometry
    }

    /// The cached flat triangle of every primitive (the `flat` field).
    fn flat_per_prim(&self) -> Vec<FlatTriangle> {
        let none = FlatTriangle {
            p: [Vec3A::ZERO; 3],
            ng: Vec3::ZERO,
            shape: u32::MAX,
        };
        self.prims
            .iter()
            .map(|p| match *p {
                Prim::Triangle { shape, tri, .. } => self.flat_triangle(shape, tri).unwrap_or(none),
                _ => none,
            })
            .collect()
    }

    /// The vertex UVs of every flat triangle of a mesh with UVs (the
    /// `flat_uv` field; empty when no mesh has UVs).
    fn flat_uv_per_prim(&self) -> Vec<[Vec2; 3]> {
        let uvs_of = |shape: u32, tri: u32| match &self.shapes[shape as usize].surface {
            Surface::Mesh(m) if m.normals.is_none() => m
                .uvs
                .as_ref()
                .map(|uv| m.indices[tri as usize].map(|i| uv[i as usize])),
            _ => None,
        };
        let any = self.prims.iter().any(|p| match *p {
            Prim::Triangle { shape, tri, .. } => uvs_of(shape, tri).is_some(),
            _ => false,
        });
        if !any {
            return Vec::new();
        }
        self.prims
            .iter()
            .map(|p| match *p {
                Prim::Triangle { shape, tri, .. } => uvs_of(shape, tri).unwrap_or([Vec2::ZERO; 3]),
                _ => [Vec2::ZERO; 3],
            })
            .collect()
    }

    /// Triangle `tri` of mesh shape `shape` as a [`FlatTriangle`]; `None`
    /// when the shape is not a mesh, has vertex normals (the shading normal
    /// then varies over the triangle) or has no such triangle.
    pub fn flat_triangle(&self, shape: u32, tri: u32) -> Option<FlatTriangle> {
        let gs = self.shapes.get(shape as usize)?;
        let Surface::Mesh(m) = &gs.surface else {
            return None;
        };
        if m.normals.is_some() {
            return None;
        }
        let idx = m.indices.get(tri as usize)?;
        let ng = self.face_normals[shape as usize][tri as usize];
        Some(FlatTriangle {
            p: idx.map(|i| m.positions[i as usize].into()),
            ng: if gs.flip_normals { -ng } else { ng },
            shape,
        })
    }

    /// Bytes used by the acceleration structures: the BVH nodes, the
    /// primitive array, the triangle packs and their index, and the
    /// per-primitive cache of flat triangles.
    pub fn bvh_bytes(&self) -> usize {
        self.bvh.bytes()
            + std::mem::size_of_val(self.prims.as_slice())
            + std::mem::size_of_val(self.packs.as_slice())
            + std::mem::size_of_val(self.leaf_pack.as_slice())
            + std::mem::size_of_val(self.flat.as_slice())
            + std::mem::size_of_val(self.flat_uv.as_slice())
    }

    /// The axis-aligned box `(lo, hi)` of every shape (the corners of disks,
    /// the boxes of spheres); `None` when there is no shape.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let mut grow = |p: Vec3| {
            lo = lo.min(p);
            hi = hi.max(p);
        };
        for shape in &self.shapes {
            match &shape.surface {
                Surface::Mesh(m) => m.positions.iter().for_each(|&p| grow(p)),
                Surface::Sphere { center, radius, .. } => {
                    grow(*center - Vec3::splat(*radius));
                    grow(*center + Vec3::splat(*radius));
                }
                Surface::Disk { to_world, .. } => {
                    for (x, y) in [(-1.0, -1.0), (-1.0, 1.0), (1.0, -1.0), (1.0, 1.0)] {
                        grow(to_world.transform_point3(Vec3::new(x, y, 0.0)));
                    }
                }
            }
        }
        lo.cmple(hi).all().then_some((lo, hi))
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
    #[inline(always)]
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
    #[inline(always)]
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

    /// True when the segment between two surface points is unobstructed
    /// (neither point's own surface counts as a blocker).
    ///
    /// One ray from `a`, its origin offset off `a`'s surface, towards
    /// `b.p`. Instead of a second offset at `b` (pbrt-v4's two-sided
    /// `SpawnRayTo`), the ray stops where it comes within `b`'s error bound
    /// of `b`'s tangent plane: `b`'s surface lies within
    /// `e = |n_b|·p_err_b` of `b.p` along `n_b`, which the ray covers in the
    /// last `e·dist / |n_b·(b.p − o)|` of its length. Both exclude the same
    /// slab around `b`'s plane; this form needs no rounding steps. A
    /// relative margin (pbrt's `ShadowEpsilon`) covers the rounding of the
    /// hit distances as before.
    #[inline(always)]
    pub fn visible(&self, a: &SurfacePoint, b: &SurfacePoint) -> bool {
        let from = a.spawn_origin(b.p);
        let delta = b.p - from;
        let dist2 = delta.length_squared();
        if !(dist2 > 0.0) || !dist2.is_finite() {
            return dist2 == 0.0;
        }
        let err = b.ng.abs().dot(b.p_err);
        // Fraction of the segment to keep; `along` = dist·|cos θ_b|.
        let along = b.ng.dot(delta).abs();
        let keep = (1.0 - SHADOW_EPSILON) - if err > 0.0 { err / along } else { 0.0 };
        if !(keep > 0.0) {
            // The whole segment lies within `b`'s error slab (a grazing
            // segment shorter than the bounds): nothing provably blocks it.
            return true;
        }
        let dist = dist2.sqrt();
        // One SIMD division for the three components (the same quotients).
        let mut ray = Ray::new(from, (Vec3A::from(delta) / dist).into());
        ray.tmax = dist * keep;
        !self.occluded(&ray)
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
        ray.tmax = dist * (1.0 - SHADOW_EPSILON);
        !self.occluded(&ray)
    }

    /// The surface point of a hit, with its error bound and normals.
    #[inline(always)]
    pub fn surface_point(&self, ray: &Ray, hit: &Hit) -> SurfacePoint {
        // Flat triangles, the common case, need only their cached entry.
        let flat = &self.flat[hit.prim as usize];
        if flat.shape != u32::MAX {
            let b0 = 1.0 - hit.u - hit.v;
            let mut sp = flat.point(b0, hit.u, hit.v);
            if let Some([t0, t1, t2]) = self.flat_uv.get(hit.prim as usize) {
                sp.uv = *t0 * b0 + *t1 * hit.u + *t2 * hit.v;
            }
            sp.prim = hit.prim;
            return sp;
        }
        let mut sp = self.surface_point_other(ray, hit);
        sp.prim = hit.prim;
        sp
    }

    /// [`Geometry::surface_point`] on all but flat triangles.
    #[inline(never)]
    fn surface_point_other(&self, ray: &Ray, hit: &Hit) -> SurfacePoint {
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
        let uv = match &m.uvs {
            Some(t) => {
                let [t0, t1, t2] = idx.map(|i| t[i as usize]);
                t0 * b0 + t1 * b1 + t2 * b2
            }
            None => Vec2::new(b1, b2),
        };
        SurfacePoint {
            p,
            p_err,
            ng,
            ns,
            uv,
            shape,
            prim: NO_PRIM,
        }
    }

    /// The surface's derivatives (∂p/∂u, ∂p/∂v) at a hit point, with
    /// Mitsuba 3's parametrisation of each shape: on mesh triangles from
    /// the vertex UVs (an arbitrary basis of the face when they are
    /// degenerate), from the barycentrics on meshes without UVs; spherical
    /// and polar coordinates on spheres and disks. Only normal and bump
    /// maps need it, so it is computed on demand rather than at every hit.
    /// A point no ray hit ([`NO_PRIM`]) gets an arbitrary basis of its
    /// tangent plane.
    pub fn tangents(&self, sp: &SurfacePoint) -> (Vec3, Vec3) {
        let basis = || {
            let f = crate::frame::Frame::from_normal(sp.ng);
            (f.s, f.t)
        };
        let Some(prim) = self.prims.get(sp.prim as usize) else {
            return basis();
        };
        match *prim {
            Prim::Triangle { shape, tri, .. } => {
                let Surface::Mesh(m) = &self.shapes[shape as usize].surface else {
                    return basis();
                };
                let idx = m.indices[tri as usize];
                let [p0, p1, p2] = idx.map(|i| m.positions[i as usize]);
                let (dp0, dp1) = (p1 - p0, p2 - p0);
                let Some(uvs) = &m.uvs else {
                    return (dp0, dp1);
                };
                let [t0, t1, t2] = idx.map(|i| uvs[i as usize]);
                let (duv0, duv1) = (t1 - t0, t2 - t0);
                let det = duv0.x * duv1.y - duv0.y * duv1.x;
                if det == 0.0 {
                    return basis();
                }
                let inv = 1.0 / det;
                (
                    (dp0 * duv1.y - dp1 * duv0.y) * inv,
                    (dp1 * duv0.x - dp0 * duv1.x) * inv,
                )
            }
            Prim::Sphere { shape, .. } => {
                let Surface::Sphere {
                    center,
                    radius,
                    frame,
                } = self.shapes[shape as usize].surface
                else {
                    return basis();
                };
                // Object space: the unit sphere, scaled by the radius and
                // rotated by `frame` into the world.
                let q = frame.transpose() * ((sp.p - center) / radius);
                let rd = (q.x * q.x + q.y * q.y).sqrt();
                let du = Vec3::new(-q.y, q.x, 0.0) * (2.0 * std::f32::consts::PI);
                let dv = if rd > 0.0 {
                    Vec3::new(q.z * q.x / rd, q.z * q.y / rd, -rd)
                } else {
                    Vec3::X
                } * std::f32::consts::PI;
                (frame * du * radius, frame * dv * radius)
            }
            Prim::Disk { shape } => {
                let Surface::Disk { to_world, .. } = &self.shapes[shape as usize].surface else {
                    return basis();
                };
                let r = sp.uv.x;
                let phi = sp.uv.y * 2.0 * std::f32::consts::PI;
                let (sin, cos) = phi.sin_cos();
                (
                    to_world.transform_vector3(Vec3::new(cos, sin, 0.0)),
                    to_world.transform_vector3(Vec3::new(-sin, cos, 0.0))
                        * (2.0 * std::f32::consts::PI * r),
                )
            }
        }
    }

    /// Point on a sphere near `p_guess` (reprojected onto the surface).
    pub fn sphere_point(&self, shape: u32, p_guess: Vec3) -> SurfacePoint {
        let gs = &self.shapes[shape as usize];
        let Surface::Sphere {
            center,
            radius,
            frame,
        } = gs.surface
        else {
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
        // Mitsuba's spherical mapping, in object space: u = φ/2π with φ
        // the azimuth from +x towards +y in [0, 2π), v = θ/π with θ the
        // polar angle from +z.
        let q = frame.transpose() * n;
        let uv = Vec2::new(
            azimuth(q.x, q.y) * (0.5 * std::f32::consts::FRAC_1_PI),
            q.z.clamp(-1.0, 1.0).acos() * std::f32::consts::FRAC_1_PI,
        );
        if gs.flip_normals {
            n = -n;
        }
        SurfacePoint {
            p,
            p_err,
            ng: n,
            ns: n,
            uv,
            shape,
            prim: NO_PRIM,
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
        // Mitsuba's polar mapping: u = r, v = φ/2π.
        let uv = Vec2::new(
            (x * x + y * y).sqrt(),
            azimuth(x, y) * (0.5 * std::f32::consts::FRAC_1_PI),
        );
        SurfacePoint {
            p,
            p_err,
            ng: n,
            ns: n,
            uv,
            shape,
            prim: NO_PRIM,
        }
    }
}

/// The angle of (x, y) from +x towards +y, in [0, 2π).
fn azimuth(x: f32, y: f32) -> f32 {
    let phi = y.atan2(x);
    if phi < 0.0 {
        phi + 2.0 * std::f32::consts::PI
    } else {
        phi
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

    /// The three-lane step equals the scalar one lane by lane.
    #[test]
    fn ulp_step3_matches_ulp_step() {
        let xs = [
            0.0f32,
            -0.0,
            f32::from_bits(1),
            -f32::from_bits(1),
            f32::MIN_POSITIVE,
            1.0,
            -123.456,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let dirs = [1.0f32, -1e-30, 0.0, -0.0, 5.0];
        for &x0 in &xs {
            for &d0 in &dirs {
                for (x1, d1) in [(0.3f32, -2.0f32), (-0.0, 1e-20)] {
                    let (x, d) = (Vec3A::new(x0, x1, -x0), Vec3A::new(d0, d1, d0));
                    let got = ulp_step3(x, d);
                    for i in 0..3 {
                        assert_eq!(
                            got[i].to_bits(),
                            ulp_step(x[i], d[i]).to_bits(),
                            "x={} dir={}",
                            x[i],
                            d[i]
                        );
                    }
                }
            }
        }
    }

    /// A quad `c + x·ex + y·ey` for x, y in [0, 1], as two triangles
    /// whose normal is `ex × ey`.
    fn quad(c: Vec3, ex: Vec3, ey: Vec3) -> GeoShape {
        GeoShape {
            surface: Surface::Mesh(MeshData {
                positions: vec![c, c + ex, c + ex + ey, c + ey],
                normals: None,
                uvs: None,
                indices: vec![[0, 1, 2], [0, 2, 3]],
            }),
            flip_normals: false,
        }
    }

    /// A uniform-ish point on quad shape `shape` (its two triangles).
    fn point_on(g: &Geometry, shape: u32, s: &mut u64) -> SurfacePoint {
        let (b0, b1) = (lcg(s), lcg(s));
        let (b0, b1) = if b0 + b1 > 1.0 {
            (1.0 - b0, 1.0 - b1)
        } else {
            (b0, b1)
        };
        let tri = (lcg(s) * 2.0) as u32;
        g.triangle_point(shape, tri.min(1), 1.0 - b0 - b1, b0, b1)
    }

    /// Shadow rays between points on surfaces that touch (a floor and a
    /// wall meeting at an edge, at grazing angles near it) or are coplanar
    /// (a light set into the ceiling) never see their own surfaces, at
    /// scales from 1e-3 to 1e4 and far from the origin; a blocker between
    /// them is still found.
    #[test]
    fn shadow_rays_between_touching_and_coplanar_surfaces_at_any_scale() {
        for (scale, origin) in [
            (1e-3f32, Vec3::ZERO),
            (1e-3, Vec3::new(0.5, -0.25, 0.125)),
            (1.0, Vec3::ZERO),
            (1.0, Vec3::new(300.0, -200.0, 100.0)),
            (1e4, Vec3::new(-3e4, 1e4, 2e4)),
        ] {
            let at = |x: f32, y: f32, z: f32| origin + Vec3::new(x, y, z) * scale;
            let (ex, ey, ez) = (Vec3::X * scale, Vec3::Y * scale, Vec3::Z * scale);
            let shapes = vec![
                // 0: floor z = 0 (normal +z).
                quad(at(0.0, 0.0, 0.0), ex, ey),
                // 1: wall x = 0 (normal +x), touching the floor along y.
                quad(at(0.0, 0.0, 0.0), ey, ez),
                // 2: ceiling z = 1 (normal −z).
                quad(at(0.0, 0.0, 1.0), ey, ex),
                // 3: a light in the ceiling's plane (normal −z).
                quad(at(0.25, 0.25, 1.0), ey * 0.5, ex * 0.5),
            ];
            let g = Geometry::build(shapes);
            let mut s = 7u64;
            for _ in 0..5_000 {
                let floor = point_on(&g, 0, &mut s);
                for other in [1, 2, 3] {
                    let q = point_on(&g, other, &mut s);
                    assert!(
                        g.visible(&floor, &q),
                        "scale {scale}: floor {:?} to shape {other} {:?} blocked",
                        floor.p,
                        q.p
                    );
                    assert!(g.visible(&q, &floor), "scale {scale}: reverse blocked");
                }
                // Grazing: both points within 1e-3 of the shared edge.
                // Floor triangle 1 is (0,0)-(1,1)-(0,1): x = b1.
                let (x, t) = (1e-3 * lcg(&mut s), lcg(&mut s));
                let near = g.triangle_point(0, 1, (1.0 - x) * t, x, (1.0 - x) * (1.0 - t));
                // Wall triangle 0 is (y,z) = (0,0)-(1,0)-(1,1): z = b2.
                let (z, t) = (1e-3 * lcg(&mut s), lcg(&mut s));
                let wall = g.triangle_point(1, 0, (1.0 - z) * t, (1.0 - z) * (1.0 - t), z);
                assert!(g.visible(&near, &wall), "scale {scale}: grazing blocked");
                assert!(g.visible(&wall, &near), "scale {scale}: grazing reverse");
            }
            // A blocker halfway between the floor and the light is found.
            let mut shapes = g.shapes.clone();
            shapes.push(quad(at(0.0, 0.0, 0.5), ex, ey));
            let g = Geometry::build(shapes);
            for _ in 0..1_000 {
                let floor = point_on(&g, 0, &mut s);
                let light = point_on(&g, 3, &mut s);
                assert!(!g.visible(&floor, &light), "scale {scale}: blocker missed");
            }
        }
    }

    /// The cached flat triangles give bit for bit the points of the general
    /// `triangle_point`, with and without `flip_normals`, and meshes with
    /// vertex normals get no cache entry (their shading normal varies).
    #[test]
    fn flat_triangle_points_equal_triangle_point() {
        let mesh = |flip: bool, normals: Option<Vec<Vec3>>| GeoShape {
            surface: Surface::Mesh(MeshData {
                positions: vec![
                    Vec3::new(0.3, -1.7, 2.0),
                    Vec3::new(4.1, 0.2, 1.5),
                    Vec3::new(-0.6, 3.3, 0.7),
                ],
                normals,
                uvs: None,
                indices: vec![[0, 1, 2]],
            }),
            flip_normals: flip,
        };
        let g = Geometry::build(vec![
            mesh(false, None),
            mesh(true, None),
            mesh(false, Some(vec![Vec3::Z; 3])),
        ]);
        assert!(g.flat_triangle(2, 0).is_none());
        assert!(g.flat_triangle(0, 1).is_none());
        let bits = |sp: &SurfacePoint| {
            [sp.p, sp.p_err, sp.ng, sp.ns].map(|v| v.to_array().map(f32::to_bits))
        };
        let mut s = 3u64;
        for shape in [0, 1] {
            let flat = g.flat_triangle(shape, 0).expect("flat mesh");
            for _ in 0..1000 {
                let (b1, b2) = (lcg(&mut s) * 0.5, lcg(&mut s) * 0.5);
                let want = g.triangle_point(shape, 0, 1.0 - b1 - b2, b1, b2);
                let got = flat.point(1.0 - b1 - b2, b1, b2);
                assert_eq!(bits(&got), bits(&want));
                assert_eq!(got.uv, want.uv);
                assert_eq!(got.shape, want.shape);
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
                surface: Surface::Sphere {
                    center,
                    radius,
                    frame: Mat3::IDENTITY,
                },
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
