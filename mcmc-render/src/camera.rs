//! Mitsuba's perspective cameras — the pinhole `perspective` and the
//! `thinlens` — with the importance function `W_e` and its densities that
//! light tracing and bidirectional methods need, and the film's crop
//! window.
//!
//! Thin lens (Mitsuba 3's `thinlens`): a ray starts at a point uniform on
//! the lens disk of radius `aperture_radius` (z = 0 in camera space) and
//! passes through the point where the pinhole ray of its raster position
//! meets the focus plane z = `focus_distance`. The lens point comes from
//! two numbers through the concentric map of
//! [`crate::bsdf::diffuse::square_to_cosine_hemisphere`] (its `x, y`), so
//! [`Camera::invert`] undoes it exactly. The density of the lens point is
//! the same (uniform) for every technique, so it is left out of `W_e` and
//! of the densities below, as the pinhole's delta is.
//!
//! Crop window (`crop_offset_x/y`, `crop_width/height` of `hdrfilm`): the
//! field of view spans the full film, the image is the window; raster
//! coordinates are the window's.
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

use crate::bsdf::diffuse::{cosine_hemisphere_to_square, square_to_cosine_hemisphere};
use crate::geometry::Ray;
use crate::scene::{CameraDesc, FilmDesc, FovAxis};
use glam::{Mat3, Vec2, Vec3};

/// Pinhole or thin-lens camera.
#[derive(Clone, Debug)]
pub struct Camera {
    origin: Vec3,
    /// Camera to world rotation (columns: local x, y, z in world).
    rot: Mat3,
    /// Half extent of the full film on the plane z = 1, horizontally.
    tan_x: f32,
    /// Half extent of the full film on the plane z = 1, vertically.
    tan_y: f32,
    /// Image (crop window) size in pixels.
    width: f32,
    height: f32,
    /// Full film size in pixels.
    full_width: f32,
    full_height: f32,
    /// Crop window offset in full-film pixels.
    offset: Vec2,
    near: f32,
    far: f32,
    /// Area of the image (crop window) rectangle on the plane z = 1.
    area: f32,
    /// Lens radius (0 for the pinhole).
    lens_radius: f32,
    /// Distance of the plane in focus.
    focus: f32,
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
    /// The point on the lens (the camera position for the pinhole).
    pub origin: Vec3,
}

impl Camera {
    /// Builds the camera for a film (full size, crop window).
    pub fn new(desc: &CameraDesc, film: &FilmDesc) -> Result<Camera, String> {
        let (width, height) = (film.full_width, film.full_height);
        let m = Mat3::from_mat4(desc.to_world);
        // Mitsuba scenes may mirror the camera (scale x = −1); any other
        // scale or shear would make W_e inconsistent with the ray mapping.
        if !crate::frame::is_rotation(m) {
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
        let (cw, ch) = (film.width as f32, film.height as f32);
        Ok(Camera {
            origin: desc.to_world.w_axis.truncate(),
            rot: m,
            tan_x,
            tan_y,
            width: cw,
            height: ch,
            full_width: w,
            full_height: h,
            offset: Vec2::new(film.crop_offset.0 as f32, film.crop_offset.1 as f32),
            near: desc.near_clip,
            far: desc.far_clip,
            area: 4.0 * tan_x * tan_y * (cw * ch) / (w * h),
            lens_radius: desc.aperture_radius,
            focus: desc.focus_distance,
        })
    }

    /// True for a thin lens: rays and camera connections then take two
    /// numbers for the lens point.
    #[inline]
    pub fn has_lens(&self) -> bool {
        self.lens_radius > 0.0
    }

    /// The lens point (camera space, z = 0) of two numbers.
    fn lens_local(&self, u: (f32, f32)) -> Vec3 {
        let d = square_to_cosine_hemisphere(u);
        Vec3::new(d.x * self.lens_radius, d.y * self.lens_radius, 0.0)
    }

    /// The world position of the lens point of two numbers (the camera's
    /// position for the pinhole).
    pub fn lens_point(&self, u: (f32, f32)) -> Vec3 {
        if self.has_lens() {
            self.origin + self.rot * self.lens_local(u)
        } else {
            self.origin
        }
    }

    /// The point on the plane z = 1 (camera space) of a raster position.
    fn film_point(&self, raster: Vec2) -> Vec3 {
        let x = -(2.0 * (raster.x + self.offset.x) / self.full_width - 1.0) * self.tan_x;
        let y = -(2.0 * (raster.y + self.offset.y) / self.full_height - 1.0) * self.tan_y;
        Vec3::new(x, y, 1.0)
    }

    /// Raster position of the point `(x, y)` of the plane z = 1, if it is
    /// in the image.
    fn raster_of_film_point(&self, x: f32, y: f32) -> Option<Vec2> {
        let rx = (1.0 - x / self.tan_x) * 0.5 * self.full_width - self.offset.x;
        let ry = (1.0 - y / self.tan_y) * 0.5 * self.full_height - self.offset.y;
        (rx >= 0.0 && rx < self.width && ry >= 0.0 && ry < self.height).then_some(Vec2::new(rx, ry))
    }

    /// Camera position.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Image size in pixels.
    pub fn resolution(&self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// Primary ray through a raster position from the lens centre (the
    /// pinhole's ray); its `tmin`/`tmax` honour the clip planes.
    pub fn generate_ray(&self, raster: Vec2) -> Ray {
        let local = self.film_point(raster).normalize();
        let mut ray = Ray::new(self.origin, (self.rot * local).normalize());
        ray.tmin = self.near / local.z;
        ray.tmax = self.far / local.z;
        ray
    }

    /// Primary ray through a raster position from the lens point of
    /// `u_lens` (the pinhole ignores it); clip distances are measured
    /// along the camera's axis, as Mitsuba's.
    pub fn generate_ray_lens(&self, raster: Vec2, u_lens: (f32, f32)) -> Ray {
        if !self.has_lens() {
            return self.generate_ray(raster);
        }
        let lens = self.lens_local(u_lens);
        let local = (self.film_point(raster) * self.focus - lens).normalize();
        let mut ray = Ray::new(
            self.origin + self.rot * lens,
            (self.rot * local).normalize(),
        );
        ray.tmin = self.near / local.z;
        ray.tmax = self.far / local.z;
        ray
    }

    /// Raster position of a world direction leaving the lens centre (the
    /// pinhole), if it is on the image, and the cosine to the axis.
    pub fn raster_of(&self, dir: Vec3) -> Option<(Vec2, f32)> {
        let local = self.rot.transpose() * dir;
        if local.z <= 0.0 {
            return None;
        }
        let raster = self.raster_of_film_point(local.x / local.z, local.y / local.z)?;
        Some((raster, local.z / local.length()))
    }

    /// Raster position of a ray leaving the lens at world point `lens`
    /// along `dir`, if it is on the image, and the cosine to the axis.
    pub fn raster_of_ray(&self, lens: Vec3, dir: Vec3) -> Option<(Vec2, f32)> {
        if !self.has_lens() {
            return self.raster_of(dir);
        }
        let l = self.rot.transpose() * (lens - self.origin);
        let d = self.rot.transpose() * dir;
        if d.z <= 0.0 {
            return None;
        }
        // Where the ray meets the focus plane, seen from the lens centre.
        let t = (self.focus - l.z) / d.z;
        let f = l + d * t;
        let raster = self.raster_of_film_point(f.x / self.focus, f.y / self.focus)?;
        Some((raster, d.z / d.length()))
    }

    /// Importance `W_e` of a ray leaving the lens centre along unit `dir`.
    pub fn we(&self, dir: Vec3) -> f32 {
        match self.raster_of(dir) {
            Some((_, cos)) => 1.0 / (self.area * cos * cos * cos * cos),
            None => 0.0,
        }
    }

    /// Densities of generating a ray from the lens point `lens` (world)
    /// along `dir`: (position, solid angle). The lens position's density
    /// is left out (uniform for every technique; the pinhole's is a delta):
    /// reported as 1, pbrt's convention.
    pub fn pdf_we(&self, lens: Vec3, dir: Vec3) -> (f32, f32) {
        match self.raster_of_ray(lens, dir) {
            Some((_, cos)) => (1.0, 1.0 / (self.area * cos * cos * cos)),
            None => (0.0, 0.0),
        }
    }

    /// The numbers `(raster, u_lens)` that make [`Camera::generate_ray_lens`]
    /// produce the ray from world point `lens` along `dir` (for the fused
    /// state space); `None` when the ray misses the image or does not
    /// start on the lens.
    pub fn invert(&self, lens: Vec3, dir: Vec3) -> Option<(Vec2, (f32, f32))> {
        let (raster, _) = self.raster_of_ray(lens, dir)?;
        if !self.has_lens() {
            return Some((raster, (0.5, 0.5)));
        }
        let l = self.rot.transpose() * (lens - self.origin) / self.lens_radius;
        let r2 = l.x * l.x + l.y * l.y;
        if !(r2 <= 1.0 + 1e-5) {
            return None;
        }
        let w = Vec3::new(l.x, l.y, (1.0 - r2).max(0.0).sqrt());
        Some((raster, cosine_hemisphere_to_square(w)))
    }

    /// Connects a scene point to the lens centre (the pinhole).
    pub fn sample_wi(&self, p: Vec3) -> Option<CameraSample> {
        self.connect(self.origin, p)
    }

    /// Connects a scene point to the lens point of `u_lens`.
    pub fn sample_wi_lens(&self, p: Vec3, u_lens: (f32, f32)) -> Option<CameraSample> {
        self.connect(self.lens_point(u_lens), p)
    }

    /// Connects a scene point `p` to the lens point `lens` (world).
    pub fn connect(&self, lens: Vec3, p: Vec3) -> Option<CameraSample> {
        let delta = lens - p;
        let dist2 = delta.length_squared();
        if !(dist2 > 0.0) {
            return None;
        }
        let dist = dist2.sqrt();
        let wi = delta / dist;
        let (raster, cos) = self.raster_of_ray(lens, -wi)?;
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
            origin: lens,
        })
    }

    /// Angle per pixel of the full film, the smaller of the horizontal and
    /// vertical field of view over its pixels (Mitsuba 0.6's `radPerPixel`,
    /// which sizes the caustic perturbation).
    pub fn radians_per_pixel(&self) -> f32 {
        let x = 2.0 * self.tan_x.atan() / self.full_width;
        let y = 2.0 * self.tan_y.atan() / self.full_height;
        x.min(y)
    }
}
