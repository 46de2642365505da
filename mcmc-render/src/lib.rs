//! `mcmc-render`: a physically based renderer built on `mcmc-core`.
//!
//! Work in progress: the crate does not render images yet. What exists is
//! the colour type, the random-number source seam and the BSDF interface.

pub mod bsdf;
pub mod color;
pub mod frame;
pub mod sampling;
