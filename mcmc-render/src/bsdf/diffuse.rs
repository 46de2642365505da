//! One-sided Lambertian reflection (Mitsuba 3 `diffuse`).

use super::{BsdfSample, TransportMode};
use crate::color::Rgb;
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4};

/// Lambertian reflector: f = reflectance/π above the surface, zero when
/// either direction is below it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    /// Albedo per channel.
    pub reflectance: Rgb,
}

impl Diffuse {
    /// f(wo, wi) without the cosine.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::BLACK;
        }
        self.reflectance * FRAC_1_PI
    }

    /// Cosine-weighted hemisphere density of `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        wi.z * FRAC_1_PI
    }

    /// Cosine-weighted sampling (concentric disk, lifted to the hemisphere).
    pub fn sample(&self, wo: Vec3, u: (f32, f32), _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = square_to_cosine_hemisphere(u);
        if wi.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight: self.reflectance,
            pdf: wi.z * FRAC_1_PI,
            is_delta: false,
            eta: 1.0,
        })
    }
}

/// Maps the unit square to the cosine-weighted upper hemisphere (Shirley–Chiu
/// concentric disk, then z = √(1 − r²)). Consumes `u.0` then `u.1`.
pub fn square_to_cosine_hemisphere(u: (f32, f32)) -> Vec3 {
    let a = 2.0 * u.0 - 1.0;
    let b = 2.0 * u.1 - 1.0;
    if a == 0.0 && b == 0.0 {
        return Vec3::Z;
    }
    // φ = π/4·t in the first wedge and π/2 − π/4·t in the second, with
    // |t| ≤ 1; sin(π/2 − θ) = cos θ lets one polynomial pair on [−π/4, π/4]
    // serve both, without a libm call (≈ 4% of a path-traced sample).
    let (x, y) = if a.abs() > b.abs() {
        let (s, c) = sin_cos_quarter(FRAC_PI_4 * (b / a));
        (a * c, a * s)
    } else {
        let (s, c) = sin_cos_quarter(FRAC_PI_4 * (a / b));
        (b * s, b * c)
    };
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    Vec3::new(x, y, z)
}

/// `(sin θ, cos θ)` for |θ| ≤ π/4 by their Taylor polynomials through θ⁹ and
/// θ⁸: the first omitted terms are below 2e-9 and 3e-8 there, under half an
/// ulp of the results, so this is as accurate as `f32::sin_cos`.
#[inline]
fn sin_cos_quarter(theta: f32) -> (f32, f32) {
    let t2 = theta * theta;
    let s = theta
        * (1.0 + t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0 + t2 * (-1.0 / 5040.0 + t2 / 362_880.0))));
    let c = 1.0 + t2 * (-0.5 + t2 * (1.0 / 24.0 + t2 * (-1.0 / 720.0 + t2 / 40_320.0)));
    (s, c)
}

/// Inverse of [`square_to_cosine_hemisphere`]: the `u` that maps to `w`
/// (w.z > 0 assumed; only `w.x`, `w.y` are used).
pub fn cosine_hemisphere_to_square(w: Vec3) -> (f32, f32) {
    let (x, y) = (w.x, w.y);
    let rho = (x * x + y * y).sqrt();
    if rho == 0.0 {
        return (0.5, 0.5);
    }
    let phi = y.atan2(x);
    let q = FRAC_PI_4;
    // Undo the four wedges of the concentric map (r may be negative there).
    let (a, b) = if phi.abs() <= q {
        (rho, rho * phi / q)
    } else if phi > q && phi <= 3.0 * q {
        (rho * (2.0 * q - phi) / q, rho)
    } else if phi < -q && phi >= -3.0 * q {
        let p = phi + 4.0 * q;
        (-rho * (2.0 * q - p) / q, -rho)
    } else {
        let p = if phi > 0.0 {
            phi - 4.0 * q
        } else {
            phi + 4.0 * q
        };
        (-rho, -rho * p / q)
    };
    let c = |v: f32| ((v + 1.0) * 0.5).clamp(0.0, crate::sampling::ONE_MINUS_EPSILON);
    (c(a), c(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_sin_cos_matches_libm_to_an_ulp_or_two() {
        // Both are within about an ulp of the true values, so they may
        // differ by two ulps (≤ 1.2e-7 for results ≤ 1).
        let n = 100_000;
        for i in 0..=n {
            let theta = FRAC_PI_4 * (2.0 * i as f32 / n as f32 - 1.0);
            let (s, c) = sin_cos_quarter(theta);
            let (s_ref, c_ref) = theta.sin_cos();
            assert!((s - s_ref).abs() <= 1.2e-7, "sin({theta}): {s} vs {s_ref}");
            assert!((c - c_ref).abs() <= 1.2e-7, "cos({theta}): {c} vs {c_ref}");
        }
    }

    #[test]
    fn cosine_hemisphere_map_round_trips_and_stays_unit() {
        let n = 257;
        for i in 0..n {
            for j in 0..n {
                let u = ((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                let w = square_to_cosine_hemisphere(u);
                assert!(
                    (w.length() - 1.0).abs() < 1e-6,
                    "|w| = {} at {u:?}",
                    w.length()
                );
                let back = cosine_hemisphere_to_square(w);
                assert!(
                    (back.0 - u.0).abs() < 1e-5 && (back.1 - u.1).abs() < 1e-5,
                    "{u:?} -> {w:?} -> {back:?}"
                );
            }
        }
    }
}
