//! Local differential geometry at a surface hit, computed on demand (the
//! hot path's [`SurfacePoint`] does not carry it): the position's partial
//! derivatives `dp/du`, `dp/dv` and the shading normal's `dn/du`, `dn/dv`
//! with respect to the shape's surface parameterisation, which is the one
//! [`SurfacePoint::uv`] reports (Mitsuba's):
//!
//! - meshes with vertex UVs: the interpolated UV (derivatives from the UV
//!   map of the triangle, pbrt's and Mitsuba's `dp_du` / `dp_dv`);
//! - meshes without UVs: the barycentrics `(b1, b2)`, so `dp/du = p1 − p0`
//!   and `dp/dv = p2 − p0` (Mitsuba does the same);
//! - sphere: `u = φ/2π`, `v = θ/π` in the sphere's object frame;
//! - disk: `u = r`, `v = φ/2π` in object space;
//! - `rectangle` and `cube` are meshes with UVs.
//!
//! Flat triangles and disks have `dn = 0`; meshes with vertex normals
//! differentiate the *normalised* interpolated normal; spheres have
//! `dn = ±dp/r`. Everything is in `f64` so that the manifold walk's
//! Jacobians (see [`crate::manifold`]) do not inherit `f32` rounding from
//! the derivative arithmetic; the inputs are the scene's `f32` data.

use super::{Geometry, Hit, Prim, Ray, Surface, SurfacePoint};
use glam::{DMat2, DVec2, DVec3};

/// Position and shading-normal derivatives at a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Differential {
    /// Position (the hit's `SurfacePoint::p`).
    pub p: DVec3,
    /// Unit geometric normal, oriented as `SurfacePoint::ng`.
    pub ng: DVec3,
    /// Unit shading normal, oriented as `SurfacePoint::ns`.
    pub ns: DVec3,
    /// ∂p/∂u.
    pub dpdu: DVec3,
    /// ∂p/∂v.
    pub dpdv: DVec3,
    /// ∂n_s/∂u (tangent to the unit sphere: `ns · dndu = 0`).
    pub dndu: DVec3,
    /// ∂n_s/∂v.
    pub dndv: DVec3,
}

impl Differential {
    /// An orthonormal basis `(s, t)` of the geometric tangent plane and the
    /// shading normal's derivatives along it: `dn/ds`, `dn/dt` (the chain
    /// rule through the parameterisation, whatever its scaling or shear).
    /// `None` where the parameterisation is singular (a sphere's poles, a
    /// disk's centre, a degenerate UV map).
    pub fn orthonormal(&self) -> Option<OrthonormalDifferential> {
        let cross = self.dpdu.cross(self.dpdv);
        let scale = self.dpdu.length() * self.dpdv.length();
        if !(cross.length() > 1e-9 * scale) {
            return None;
        }
        let s = (self.dpdu - self.ng * self.ng.dot(self.dpdu)).try_normalize()?;
        let t = self.ng.cross(s);
        // (u, v) as functions of (α, β) along (s, t): the inverse of the
        // 2×2 map (du, dv) ↦ (α, β) = (s·dp, t·dp).
        let to_st = DMat2::from_cols(
            DVec2::new(s.dot(self.dpdu), t.dot(self.dpdu)),
            DVec2::new(s.dot(self.dpdv), t.dot(self.dpdv)),
        );
        let uv_of_st = to_st.inverse();
        let dn = |c: DVec2| self.dndu * c.x + self.dndv * c.y;
        Some(OrthonormalDifferential {
            p: self.p,
            ng: self.ng,
            ns: self.ns,
            s,
            t,
            dnds: dn(uv_of_st.x_axis),
            dndt: dn(uv_of_st.y_axis),
        })
    }
}

/// A [`Differential`] re-expressed in an orthonormal tangent basis: moving
/// the point by `α s + β t` moves the shading normal by `α dnds + β dndt`
/// to first order, and `dα dβ` is the area element.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrthonormalDifferential {
    /// Position.
    pub p: DVec3,
    /// Unit geometric normal.
    pub ng: DVec3,
    /// Unit shading normal.
    pub ns: DVec3,
    /// First unit tangent (along `dp/du`).
    pub s: DVec3,
    /// Second unit tangent, `ng × s`.
    pub t: DVec3,
    /// ∂n_s/∂α along `s`.
    pub dnds: DVec3,
    /// ∂n_s/∂β along `t`.
    pub dndt: DVec3,
}

fn d(v: glam::Vec3) -> DVec3 {
    v.as_dvec3()
}

impl Geometry {
    /// The hit that produced a surface point, found again for callers that
    /// kept only the point (path vertices store a `SurfacePoint`): a ray
    /// along `−ng` from just in front of the point, whose first hit must
    /// be on `sp`'s shape within a short distance. `None` when another
    /// surface is met first there (coincident geometry).
    pub fn locate(&self, sp: &SurfacePoint) -> Option<Hit> {
        // Well outside the point's error bound, and small at its scale.
        let back = (sp.p_err.length() * 16.0)
            .max(sp.p.abs().max_element() * 1e-5)
            .max(1e-6);
        let mut ray = Ray::new(sp.p + sp.ng * back, -sp.ng);
        ray.tmax = 2.0 * back;
        let hit = self.intersect(&ray)?;
        (self.surface_point(&ray, &hit).shape == sp.shape).then_some(hit)
    }

    /// The differential geometry at `sp`, the surface point of `hit`
    /// (from [`Geometry::surface_point`] for the same hit).
    pub fn differential(&self, hit: &Hit, sp: &SurfacePoint) -> Differential {
        let mut out = Differential {
            p: d(sp.p),
            ng: d(sp.ng).normalize(),
            ns: d(sp.ns).normalize(),
            dpdu: DVec3::ZERO,
            dpdv: DVec3::ZERO,
            dndu: DVec3::ZERO,
            dndv: DVec3::ZERO,
        };
        match self.prims[hit.prim as usize] {
            Prim::Triangle { shape, tri, .. } => {
                self.triangle_differential(shape, tri, hit.u as f64, hit.v as f64, &mut out)
            }
            Prim::Sphere { shape, .. } => self.sphere_differential(shape, &mut out),
            Prim::Disk { shape } => {
                self.disk_differential(shape, hit.u as f64, hit.v as f64, &mut out)
            }
        }
        out
    }

    /// Mesh triangle at barycentrics `(1 − b1 − b2, b1, b2)`.
    fn triangle_differential(
        &self,
        shape: u32,
        tri: u32,
        b1: f64,
        b2: f64,
        out: &mut Differential,
    ) {
        let gs = &self.shapes[shape as usize];
        let Surface::Mesh(m) = &gs.surface else {
            unreachable!("triangle primitive on a non-mesh shape")
        };
        let idx = m.indices[tri as usize];
        let [p0, p1, p2] = idx.map(|i| d(m.positions[i as usize]));
        // Derivatives with respect to (b1, b2) first.
        let (mut dpdu, mut dpdv) = (p1 - p0, p2 - p0);
        let (mut dndu, mut dndv) = (DVec3::ZERO, DVec3::ZERO);
        if let Some(normals) = &m.normals {
            let [n0, n1, n2] = idx.map(|i| d(normals[i as usize]));
            let big_n = n0 * (1.0 - b1 - b2) + n1 * b1 + n2 * b2;
            let len = big_n.length();
            if len > 0.0 {
                let n = big_n / len;
                // d(N/|N|) = (I − n nᵀ) dN / |N|.
                let project = |dn: DVec3| (dn - n * n.dot(dn)) / len;
                dndu = project(n1 - n0);
                dndv = project(n2 - n0);
            }
            if gs.flip_normals {
                dndu = -dndu;
                dndv = -dndv;
            }
        }
        if let Some(uvs) = &m.uvs {
            let [t0, t1, t2] = idx.map(|i| uvs[i as usize].as_dvec2());
            // (du, dv) = M (db1, db2); invert M to differentiate by (u, v).
            let m_uv = DMat2::from_cols(t1 - t0, t2 - t0);
            let det = m_uv.determinant();
            let size = (t1 - t0).length() * (t2 - t0).length();
            // A degenerate UV map keeps the barycentric derivatives (the
            // UV then does not parameterise the triangle).
            if det.abs() > 1e-12 * size && det.is_finite() {
                let inv = m_uv.inverse();
                let by_uv = |a: DVec3, b: DVec3, c: DVec2| a * c.x + b * c.y;
                (dpdu, dpdv) = (by_uv(dpdu, dpdv, inv.x_axis), by_uv(dpdu, dpdv, inv.y_axis));
                (dndu, dndv) = (by_uv(dndu, dndv, inv.x_axis), by_uv(dndu, dndv, inv.y_axis));
            }
        }
        out.dpdu = dpdu;
        out.dpdv = dpdv;
        out.dndu = dndu;
        out.dndv = dndv;
    }

    /// Sphere: spherical coordinates of the object frame.
    fn sphere_differential(&self, shape: u32, out: &mut Differential) {
        let gs = &self.shapes[shape as usize];
        let Surface::Sphere {
            center,
            radius,
            frame,
        } = gs.surface
        else {
            unreachable!("sphere primitive on a non-sphere shape")
        };
        let (c, r) = (d(center), radius as f64);
        let frame = frame.as_dmat3();
        let n = (out.p - c).normalize();
        let q = frame.transpose() * n;
        let sin_theta = (q.x * q.x + q.y * q.y).sqrt();
        use std::f64::consts::PI;
        // p = c + r·F(sinθ cosφ, sinθ sinφ, cosθ), u = φ/2π, v = θ/π.
        out.dpdu = frame * DVec3::new(-q.y, q.x, 0.0) * (2.0 * PI * r);
        out.dpdv = if sin_theta > 0.0 {
            frame * DVec3::new(q.z * q.x / sin_theta, q.z * q.y / sin_theta, -sin_theta) * (PI * r)
        } else {
            DVec3::ZERO
        };
        // The unit normal is (p − c)/r, negated by flip_normals.
        let sign = if gs.flip_normals { -1.0 } else { 1.0 };
        out.dndu = out.dpdu * (sign / r);
        out.dndv = out.dpdv * (sign / r);
    }

    /// Disk at object-space `(x, y)`: polar coordinates, flat.
    fn disk_differential(&self, shape: u32, x: f64, y: f64, out: &mut Differential) {
        let Surface::Disk { to_world, .. } = &self.shapes[shape as usize].surface else {
            unreachable!("disk primitive on a non-disk shape")
        };
        let to_world = to_world.as_dmat4();
        let r = (x * x + y * y).sqrt();
        let (cos_phi, sin_phi) = if r > 0.0 { (x / r, y / r) } else { (1.0, 0.0) };
        out.dpdu = to_world.transform_vector3(DVec3::new(cos_phi, sin_phi, 0.0));
        out.dpdv =
            to_world.transform_vector3(DVec3::new(-y, x, 0.0) * (2.0 * std::f64::consts::PI));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{GeoShape, MeshData};
    use glam::{Mat3, Mat4, Quat, Vec2, Vec3};

    /// A shape seen from `eye`: central differences of the hit position
    /// and shading normal along the surface (two rays at ±δ around each
    /// aim point, in two directions) against `dp = dp/du du + dp/dv dv`
    /// with `(du, dv)` the difference of the hits' reported UVs, and the
    /// same for `n`. Returns the largest relative error over the aims.
    ///
    /// Tolerance derivation: the hits are `f32` (relative rounding
    /// ~1e-7 of the coordinates, so ~1e-7/δ relative to the differences);
    /// the UV offsets of the ±δ hits are symmetric to first order, so the
    /// second-order terms cancel and the truncation error is O(δ²). With
    /// δ = 1e-3 of the scene scale both are ≤ ~1e-4: 1e-3 leaves a margin
    /// of ten, while a missing or wrong derivative is off by O(1).
    fn max_fd_error(
        g: &Geometry,
        eye: Vec3,
        aims: &[Vec3],
        diff: impl Fn(&Differential) -> Differential,
    ) -> f64 {
        let mut worst = 0.0f64;
        for &aim in aims {
            let w = (aim - eye).normalize();
            let frame = crate::frame::Frame::from_normal(w);
            let center = hit_at(g, eye, w).expect("aim hits");
            let dg = diff(&g.differential(&center.0, &center.1));
            let delta = 1e-3 * (aim - eye).length();
            for side in [frame.s, frame.t] {
                let a = hit_at(g, eye, (aim + side * delta - eye).normalize()).expect("hit +");
                let b = hit_at(g, eye, (aim - side * delta - eye).normalize()).expect("hit -");
                assert_eq!(a.1.shape, center.1.shape);
                assert_eq!(b.1.shape, center.1.shape);
                let duv = (a.1.uv - b.1.uv).as_dvec2();
                let dp = d(a.1.p) - d(b.1.p);
                let dp_lin = dg.dpdu * duv.x + dg.dpdv * duv.y;
                worst = worst.max((dp - dp_lin).length() / dp.length());
                let dn = d(a.1.ns) - d(b.1.ns);
                let dn_lin = dg.dndu * duv.x + dg.dndv * duv.y;
                // Relative to |dp|/scale, so that flat shapes (dn = 0) are
                // measured too: a curvature radius ≥ the scene scale gives
                // |dn| ≤ |dp| there.
                worst = worst.max((dn - dn_lin).length() / dp.length());
            }
        }
        worst
    }

    fn hit_at(g: &Geometry, eye: Vec3, w: Vec3) -> Option<(Hit, SurfacePoint)> {
        let ray = Ray::new(eye, w);
        let hit = g.intersect(&ray)?;
        Some((hit, g.surface_point(&ray, &hit)))
    }

    fn identity(x: &Differential) -> Differential {
        *x
    }

    /// A bumpy mesh patch: a 3×3 grid of vertices on z = 0.2·sin(x)cos(y),
    /// optionally with analytic vertex normals and skewed UVs.
    fn patch(normals: bool, uvs: bool, flip: bool) -> GeoShape {
        let h = |x: f32, y: f32| 0.2 * x.sin() * y.cos();
        let mut positions = Vec::new();
        let mut ns = Vec::new();
        let mut tex = Vec::new();
        for j in 0..3 {
            for i in 0..3 {
                let (x, y) = (i as f32 - 1.0, j as f32 - 1.0);
                positions.push(Vec3::new(x, y, h(x, y)));
                let (hx, hy) = (0.2 * x.cos() * y.cos(), -0.2 * x.sin() * y.sin());
                ns.push(Vec3::new(-hx, -hy, 1.0).normalize());
                // A sheared, scaled UV map (not aligned with the edges).
                tex.push(Vec2::new(
                    0.3 * x + 0.1 * y + 0.5,
                    -0.05 * x + 0.4 * y + 0.5,
                ));
            }
        }
        let mut indices = Vec::new();
        for j in 0..2u32 {
            for i in 0..2u32 {
                let k = j * 3 + i;
                indices.push([k, k + 1, k + 4]);
                indices.push([k, k + 4, k + 3]);
            }
        }
        GeoShape {
            surface: Surface::Mesh(MeshData {
                positions,
                normals: normals.then_some(ns),
                uvs: uvs.then_some(tex),
                indices,
            }),
            flip_normals: flip,
        }
    }

    /// Aim points inside the patch's triangles, away from their edges.
    fn patch_aims() -> Vec<Vec3> {
        [
            (-0.6, -0.3),
            (-0.25, -0.7),
            (0.4, 0.2),
            (0.7, -0.55),
            (-0.5, 0.6),
            (0.3, 0.75),
        ]
        .map(|(x, y)| Vec3::new(x, y, 0.2 * x.sin() * y.cos()))
        .to_vec()
    }

    #[test]
    fn mesh_derivatives_match_finite_differences() {
        let eye = Vec3::new(0.3, -0.4, 3.0);
        for normals in [false, true] {
            for uvs in [false, true] {
                for flip in [false, true] {
                    let g = Geometry::build(vec![patch(normals, uvs, flip)]);
                    let err = max_fd_error(&g, eye, &patch_aims(), identity);
                    assert!(err < 1e-3, "normals {normals} uvs {uvs} flip {flip}: {err}");
                }
            }
        }
    }

    /// Control: treating interpolated normals as constant (dn = 0) fails.
    #[test]
    fn mesh_control_without_normal_derivatives_fails() {
        let g = Geometry::build(vec![patch(true, true, false)]);
        let eye = Vec3::new(0.3, -0.4, 3.0);
        let flat = |x: &Differential| Differential {
            dndu: DVec3::ZERO,
            dndv: DVec3::ZERO,
            ..*x
        };
        let err = max_fd_error(&g, eye, &patch_aims(), flat);
        assert!(err > 1e-2, "{err}");
        // Control: the barycentric derivatives on a mesh with UVs fail.
        let g_bary = Geometry::build(vec![patch(true, false, false)]);
        let g_uv = Geometry::build(vec![patch(true, true, false)]);
        let (h, sp) = hit_at(&g_bary, eye, (patch_aims()[0] - eye).normalize()).unwrap();
        let bary = g_bary.differential(&h, &sp);
        let err = max_fd_error(&g_uv, eye, &patch_aims()[..1], |x| Differential {
            dpdu: bary.dpdu,
            dpdv: bary.dpdv,
            ..*x
        });
        assert!(err > 1e-2, "{err}");
    }

    #[test]
    fn sphere_derivatives_match_finite_differences() {
        for flip in [false, true] {
            let frame = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1));
            let center = Vec3::new(0.5, -0.2, 0.1);
            let g = Geometry::build(vec![GeoShape {
                surface: Surface::Sphere {
                    center,
                    radius: 0.8,
                    frame,
                },
                flip_normals: flip,
            }]);
            let eye = Vec3::new(0.2, 0.4, 4.0);
            // Aims on the visible cap, away from the object frame's poles
            // and from the φ = 0 seam of the UV map.
            let mut aims = Vec::new();
            for (x, y) in [
                (0.3, 0.2),
                (-0.4, 0.1),
                (0.1, -0.5),
                (-0.2, -0.3),
                (0.5, -0.4),
            ] {
                let dir = Vec3::new(x, y, 1.0).normalize();
                let q = frame.transpose() * dir;
                if q.y.atan2(q.x).abs() > 0.1 && q.z.abs() < 0.95 {
                    aims.push(center + dir * 0.8);
                }
            }
            assert!(aims.len() >= 3);
            let err = max_fd_error(&g, eye, &aims, identity);
            assert!(err < 1e-3, "flip {flip}: {err}");
            // Control: a sphere treated as flat (dn = 0) fails.
            let flat = |x: &Differential| Differential {
                dndu: DVec3::ZERO,
                dndv: DVec3::ZERO,
                ..*x
            };
            assert!(max_fd_error(&g, eye, &aims, flat) > 1e-2);
        }
    }

    #[test]
    fn disk_derivatives_match_finite_differences() {
        let to_world = Mat4::from_scale_rotation_translation(
            Vec3::new(1.5, 0.7, 1.0),
            Quat::from_euler(glam::EulerRot::XYZ, 0.4, 0.2, -0.3),
            Vec3::new(0.1, 0.2, -0.3),
        );
        let normal = (Mat3::from_mat4(to_world).inverse().transpose() * Vec3::Z).normalize();
        let g = Geometry::build(vec![GeoShape {
            surface: Surface::Disk {
                to_world,
                to_local: to_world.inverse(),
                normal,
            },
            flip_normals: false,
        }]);
        let eye = to_world.transform_point3(Vec3::new(0.1, 0.2, 3.0));
        let aims: Vec<Vec3> = [(0.5, 0.3), (-0.4, 0.5), (-0.3, -0.6), (0.2, -0.7)]
            .map(|(x, y)| to_world.transform_point3(Vec3::new(x, y, 0.0)))
            .to_vec();
        let err = max_fd_error(&g, eye, &aims, identity);
        assert!(err < 1e-3, "{err}");
        // Control: derivatives in object space (without to_world) fail.
        let err = max_fd_error(&g, eye, &aims, |x| Differential {
            dpdu: to_world.inverse().as_dmat4().transform_vector3(x.dpdu),
            ..*x
        });
        assert!(err > 1e-2, "{err}");
    }

    /// The built-in `rectangle` and `cube` (meshes with UVs) as the loader
    /// makes them, under a scaling, rotating transform.
    #[test]
    fn rectangle_and_cube_derivatives_match_finite_differences() {
        let to_world = Mat4::from_scale_rotation_translation(
            Vec3::new(1.2, 0.8, 0.6),
            Quat::from_euler(glam::EulerRot::XYZ, 0.5, -0.3, 0.2),
            Vec3::new(-0.2, 0.1, 0.3),
        );
        for raw in [crate::scene::mesh::rectangle(), crate::scene::mesh::cube()] {
            let mesh = MeshData {
                positions: raw
                    .positions
                    .iter()
                    .map(|&p| to_world.transform_point3(p))
                    .collect(),
                normals: None,
                uvs: raw.uvs.clone(),
                indices: raw.indices.clone(),
            };
            let g = Geometry::build(vec![GeoShape {
                surface: Surface::Mesh(mesh),
                flip_normals: false,
            }]);
            let eye = to_world.transform_point3(Vec3::new(0.4, 0.3, 4.0));
            let aims: Vec<Vec3> = [(0.3, 0.4), (-0.5, 0.2), (0.6, -0.5), (-0.2, -0.7)]
                .map(|(x, y)| to_world.transform_point3(Vec3::new(x, y, 1.0)))
                .to_vec();
            let aims = if raw.indices.len() == 2 {
                aims.iter()
                    .map(|a| *a - to_world.transform_vector3(Vec3::Z))
                    .collect()
            } else {
                aims
            };
            let err = max_fd_error(&g, eye, &aims, identity);
            assert!(err < 1e-3, "{} triangles: {err}", raw.indices.len());
        }
    }

    /// `locate` finds the hit of a surface point again: the same shape and
    /// the same derivatives (to the `f32` rounding of the barycentrics).
    #[test]
    fn locate_recovers_the_hit() {
        let g = Geometry::build(vec![
            patch(true, true, false),
            GeoShape {
                surface: Surface::Sphere {
                    center: Vec3::new(0.0, 0.0, 1.5),
                    radius: 0.3,
                    frame: Mat3::IDENTITY,
                },
                flip_normals: false,
            },
        ]);
        let eye = Vec3::new(0.3, -0.4, 3.0);
        let mut aims = patch_aims();
        aims.push(Vec3::new(0.1, 0.1, 1.75));
        for aim in aims {
            let (hit, sp) = hit_at(&g, eye, (aim - eye).normalize()).unwrap();
            let found = g.locate(&sp).expect("located");
            let (a, b) = (g.differential(&hit, &sp), g.differential(&found, &sp));
            assert!((a.dndu - b.dndu).length() < 1e-5 * (1.0 + a.dndu.length()));
            assert!((a.dpdu - b.dpdu).length() < 1e-5 * a.dpdu.length());
            assert!((a.dndv - b.dndv).length() < 1e-5 * (1.0 + a.dndv.length()));
        }
    }

    /// The orthonormal form moves the point and normal the same way as the
    /// parameterisation: `dp` along `s` has unit length, and `dn` along
    /// `s, t` agrees with the chain rule through `(u, v)`.
    #[test]
    fn orthonormal_form_is_consistent() {
        let g = Geometry::build(vec![patch(true, true, false)]);
        let eye = Vec3::new(0.3, -0.4, 3.0);
        for aim in patch_aims() {
            let (h, sp) = hit_at(&g, eye, (aim - eye).normalize()).unwrap();
            let dg = g.differential(&h, &sp);
            let o = dg.orthonormal().expect("regular");
            assert!((o.s.length() - 1.0).abs() < 1e-12);
            assert!(o.s.dot(o.t).abs() < 1e-12 && o.s.dot(o.ng).abs() < 1e-9);
            // Any (du, dv): dp = α s + β t and dn = α dnds + β dndt.
            let (du, dv) = (0.37, -0.81);
            let dp = dg.dpdu * du + dg.dpdv * dv;
            let (a, b) = (dp.dot(o.s), dp.dot(o.t));
            let dn = dg.dndu * du + dg.dndv * dv;
            assert!((o.dnds * a + o.dndt * b - dn).length() < 1e-9 * (1.0 + dn.length()));
        }
    }
}
