//! Finite-difference derivatives: for tests and for targets without an
//! analytic Hessian. Not for production gradients (each gradient costs `2d`
//! evaluations and loses about half the digits).

use super::GradientTarget;

/// A plain log density `Fn(&[f64]) -> f64` differentiated by central
/// differences with relative step `h`. For tests.
///
/// ```
/// use mcmc_core::gradient::{FiniteDifference, GradientTarget};
/// let t = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let mut g = [0.0];
/// t.log_density_gradient(&[2.0], &mut g);
/// assert!((g[0] + 2.0).abs() < 1e-6);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct FiniteDifference<F> {
    f: F,
    dim: usize,
    h: f64,
}

impl<F: Fn(&[f64]) -> f64> FiniteDifference<F> {
    /// Differentiates `f` on `R^dim` with the default step `1e-5` (relative
    /// to `max(1, |x_i|)`).
    pub fn new(f: F, dim: usize) -> Self {
        FiniteDifference { f, dim, h: 1e-5 }
    }

    /// The same with step `h`.
    pub fn with_step(f: F, dim: usize, h: f64) -> Self {
        FiniteDifference { f, dim, h }
    }

    fn step(&self, xi: f64) -> f64 {
        self.h * xi.abs().max(1.0)
    }
}

impl<F: Fn(&[f64]) -> f64> GradientTarget for FiniteDifference<F> {
    fn dim(&self) -> usize {
        self.dim
    }

    fn log_density_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        let lp = (self.f)(x);
        let mut y = x.to_vec();
        for i in 0..x.len() {
            let h = self.step(x[i]);
            y[i] = x[i] + h;
            let up = (self.f)(&y);
            y[i] = x[i] - h;
            let down = (self.f)(&y);
            y[i] = x[i];
            grad[i] = (up - down) / (2.0 * h);
        }
        lp
    }

    fn hessian(&self, x: &[f64], hessian: &mut [f64]) -> bool {
        let d = x.len();
        let mut y = x.to_vec();
        let f0 = (self.f)(x);
        for i in 0..d {
            let hi = self.step(x[i]) * 10.0;
            for j in 0..=i {
                let hj = self.step(x[j]) * 10.0;
                let v = if i == j {
                    y[i] = x[i] + hi;
                    let up = (self.f)(&y);
                    y[i] = x[i] - hi;
                    let down = (self.f)(&y);
                    y[i] = x[i];
                    (up - 2.0 * f0 + down) / (hi * hi)
                } else {
                    let mut at = |si: f64, sj: f64| {
                        y[i] = x[i] + si * hi;
                        y[j] = x[j] + sj * hj;
                        let v = (self.f)(&y);
                        y[i] = x[i];
                        y[j] = x[j];
                        v
                    };
                    (at(1.0, 1.0) - at(1.0, -1.0) - at(-1.0, 1.0) + at(-1.0, -1.0))
                        / (4.0 * hi * hj)
                };
                hessian[i * d + j] = v;
                hessian[j * d + i] = v;
            }
        }
        true
    }
}

/// The Hessian of `ln π` at `x` by central differences of the analytic
/// gradient (`2d` gradient evaluations), symmetrised; row-major into
/// `hessian`. Returns false when a gradient is not finite.
pub fn hessian_from_gradient<G: GradientTarget + ?Sized>(
    target: &G,
    x: &[f64],
    hessian: &mut [f64],
) -> bool {
    let d = x.len();
    let mut y = x.to_vec();
    let mut up = vec![0.0; d];
    let mut down = vec![0.0; d];
    for j in 0..d {
        let h = 1e-5 * x[j].abs().max(1.0);
        y[j] = x[j] + h;
        let a = target.log_density_gradient(&y, &mut up);
        y[j] = x[j] - h;
        let b = target.log_density_gradient(&y, &mut down);
        y[j] = x[j];
        if !(a.is_finite() && b.is_finite()) {
            return false;
        }
        for i in 0..d {
            hessian[i * d + j] = (up[i] - down[i]) / (2.0 * h);
        }
    }
    for i in 0..d {
        for j in 0..i {
            let m = 0.5 * (hessian[i * d + j] + hessian[j * d + i]);
            hessian[i * d + j] = m;
            hessian[j * d + i] = m;
        }
    }
    hessian.iter().all(|v| v.is_finite())
}
