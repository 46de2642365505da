//! `mcmc-render`: a physically based renderer built on `mcmc-core`.
//!
//! Layers: [`scene`] (Mitsuba 3 XML subset, OBJ/PLY) → [`geometry`] (obvhs
//! BVH) → [`bsdf`], [`light`], [`camera`] → [`integrators`] drawing numbers
//! from a [`sampling::RandomSource`] → [`film`] → [`image_io`].

// `!(x > 0.0)` is written on purpose throughout: it is true for NaN, which
// must fail every positivity check, and `x <= 0.0` would let NaN through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bsdf;
pub mod camera;
pub mod color;
pub mod compare;
pub mod convergence;
pub mod film;
pub mod frame;
pub mod geometry;
pub mod image_io;
pub mod integrators;
pub mod light;
pub mod mlt_cli;
pub mod pss;
pub mod render;
pub mod sampling;
pub mod scene;
pub mod warp;
