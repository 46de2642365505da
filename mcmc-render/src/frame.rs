//! Orthonormal shading frames: BSDFs work in a local frame whose z axis is
//! the shading normal.

use glam::{Mat3, Vec3};

/// An orthonormal basis (s, t, n) with `n` the shading normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3,
    /// Second tangent.
    pub t: Vec3,
    /// Normal (local +z).
    pub n: Vec3,
}

impl Frame {
    /// Builds a frame around a unit normal (Duff et al. 2017, branchless).
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// Mitsuba 3's shading frame: `s` is the tangent `dp_du` made
    /// orthogonal to the unit normal `n`, `t = n × s`; the frame of
    /// [`Frame::from_normal`] when `dp_du` has no component in the tangent
    /// plane. Anisotropic BSDFs need it: their `alpha_u` lies along `s`.
    pub fn from_normal_and_tangent(n: Vec3, dp_du: Vec3) -> Self {
        match (dp_du - n * n.dot(dp_du)).try_normalize() {
            Some(s) => Frame {
                s,
                t: n.cross(s),
                n,
            },
            None => Frame::from_normal(n),
        }
    }

    /// World direction to local coordinates.
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local direction to world coordinates.
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// True when `m` is a rotation, possibly mirrored: `mᵀm` is the identity
/// to 1e-3 per entry (scene transforms are parsed from text, so exactness
/// is not expected). Cameras and emitters at infinity need it: scale or
/// shear would change solid angles their densities assume preserved.
pub fn is_rotation(m: Mat3) -> bool {
    (m.transpose() * m - Mat3::IDENTITY)
        .to_cols_array()
        .iter()
        .all(|e| e.abs() < 1e-3)
}
