//! The two benchmark posteriors of the HMC examples, with analytic
//! gradients and Hessians.

use mcmc_core::gradient::GradientTarget;
use mcmc_core::rng::{standard_normal, stream_rng, uniform};
use mcmc_examples::posteriordb::transforms::log1p_exp;

/// A correlated Gaussian in `d` dimensions: AR(1) correlation `ρ` between
/// neighbours and marginal standard deviations from 0.5 to 2 (geometric),
/// `x_i = σ_i z_i` with `z` of precision
/// `Q = (1/(1−ρ²)) tridiag(−ρ, 1+ρ² (1 at the ends), −ρ)`.
#[derive(Clone, Debug)]
pub struct CorrelatedGaussian {
    pub rho: f64,
    pub scale: Vec<f64>,
}

impl CorrelatedGaussian {
    pub fn new(d: usize, rho: f64) -> Self {
        let scale = (0..d)
            .map(|i| 0.5 * 4f64.powf(i as f64 / (d - 1) as f64))
            .collect();
        CorrelatedGaussian { rho, scale }
    }
}

impl GradientTarget for CorrelatedGaussian {
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

    fn hessian(&self, _x: &[f64], h: &mut [f64]) -> bool {
        let d = self.scale.len();
        let c = 1.0 / (1.0 - self.rho * self.rho);
        h.fill(0.0);
        for i in 0..d {
            let diag = if i == 0 || i == d - 1 {
                1.0
            } else {
                1.0 + self.rho * self.rho
            };
            h[i * d + i] = -c * diag / (self.scale[i] * self.scale[i]);
            if i + 1 < d {
                let v = c * self.rho / (self.scale[i] * self.scale[i + 1]);
                h[i * d + i + 1] = v;
                h[(i + 1) * d + i] = v;
            }
        }
        true
    }
}

/// Bayesian logistic regression: `y_i ~ Bernoulli(σ(x_iᵀβ))`, prior
/// `β ~ N(0, τ² I)`, on a synthetic data set (intercept + `d − 1` standard
/// normal features, true coefficients drawn from `N(0, 0.5²)`).
#[derive(Clone, Debug)]
pub struct LogisticRegression {
    pub x: Vec<f64>, // n × d, row-major
    pub y: Vec<f64>,
    pub n: usize,
    pub d: usize,
    pub prior_scale: f64,
    pub true_beta: Vec<f64>,
}

impl LogisticRegression {
    /// `n` observations of `d` coefficients, generated from `seed`.
    pub fn synthetic(n: usize, d: usize, seed: u64) -> Self {
        let mut rng = stream_rng(seed, 0);
        let true_beta: Vec<f64> = (0..d).map(|_| 0.5 * standard_normal(&mut rng)).collect();
        let mut x = Vec::with_capacity(n * d);
        let mut y = Vec::with_capacity(n);
        for _ in 0..n {
            let row: Vec<f64> = (0..d)
                .map(|j| {
                    if j == 0 {
                        1.0
                    } else {
                        standard_normal(&mut rng)
                    }
                })
                .collect();
            let eta: f64 = row.iter().zip(&true_beta).map(|(a, b)| a * b).sum();
            let p = 1.0 / (1.0 + (-eta).exp());
            y.push(if uniform(&mut rng) < p { 1.0 } else { 0.0 });
            x.extend(row);
        }
        LogisticRegression {
            x,
            y,
            n,
            d,
            prior_scale: 2.0,
            true_beta,
        }
    }
}

impl GradientTarget for LogisticRegression {
    fn dim(&self) -> usize {
        self.d
    }

    fn log_density_gradient(&self, beta: &[f64], g: &mut [f64]) -> f64 {
        let d = self.d;
        let inv_var = 1.0 / (self.prior_scale * self.prior_scale);
        let mut lp = 0.0;
        for j in 0..d {
            g[j] = -beta[j] * inv_var;
            lp -= 0.5 * beta[j] * beta[j] * inv_var;
        }
        for i in 0..self.n {
            let row = &self.x[i * d..(i + 1) * d];
            let eta: f64 = row.iter().zip(beta).map(|(a, b)| a * b).sum();
            // ln p(y | η) = y η − ln(1 + e^η)
            lp += self.y[i] * eta - log1p_exp(eta);
            let r = self.y[i] - 1.0 / (1.0 + (-eta).exp());
            for j in 0..d {
                g[j] += r * row[j];
            }
        }
        lp
    }

    fn hessian(&self, beta: &[f64], h: &mut [f64]) -> bool {
        let d = self.d;
        h.fill(0.0);
        for i in 0..self.n {
            let row = &self.x[i * d..(i + 1) * d];
            let eta: f64 = row.iter().zip(beta).map(|(a, b)| a * b).sum();
            let p = 1.0 / (1.0 + (-eta).exp());
            let w = p * (1.0 - p);
            for a in 0..d {
                let wa = w * row[a];
                for b in 0..=a {
                    h[a * d + b] -= wa * row[b];
                }
            }
        }
        let inv_var = 1.0 / (self.prior_scale * self.prior_scale);
        for a in 0..d {
            h[a * d + a] -= inv_var;
            for b in 0..a {
                h[b * d + a] = h[a * d + b];
            }
        }
        true
    }
}
