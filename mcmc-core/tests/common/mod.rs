//! Targets shared by the integration tests.

// Index loops over coordinates read more clearly here.
#![allow(clippy::needless_range_loop)]

use mcmc_core::gradient::GradientTarget;

/// AR(1) correlated Gaussian with correlation ρ between neighbours and
/// marginal standard deviations `scale[i]` from 0.5 to 2 (geometric):
/// `x_i = scale_i z_i`, `z` with precision
/// `Q = (1/(1−ρ²)) tridiag(−ρ, 1+ρ² (1 at the ends), −ρ)`.
#[derive(Clone)]
pub struct Ar1Gaussian {
    pub rho: f64,
    pub scale: Vec<f64>,
}

impl Ar1Gaussian {
    pub fn new(d: usize, rho: f64) -> Self {
        let scale = (0..d)
            .map(|i| 0.5 * 4f64.powf(i as f64 / (d - 1) as f64))
            .collect();
        Ar1Gaussian { rho, scale }
    }
}

impl GradientTarget for Ar1Gaussian {
    fn dim(&self) -> usize {
        self.scale.len()
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let d = x.len();
        let c = 1.0 / (1.0 - self.rho * self.rho);
        let mut lp = 0.0;
        for i in 0..d {
            let zi = x[i] / self.scale[i];
            let mut qz = if i == 0 || i == d - 1 {
                zi
            } else {
                (1.0 + self.rho * self.rho) * zi
            };
            if i > 0 {
                qz -= self.rho * x[i - 1] / self.scale[i - 1];
            }
            if i + 1 < d {
                qz -= self.rho * x[i + 1] / self.scale[i + 1];
            }
            qz *= c;
            lp -= 0.5 * zi * qz;
            g[i] = -qz / self.scale[i];
        }
        lp
    }
}
