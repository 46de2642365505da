//! Anisotropic Beckmann and GGX microfacet distributions with the separable
//! Smith shadowing–masking term and visible-normal sampling.
//!
//! All directions are in the local shading frame (z = macro normal);
//! `alpha_u` is the roughness along x (tangent), `alpha_v` along y.
//!
//! # Two shadowing terms for Beckmann, and why
//!
//! Mitsuba 3 evaluates Beckmann's Smith G1 with Walter et al.'s (2007)
//! rational fit (`smith_g1` in `include/mitsuba/render/microfacet.h`: for
//! a = 1/(α tan θ), G1 = (3.535 a + 2.181 a²)/(1 + 2.276 a + 2.577 a²) below
//! a = 1.6, else 1; < 0.35 % from the exact value). The BSDF *value* here uses
//! the same fit ([`Microfacet::g1`]), so `eval` is what Mitsuba evaluates.
//!
//! The *density* of the visible normals is another matter: visible-normal
//! sampling draws m with density D_w(m) = G1(w, m) max(0, w·m) D(m) / w.z,
//! which is a normalised density only with the exact Smith G1 (it is the
//! normaliser ∫ max(0, w·m) D(m) dm / w.z = 1/G1). Mitsuba's sampler inverts
//! the exact CDF too (three Newton steps), but its `pdf` puts the fit in
//! D_w, so Mitsuba's pdf is off the true density by G1_fit/G1_exact, and its
//! sampled weight F·G1_fit(wi) integrates F D G1_exact(wo) G1_fit(wi)/(4 cos θ_o),
//! not its own `eval` (one factor of up to 0.35 % apart). Here the pdf is the
//! exact density ([`Microfacet::g1_exact`], [`Microfacet::pdf_visible`]), and
//! the sampled weight is `eval · cos / pdf`, so BSDF sampling and light
//! sampling both converge to the integral of Mitsuba's `eval`. Consequences:
//! `eval` matches Mitsuba to f32 rounding; `pdf` differs from Mitsuba's by
//! exactly the factor G1_exact(wo)/G1_fit(wo) (`tests/bsdf_mitsuba.rs`
//! checks both); a Mitsuba render can still differ from ours by up to that
//! factor on the BSDF-sampled part of its estimate. (With the fit in the
//! pdf, the chi-square test in `tests/bsdf_chi2.rs` rejects every grazing
//! Beckmann case, at p-values down to 1e-138.) For GGX both terms are the
//! same closed form.

use super::desc::MicrofacetKind;
use super::special::{erfc, erfc_f32, erfc_scaled, erfinv};
use crate::sampling::ONE_MINUS_EPSILON;
use glam::Vec3;
use std::f32::consts::PI;

/// Smallest roughness accepted; smaller values are clamped (as Mitsuba 3 does)
/// so the distribution stays representable in f32.
pub const MIN_ALPHA: f32 = 1e-4;

/// A microfacet normal distribution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microfacet {
    kind: MicrofacetKind,
    alpha_u: f32,
    alpha_v: f32,
}

impl Microfacet {
    /// A distribution with the given roughnesses, clamped below at [`MIN_ALPHA`].
    pub fn new(kind: MicrofacetKind, alpha_u: f32, alpha_v: f32) -> Self {
        Microfacet {
            kind,
            alpha_u: alpha_u.max(MIN_ALPHA),
            alpha_v: alpha_v.max(MIN_ALPHA),
        }
    }

    /// The distribution family.
    pub fn kind(&self) -> MicrofacetKind {
        self.kind
    }

    /// Roughnesses (along x, along y) after clamping.
    pub fn alpha(&self) -> (f32, f32) {
        (self.alpha_u, self.alpha_v)
    }

    /// Normal distribution D(m), normalised so that ∫ D(m) cos θ_m dω_m = 1.
    /// Zero for `m` in the lower hemisphere.
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let (au, av) = (self.alpha_u, self.alpha_v);
        let xx = m.x * m.x / (au * au);
        let yy = m.y * m.y / (av * av);
        let zz = m.z * m.z;
        match self.kind {
            MicrofacetKind::Ggx => {
                let s = xx + yy + zz;
                1.0 / (PI * au * av * s * s)
            }
            MicrofacetKind::Beckmann => {
                // exp(-tan²θ (cos²φ/αu² + sin²φ/αv²)) / (π αu αv cos⁴θ)
                let e = (xx + yy) / zz;
                if e > 80.0 {
                    return 0.0;
                }
                (-e).exp() / (PI * au * av * zz * zz)
            }
        }
    }

    /// Smith's Λ(w) for direction `w` (independent of the microfacet normal).
    fn lambda(&self, w: Vec3) -> f32 {
        let xy_alpha2 = (self.alpha_u * w.x) * (self.alpha_u * w.x)
            + (self.alpha_v * w.y) * (self.alpha_v * w.y);
        if xy_alpha2 == 0.0 {
            return 0.0;
        }
        let zz = w.z * w.z;
        if zz == 0.0 {
            return f32::INFINITY;
        }
        match self.kind {
            MicrofacetKind::Ggx => {
                // Λ = (√(1 + α² tan²θ) − 1) / 2, written without cancellation.
                let a2t2 = xy_alpha2 / zz;
                0.5 * a2t2 / (1.0 + (1.0 + a2t2).sqrt())
            }
            MicrofacetKind::Beckmann => {
                // a = 1/(α tan θ); Λ = (e^{-a²}/(a√π) − erfc(a)) / 2.
                let a = w.z.abs() / xy_alpha2.sqrt();
                if a > 6.0 {
                    return 0.0;
                }
                let l = 0.5 * ((-a * a).exp() / (a * PI.sqrt()) - erfc_f32(a));
                l.max(0.0)
            }
        }
    }

    /// Smith's monodirectional shadowing G1(w, m) as Mitsuba 3 evaluates it
    /// (the BSDF value uses this): exact for GGX, Walter's rational fit for
    /// Beckmann (see the module documentation). Zero when `w` sees the back of
    /// the microfacet (w·m and w·n of different signs).
    pub fn g1(&self, w: Vec3, m: Vec3) -> f32 {
        if w.dot(m) * w.z <= 0.0 {
            return 0.0;
        }
        match self.kind {
            MicrofacetKind::Ggx => 1.0 / (1.0 + self.lambda(w)),
            MicrofacetKind::Beckmann => {
                let xy_alpha2 = (self.alpha_u * w.x) * (self.alpha_u * w.x)
                    + (self.alpha_v * w.y) * (self.alpha_v * w.y);
                if xy_alpha2 == 0.0 {
                    return 1.0;
                }
                // a = 1/(α tan θ) = |cos θ| / √(α_x² x² + α_y² y²).
                let a = w.z.abs() / xy_alpha2.sqrt();
                if a >= 1.6 {
                    return 1.0;
                }
                let a2 = a * a;
                (3.535 * a + 2.181 * a2) / (1.0 + 2.276 * a + 2.577 * a2)
            }
        }
    }

    /// The exact Smith G1(w, m) (from Λ), the normaliser of the visible-normal
    /// density that [`Microfacet::sample_visible`] draws from; same support
    /// as [`Microfacet::g1`]. Equal to it for GGX.
    pub fn g1_exact(&self, w: Vec3, m: Vec3) -> f32 {
        if w.dot(m) * w.z <= 0.0 {
            return 0.0;
        }
        1.0 / (1.0 + self.lambda(w))
    }

    /// `(g1(w, m), g1_exact(w, m))`, computing the shared value once for GGX.
    pub fn g1_both(&self, w: Vec3, m: Vec3) -> (f32, f32) {
        match self.kind {
            MicrofacetKind::Ggx => {
                let g = self.g1_exact(w, m);
                (g, g)
            }
            MicrofacetKind::Beckmann => (self.g1(w, m), self.g1_exact(w, m)),
        }
    }

    /// Separable Smith shadowing–masking G1(wo, m)·G1(wi, m) with Mitsuba's
    /// G1 ([`Microfacet::g1`]).
    pub fn g(&self, wo: Vec3, wi: Vec3, m: Vec3) -> f32 {
        self.g1(wo, m) * self.g1(wi, m)
    }

    /// Density of visible normals seen from `w` (w.z > 0), per solid angle of m:
    /// D_w(m) = G1(w, m) · max(0, w·m) · D(m) / w.z with the exact G1, which
    /// makes it a normalised density (the one `sample_visible` draws from).
    pub fn pdf_visible(&self, w: Vec3, m: Vec3) -> f32 {
        if w.z <= 0.0 {
            return 0.0;
        }
        let wm = w.dot(m);
        if wm <= 0.0 {
            return 0.0;
        }
        let d = self.d(m);
        if d == 0.0 {
            return 0.0;
        }
        self.g1_exact(w, m) * wm * d / w.z
    }

    /// Samples a microfacet normal from the visible-normal distribution seen
    /// from `w` (which must satisfy w.z > 0), consuming `u.0` then `u.1`.
    ///
    /// GGX: Dupuy & Benyoub 2023 (spherical caps; the distribution of Heitz
    /// 2018, "Sampling the GGX distribution of visible normals").
    /// Beckmann: stretch to the isotropic unit-roughness configuration,
    /// sample the visible slope (Heitz & d'Eon 2014) with an exact inversion of
    /// its marginal CDF by safeguarded Newton iteration, then unstretch.
    pub fn sample_visible(&self, w: Vec3, u: (f32, f32)) -> Vec3 {
        match self.kind {
            MicrofacetKind::Ggx => self.sample_visible_ggx(w, u),
            MicrofacetKind::Beckmann => self.sample_visible_beckmann(w, u),
        }
    }

    fn sample_visible_ggx(&self, w: Vec3, u: (f32, f32)) -> Vec3 {
        // Dupuy & Benyoub 2023, "Sampling visible GGX normals with spherical
        // caps": in the stretched (unit-roughness) configuration, the visible
        // normals are h = c + w where c is uniform on the spherical cap
        // z ≥ −w.z. Same distribution as Heitz 2018, no basis construction.
        let (au, av) = (self.alpha_u, self.alpha_v);
        let ws = Vec3::new(au * w.x, av * w.y, w.z).normalize();
        let (sp, cp) = (2.0 * PI * u.0).sin_cos();
        let z = (1.0 - u.1) * (1.0 + ws.z) - ws.z;
        let sin_t = (1.0 - z * z).max(0.0).sqrt();
        let h = Vec3::new(sin_t * cp, sin_t * sp, z) + ws;
        Vec3::new(au * h.x, av * h.y, h.z).normalize_or(Vec3::Z)
    }

    fn sample_visible_beckmann(&self, w: Vec3, u: (f32, f32)) -> Vec3 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let ws = Vec3::new(au * w.x, av * w.y, w.z).normalize();
        let sin_t = (ws.x * ws.x + ws.y * ws.y).sqrt();
        let (cos_phi, sin_phi) = if sin_t > 0.0 {
            (ws.x / sin_t, ws.y / sin_t)
        } else {
            (1.0, 0.0)
        };
        let sx = beckmann_visible_slope_x(ws.z as f64, sin_t as f64, u.0 as f64) as f32;
        // The second slope is independent of the first: density e^{-y²}/√π.
        let sy = erfinv(2.0 * u.1 - 1.0);
        let tx = (cos_phi * sx - sin_phi * sy) * au;
        let ty = (sin_phi * sx + cos_phi * sy) * av;
        Vec3::new(-tx, -ty, 1.0).normalize()
    }

    /// Inverse of [`Microfacet::sample_visible`]: the `u` that samples the
    /// normal `m` seen from `w` (w.z > 0), or `None` when `m` is not a
    /// visible normal. Used to map a path back to its random numbers.
    pub fn invert_visible(&self, w: Vec3, m: Vec3) -> Option<(f32, f32)> {
        if w.z <= 0.0 || m.z <= 0.0 || w.dot(m) <= 0.0 {
            return None;
        }
        let (au, av) = (self.alpha_u, self.alpha_v);
        let ws = Vec3::new(au * w.x, av * w.y, w.z).normalize();
        match self.kind {
            MicrofacetKind::Ggx => {
                // The stretched normal ĥ ∝ (m.x/αu, m.y/αv, m.z); the cap point
                // c = t ĥ − ws with |c| = 1 is the reflection of ws about ĥ.
                let h = Vec3::new(m.x / au, m.y / av, m.z).normalize();
                let c = 2.0 * h.dot(ws) * h - ws;
                let u1 = 1.0 - (c.z + ws.z) / (1.0 + ws.z);
                let mut u0 = c.y.atan2(c.x) / (2.0 * PI);
                if u0 < 0.0 {
                    u0 += 1.0;
                }
                Some((
                    u0.clamp(0.0, ONE_MINUS_EPSILON),
                    u1.clamp(0.0, ONE_MINUS_EPSILON),
                ))
            }
            MicrofacetKind::Beckmann => {
                let sin_t = (ws.x * ws.x + ws.y * ws.y).sqrt();
                let (cos_phi, sin_phi) = if sin_t > 0.0 {
                    (ws.x / sin_t, ws.y / sin_t)
                } else {
                    (1.0, 0.0)
                };
                // Slopes of m, unstretched back to unit roughness, rotated back.
                let (tx, ty) = (-m.x / m.z / au, -m.y / m.z / av);
                let sx = cos_phi * tx + sin_phi * ty;
                let sy = -sin_phi * tx + cos_phi * ty;
                let (cos_t, sin_t) = (ws.z as f64, sin_t as f64);
                let hi = beckmann_slope_hi(cos_t, sin_t);
                let u0 = beckmann_slope_cdf(cos_t, sin_t, (sx as f64).min(hi))
                    / beckmann_slope_cdf(cos_t, sin_t, hi);
                // Second slope: CDF of e^{-y²}/√π is erfc(−y)/2.
                let u1 = 0.5 * erfc(-(sy as f64));
                Some((
                    (u0 as f32).clamp(0.0, ONE_MINUS_EPSILON),
                    (u1 as f32).clamp(0.0, ONE_MINUS_EPSILON),
                ))
            }
        }
    }
}

/// Inverts the marginal CDF of the first visible slope of the unit isotropic
/// Beckmann distribution seen under angle θ (given as cos θ, sin θ):
/// density ∝ (cos θ − x sin θ) e^{-x²} on x < cot θ, whose primitive is
/// F(x) = cos θ · (√π/2) · erfc(−x) + (sin θ / 2) · e^{-x²}.
/// Upper end of the visible-slope support, min(cot θ, 6): beyond ±6 the
/// density is below e^{-36}, so the bracket loses nothing.
fn beckmann_slope_hi(cos_t: f64, sin_t: f64) -> f64 {
    if sin_t > 0.0 {
        (cos_t / sin_t).min(6.0)
    } else {
        6.0
    }
}

/// Unnormalised CDF F(x) of the first visible slope (see below).
fn beckmann_slope_cdf(cos_t: f64, sin_t: f64, x: f64) -> f64 {
    const SQRT_PI_2: f64 = 0.886_226_925_452_758; // √π / 2
    cos_t * SQRT_PI_2 * erfc(-x) + 0.5 * sin_t * (-x * x).exp()
}

fn beckmann_visible_slope_x(cos_t: f64, sin_t: f64, u: f64) -> f64 {
    const SQRT_PI_2: f64 = 0.886_226_925_452_758; // √π / 2
    // F(x) with e = e^{-x²} supplied, so one iteration costs two `exp`s.
    let cdf_with = |x: f64, e: f64| {
        let ec = e * erfc_scaled(x.abs());
        let erfc_neg_x = if x <= 0.0 { ec } else { 2.0 - ec };
        cos_t * SQRT_PI_2 * erfc_neg_x + 0.5 * sin_t * e
    };
    let mut hi = beckmann_slope_hi(cos_t, sin_t);
    let mut lo = -6.0f64;
    let target = u * cdf_with(hi, (-hi * hi).exp());
    // Start from the normal-incidence answer, which is exact when sin θ = 0.
    let mut x = (erfinv((2.0 * u - 1.0) as f32) as f64).clamp(lo, hi);
    for _ in 0..64 {
        let e = (-x * x).exp();
        let f = cdf_with(x, e) - target;
        if f > 0.0 {
            hi = x;
        } else {
            lo = x;
        }
        // Halley's method (cubic convergence): F' = (c − x s) e,
        // F'' = (−s − 2x (c − x s)) e.
        let lin = cos_t - x * sin_t;
        let d1 = lin * e;
        // Converged when the Newton distance δ = |F − target| / F' to the root
        // is below 1e-5: the Newton-corrected point is then within ~δ² ≈ 1e-10
        // of the root, far beyond the f32 the slope is returned in. (A small
        // *step* is no test: where F' vanishes, Halley steps are tiny too.)
        if d1 > 0.0 && f.abs() < 1e-5 * d1 {
            return (x - f / d1).clamp(lo, hi);
        }
        let d2 = (-sin_t - 2.0 * x * lin) * e;
        let denom = 2.0 * d1 * d1 - f * d2;
        let mut next = if d1 > 0.0 && denom > 0.0 {
            x - 2.0 * f * d1 / denom
        } else {
            f64::NAN
        };
        // A step leaving the bracket (or undefined) falls back to bisection.
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        x = next;
        if hi - lo < 1e-9 {
            break;
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sph(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// ∫ D(m) cos θ_m dω and ∫ D_w(m) dω by a fine midpoint rule in (θ, φ).
    fn integrate(f: impl Fn(Vec3) -> f64) -> f64 {
        let (nt, np) = (2000, 400);
        let mut sum = 0.0;
        for i in 0..nt {
            let t = (i as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
            for j in 0..np {
                let p = (j as f64 + 0.5) / np as f64 * std::f64::consts::TAU;
                sum += f(sph(t as f32, p as f32)) * t.sin();
            }
        }
        sum * std::f64::consts::FRAC_PI_2 / nt as f64 * std::f64::consts::TAU / np as f64
    }

    #[test]
    fn distributions_are_normalised_and_visible_normals_integrate_to_one() {
        for kind in [MicrofacetKind::Beckmann, MicrofacetKind::Ggx] {
            for (au, av) in [(0.3f32, 0.3f32), (0.5, 0.2), (1.0, 1.0)] {
                let mf = Microfacet::new(kind, au, av);
                let proj = integrate(|m| mf.d(m) as f64 * m.z as f64);
                // Midpoint rule with 2000×400 cells on a smooth integrand: error ≪ 1e-3.
                assert!(
                    (proj - 1.0).abs() < 2e-3,
                    "{kind:?} {au},{av}: ∫D cos = {proj}"
                );
                for theta in [0.0f32, 0.7, 1.3, 1.55] {
                    let w = sph(theta, 0.4);
                    let vis = integrate(|m| mf.pdf_visible(w, m) as f64);
                    // Exact Smith G1 makes D_w a density; the tolerance covers the quadrature error.
                    assert!(
                        (vis - 1.0).abs() < 3e-3,
                        "{kind:?} {au},{av} θ={theta}: ∫D_w = {vis}"
                    );
                }
            }
        }
    }

    #[test]
    fn beckmann_slope_inversion_hits_the_target_cdf() {
        for k in 0..=40 {
            let theta = k as f64 / 40.0 * 1.5706;
            let (s, c) = theta.sin_cos();
            for i in 0..2000 {
                let u = (i as f64 + 0.5) / 2000.0;
                let x = beckmann_visible_slope_x(c, s, u);
                let cdf = |x: f64| c * 0.886_226_925_452_758 * erfc(-x) + 0.5 * s * (-x * x).exp();
                let hi = if s > 0.0 { c / s } else { 50.0 };
                let got = cdf(x) / cdf(hi.min(6.0));
                assert!((got - u).abs() < 1e-6, "θ={theta} u={u}: F(x)={got}");
            }
        }
    }
}
