//! Specular manifolds (Jakob & Marschner 2012, "Manifold exploration"):
//! the geometry behind the manifold perturbation of path-space MLT.
//!
//! A **chain** is a slice of [`ManifoldVertex`]: a fixed non-specular
//! anchor `x_0`, specular vertices `x_1 … x_k` (k ≥ 1, each a mirror
//! reflection or a refraction with its η) and a non-specular endpoint
//! `x_{k+1}` on a surface. The chain is on the specular manifold when at
//! every specular vertex the generalised half-vector is parallel to the
//! shading normal ([`constraint`]). Moving the endpoint to first order moves
//! the specular vertices by the solution of a block-tridiagonal system in
//! the constraint Jacobian ([`constraint::tangent_map`]); its first block's
//! determinant gives the **generalised geometry term**
//! ([`constraint::generalized_geometry`]). The **manifold walk**
//! ([`walk::walk`]) moves the endpoint to a target by Newton steps in that
//! tangent space, each projected back onto the surfaces by ray tracing from
//! the anchor through the chain; [`walk::walk_reversible`] adds the
//! reverse-walk check. `docs/manifold.md` has the formulas and tests.
//!
//! Glossy vertices: [`ManifoldVertex::from_path_vertex`] makes only Dirac
//! (smooth) vertices specular; [`ManifoldVertex::from_glossy_path_vertex`]
//! and [`set_offsets`] put glossy ones on their **offset manifold** (the
//! current half-vector held fixed in the normal's frame), as Mitsuba 0.6
//! does for the rough vertices it chooses at random to treat as specular.
//! Which ones to choose, and the acceptance ratio's extra determinant for
//! several glossy vertices, are the mutation's (`docs/manifold.md`).

pub mod constraint;
pub mod perturbation;
pub mod walk;

use crate::bsdf::Bsdf;
use crate::bsdf::OneSided;
use crate::geometry::differential::OrthonormalDifferential;
use crate::geometry::{Geometry, Hit, SurfacePoint};
use crate::integrators::path_vertex::{Vertex, VertexKind};
use crate::scene::Scene;
use glam::{DVec2, DVec3, Vec3};

/// How light scatters at a specular vertex.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Specular {
    /// Mirror reflection about the shading normal.
    Reflect,
    /// Refraction; `eta` is η_inside/η_outside, the outside being the side
    /// the shading normal points to (the renderer's dielectric `eta`).
    Refract {
        /// η_inside / η_outside.
        eta: f64,
    },
}

/// A vertex's part in a chain.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Role {
    /// A specular interior vertex.
    Specular(Specular),
    /// A non-specular vertex ending the chain (diffuse, glossy, an emitter
    /// or the camera): the fixed anchor or the moving endpoint.
    Endpoint,
}

/// One vertex of a chain: position, normals, an orthonormal tangent frame
/// with the shading normal's derivatives along it, and its role.
#[derive(Clone, Copy, Debug)]
pub struct ManifoldVertex {
    /// The renderer's point (rays leave from it with its error bound).
    pub sp: SurfacePoint,
    /// Local geometry in `f64`. For a point not on a surface (pinhole,
    /// point light) the normals, tangents and derivatives are zero.
    pub geo: OrthonormalDifferential,
    /// Specular or endpoint.
    pub role: Role,
    /// Half-vector offset `(o_s, o_t)` a specular vertex keeps (its
    /// constraint is `c = (h·s, h·t) − offset`, see [`constraint`]): zero
    /// for smooth surfaces; a glossy vertex treated as specular keeps its
    /// current one ([`set_offsets`]).
    pub offset: DVec2,
}

impl ManifoldVertex {
    /// A vertex at the surface point `sp` of `hit`; `None` where the
    /// surface parameterisation is singular (a sphere's pole, a disk's
    /// centre): no tangent frame there.
    pub fn at_hit(geometry: &Geometry, hit: &Hit, sp: SurfacePoint, role: Role) -> Option<Self> {
        let geo = geometry.differential(hit, &sp).orthonormal()?;
        Some(ManifoldVertex {
            sp,
            geo,
            role,
            offset: DVec2::ZERO,
        })
    }

    /// A fixed point that is not on a surface (the pinhole, a point
    /// light): usable only as a chain's anchor.
    pub fn point(p: Vec3) -> Self {
        let mut sp = crate::integrators::path_vertex::Vertex::EMPTY.sp;
        sp.p = p;
        ManifoldVertex {
            sp,
            geo: OrthonormalDifferential {
                p: p.as_dvec3(),
                ng: DVec3::ZERO,
                ns: DVec3::ZERO,
                s: DVec3::ZERO,
                t: DVec3::ZERO,
                dnds: DVec3::ZERO,
                dndt: DVec3::ZERO,
            },
            role: Role::Endpoint,
            offset: DVec2::ZERO,
        }
    }

    /// The descriptor of a path vertex of the renderer. `hit` is the hit
    /// that produced `v` when the caller kept it (ignored for camera and
    /// point-light vertices off surfaces); without it the hit is found
    /// again with [`Geometry::locate`]. `next` is the
    /// position of the vertex after it along the chain, which says whether
    /// a dielectric reflected or refracted.
    ///
    /// A surface vertex whose sampled lobe was a Dirac delta (`v.delta`)
    /// becomes specular: a smooth conductor, the coating of `plastic`, or a
    /// smooth dielectric (reflection or refraction with its η). Every
    /// other vertex is an endpoint. `None` for what a chain cannot hold:
    /// emitters at infinity, transmission through a `thindielectric` (no
    /// deflection, so no half-vector constraint), a surface point that
    /// cannot be located, or a singular parameterisation.
    pub fn from_path_vertex(
        scene: &Scene,
        v: &Vertex,
        hit: Option<&Hit>,
        next: Vec3,
    ) -> Option<Self> {
        match v.kind {
            VertexKind::Infinite => return None,
            VertexKind::Camera | VertexKind::Light if !v.on_surface() => {
                return Some(Self::point(v.p()));
            }
            _ => {}
        }
        let role = if v.kind == VertexKind::Surface && v.delta {
            let ng = v.sp.ng;
            let transmitted = (v.wo.dot(ng) > 0.0) != ((next - v.p()).dot(ng) > 0.0);
            // A normal- or bump-mapped specular surface reflects about the
            // perturbed normal, and a masked one may pass light straight
            // through: the constraint models neither.
            let bsdf = scene.bsdf_at(&v.sp);
            if matches!(bsdf, crate::bsdf::textured::BsdfAt::Wrapped(..)) {
                return None;
            }
            Role::Specular(specular_of(bsdf.model(), transmitted)?)
        } else {
            Role::Endpoint
        };
        let located;
        let hit = match hit {
            Some(h) => h,
            None => {
                located = scene.geometry.locate(&v.sp)?;
                &located
            }
        };
        Self::at_hit(&scene.geometry, hit, v.sp, role)
    }

    /// [`Self::from_path_vertex`] that also makes a **glossy** surface
    /// vertex specular (rough conductor and `roughplastic` reflect, rough
    /// dielectric reflects or refracts with its η), for the offset
    /// manifolds of Jakob & Marschner: its offset is zero here; call
    /// [`set_offsets`] on the chain to hold its current half-vector.
    /// Whether to treat a glossy vertex so (Mitsuba 0.6 decides at random,
    /// by roughness) is the mutation's choice.
    pub fn from_glossy_path_vertex(
        scene: &Scene,
        v: &Vertex,
        hit: Option<&Hit>,
        next: Vec3,
    ) -> Option<Self> {
        let mut out = Self::from_path_vertex(scene, v, hit, next)?;
        if v.kind == VertexKind::Surface && out.role == Role::Endpoint {
            let ng = v.sp.ng;
            let transmitted = (v.wo.dot(ng) > 0.0) != ((next - v.p()).dot(ng) > 0.0);
            let bsdf = scene.bsdf_at(&v.sp);
            if matches!(bsdf, crate::bsdf::textured::BsdfAt::Wrapped(..)) {
                return None;
            }
            let glossy = match (bsdf.model(), transmitted) {
                (Bsdf::RoughDielectric(d), true) => Some(Specular::Refract { eta: d.eta as f64 }),
                (
                    Bsdf::RoughDielectric(_)
                    | Bsdf::RoughConductor(_)
                    | Bsdf::RoughPlastic(_)
                    | Bsdf::TwoSided(OneSided::RoughConductor(_) | OneSided::RoughPlastic(_)),
                    false,
                ) => Some(Specular::Reflect),
                _ => None,
            };
            if let Some(spec) = glossy {
                out.role = Role::Specular(spec);
            }
        }
        Some(out)
    }

    /// Position.
    #[inline]
    pub fn p(&self) -> DVec3 {
        self.geo.p
    }

    /// True when the vertex lies on a surface (it has a normal).
    #[inline]
    pub fn on_surface(&self) -> bool {
        self.geo.ng != DVec3::ZERO
    }
}

/// The specular interaction of a Dirac lobe of `bsdf`, reflected or
/// transmitted; `None` when it has none the manifold can describe.
fn specular_of(bsdf: &Bsdf, transmitted: bool) -> Option<Specular> {
    match (bsdf, transmitted) {
        (Bsdf::Dielectric(d), true) => Some(Specular::Refract { eta: d.eta as f64 }),
        (Bsdf::Dielectric(_) | Bsdf::ThinDielectric(_), false) => Some(Specular::Reflect),
        (
            Bsdf::Conductor(_)
            | Bsdf::Plastic(_)
            | Bsdf::TwoSided(OneSided::Conductor(_) | OneSided::Plastic(_)),
            false,
        ) => Some(Specular::Reflect),
        _ => None,
    }
}

/// Chain length `Σ |x_{i+1} − x_i|`: the scale of the walk's tolerances.
pub fn chain_length(chain: &[ManifoldVertex]) -> f64 {
    chain
        .windows(2)
        .map(|w| (w[1].p() - w[0].p()).length())
        .sum()
}

/// Sets every specular vertex's offset to its current half-vector, so that
/// the chain lies on its offset manifold exactly (smooth vertices of a
/// traced chain get offsets of the order of rounding). `None` where a
/// constraint is undefined (see [`constraint::constraint_blocks`]).
pub fn set_offsets(chain: &mut [ManifoldVertex]) -> Option<()> {
    for i in 1..chain.len().saturating_sub(1) {
        if let Role::Specular(_) = chain[i].role {
            let mut v = chain[i];
            v.offset = DVec2::ZERO;
            chain[i].offset =
                constraint::constraint_blocks(&chain[i - 1], &v, &chain[i + 1])?.value;
        }
    }
    Some(())
}
