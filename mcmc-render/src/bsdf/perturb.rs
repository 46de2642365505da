//! `normalmap` and `bumpmap`: BSDF wrappers that tilt the shading frame
//! at each point, with Mitsuba 3.9's semantics.
//!
//! The scene keeps the nested BSDF as any other and, beside it, a
//! [`Perturbation`]. At a hit, [`Perturbation::normal`] gives the
//! perturbed normal `n′` in the world; [`Perturbed`] then evaluates the
//! nested BSDF in the tilted frame while the integrators keep working in
//! the point's own shading frame (`sp.ns`), so their cosines, adjoint
//! corrections and MIS densities need no change.
//!
//! Mitsuba 3 (`src/bsdfs/normalmap.cpp`, `bumpmap.cpp`, 3.9) defines, with
//! `wi` the direction towards the camera side (its `si.wi`) and `wo` the
//! one towards the light side, both in the shading frame:
//! - `flip_invalid_normals` (default true): when `wi` lies on the other
//!   side of `n′` than of the shading normal, `n′` is mirrored to
//!   `(−x, −y, z)`;
//! - the nested BSDF is evaluated with both directions in the tilted
//!   frame; its value (which includes the cosine of `wo` about `n′`) is
//!   zero unless `wo` lies on the same side of `n′` and of the shading
//!   normal;
//! - `use_shadowing_function` (default true): the value is multiplied by
//!   Estevez et al.'s (2019) terminator term
//!   `2 / (1 + √(1 + α² tan²θ_o))`, `α² = min(tan²θ(n′)/8, 1)`, `θ_o` the
//!   angle of `wo` to the shading normal.
//!
//! The integrators multiply `eval` by `|cos θ|` about the shading normal
//! themselves, so [`Perturbed::eval`] returns Mitsuba's value divided by
//! that cosine. That function of (camera side, light side) is what every
//! integrator transports: in [`TransportMode::Importance`] the arguments
//! are swapped (`wo` is the light side), which with the nested BSDF's own
//! adjoint keeps light tracing the adjoint of path tracing. Because the
//! flip depends on the camera-side direction, which a light path samples
//! rather than knows, importance sampling draws from the unflipped or the
//! flipped frame with probability ½ each and keeps only directions that
//! select the frame they were drawn from; its density is ½ of the
//! nested one (exactly what [`Perturbed::pdf`] reports).

use super::invert::SampleInverse;
use super::{Bsdf, BsdfSample, TransportMode};
use crate::color::Rgb;
use crate::frame::Frame;
use crate::texture::{Bitmap, Texture};
use glam::Vec3;
use std::sync::Arc;

/// What tilts the shading frame of a BSDF.
#[derive(Clone, Debug)]
pub enum PerturbKind {
    /// `normalmap`: the texture's RGB `c` gives the normal `2c − 1` in the
    /// shading frame whose first tangent is ∂p/∂u.
    Normal(Texture),
    /// `bumpmap`: the texture's luminance is a height field, scaled by
    /// `scale`, whose UV gradient displaces ∂p/∂u and ∂p/∂v.
    Bump {
        /// The height texture (a bitmap: Mitsuba 3 has gradients only there).
        height: Arc<Bitmap>,
        /// Mitsuba's `scale` (gradient multiplier, default 1).
        scale: f32,
    },
}

/// A `normalmap` or `bumpmap` wrapper as the scene holds it.
#[derive(Clone, Debug)]
pub struct Perturbation {
    /// The map.
    pub kind: PerturbKind,
    /// Mitsuba's `flip_invalid_normals` (default true).
    pub flip_invalid_normals: bool,
    /// Mitsuba's `use_shadowing_function` (default true).
    pub use_shadowing_function: bool,
}

impl Perturbation {
    /// The perturbed unit normal in the world at a point with shading
    /// normal `ns`, geometric normal `ng`, UV `uv` and surface derivatives
    /// `(dp_du, dp_dv)`; `ns` itself when the map gives no direction.
    pub fn normal(&self, ns: Vec3, ng: Vec3, uv: glam::Vec2, (dp_du, dp_dv): (Vec3, Vec3)) -> Vec3 {
        let n = match &self.kind {
            PerturbKind::Normal(texture) => {
                let c = texture.eval(uv);
                let local = Vec3::new(2.0 * c.r - 1.0, 2.0 * c.g - 1.0, 2.0 * c.b - 1.0);
                // The map's tangent space is Mitsuba's shading frame.
                Frame::from_normal_and_tangent(ns, dp_du).to_world(local)
            }
            PerturbKind::Bump { height, scale } => {
                let g = height.luminance_gradient(uv) * *scale;
                let du = dp_du + ns * (g.x - ns.dot(dp_du));
                let dv = dp_dv + ns * (g.y - ns.dot(dp_dv));
                let n = du.cross(dv);
                // Keep it on the side of the geometric normal.
                if n.dot(ng) < 0.0 { -n } else { n }
            }
        };
        n.try_normalize().unwrap_or(ns)
    }

    /// The wrapper at a point whose shading frame is `frame` and whose
    /// perturbed normal (from [`Perturbation::normal`]) is `n_world`.
    pub fn at(&self, frame: &Frame, n_world: Vec3) -> Perturbed {
        let n = frame.to_local(n_world);
        let alpha2 = if self.use_shadowing_function {
            (0.125 * tan2(n)).min(1.0)
        } else {
            0.0
        };
        Perturbed {
            n,
            flip: self.flip_invalid_normals,
            alpha2,
        }
    }
}

/// `tan²θ` of a direction about the local +z.
#[inline]
fn tan2(w: Vec3) -> f32 {
    (1.0 - w.z * w.z).max(0.0) / (w.z * w.z)
}

/// A perturbed shading frame at one point, in the coordinates of the
/// point's own shading frame (+z the shading normal): the wrapper's
/// `eval`/`sample`/`pdf` around a nested BSDF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perturbed {
    /// The perturbed unit normal `n′` (unflipped).
    n: Vec3,
    /// `flip_invalid_normals`.
    flip: bool,
    /// α² of the shadowing term (0: no term).
    alpha2: f32,
}

impl Perturbed {
    /// `n′`, or its mirror image when `w_cam` sees it from the wrong side.
    #[inline]
    fn normal_for(&self, w_cam: Vec3) -> Vec3 {
        if self.flip && w_cam.z * w_cam.dot(self.n) <= 0.0 {
            self.flipped()
        } else {
            self.n
        }
    }

    /// True when importance sampling draws from two frames (½ each): with
    /// `flip_invalid_normals`, unless the mirror image is `n′` itself (an
    /// untilted normal, e.g. a flat region of a bump map on an
    /// axis-aligned plane), where both halves would draw from one frame
    /// and every direction would be kept twice.
    #[inline]
    fn splits(&self) -> bool {
        self.flip && self.flipped() != self.n
    }

    /// The mirrored normal `(−x, −y, z)`.
    #[inline]
    fn flipped(&self) -> Vec3 {
        Vec3::new(-self.n.x, -self.n.y, self.n.z)
    }

    /// The light-side factor: zero unless `w_light` lies on the same side
    /// of the shading normal and of the tilted one; else the terminator
    /// term.
    #[inline]
    fn light_side(&self, w_light: Vec3, n: Vec3) -> f32 {
        if !(w_light.z * w_light.dot(n) > 0.0) {
            return 0.0;
        }
        if self.alpha2 > 0.0 {
            2.0 / (1.0 + (1.0 + self.alpha2 * tan2(w_light)).sqrt())
        } else {
            1.0
        }
    }

    /// (camera side, light side) of `(wo, wi)` in `mode`.
    #[inline]
    fn sides(wo: Vec3, wi: Vec3, mode: TransportMode) -> (Vec3, Vec3) {
        match mode {
            TransportMode::Radiance => (wo, wi),
            TransportMode::Importance => (wi, wo),
        }
    }

    /// The wrapper's `(eval, pdf)` of `nested` (see [`Bsdf::eval_pdf`]):
    /// out of line, as are the other methods: they are the rare case in
    /// the integrators' loops.
    /// the value is Mitsuba's divided by `|cos θ|` of the sampled
    /// direction `wi` about the shading normal.
    #[inline(never)]
    pub fn eval_pdf(&self, nested: &Bsdf, wo: Vec3, wi: Vec3, mode: TransportMode) -> (Rgb, f32) {
        let (w_cam, w_light) = Self::sides(wo, wi, mode);
        let n = self.normal_for(w_cam);
        let k = self.light_side(w_light, n);
        if k == 0.0 {
            return (Rgb::BLACK, 0.0);
        }
        let frame = Frame::from_normal(n);
        let (lo, li) = (frame.to_local(wo), frame.to_local(wi));
        let (f, pdf) = nested.eval_pdf(lo, li, mode);
        // Mitsuba's value carries |cos| about n′ of the light side; the
        // integrators multiply by |cos| about the shading normal of the
        // light side in radiance mode, and apply the adjoint correction
        // (which expects the same function of the swapped arguments) in
        // importance mode. `light_side` ensured w_light.z ≠ 0.
        let cos = frame.to_local(w_light).z.abs() / w_light.z.abs();
        let pdf = match mode {
            TransportMode::Radiance => pdf,
            TransportMode::Importance if self.splits() => 0.5 * pdf,
            TransportMode::Importance => pdf,
        };
        (f * (k * cos), pdf)
    }

    /// The wrapper's value (see [`Perturbed::eval_pdf`]).
    pub fn eval(&self, nested: &Bsdf, wo: Vec3, wi: Vec3, mode: TransportMode) -> Rgb {
        self.eval_pdf(nested, wo, wi, mode).0
    }

    /// The wrapper's sampling density of `wi` from `wo`.
    pub fn pdf(&self, nested: &Bsdf, wo: Vec3, wi: Vec3, mode: TransportMode) -> f32 {
        self.eval_pdf(nested, wo, wi, mode).1
    }

    /// Samples `wi` from `wo` through the nested BSDF in the tilted frame.
    /// In importance mode with `flip_invalid_normals`, `u_lobe` first picks
    /// the unflipped or the flipped frame (½ each) and is rescaled for the
    /// nested BSDF.
    #[inline(never)]
    pub fn sample(
        &self,
        nested: &Bsdf,
        wo: Vec3,
        u_lobe: f32,
        u: (f32, f32),
        mode: TransportMode,
    ) -> Option<BsdfSample> {
        let (n, u_lobe, choice) = match mode {
            TransportMode::Radiance => (self.normal_for(wo), u_lobe, 1.0),
            TransportMode::Importance if self.splits() => {
                if u_lobe < 0.5 {
                    (self.n, 2.0 * u_lobe, 0.5)
                } else {
                    (
                        self.flipped(),
                        (2.0 * u_lobe - 1.0).min(1.0 - f32::EPSILON / 2.0),
                        0.5,
                    )
                }
            }
            TransportMode::Importance => (self.n, u_lobe, 1.0),
        };
        let frame = Frame::from_normal(n);
        let lo = frame.to_local(wo);
        let mut bs = nested.sample(lo, u_lobe, u, mode)?;
        let li = bs.wi;
        let wi = frame.to_world(li);
        if wi.z == 0.0 {
            return None;
        }
        let (w_cam, w_light, light_local) = match mode {
            TransportMode::Radiance => (wo, wi, li),
            TransportMode::Importance => (wi, wo, lo),
        };
        if li.z == 0.0 {
            return None;
        }
        // A direction drawn from one frame must select that frame.
        if mode == TransportMode::Importance && self.normal_for(w_cam) != n {
            return None;
        }
        let k = self.light_side(w_light, n);
        if k == 0.0 {
            return None;
        }
        // weight = eval · |wi.z| / pdf, with eval as in `eval_pdf`; the
        // nested weight carries |cos| about n′ of the sampled direction.
        // (In radiance mode the light side is the sampled direction and
        // the factor is k.)
        let cos = (light_local.z.abs() / w_light.z.abs()) * (wi.z.abs() / li.z.abs());
        bs.weight *= k * cos / choice;
        bs.pdf *= choice;
        bs.wi = wi;
        bs.weight.is_finite().then_some(bs)
    }

    /// The numbers with which [`Perturbed::sample`] returns `wi` from `wo`
    /// in `mode` (see [`Bsdf::invert`]), or `None` when it cannot: the
    /// nested BSDF's inverse in the frame the sampler draws from. That
    /// frame is a function of the directions (of `wo` in radiance mode; in
    /// importance mode with `flip_invalid_normals`, of `wi`, which must
    /// select the frame it was drawn from), so the inverse of the frame
    /// choice is deterministic: the half `[0, ½)` (unflipped) or `[½, 1)`
    /// (flipped) of `u_lobe`, scaled onto the nested interval.
    pub fn invert(
        &self,
        nested: &Bsdf,
        wo: Vec3,
        wi: Vec3,
        u_choice: f32,
        mode: TransportMode,
    ) -> Option<SampleInverse> {
        let (n, half) = match mode {
            TransportMode::Radiance => (self.normal_for(wo), None),
            TransportMode::Importance if self.splits() => {
                let n = self.normal_for(wi);
                (n, Some(n != self.n))
            }
            TransportMode::Importance => (self.n, None),
        };
        // The sampler rejects directions on the wrong side of the light
        // side's planes, and directions in the shading plane.
        let (_, w_light) = Self::sides(wo, wi, mode);
        if wi.z == 0.0 || self.light_side(w_light, n) == 0.0 {
            return None;
        }
        let frame = Frame::from_normal(n);
        let mut inv = nested.invert(frame.to_local(wo), frame.to_local(wi), u_choice)?;
        if let Some(flipped) = half {
            let o = if flipped { 0.5 } else { 0.0 };
            inv.u_lobe = (o + 0.5 * inv.u_lobe.0, o + 0.5 * inv.u_lobe.1);
        }
        Some(inv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::BsdfDesc;

    fn diffuse() -> Bsdf {
        Bsdf::from_desc(&BsdfDesc::Diffuse {
            reflectance: Rgb::new(0.8, 0.5, 0.2),
        })
        .unwrap()
    }

    fn diff(a: Rgb, b: Rgb) -> f32 {
        (a.r - b.r)
            .abs()
            .max((a.g - b.g).abs())
            .max((a.b - b.b).abs())
    }

    fn lcg(s: &mut u64) -> f32 {
        *s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*s >> 40) as f32) / (1u64 << 24) as f32
    }

    fn unit(x: f32, y: f32, z: f32) -> Vec3 {
        Vec3::new(x, y, z).normalize()
    }

    /// With the perturbed normal equal to the shading normal and no
    /// shadowing term, the wrapper is the nested BSDF, in both modes: its
    /// mirror image is itself, so importance sampling does not split
    /// between two frames (it did, and kept every direction twice: the
    /// mean importance weight was twice the albedo).
    #[test]
    fn identity_perturbation_is_the_nested_bsdf() {
        let p = Perturbed {
            n: Vec3::Z,
            flip: true,
            alpha2: 0.0,
        };
        let b = diffuse();
        let (wo, wi) = (unit(0.3, -0.2, 0.9), unit(-0.5, 0.1, 0.4));
        for mode in [TransportMode::Radiance, TransportMode::Importance] {
            let (f, pdf) = p.eval_pdf(&b, wo, wi, mode);
            let (g, q) = b.eval_pdf(wo, wi, mode);
            assert!(diff(f, g) < 1e-6, "{mode:?}");
            assert!((pdf - q).abs() < 1e-6);
            // Mean sample weight over a grid of numbers: the albedo
            // (0.5 for the green channel), as the nested BSDF's.
            let n = 64;
            let mut sum = [0.0f32; 2];
            for i in 0..n * n {
                let u = (
                    ((i % n) as f32 + 0.5) / n as f32,
                    ((i / n) as f32 + 0.5) / n as f32,
                );
                let ul = ((i * 7919) % (n * n)) as f32 / (n * n) as f32;
                sum[0] += p.sample(&b, wo, ul, u, mode).map_or(0.0, |s| s.weight.g);
                sum[1] += b.sample(wo, ul, u, mode).map_or(0.0, |s| s.weight.g);
            }
            assert!((sum[0] - sum[1]).abs() < 1e-3 * sum[1], "{mode:?} {sum:?}");
        }
    }

    /// Radiance eval · |cos θ_i| equals Mitsuba's value: the nested value
    /// times the cosine about n′, zero when `wi` crosses between the planes.
    #[test]
    fn eval_times_cosine_is_mitsuba_value() {
        let n = unit(0.4, 0.0, 1.0);
        let p = Perturbed {
            n,
            flip: true,
            alpha2: 0.0,
        };
        let b = diffuse();
        let wo = unit(0.0, 0.3, 1.0);
        let wi = unit(-0.6, 0.2, 0.5);
        let f = p.eval(&b, wo, wi, TransportMode::Radiance) * wi.z;
        let want = Rgb::new(0.8, 0.5, 0.2) * (std::f32::consts::FRAC_1_PI * wi.dot(n));
        assert!(diff(f, want) < 1e-6, "{f:?} {want:?}");
        // Above the tilted plane but below the shading plane: zero.
        let below = unit(1.0, 0.0, -0.1);
        assert!(below.dot(n) > 0.0);
        assert!(p.eval(&b, wo, below, TransportMode::Radiance).is_black());
    }

    /// Importance mode evaluates the radiance function with the arguments
    /// swapped, f_imp(a, b) = f_rad(b, a) (for the reciprocal nested
    /// diffuse BSDF), flips and shadowing term included: what the
    /// adjoint shading-normal correction of the integrators expects.
    #[test]
    fn importance_is_radiance_with_swapped_arguments() {
        let p = Perturbed {
            n: unit(0.7, -0.2, 0.6),
            flip: true,
            alpha2: 0.3,
        };
        let b = diffuse();
        let mut s = 9u64;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 40) as f32) / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..2000 {
            let a = unit(r(), r(), r().abs() + 0.01);
            let c = unit(r(), r(), r().abs() + 0.01);
            let fi = p.eval(&b, a, c, TransportMode::Importance);
            let fr = p.eval(&b, c, a, TransportMode::Radiance);
            assert!(diff(fi, fr) < 1e-5, "{fi:?} {fr:?}");
        }
    }

    /// In both modes, every sample's weight and density equal
    /// `eval · |cos| / pdf` and `pdf` at its direction, and the mean
    /// sample weight (the albedo by importance sampling) equals the albedo
    /// by uniform sampling of the sphere: the sampler covers the
    /// wrapper's support with the density it reports, including the
    /// flipped frame's half in importance mode. Tolerance: 5 standard
    /// errors of the difference of the two estimates (N = 400k each).
    #[test]
    fn sampling_matches_eval_and_pdf() {
        let b = diffuse();
        let p = Perturbed {
            n: unit(0.8, 0.1, 0.6),
            flip: true,
            alpha2: 0.2,
        };
        let mut s = 17u64;
        for mode in [TransportMode::Radiance, TransportMode::Importance] {
            // A grazing wo: the flip and the clip both matter.
            for wo in [unit(-0.9, 0.0, 0.25), unit(0.2, 0.3, 0.9)] {
                let n = 400_000;
                let (mut m1, mut m2) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let u = (lcg(&mut s), (lcg(&mut s), lcg(&mut s)));
                    if let Some(bs) = p.sample(&b, wo, u.0, u.1, mode) {
                        let (f, pdf) = p.eval_pdf(&b, wo, bs.wi, mode);
                        assert!((bs.pdf - pdf).abs() <= 1e-4 * pdf, "{mode:?}");
                        let w = f * (bs.wi.z.abs() / pdf);
                        assert!(diff(w, bs.weight) <= 1e-4 * (1.0 + w.g), "{mode:?}");
                        let x = bs.weight.g as f64;
                        m1 += x;
                        m2 += x * x;
                    }
                }
                let (mut u1, mut u2) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let wi = crate::warp::uniform_sphere((lcg(&mut s), lcg(&mut s)));
                    let x = (p.eval(&b, wo, wi, mode).g * wi.z.abs()) as f64
                        * 4.0
                        * std::f64::consts::PI;
                    u1 += x;
                    u2 += x * x;
                }
                let nf = n as f64;
                let (a, c) = (m1 / nf, u1 / nf);
                let se = ((m2 / nf - a * a) / nf + (u2 / nf - c * c) / nf).sqrt();
                assert!(a > 0.05, "{mode:?}: albedo {a}");
                assert!(
                    (a - c).abs() < 5.0 * se,
                    "{mode:?} {wo:?}: {a} vs {c} (se {se})"
                );
            }
        }
    }
}
