//! Mitsuba's pinhole perspective camera, with the importance function
//! `W_e` and its densities that light tracing and bidirectional methods need.
//!
//! Conventions (checked against Mitsuba 3 `scalar_rgb` on an asymmetric
//! scene): the camera looks down local +z with +y up; raster x grows
//! towards local −x and raster y towards local −y, so a `lookat` camera
//! shows the world unmirrored. Raster coordinates are continuous, pixel
//! (i, j) covers [i, i+1) × [j, j+1).
//!
//! `W_e` is normalised over the whole image (pbrt's convention):
//! `W_e = 1 / (A cos⁴θ)` with `A` the image rectangle's area on the plane
//! z = 1, so the measurement it defines is the mean radiance over the
//! image; a pixel's value is `N_pixels` times its share.

use crate::geometry::Ray;
use crate::scene::{CameraDesc, FovAxis};
use glam::{Mat3, Vec2, Vec3};

/// Pinhole camera.
#[derive(Clone, Debug)]
pub struct Camera {
    origin: Vec3,
    /// Camera to world rotation (columns: local x, y, z in world).
    rot: Mat3,
    /// Half extent of the image on the plane z = 1, horizontally.
    tan_x: f32,
    /// Half extent of the image on the plane z = 1, vertically.
    tan_y: f32,
    width: f32,
    height: f32,
    near: f32,
    far: f32,
    /// Area of the image rectangle on the plane z = 1.
    area: f32,
}

/// A camera connection from a scene point (light tracing's splat).
#[derive(Clone, Copy, Debug)]
pub struct CameraSample {
    /// Importance `W_e` along the connecting ray.
    pub we: f32,
    /// Unit direction from the reference point to the camera.
    pub wi: Vec3,
    /// Distance to the camera.
    pub dist: f32,
    /// Solid-angle density at the reference point (`dist² / cos θ_camera`).
    pub pdf: f32,
    /// Raster position the connection lands on.
    pub raster: Vec2,
    /// Camera position.
    pub origin: Vec3,
}

impl Camera {
    /// Builds the camera for an image of `width × height` pixels.
    pub fn new(desc: &CameraDesc, width: u32, height: u32) -> Result<Camera, String> {
        let m = Mat3::from_mat4(desc.to_world);
        // Mitsuba scenes may mirror the camera (scale x = −1); any other
        // scale or shear would make W_e inconsistent with the ray mapping.
        let ortho = (m.transpose() * m - Mat3::IDENTITY)
            .to_cols_array()
            .iter()
            .all(|v| v.abs() < 1e-3);
        if !ortho {
            return Err("sensor to_world must be a rotation/translation (optionally mirrored), without scaling".into());
        }
        let (w, h) = (width as f32, height as f32);
        let aspect = w / h;
        let t = (desc.fov_deg.to_radians() * 0.5).tan();
        let (tan_x, tan_y) = match desc.fov_axis {
            FovAxis::X => (t, t / aspect),
            FovAxis::Y => (t * aspect, t),
            FovAxis::Diagonal => {
                let diag = (w * w + h * h).sqrt();
                (t * w / diag, t * h / diag)
            }
            FovAxis::Smaller => {
                if w <= h {
                    (t, t / aspect)
                } else {
                    (t * aspect, t)
                }
            }
            FovAxis::Larger => {
                if w >= h {
                    (t, t / aspect)
                } else {
                    (t * aspect, t)
                }
            }
        };
        Ok(Camera {
            origin: desc.to_world.w_axis.truncate(),
            rot: m,
            tan_x,
            tan_y,
            width: w,
            height: h,
            near: desc.near_clip,
            far: desc.far_clip,
            area: 4.0 * tan_x * tan_y,
        })
    }

    /// Camera position.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Image size in pixels.
    pub fn resolution(&self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// Primary ray through a raster position; its `tmin`/`tmax` honour the clip planes.
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let x = -(2.0 * raster.x / self.width - 1.0) * self.tan_x;
        let y = -(2.0 * raster.y / self.height - 1.0) * self.tan_y;
        let local = Vec3::new(x, y, 1.0).normalize();
        let mut ray = Ray::new(self.origin, (self.rot * local).normalize());
        ray.tmin = self.near / local.z;
        ray.tmax = self.far / local.z;
        ray
    }

    /// Raster position of a world direction leaving the camera, if it is on the image.
    pub fn raster_of(&self, dir: Vec3) -> Option<(Vec2, f32)> {
        let local = self.rot.transpose() * dir;
        if local.z <= 0.0 {
            return None;
        }
        let x = local.x / local.z;
        let y = local.y / local.z;
        let rx = (1.0 - x / self.tan_x) * 0.5 * self.width;
        let ry = (1.0 - y / self.tan_y) * 0.5 * self.height;
        if rx >= 0.0 && rx < self.width && ry >= 0.0 && ry < self.height {
            Some((Vec2::new(rx, ry), local.z / local.length()))
        } else {
            None
        }
    }

    /// Importance `W_e` of a ray leaving the camera along unit `dir`.
    pub fn we(&self, dir: Vec3) -> f32 {
        match self.raster_of(dir) {
            Some((_, cos)) => 1.0 / (self.area * cos * cos * cos * cos),
            None => 0.0,
        }
    }

    /// Densities of generating a ray along `dir`: (position, solid angle).
    /// The pinhole's position is a delta, reported as density 1 (pbrt's convention).
    pub fn pdf_we(&self, dir: Vec3) -> (f32, f32) {
        match self.raster_of(dir) {
            Some((_, cos)) => (1.0, 1.0 / (self.area * cos * cos * cos)),
            None => (0.0, 0.0),
        }
    }

    /// Connects a scene point to the camera (no random numbers are used).
    pub fn sample_wi(&self, p: Vec3) -> Option<CameraSample> {
        let delta = self.origin - p;
        let dist2 = delta.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = delta / dist;
        let (raster, cos) = self.raster_of(-wi)?;
        // Points in front of the near plane or beyond the far plane are invisible.
        let depth = dist * cos;
        if depth < self.near || depth > self.far {
            return None;
        }
        Some(CameraSample {
            we: 1.0 / (self.area * cos * cos * cos * cos),
            wi,
            dist,
            pdf: dist2 / cos,
            raster,
            origin: self.origin,
        })
    }
}
