//! Differentiable targets: `ln π` together with `∇ ln π`, for gradient-based
//! kernels (HMC, MALA, H²MC).
//!
//! A [`GradientTarget`] writes the gradient into a caller-owned buffer, so a
//! leapfrog trajectory allocates nothing. [`Differentiable`] turns one into a
//! [`Target<Vec<f64>>`](crate::target::Target) whose payload carries the
//! gradient ([`GradientPayload`]): the gradient travels with the state through
//! accept/reject and replica swaps, and a kernel never recomputes it at the
//! current state. [`Tempered`] builds `ln π_β = β ln L + ln prior` for power
//! families, so each replica level differentiates its own density.
//! [`TemperedFamily`] is the replica family of such levels.
//! [`FiniteDifference`] exists for tests only.

mod family;
mod finite_difference;
mod tempered;

pub use family::TemperedFamily;
pub use finite_difference::{FiniteDifference, hessian_from_gradient};
pub use tempered::Tempered;

use crate::target::{Evaluation, Target};
use std::sync::Arc;

/// A log density with its gradient (and optionally its Hessian).
///
/// `log_density_gradient` returns `ln π(x)` and writes `∇ ln π(x)` into
/// `grad` (length [`dim`](Self::dim)). Outside the support return `−∞`
/// (the gradient is then ignored). A NaN or infinite gradient component makes
/// the kernels reject the proposal and count it; it never panics.
///
/// ```
/// use mcmc_core::gradient::GradientTarget;
/// struct StdNormal(usize);
/// impl GradientTarget for StdNormal {
///     fn dim(&self) -> usize { self.0 }
///     fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
///         for (g, v) in grad.iter_mut().zip(x) { *g = -v; }
///         -0.5 * x.iter().map(|v| v * v).sum::<f64>()
///     }
/// }
/// let mut g = [0.0; 2];
/// assert_eq!(StdNormal(2).log_density_gradient(&[1.0, 2.0], &mut g), -2.5);
/// assert_eq!(g, [-1.0, -2.0]);
/// ```
pub trait GradientTarget {
    /// Dimension of the state.
    fn dim(&self) -> usize;

    /// `ln π(x)`, writing `∇ ln π(x)` into `grad`.
    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64;

    /// Writes the dense Hessian of `ln π` at `x` (row-major, `d×d`) into
    /// `hessian` and returns true; returns false when the target provides no
    /// Hessian (kernels then difference the gradient, see
    /// [`hessian_from_gradient`]).
    fn hessian(&self, _x: &[f64], _hessian: &mut [f64]) -> bool {
        false
    }
}

impl<G: GradientTarget + ?Sized> GradientTarget for &G {
    fn dim(&self) -> usize {
        (**self).dim()
    }
    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        (**self).log_density_gradient(x, grad)
    }
    fn hessian(&self, x: &[f64], hessian: &mut [f64]) -> bool {
        (**self).hessian(x, hessian)
    }
}

impl<G: GradientTarget + ?Sized> GradientTarget for Arc<G> {
    fn dim(&self) -> usize {
        (**self).dim()
    }
    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        (**self).log_density_gradient(x, grad)
    }
    fn hessian(&self, x: &[f64], hessian: &mut [f64]) -> bool {
        (**self).hessian(x, hessian)
    }
}

/// The payload of a differentiable target: `∇ ln π` at the state.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GradientPayload {
    /// `∇ ln π(state)`; meaningful only when `ln π` is finite.
    pub gradient: Vec<f64>,
}

impl GradientPayload {
    /// True when every gradient component is finite.
    pub fn is_finite(&self) -> bool {
        self.gradient.iter().all(|g| g.is_finite())
    }
}

/// `ln π` and `∇ ln π` in one call, checking the result: a non-finite
/// gradient at a finite density turns the density into NaN, so the
/// standard acceptance step rejects and counts it as invalid.
#[inline]
/// Refuses a target of dimension 0: the gradient kernels size their
/// buffers and factorisations by it.
pub(crate) fn check_dimension<G: GradientTarget + ?Sized>(target: &G) -> crate::Result<()> {
    if target.dim() == 0 {
        return Err(crate::error::invalid(
            "target",
            "a gradient target must have dimension at least 1, got 0",
        ));
    }
    Ok(())
}

/// Refuses a state whose length is not the kernel's dimension `dim`.
pub(crate) fn check_state_dimension(dim: usize, state: &[f64]) -> crate::Result<()> {
    if state.len() != dim {
        return Err(crate::CoreError::DimensionMismatch {
            expected: dim,
            got: state.len(),
        });
    }
    Ok(())
}

/// True when every entry of `v` is finite. Branch-free over blocks of four
/// (`u − u` is 0 for a finite `u` and NaN for ±∞ or NaN), so it vectorises,
/// where `iter().all(is_finite)` is a scalar loop with an exit per entry;
/// it runs twice per leapfrog step (position and gradient).
#[inline]
#[allow(clippy::eq_op)] // `u − u` is the test, not a mistake.
pub(crate) fn all_finite(v: &[f64]) -> bool {
    let mut acc = [0.0f64; 4];
    let blocks = v.chunks_exact(4);
    let tail = blocks.remainder();
    for b in blocks {
        for k in 0..4 {
            acc[k] += b[k] - b[k];
        }
    }
    tail.iter().all(|u| u.is_finite()) && (acc[0] + acc[1] + acc[2] + acc[3]) == 0.0
}

pub(crate) fn evaluate_checked<G: GradientTarget + ?Sized>(
    target: &G,
    x: &[f64],
    grad: &mut [f64],
) -> f64 {
    let lp = target.log_density_gradient(x, grad);
    if lp.is_finite() && !all_finite(grad) {
        f64::NAN
    } else {
        lp
    }
}

/// A [`GradientTarget`] seen as a [`Target<Vec<f64>>`](Target) whose payload
/// is the gradient. Use it as the chain's target with the gradient kernels.
///
/// A non-finite gradient at a finite density is reported as an invalid
/// (NaN) density, so the state is never accepted (and an initial state with
/// such a gradient is refused).
#[derive(Clone, Copy, Debug)]
pub struct Differentiable<G>(pub G);

impl<G: GradientTarget> Target<Vec<f64>> for Differentiable<G> {
    type Payload = GradientPayload;

    fn evaluate(&self, state: &Vec<f64>) -> Evaluation<GradientPayload> {
        let mut gradient = vec![0.0; state.len()];
        let lp = evaluate_checked(&self.0, state, &mut gradient);
        Evaluation::new(lp, GradientPayload { gradient })
    }
}

impl<G: GradientTarget> GradientTarget for Differentiable<G> {
    fn dim(&self) -> usize {
        self.0.dim()
    }
    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        self.0.log_density_gradient(x, grad)
    }
    fn hessian(&self, x: &[f64], hessian: &mut [f64]) -> bool {
        self.0.hessian(x, hessian)
    }
}
