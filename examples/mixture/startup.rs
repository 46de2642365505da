//! Initial states: start-up importance resampling from a broad reference.
//!
//! Each chain draws its own candidates from a reference distribution `p₀`
//! with its own random stream and starts at one candidate resampled with
//! probability `∝ π/p₀` (mcmc-core's `Bootstrap`). The reference is
//! - uniform on `[0,1)^d` for torus kernels;
//! - uniform on the bounds box for bounded targets;
//! - otherwise the product Gaussian whose means are the mixture's and whose
//!   standard deviations are twice the mixture's, per coordinate: broader
//!   than the target, so the importance weights stay bounded in the tails.

use mcmc_core::rng::{ChainRng, uniform};
use mcmc_core::sample::Sample;
use mcmc_core::space::{Euclidean, UnitTorus};
use mcmc_core::startup::Bootstrap;

use super::error::ExampleError;
use super::space::{Coordinates, StateTarget};

/// How much broader than the mixture the Gaussian reference is.
const REFERENCE_WIDENING: f64 = 2.0;

/// Draws `candidates` start-up candidates and resamples one initial state.
pub fn initial_sample(
    target: &StateTarget<'_>,
    candidates: usize,
    rng: &mut ChainRng,
) -> Result<Sample<Vec<f64>>, ExampleError> {
    let mixture = target.mixture;
    let d = mixture.dim();
    let bootstrap = match (target.coordinates, mixture.bounds()) {
        (Coordinates::UnitBox(_), _) => {
            Bootstrap::from_reference(target, &UnitTorus::new(d), candidates, rng)
        }
        (Coordinates::Target, Some(bounds)) => {
            let log_p0: f64 = -bounds.iter().map(|(lo, hi)| (hi - lo).ln()).sum::<f64>();
            Bootstrap::from_sampler(target, candidates, rng, |rng| {
                let x = bounds
                    .iter()
                    .map(|(lo, hi)| lo + uniform(rng) * (hi - lo))
                    .collect();
                (x, log_p0)
            })
        }
        (Coordinates::Target, None) => {
            let (mean, var) = mixture.untruncated_moments();
            let scale = var.iter().map(|v| REFERENCE_WIDENING * v.sqrt()).collect();
            let space = Euclidean::new(d)
                .with_reference(mean, scale)
                .map_err(|e| ExampleError::run(format!("start-up reference: {e}")))?;
            Bootstrap::from_reference(target, &space, candidates, rng)
        }
    }
    .map_err(|e| ExampleError::run(format!("start-up: {e}")))?;
    bootstrap
        .resample_one(rng)
        .map_err(|e| ExampleError::run(format!("start-up: {e}")))
}
