//! Where the chains move: the target's own coordinates, or the unit torus
//! that the target's bounds box is mapped to (for torus kernels).

use mcmc_core::target::{Evaluation, Target};

use super::cli::KernelKind;
use super::target::GaussianMixture;

/// The coordinates a chain's state is written in.
#[derive(Clone, Debug, PartialEq)]
pub enum Coordinates {
    /// The state is the point `x` itself.
    Target,
    /// The state is `u ∈ [0,1)^d` and `x_i = lo_i + u_i (hi_i − lo_i)`. The
    /// Jacobian of this map is constant, so the density of `u` is the
    /// target's up to a constant factor, which MCMC ignores.
    UnitBox(Vec<(f64, f64)>),
}

impl Coordinates {
    /// The coordinates `kernel` works in (torus kernels need the bounds;
    /// the plan has already checked they exist).
    pub fn for_kernel(kernel: KernelKind, mixture: &GaussianMixture) -> Self {
        match (kernel, mixture.bounds()) {
            (KernelKind::Kelemen, Some(b)) => Coordinates::UnitBox(b.to_vec()),
            _ => Coordinates::Target,
        }
    }

    /// Writes the target-space point of `state` into `x`.
    pub fn to_target(&self, state: &[f64], x: &mut Vec<f64>) {
        x.clear();
        match self {
            Coordinates::Target => x.extend_from_slice(state),
            Coordinates::UnitBox(b) => {
                x.extend(state.iter().zip(b).map(|(u, (lo, hi))| lo + u * (hi - lo)))
            }
        }
    }
}

/// The mixture seen from a chain's coordinates.
#[derive(Clone, Copy, Debug)]
pub struct StateTarget<'a> {
    /// The mixture.
    pub mixture: &'a GaussianMixture,
    /// How states map to the mixture's coordinates.
    pub coordinates: &'a Coordinates,
}

impl Target<Vec<f64>> for StateTarget<'_> {
    type Payload = ();

    #[inline]
    fn evaluate(&self, state: &Vec<f64>) -> Evaluation<()> {
        let log_density = match self.coordinates {
            Coordinates::Target => self.mixture.log_density(state),
            Coordinates::UnitBox(b) => {
                if state.len() != b.len() {
                    f64::NAN
                } else {
                    self.mixture
                        .log_density_with(|i| b[i].0 + state[i] * (b[i].1 - b[i].0))
                }
            }
        };
        Evaluation::density(log_density)
    }
}
