use super::{ReferenceMeasure, StateSpace};
use crate::error::{Result, invalid};
use crate::rng::{ChainRng, standard_normal};

/// `R^d`. States are `Vec<f64>` of length `d`.
///
/// Its reference measure is a product Gaussian `N(mean, diag(scale²))`
/// (default `N(0, I)`), used by independent proposals and start-up.
#[derive(Clone, Debug, PartialEq)]
pub struct Euclidean {
    dim: usize,
    mean: Vec<f64>,
    scale: Vec<f64>,
}

impl Euclidean {
    /// `R^dim` with the standard normal reference measure.
    pub fn new(dim: usize) -> Self {
        Euclidean {
            dim,
            mean: vec![0.0; dim],
            scale: vec![1.0; dim],
        }
    }

    /// Replaces the reference measure by `N(mean, diag(scale²))`.
    pub fn with_reference(mut self, mean: Vec<f64>, scale: Vec<f64>) -> Result<Self> {
        if mean.len() != self.dim || scale.len() != self.dim {
            return Err(invalid(
                "reference",
                "mean and scale must have the space's dimension",
            ));
        }
        if scale.iter().any(|s| !(s.is_finite() && *s > 0.0)) || mean.iter().any(|m| !m.is_finite())
        {
            return Err(invalid(
                "reference",
                "mean must be finite and scales finite and positive",
            ));
        }
        self.mean = mean;
        self.scale = scale;
        Ok(self)
    }

    /// The dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }
}

impl StateSpace for Euclidean {
    type State = Vec<f64>;

    fn contains(&self, state: &Vec<f64>) -> bool {
        state.len() == self.dim && state.iter().all(|x| x.is_finite())
    }
}

impl ReferenceMeasure for Euclidean {
    fn sample_reference(&self, rng: &mut ChainRng) -> Vec<f64> {
        let mut out = vec![0.0; self.dim];
        self.sample_reference_into(rng, &mut out);
        out
    }

    fn sample_reference_into(&self, rng: &mut ChainRng, out: &mut Vec<f64>) {
        out.resize(self.dim, 0.0);
        for ((o, m), s) in out.iter_mut().zip(&self.mean).zip(&self.scale) {
            *o = m + s * standard_normal(rng);
        }
    }

    fn log_reference_density(&self, state: &Vec<f64>) -> f64 {
        const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_7;
        state
            .iter()
            .zip(&self.mean)
            .zip(&self.scale)
            .map(|((x, m), s)| {
                let z = (x - m) / s;
                -0.5 * z * z - s.ln() - LN_SQRT_2PI
            })
            .sum()
    }
}
