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
    let (r, phi) = if a.abs() > b.abs() {
        (a, FRAC_PI_4 * (b / a))
    } else {
        (b, 2.0 * FRAC_PI_4 - FRAC_PI_4 * (a / b))
    };
    let (s, c) = phi.sin_cos();
    let (x, y) = (r * c, r * s);
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    Vec3::new(x, y, z)
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
