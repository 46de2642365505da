//! The power family for gradient targets: `ln π_β = β ln L + ln prior`.

use super::GradientTarget;
use std::cell::RefCell;

thread_local! {
    // Scratch for the prior's gradient: reused across calls so a tempered
    // evaluation allocates only when the dimension grows.
    static SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

/// `ln π_β(x) = β ln L(x) + ln prior(x)` with `∇ ln π_β = β ∇ ln L + ∇ ln
/// prior`, for one level of a replica family of gradient targets. Each level
/// differentiates its own density, so an HMC kernel at level β follows that
/// level's gradient. `0·(−∞) = −∞`: a state outside the likelihood's
/// support stays outside at `β = 0`.
///
/// ```
/// use mcmc_core::gradient::{FiniteDifference, GradientTarget, Tempered};
/// let like = FiniteDifference::new(|x: &[f64]| -2.0 * x[0] * x[0], 1);
/// let prior = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let level = Tempered::new(like, prior, 0.5).unwrap();
/// let mut g = [0.0];
/// assert!((level.log_density_gradient(&[1.0], &mut g) + 1.5).abs() < 1e-9);
/// assert!((g[0] + 3.0).abs() < 1e-6);
/// ```
#[derive(Clone, Debug)]
pub struct Tempered<L, Q> {
    likelihood: L,
    prior: Q,
    beta: f64,
}

impl<L: GradientTarget, Q: GradientTarget> Tempered<L, Q> {
    /// Level `β ∈ [0, 1]` of the family; errors on another β or on
    /// mismatched dimensions.
    pub fn new(likelihood: L, prior: Q, beta: f64) -> crate::Result<Self> {
        if !(0.0..=1.0).contains(&beta) {
            return Err(crate::error::invalid(
                "beta",
                format!("{beta} must lie in [0, 1]"),
            ));
        }
        if likelihood.dim() != prior.dim() {
            return Err(crate::CoreError::DimensionMismatch {
                expected: likelihood.dim(),
                got: prior.dim(),
            });
        }
        Ok(Tempered {
            likelihood,
            prior,
            beta,
        })
    }

    /// The inverse temperature β.
    pub fn beta(&self) -> f64 {
        self.beta
    }

    /// The likelihood.
    pub fn likelihood(&self) -> &L {
        &self.likelihood
    }

    /// The prior.
    pub fn prior(&self) -> &Q {
        &self.prior
    }
}

impl<L: GradientTarget, Q: GradientTarget> GradientTarget for Tempered<L, Q> {
    fn dim(&self) -> usize {
        self.likelihood.dim()
    }

    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        let ll = self.likelihood.log_density_gradient(x, grad);
        if ll == f64::NEG_INFINITY {
            return f64::NEG_INFINITY;
        }
        if self.beta == 0.0 {
            // β = 0 ignores the likelihood's gradient, even a non-finite one.
            grad.fill(0.0);
        } else {
            for g in grad.iter_mut() {
                *g *= self.beta;
            }
        }
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            s.clear();
            s.resize(x.len(), 0.0);
            let lp = self.prior.log_density_gradient(x, &mut s);
            for (g, p) in grad.iter_mut().zip(s.iter()) {
                *g += p;
            }
            if self.beta == 0.0 {
                // 0 · finite = 0; NaN/∞ likelihoods stay invalid below.
                if ll.is_finite() { lp } else { f64::NAN }
            } else {
                self.beta * ll + lp
            }
        })
    }

    fn hessian(&self, x: &[f64], hessian: &mut [f64]) -> bool {
        if !self.likelihood.hessian(x, hessian) {
            return false;
        }
        for h in hessian.iter_mut() {
            *h *= self.beta;
        }
        let d = x.len();
        let mut prior = vec![0.0; d * d];
        if !self.prior.hessian(x, &mut prior) {
            return false;
        }
        for (h, p) in hessian.iter_mut().zip(&prior) {
            *h += p;
        }
        true
    }
}
