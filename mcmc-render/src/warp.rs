//! Warps from the unit square to common domains, with their densities.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};

/// Shirley–Chiu concentric map from [0,1)² to the unit disk (area-preserving).
pub fn concentric_disk(u: (f32, f32)) -> Vec2 {
    let a = 2.0 * u.0 - 1.0;
    let b = 2.0 * u.1 - 1.0;
    if a == 0.0 && b == 0.0 {
        return Vec2::ZERO;
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, FRAC_PI_4 * (b / a))
    } else {
        (b, FRAC_PI_2 - FRAC_PI_4 * (a / b))
    };
    Vec2::new(r * phi.cos(), r * phi.sin())
}

/// Cosine-weighted direction about +z; density `cos θ / π`.
pub fn cosine_hemisphere(u: (f32, f32)) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// Uniform direction on the unit sphere; density `1 / (4π)`.
pub fn uniform_sphere(u: (f32, f32)) -> Vec3 {
    let z = 1.0 - 2.0 * u.0;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.1;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Uniform barycentrics (b0, b1, b2) on a triangle.
pub fn uniform_triangle(u: (f32, f32)) -> (f32, f32, f32) {
    let su = u.0.sqrt();
    let b0 = 1.0 - su;
    let b1 = u.1 * su;
    (b0, b1, (1.0 - b0 - b1).max(0.0))
}

/// Power heuristic (β = 2) weight of a strategy with density `a` against one with `b`.
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let a2 = a * a;
    let b2 = b * b;
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 > 0.0 { a2 / (a2 + b2) } else { 0.0 }
}
