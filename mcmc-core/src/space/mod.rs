//! State spaces: where states live, and what each space offers to kernels.
//!
//! - [`Euclidean`]: `R^d`, states are `Vec<f64>`, with a Gaussian reference
//!   measure for independent proposals and start-up.
//! - [`UnitTorus`]: `[0,1)^d` with wrap-around, states are `Vec<f64>`.
//! - [`PrimarySampleSpace`]: the torus `[0,1)^∞` whose states
//!   ([`TorusPoint`]) grow lazily as a consumer asks for coordinates, with
//!   pbrt's lazy mutation scheme (primary sample space for rendering).
//! - [`FiniteSet`]: `{0, …, n−1}`, enumerable, for exact tests.
//!
//! User-defined spaces implement [`StateSpace`] (and [`ReferenceMeasure`]
//! if independent proposals or importance-resampled start-up are wanted).

mod euclidean;
mod finite;
mod lazy_torus;
mod torus;

pub use euclidean::Euclidean;
pub use finite::FiniteSet;
pub use lazy_torus::{PrimarySampleSpace, SmallStep, TorusPoint};
pub use torus::{UnitTorus, wrap_unit};

use crate::rng::ChainRng;

/// A set of states.
pub trait StateSpace {
    /// The state type.
    type State: Clone;

    /// True when `state` belongs to the space (right dimension, inside bounds).
    fn contains(&self, state: &Self::State) -> bool;
}

/// A space with a reference probability measure that can be sampled: the
/// source of independent ("large step") proposals and of start-up
/// candidates.
pub trait ReferenceMeasure: StateSpace {
    /// Draws a state from the reference measure.
    fn sample_reference(&self, rng: &mut ChainRng) -> Self::State;

    /// Draws into an existing state, reusing its allocation where possible.
    fn sample_reference_into(&self, rng: &mut ChainRng, out: &mut Self::State) {
        *out = self.sample_reference(rng);
    }

    /// `ln p(state)` of the reference measure with respect to the space's base
    /// measure (Lebesgue for continuous spaces, counting for finite ones).
    fn log_reference_density(&self, state: &Self::State) -> f64;
}

/// A finite space whose states can be enumerated.
pub trait FiniteSpace: StateSpace<State = usize> {
    /// Number of states; the states are `0..size()`.
    fn size(&self) -> usize;
}
