//! Fresnel reflectance of dielectric and conductor interfaces, and the
//! reflection/refraction directions they go with.

use crate::color::Rgb;
use glam::Vec3;

/// Unpolarised Fresnel reflectance at a dielectric interface, with the
/// quantities refraction needs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DielectricFresnel {
    /// Reflectance in `[0, 1]` (1 under total internal reflection).
    pub r: f32,
    /// Signed cosine of the refracted direction: opposite in sign to the
    /// incident cosine (zero under total internal reflection).
    pub cos_t: f32,
    /// Relative index η_t/η_i seen along the refracted direction.
    pub eta_it: f32,
    /// Its reciprocal η_i/η_t.
    pub eta_ti: f32,
}

/// Fresnel reflectance for an incident cosine `cos_i` (signed against the
/// interface normal) and relative index `eta` = η_inside/η_outside.
///
/// Mitsuba 3 semantics: `cos_i < 0` means the incident direction is inside,
/// `eta == 1` (index-matched) reflects nothing, and a grazing `cos_i == 0`
/// reflects everything.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> DielectricFresnel {
    let outside = cos_i >= 0.0;
    let (eta_it, eta_ti) = if outside {
        (eta, 1.0 / eta)
    } else {
        (1.0 / eta, eta)
    };
    // Snell: sin²θ_t = sin²θ_i · (η_i/η_t)².
    let cos_t_sqr = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti;
    let ci = cos_i.abs();
    if eta == 1.0 {
        return DielectricFresnel {
            r: 0.0,
            cos_t: -cos_i,
            eta_it,
            eta_ti,
        };
    }
    if cos_t_sqr <= 0.0 {
        return DielectricFresnel {
            r: 1.0,
            cos_t: 0.0,
            eta_it,
            eta_ti,
        };
    }
    let ct = cos_t_sqr.sqrt();
    if ci == 0.0 {
        return DielectricFresnel {
            r: 1.0,
            cos_t: -ct.copysign(cos_i),
            eta_it,
            eta_ti,
        };
    }
    let a_s = (ci - eta_it * ct) / (ci + eta_it * ct);
    let a_p = (ct - eta_it * ci) / (ct + eta_it * ci);
    let r = (0.5 * (a_s * a_s + a_p * a_p)).min(1.0);
    DielectricFresnel {
        r,
        cos_t: -ct.copysign(cos_i),
        eta_it,
        eta_ti,
    }
}

/// Hemispherically averaged (diffuse) Fresnel reflectance of a dielectric
/// interface seen from the side whose relative index across it is `eta`:
/// 2 ∫₀¹ F(μ, eta) μ dμ, by the polynomial fits Mitsuba 3 uses
/// (`fresnel_diffuse_reflectance`): Egan & Hilgeman (1973) for `eta < 1`,
/// d'Eon & Irving (2011), a quintic in 1/`eta`, otherwise; both within
/// 0.1 % on the range of common materials.
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        0.0636 * inv + eta * (0.7099 - 1.4399 * eta) + 0.6681
    } else {
        0.919_317
            + inv * (-3.4793 + inv * (6.75335 + inv * (-7.80989 + inv * (4.98554 - 1.36881 * inv))))
    }
}

/// Complex index of refraction of a conductor, per channel, with a fast path
/// for the perfect mirror (`eta = 0, k = 1`, reflectance exactly one).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConductorFresnel {
    eta: Rgb,
    k: Rgb,
    mirror: bool,
}

impl ConductorFresnel {
    /// A conductor with complex index `eta + i·k` (relative to the outside).
    pub fn new(eta: Rgb, k: Rgb) -> Self {
        let mirror = eta.is_black() && k == Rgb::WHITE;
        ConductorFresnel { eta, k, mirror }
    }

    /// The perfect mirror: reflectance one at every angle.
    pub fn mirror() -> Self {
        ConductorFresnel::new(Rgb::BLACK, Rgb::WHITE)
    }

    /// True for the perfect mirror.
    pub fn is_mirror(&self) -> bool {
        self.mirror
    }

    /// Reflectance per channel for the cosine `cos_i` between the incident
    /// direction and the (micro)surface normal.
    pub fn eval(&self, cos_i: f32) -> Rgb {
        if self.mirror {
            return Rgb::WHITE;
        }
        let c = cos_i.abs().min(1.0);
        Rgb::new(
            fresnel_conductor(c, self.eta.r, self.k.r),
            fresnel_conductor(c, self.eta.g, self.k.g),
            fresnel_conductor(c, self.eta.b, self.k.b),
        )
    }
}

/// Exact unpolarised Fresnel reflectance of a conductor with complex index
/// `eta + i·k`, for `cos_i` in `[0, 1]` (the closed form of the complex
/// amplitude ratios r_s, r_p).
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let eta2 = eta * eta;
    let k2 = k * k;
    let t0 = eta2 - k2 - sin2;
    let a2pb2 = (t0 * t0 + 4.0 * eta2 * k2).sqrt();
    let a = (0.5 * (a2pb2 + t0)).max(0.0).sqrt();
    let t1 = a2pb2 + cos2;
    let t2 = 2.0 * a * cos_i;
    let rs = (t1 - t2) / (t1 + t2);
    let t3 = a2pb2 * cos2 + sin2 * sin2;
    let t4 = t2 * sin2;
    let rp = rs * (t3 - t4) / (t3 + t4);
    let r = 0.5 * (rp + rs);
    // 0/0 only at grazing incidence on an index-matched, lossless interface,
    // where reflectance is one in the limit.
    if r.is_finite() {
        r.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Mirror reflection of `w` about the normal `n`.
#[inline]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// Refraction of `w` through the normal `m`, given the signed refracted cosine
/// and η_i/η_t from [`fresnel_dielectric`] evaluated at `w·m`.
#[inline]
pub fn refract(w: Vec3, m: Vec3, cos_t: f32, eta_ti: f32) -> Vec3 {
    m * (w.dot(m) * eta_ti + cos_t) - w * eta_ti
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_normal_incidence_matches_closed_form() {
        for eta in [1.1f32, 1.5, 2.4, 1.0 / 1.5] {
            let want = ((eta - 1.0) / (eta + 1.0)).powi(2);
            let f = fresnel_dielectric(1.0, eta);
            assert!((f.r - want).abs() < 1e-6, "eta {eta}: {} vs {want}", f.r);
            // Same reflectance from the other side (reciprocity of Fresnel).
            let g = fresnel_dielectric(-1.0, 1.0 / eta);
            assert!((g.r - want).abs() < 1e-6);
        }
    }

    #[test]
    fn dielectric_total_internal_reflection_beyond_critical_angle() {
        let eta = 1.5f32;
        let cos_crit = (1.0 - 1.0 / (eta * eta)).sqrt();
        assert_eq!(fresnel_dielectric(-(cos_crit - 1e-3), eta).r, 1.0);
        assert!(fresnel_dielectric(-(cos_crit + 1e-3), eta).r < 1.0);
    }

    #[test]
    fn dielectric_reflectance_is_symmetric_across_a_refraction_pair() {
        // F(θ_i) from outside equals F(θ_t) from inside: the basis of reciprocity.
        let eta = 1.33f32;
        for i in 1..100 {
            let ci = i as f32 / 100.0;
            let out = fresnel_dielectric(ci, eta);
            let back = fresnel_dielectric(out.cos_t, eta);
            assert!(
                (out.r - back.r).abs() < 2e-5,
                "cos {ci}: {} vs {}",
                out.r,
                back.r
            );
            assert!((back.cos_t - ci).abs() < 1e-4);
        }
    }

    #[test]
    fn conductor_with_zero_absorption_equals_dielectric() {
        for eta in [1.2f32, 1.5, 3.0] {
            for i in 0..=100 {
                let c = i as f32 / 100.0;
                let want = fresnel_dielectric(c, eta).r;
                let got = fresnel_conductor(c, eta, 0.0);
                assert!(
                    (got - want).abs() < 2e-5,
                    "eta {eta} cos {c}: {got} vs {want}"
                );
            }
        }
    }

    #[test]
    fn conductor_normal_incidence_matches_closed_form() {
        // R(0) = ((η-1)² + k²) / ((η+1)² + k²).
        let (eta, k) = (0.2f32, 3.6f32);
        let want = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, eta, k) - want).abs() < 1e-6);
        // Reflectance rises to one at grazing incidence.
        assert!((fresnel_conductor(0.0, eta, k) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn diffuse_fresnel_fits_match_the_hemispherical_average() {
        // 2∫F(μ)μ dμ by the midpoint rule on 20000 cells (error ≪ 1e-4
        // except at the critical-angle kink, still < 1e-4), against the fits'
        // documented accuracy (≤ 0.6 % for η in 1–2 and its inverse).
        for eta in [1.2f32, 1.49, 1.6, 1.0 / 1.2, 1.0 / 1.49, 1.0 / 1.6] {
            let n = 20_000;
            let avg: f64 = (0..n)
                .map(|i| {
                    let mu = (i as f64 + 0.5) / n as f64;
                    2.0 * fresnel_dielectric(mu as f32, eta).r as f64 * mu / n as f64
                })
                .sum();
            let fit = fresnel_diffuse_reflectance(eta) as f64;
            assert!(
                (fit - avg).abs() < 6e-3 * avg,
                "η = {eta}: fit {fit} vs quadrature {avg}"
            );
        }
    }

    #[test]
    fn mirror_reflects_everything() {
        let m = ConductorFresnel::mirror();
        assert!(m.is_mirror());
        for i in 0..=10 {
            let c = i as f32 / 10.0;
            assert_eq!(m.eval(c), Rgb::WHITE);
            assert!((fresnel_conductor(c, 0.0, 1.0) - 1.0).abs() < 1e-6);
        }
    }
}
