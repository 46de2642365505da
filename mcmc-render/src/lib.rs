//! `mcmc-render`: a physically based renderer built on `mcmc-core`.
//!
//! Layers: [`scene`] (Mitsuba 3 XML subset, OBJ/PLY) → [`geometry`] (obvhs
//! BVH) → [`bsdf`], [`light`], [`camera`] → [`integrators`] drawing numbers
//! from a [`sampling::RandomSource`] → [`film`] → [`image_io`].

pub mod bsdf;
pub mod camera;
pub mod color;
pub mod compare;
pub mod film;
pub mod frame;
pub mod geometry;
pub mod image_io;
pub mod integrators;
pub mod light;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod warp;
