//! `mcmc-render`: a physically based renderer built on `mcmc-core`.
//!
//! Layers: [`scene`] (Mitsuba 3 XML subset, OBJ/PLY) → [`geometry`] (obvhs
//! BVH) → [`bsdf`], [`light`], [`camera`] → path samplers drawing numbers
//! from a [`sampling::RandomSource`] → state spaces ([`pss`]) → the
//! [`integrators`] in their registry, run by one of two drivers (per pixel:
//! [`render`]; Markov chains: [`markov`]) → [`film`] → [`image_io`]. The
//! command line lives in [`cli`]; nothing else depends on it.
//!
//! Rendering from Rust, without the command line:
//!
//! ```no_run
//! use mcmc_render::integrators::{RunSettings, registry};
//! use mcmc_render::observer::NoObserver;
//! use mcmc_render::scene::Scene;
//! use std::collections::HashMap;
//! use std::sync::atomic::AtomicBool;
//!
//! let scene = Scene::load("scene.xml".as_ref(), &HashMap::new())?;
//! // The scene's <integrator>, here overridden by pssmlt with sigma = 0.02.
//! let integrator = registry::configure(
//!     scene.integrator_element.as_ref(),
//!     Some("pssmlt"),
//!     &[("small_step".into(), "gaussian".into()), ("sigma".into(), "0.02".into())],
//! )?;
//! let run = RunSettings { time_budget: Some(std::time::Duration::from_secs(10)), ..RunSettings::default() };
//! let out = integrator.render(&scene, &run, &AtomicBool::new(false), &NoObserver)?;
//! println!("{} ({} pixels)", out.summary, out.image.len());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// `!(x > 0.0)` is written on purpose throughout: it is true for NaN, which
// must fail every positivity check, and `x <= 0.0` would let NaN through.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bsdf;
pub mod camera;
pub mod checkpoint;
pub mod cli;
pub mod cluster;
pub mod color;
pub mod compare;
pub mod deadline;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod distribution;
pub mod environment;
pub mod film;
pub mod frame;
pub mod fused_space;
pub mod geometry;
pub mod guiding;
pub mod hash_grid;
pub mod image_io;
pub mod integrators;
pub mod inverse;
pub mod light;
pub mod manifold;
pub mod markov;
pub mod observer;
pub mod path_classes;
pub mod path_space;
pub mod pss;
pub mod pss_dump;
pub mod render;
pub mod resources;
pub mod sampling;
pub mod scene;
pub mod settings;
pub mod smcmc;
pub mod staged;
pub mod tempered;
pub mod texture;
pub mod warp;
