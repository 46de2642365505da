use super::{FiniteSpace, ReferenceMeasure, StateSpace};
use crate::rng::ChainRng;
use rand::RngExt;

/// The finite set `{0, …, n−1}` with the uniform reference measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FiniteSet {
    size: usize,
}

impl FiniteSet {
    /// `{0, …, size−1}`.
    pub fn new(size: usize) -> Self {
        FiniteSet { size }
    }
}

impl StateSpace for FiniteSet {
    type State = usize;

    fn contains(&self, state: &usize) -> bool {
        *state < self.size
    }
}

impl FiniteSpace for FiniteSet {
    fn size(&self) -> usize {
        self.size
    }
}

impl ReferenceMeasure for FiniteSet {
    fn sample_reference(&self, rng: &mut ChainRng) -> usize {
        rng.random_range(0..self.size)
    }

    fn log_reference_density(&self, _state: &usize) -> f64 {
        -(self.size as f64).ln()
    }
}
