//! Veach's lens subpath mutation (Veach 1997 §11.4.4): replace the path's
//! lens subpath (the camera, its specular chain and the first vertex
//! after it that does not scatter through a Dirac lobe) by a new one
//! through a raster position uniform over the image, reconnected to the
//! kept light side. Not in Mitsuba 0.6.
//!
//! # Pattern
//!
//! The lens perturbation's: `(L|D) D S* E` ([`lens_chain`]). Other paths
//! get a failed proposal (component "pattern mismatch").
//!
//! # The move and its density
//!
//! A raster position uniform over the image, then the lens perturbation's
//! steps 2 and 3 (camera walk from the same lens point through the Dirac
//! chain to `y_j`, connection to the kept `x_{j−1}`). The new camera part
//! is a camera walk of the path state's own densities, so
//!
//! ```text
//! T(x→y) = Π_{i=j}^{k−1} pdf_rev(y_i)
//! ```
//!
//! (the camera's `pdf_rev(y_{k−1})` holds the uniform raster density) and
//! `ln T(y→x) − ln T(x→y) = Σ_{i=j}^{k−1} ln pdf_rev(x_i) − ln pdf_rev(y_i)`.
//! Veach stratifies the new raster positions over the image across
//! mutations; one uniform position per mutation keeps the kernel a fixed
//! Markov kernel.

use super::lens_perturbation::{Invalid, LensPerturbation, lens_chain, log_chain_density};
use super::retrace::component_names;
use super::state::Path;
use crate::pss::PathSample;
use glam::Vec2;
use mcmc_core::kernel::{Kernel, Proposal};
use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;

/// Veach's lens subpath mutation as an `mcmc-core` kernel over
/// [`Path`]s: component 0 is the mutation, components 1–7 its failed
/// proposals by [`Invalid`] reason (the lens perturbation's reasons).
#[derive(Clone, Debug)]
pub struct LensSubpath {
    /// The statistics' name of component 0.
    pub name: String,
    retrace: LensPerturbation,
}

impl Default for LensSubpath {
    fn default() -> Self {
        LensSubpath {
            name: "lens subpath mutation".into(),
            retrace: LensPerturbation::default(),
        }
    }
}

impl LensSubpath {
    /// `ln T(x→y)` (module docs), `−∞` when the move cannot produce `y`
    /// from `x`.
    pub fn log_transition_density(&self, x: &Path, y: &Path) -> f64 {
        let Some(j) = lens_chain(x) else {
            return f64::NEG_INFINITY;
        };
        if y.len() != x.len() || lens_chain(y) != Some(j) || y.contribution.is_black() {
            return f64::NEG_INFINITY;
        }
        log_chain_density(y, j)
    }
}

impl<'s> Kernel<Path<'s>, PathSample> for LensSubpath {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let x = &current.state;
        let y = &mut proposal.state;
        let Some(j) = lens_chain(x) else {
            return Proposal::failed(Invalid::Pattern as usize);
        };
        let film = &x.scene.film;
        let (w, h) = (film.width as f32, film.height as f32);
        let raster = Vec2::new(
            (uniform(rng) as f32 * w).min(w * (1.0 - f32::EPSILON)),
            (uniform(rng) as f32 * h).min(h * (1.0 - f32::EPSILON)),
        );
        if let Err(reason) = self.retrace.retrace(x, y, j, raster, rng) {
            return Proposal::failed(reason as usize);
        }
        let forward = log_chain_density(y, j);
        let backward = log_chain_density(x, j);
        if !(forward > f64::NEG_INFINITY) {
            return Proposal::failed(Invalid::ZeroDensity as usize);
        }
        Proposal::with_ratio(backward - forward, 0)
    }

    fn component_names(&self) -> Vec<String> {
        component_names(&self.name, Invalid::ALL.iter().map(|r| r.name()))
    }
}
