use super::{ReferenceMeasure, StateSpace};
use crate::rng::{ChainRng, uniform};

/// The unit torus `[0,1)^d` of fixed dimension. States are `Vec<f64>`.
///
/// Its reference measure is uniform (density 1). Torus kernels wrap around.
/// For primary sample space, whose dimension grows on demand, use
/// [`super::PrimarySampleSpace`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnitTorus {
    dim: usize,
}

impl UnitTorus {
    /// `[0,1)^dim`.
    pub fn new(dim: usize) -> Self {
        UnitTorus { dim }
    }

    /// The dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }
}

/// Wraps a real number into `[0, 1)`.
///
/// Rounding can make `x − ⌊x⌋` equal to 1 for tiny negative `x`; that case
/// maps to 0 so the result always lies in the half-open interval.
#[inline]
pub fn wrap_unit(x: f64) -> f64 {
    let w = x - x.floor();
    if w < 1.0 { w } else { 0.0 }
}

impl StateSpace for UnitTorus {
    type State = Vec<f64>;

    fn contains(&self, state: &Vec<f64>) -> bool {
        state.len() == self.dim && state.iter().all(|&x| (0.0..1.0).contains(&x))
    }
}

impl ReferenceMeasure for UnitTorus {
    fn sample_reference(&self, rng: &mut ChainRng) -> Vec<f64> {
        (0..self.dim).map(|_| uniform(rng)).collect()
    }

    fn sample_reference_into(&self, rng: &mut ChainRng, out: &mut Vec<f64>) {
        out.clear();
        out.extend((0..self.dim).map(|_| uniform(rng)));
    }

    fn log_reference_density(&self, _state: &Vec<f64>) -> f64 {
        0.0
    }
}
