//! `mcmc-core`: generic Markov chain Monte Carlo.
//!
//! The pieces, each in its own module:
//! - [`target`]: unnormalised densities in log space, with payloads;
//!   closures `Fn(&[f64]) -> f64` are targets as they are.
//! - [`space`]: Euclidean `R^d`, the unit torus, lazily grown primary sample
//!   space, finite sets, and traits for user-defined spaces.
//! - [`kernel`]: proposals reporting `ln q(y→x) − ln q(x→y)`: Gaussian
//!   random walks (isotropic, full, adaptive covariance), torus small steps
//!   (Kelemen, Gaussian, adaptive), independent large steps, mixtures.
//! - [`mh`], [`mtm`], [`delayed_rejection`]: transition algorithms driving a
//!   [`chain::Chain`].
//! - [`expected`]: Rao–Blackwellised estimates from transitions.
//! - [`startup`]: start-up bias elimination by importance resampling.
//! - [`runner`]: many chains on rayon, bit-identical for any thread count.
//! - [`gradient`], [`adaptation`]: differentiable targets and warm-up for
//!   the gradient kernels (NUTS, HMC, MALA, H²MC in [`kernel`]).
//! - [`fit`], [`cmdstan`]: multi-chain NUTS runs with Stan's defaults and
//!   sampler statistics, written as CmdStan CSV for ArviZ and cmdstanpy.
//! - [`exact`]: transition matrices on finite spaces for exact tests.
//! - [`diagnostics`]: rank-normalised split R-hat, bulk and tail ESS, MCSE,
//!   FFT autocorrelation (Vehtari et al. 2021, checked against ArviZ).
//!
//! ```
//! use mcmc_core::prelude::*;
//! // A correlated 2-d Gaussian, sampled with a random walk.
//! let target = |x: &[f64]| -(x[0] * x[0] - 1.6 * x[0] * x[1] + x[1] * x[1]) / (2.0 * 0.36);
//! let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(0.8).unwrap());
//! let mut chain = Chain::new(&target, vec![0.0, 0.0], mh, stream_rng(1, 0)).unwrap();
//! let mut mean = RaoBlackwellMean::new(2);
//! for _ in 0..1000 {
//!     chain.step_with(&target, |t| mean.add(t, |s| s.state.clone()));
//! }
//! assert!(mean.mean()[0].abs() < 1.0);
//! ```

// Index loops over matrices and parallel arrays read more clearly than zipped iterators here.
#![allow(clippy::needless_range_loop)]

pub mod adaptation;
pub mod chain;
pub mod checkpoint;
pub mod cmdstan;
pub mod delayed_rejection;
pub mod diagnostics;
#[cfg(feature = "mpi")]
pub mod distributed;
pub mod error;
pub mod exact;
pub mod expected;
pub mod fit;
pub mod gradient;
pub mod kernel;
mod linalg;
pub mod math;
pub mod mh;
pub mod mtm;
pub mod npz;
pub mod replica;
pub mod resume;
pub mod rng;
pub mod runner;
pub mod sample;
pub mod space;
pub mod startup;
pub mod stats;
pub mod target;

pub use error::{CoreError, Result};

/// The names most programs need.
pub mod prelude {
    pub use crate::chain::{Algorithm, Chain, StepInfo, Transition};
    pub use crate::delayed_rejection::DelayedRejection;
    pub use crate::error::{CoreError, Result};
    pub use crate::expected::RaoBlackwellMean;
    pub use crate::kernel::{
        AdaptiveCovariance, AdaptiveTorusStep, GaussianRandomWalk, Independent, Kernel, Mixture,
        TorusStep, UniformRandomWalk,
    };
    pub use crate::mh::MetropolisHastings;
    pub use crate::mtm::{Lambda, MultipleTry};
    pub use crate::rng::{ChainRng, stream_rng};
    pub use crate::sample::Sample;
    pub use crate::space::{
        Euclidean, FiniteSet, PrimarySampleSpace, ReferenceMeasure, SmallStep, StateSpace,
        TorusPoint, UnitTorus,
    };
    pub use crate::target::{Evaluation, FnTarget, Target};
}
