//! The posteriordb models, each written by hand from its Stan program
//! (`posterior_database/models/stan/<model>.stan`): the log density on the
//! unconstrained space (Stan's transforms and their log-Jacobians, constant
//! terms dropped), its gradient, and the constrained quantities posteriordb
//! reports draws of, in posteriordb's order.

// Index loops over coefficients and lags read more clearly here.
#![allow(clippy::needless_range_loop)]

use super::transforms::{
    cauchy_log1p, cauchy_log1p_derivative, log_logistic_jacobian, log1p_exp, logistic, positive,
};
use mcmc_core::gradient::GradientTarget;
use serde_json::Value;
use std::collections::BTreeMap;

/// A posterior: a gradient target on the unconstrained space plus the map
/// to the quantities posteriordb has reference draws of.
pub trait Model: GradientTarget + Send + Sync {
    /// Names of the reported quantities, as posteriordb spells them.
    fn names(&self) -> Vec<String>;
    /// The reported quantities at the unconstrained point `x`.
    fn constrain(&self, x: &[f64]) -> Vec<f64>;
}

fn field<'a>(data: &'a Value, key: &str) -> Result<&'a Value, String> {
    data.get(key)
        .ok_or_else(|| format!("data has no field `{key}`"))
}

/// A numeric array field.
pub(crate) fn reals(data: &Value, key: &str) -> Result<Vec<f64>, String> {
    field(data, key)?
        .as_array()
        .ok_or_else(|| format!("`{key}` is not an array"))?
        .iter()
        .map(|v| {
            v.as_f64()
                .ok_or_else(|| format!("`{key}` has a non-number"))
        })
        .collect()
}

/// An integer field.
fn int(data: &Value, key: &str) -> Result<usize, String> {
    field(data, key)?
        .as_u64()
        .map(|n| n as usize)
        .ok_or_else(|| format!("`{key}` is not a non-negative integer"))
}

/// `name[1]`, …, `name[n]`.
fn indexed(name: &str, n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("{name}[{i}]")).collect()
}

// ---- eight schools -----------------------------------------------------------

/// `eight_schools_noncentered` and `eight_schools_centered`: `J` schools
/// with estimates `y ± σ`, `θ_j ~ N(μ, τ)`, `μ ~ N(0, 5)`, `τ ~ Cauchy⁺(0, 5)`.
/// Unconstrained coordinates: `(θ̃ or θ)[J], μ, ln τ`.
pub struct EightSchools {
    y: Vec<f64>,
    sigma: Vec<f64>,
    centered: bool,
}

impl EightSchools {
    /// From posteriordb's `eight_schools` data; `centered` picks the
    /// parameterisation.
    pub fn new(data: &Value, centered: bool) -> Result<Self, String> {
        let (y, sigma) = (reals(data, "y")?, reals(data, "sigma")?);
        if y.len() != int(data, "J")? || sigma.len() != y.len() {
            return Err("eight_schools: y and sigma must have J entries".into());
        }
        Ok(EightSchools { y, sigma, centered })
    }
}

impl GradientTarget for EightSchools {
    fn dim(&self) -> usize {
        self.y.len() + 2
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let j = self.y.len();
        let (mu, u) = (x[j], x[j + 1]);
        let tau = positive(u);
        // μ ~ N(0, 5), τ ~ Cauchy(0, 5) on τ > 0, Jacobian e^u.
        let mut lp = -0.5 * mu * mu / 25.0 - cauchy_log1p(tau, 5.0) + u;
        let mut d_mu = -mu / 25.0;
        let mut d_tau = -cauchy_log1p_derivative(tau, 5.0);
        for i in 0..j {
            let theta = if self.centered { x[i] } else { mu + tau * x[i] };
            // y ~ N(θ, σ)
            let r = (self.y[i] - theta) / (self.sigma[i] * self.sigma[i]);
            lp -= 0.5 * (self.y[i] - theta).powi(2) / (self.sigma[i] * self.sigma[i]);
            if self.centered {
                // θ ~ N(μ, τ)
                let z = (x[i] - mu) / tau;
                lp -= tau.ln() + 0.5 * z * z;
                g[i] = -z / tau + r;
                d_mu += z / tau;
                d_tau += -1.0 / tau + z * z / tau;
            } else {
                // θ̃ ~ N(0, 1), θ = μ + τ θ̃
                lp -= 0.5 * x[i] * x[i];
                g[i] = -x[i] + r * tau;
                d_mu += r;
                d_tau += r * x[i];
            }
        }
        g[j] = d_mu;
        g[j + 1] = d_tau * tau + 1.0;
        lp
    }
}

impl Model for EightSchools {
    fn names(&self) -> Vec<String> {
        let mut n = indexed("theta", self.y.len());
        n.extend(["mu".to_string(), "tau".to_string()]);
        n
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        let j = self.y.len();
        let (mu, tau) = (x[j], positive(x[j + 1]));
        let mut q: Vec<f64> = (0..j)
            .map(|i| if self.centered { x[i] } else { mu + tau * x[i] })
            .collect();
        q.extend([mu, tau]);
        q
    }
}

// ---- linear regressions --------------------------------------------------------

/// A prior on the regression coefficients or on the noise scale.
#[derive(Clone, Copy, Debug)]
pub enum Prior {
    /// Stan's default: improper uniform.
    Flat,
    /// `N(0, s)` (on `σ > 0`: half-normal).
    Normal(f64),
    /// `Cauchy(0, s)` (on `σ > 0`: half-Cauchy).
    Cauchy(f64),
}

impl Prior {
    /// `ln p(v)` up to a constant, and its derivative.
    fn log_density(self, v: f64) -> (f64, f64) {
        match self {
            Prior::Flat => (0.0, 0.0),
            Prior::Normal(s) => (-0.5 * v * v / (s * s), -v / (s * s)),
            Prior::Cauchy(s) => (-cauchy_log1p(v, s), -cauchy_log1p_derivative(v, s)),
        }
    }
}

/// `y ~ N(Xβ, σ)`: `kidscore_momiq`, `blr`, `logmesquite`. Unconstrained
/// coordinates: `β[D], ln σ`.
pub struct LinearRegression {
    /// `n × D`, row-major.
    x: Vec<f64>,
    y: Vec<f64>,
    d: usize,
    beta_prior: Prior,
    sigma_prior: Prior,
}

impl LinearRegression {
    /// From the design matrix rows and the responses.
    fn new(
        rows: Vec<Vec<f64>>,
        y: Vec<f64>,
        beta_prior: Prior,
        sigma_prior: Prior,
    ) -> Result<Self, String> {
        let d = rows.first().map_or(0, Vec::len);
        if rows.len() != y.len() || d == 0 || rows.iter().any(|r| r.len() != d) {
            return Err("regression: design matrix and responses disagree".into());
        }
        Ok(LinearRegression {
            x: rows.concat(),
            y,
            d,
            beta_prior,
            sigma_prior,
        })
    }

    /// `kidscore_momiq`: `kid_score ~ N(β₁ + β₂ mom_iq, σ)`, `σ ~ Cauchy⁺(0, 2.5)`.
    pub fn kidscore_momiq(data: &Value) -> Result<Self, String> {
        let iq = reals(data, "mom_iq")?;
        let rows = iq.iter().map(|&v| vec![1.0, v]).collect();
        Self::new(
            rows,
            reals(data, "kid_score")?,
            Prior::Flat,
            Prior::Cauchy(2.5),
        )
    }

    /// `blr`: `y ~ N(Xβ, σ)`, `β ~ N(0, 10)`, `σ ~ N⁺(0, 10)`.
    pub fn blr(data: &Value) -> Result<Self, String> {
        let rows = field(data, "X")?
            .as_array()
            .ok_or("`X` is not an array")?
            .iter()
            .map(|r| {
                r.as_array()
                    .ok_or("`X` is not a matrix")?
                    .iter()
                    .map(|v| v.as_f64().ok_or("`X` has a non-number"))
                    .collect::<Result<Vec<f64>, _>>()
            })
            .collect::<Result<Vec<_>, _>>()?;
        if rows.first().map(Vec::len) != Some(int(data, "D")?) {
            return Err("blr: X must have D columns".into());
        }
        Self::new(
            rows,
            reals(data, "y")?,
            Prior::Normal(10.0),
            Prior::Normal(10.0),
        )
    }

    /// `logmesquite`: `ln weight ~ N(β₁ + β₂ ln diam1 + β₃ ln diam2 +
    /// β₄ ln canopy_height + β₅ ln total_height + β₆ ln density + β₇ group, σ)`,
    /// flat priors.
    pub fn logmesquite(data: &Value) -> Result<Self, String> {
        let cols: Vec<Vec<f64>> = ["diam1", "diam2", "canopy_height", "total_height", "density"]
            .iter()
            .map(|k| Ok(reals(data, k)?.iter().map(|v| v.ln()).collect()))
            .collect::<Result<_, String>>()?;
        let group = reals(data, "group")?;
        let rows = (0..group.len())
            .map(|i| {
                let mut r = vec![1.0];
                r.extend(cols.iter().map(|c| c[i]));
                r.push(group[i]);
                r
            })
            .collect();
        let y = reals(data, "weight")?.iter().map(|v| v.ln()).collect();
        Self::new(rows, y, Prior::Flat, Prior::Flat)
    }
}

impl GradientTarget for LinearRegression {
    fn dim(&self) -> usize {
        self.d + 1
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let d = self.d;
        let (beta, u) = (&x[..d], x[d]);
        let sigma = positive(u);
        let (mut lp, d_sigma_prior) = self.sigma_prior.log_density(sigma);
        lp += u;
        for j in 0..d {
            let (l, dl) = self.beta_prior.log_density(beta[j]);
            lp += l;
            g[j] = dl;
        }
        let mut ss = 0.0;
        let inv_var = 1.0 / (sigma * sigma);
        for (row, &y) in self.x.chunks_exact(d).zip(&self.y) {
            let e = y - row.iter().zip(beta).map(|(a, b)| a * b).sum::<f64>();
            ss += e * e;
            for j in 0..d {
                g[j] += e * inv_var * row[j];
            }
        }
        let n = self.y.len() as f64;
        lp += -n * u - 0.5 * ss * inv_var;
        // d/du of (−n ln σ − ss/(2σ²)) = −n + ss/σ²; the prior's by the chain rule.
        g[d] = -n + ss * inv_var + d_sigma_prior * sigma + 1.0;
        lp
    }
}

impl Model for LinearRegression {
    fn names(&self) -> Vec<String> {
        let mut n = indexed("beta", self.d);
        n.push("sigma".into());
        n
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        let mut q = x[..self.d].to_vec();
        q.push(positive(x[self.d]));
        q
    }
}

// ---- logistic regression -----------------------------------------------------

/// `y ~ Bernoulli(logit⁻¹(Xβ))`, `β ~ N(0, s)`: `dogs`. Observations with
/// the same row of `X` are pooled into one binomial term
/// `k η − n ln(1 + e^η)` (`k` successes in `n`), which is the sum of their
/// Bernoulli terms exactly: the dogs' 775 trials have 195 distinct rows.
/// Unconstrained coordinates: `β[D]`.
pub struct LogisticRegression {
    /// Distinct rows of the design matrix, `groups × D`, row-major.
    x: Vec<f64>,
    /// Successes `k` and trials `n` per distinct row.
    counts: Vec<(f64, f64)>,
    d: usize,
    prior_sd: f64,
}

impl LogisticRegression {
    /// `dogs` (Gelman & Hill, ch. 24): `y = 1` at dog `j`'s trial `t` with
    /// logit `β₁ + β₂ n_avoid + β₃ n_shock`, the counts of its earlier
    /// trials with `y = 0` (avoidances) and `y = 1` (shocks), as the Stan
    /// program counts them; `β ~ N(0, 100)`.
    pub fn dogs(data: &Value) -> Result<Self, String> {
        let (n_dogs, n_trials) = (int(data, "n_dogs")?, int(data, "n_trials")?);
        let y = field(data, "y")?
            .as_array()
            .filter(|rows| rows.len() == n_dogs)
            .ok_or("dogs: `y` must have n_dogs rows")?;
        // (n_avoid, n_shock) → (successes, trials), in a fixed order.
        let mut groups: BTreeMap<(u64, u64), (f64, f64)> = BTreeMap::new();
        for row in y {
            let row = row
                .as_array()
                .filter(|r| r.len() == n_trials)
                .ok_or("dogs: every row of `y` must have n_trials entries")?;
            let (mut avoid, mut shock) = (0, 0);
            for v in row {
                let shocked: u64 = match v.as_u64() {
                    Some(b @ (0 | 1)) => b,
                    _ => return Err("dogs: `y` must be 0 or 1".into()),
                };
                let g = groups.entry((avoid, shock)).or_default();
                g.0 += shocked as f64;
                g.1 += 1.0;
                avoid += 1 - shocked;
                shock += shocked;
            }
        }
        Ok(LogisticRegression {
            x: groups
                .keys()
                .flat_map(|&(a, s)| [1.0, a as f64, s as f64])
                .collect(),
            counts: groups.into_values().collect(),
            d: 3,
            prior_sd: 100.0,
        })
    }
}

impl GradientTarget for LogisticRegression {
    fn dim(&self) -> usize {
        self.d
    }

    fn log_density_gradient(&self, beta: &[f64], g: &mut [f64]) -> f64 {
        let inv_var = 1.0 / (self.prior_sd * self.prior_sd);
        let mut lp = 0.0;
        for j in 0..self.d {
            lp -= 0.5 * beta[j] * beta[j] * inv_var;
            g[j] = -beta[j] * inv_var;
        }
        for (row, &(k, n)) in self.x.chunks_exact(self.d).zip(&self.counts) {
            let eta: f64 = row.iter().zip(beta).map(|(a, b)| a * b).sum();
            lp += k * eta - n * log1p_exp(eta);
            // d/dη = k − n logit⁻¹(η).
            let r = k - n * logistic(eta);
            for j in 0..self.d {
                g[j] += r * row[j];
            }
        }
        lp
    }
}

impl Model for LogisticRegression {
    fn names(&self) -> Vec<String> {
        indexed("beta", self.d)
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        x.to_vec()
    }
}

// ---- time series -----------------------------------------------------------------

/// `arK`: `y_t ~ N(α + Σ_k β_k y_{t−k}, σ)` for `t > K`, `α, β ~ N(0, 10)`,
/// `σ ~ Cauchy⁺(0, 2.5)`. Unconstrained coordinates: `α, β[K], ln σ`.
pub struct Ark {
    y: Vec<f64>,
    k: usize,
}

impl Ark {
    /// From posteriordb's `arK` data.
    pub fn new(data: &Value) -> Result<Self, String> {
        let (y, k) = (reals(data, "y")?, int(data, "K")?);
        if y.len() != int(data, "T")? || k >= y.len() {
            return Err("arK: y must have T > K entries".into());
        }
        Ok(Ark { y, k })
    }
}

impl GradientTarget for Ark {
    fn dim(&self) -> usize {
        self.k + 2
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let k = self.k;
        let (alpha, beta, u) = (x[0], &x[1..=k], x[k + 1]);
        let sigma = positive(u);
        let inv_var = 1.0 / (sigma * sigma);
        let mut lp = -0.5 * (alpha * alpha + beta.iter().map(|b| b * b).sum::<f64>()) / 100.0
            - cauchy_log1p(sigma, 2.5)
            + u;
        g[0] = -alpha / 100.0;
        for j in 0..k {
            g[1 + j] = -beta[j] / 100.0;
        }
        let mut ss = 0.0;
        for t in k..self.y.len() {
            let mut mu = alpha;
            for j in 0..k {
                mu += beta[j] * self.y[t - 1 - j];
            }
            let e = self.y[t] - mu;
            ss += e * e;
            g[0] += e * inv_var;
            for j in 0..k {
                g[1 + j] += e * inv_var * self.y[t - 1 - j];
            }
        }
        let n = (self.y.len() - k) as f64;
        lp += -n * u - 0.5 * ss * inv_var;
        g[k + 1] = -n + ss * inv_var - cauchy_log1p_derivative(sigma, 2.5) * sigma + 1.0;
        lp
    }
}

impl Model for Ark {
    fn names(&self) -> Vec<String> {
        let mut n = vec!["alpha".to_string()];
        n.extend(indexed("beta", self.k));
        n.push("sigma".into());
        n
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        let mut q = x[..=self.k].to_vec();
        q.push(positive(x[self.k + 1]));
        q
    }
}

/// `arma11`: `err_t = y_t − μ − φ y_{t−1} − θ err_{t−1}` (with
/// `ν₁ = μ + φμ`), `err ~ N(0, σ)`, `μ ~ N(0, 10)`, `φ, θ ~ N(0, 2)`,
/// `σ ~ Cauchy⁺(0, 2.5)`. Unconstrained coordinates: `μ, φ, θ, ln σ`.
pub struct Arma11 {
    y: Vec<f64>,
}

impl Arma11 {
    /// From posteriordb's `arma` data.
    pub fn new(data: &Value) -> Result<Self, String> {
        let y = reals(data, "y")?;
        if y.len() != int(data, "T")? || y.is_empty() {
            return Err("arma: y must have T ≥ 1 entries".into());
        }
        Ok(Arma11 { y })
    }
}

impl GradientTarget for Arma11 {
    fn dim(&self) -> usize {
        4
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let (mu, phi, theta, u) = (x[0], x[1], x[2], x[3]);
        let sigma = positive(u);
        let inv_var = 1.0 / (sigma * sigma);
        // Forward sensitivities of err_t in (μ, φ, θ), carried along the
        // recursion.
        let mut err = self.y[0] - (mu + phi * mu);
        let mut de = [-(1.0 + phi), -mu, 0.0];
        let mut ss = err * err;
        let mut dss = [2.0 * err * de[0], 2.0 * err * de[1], 0.0];
        for t in 1..self.y.len() {
            let prev = err;
            err = self.y[t] - mu - phi * self.y[t - 1] - theta * prev;
            de = [
                -1.0 - theta * de[0],
                -self.y[t - 1] - theta * de[1],
                -prev - theta * de[2],
            ];
            ss += err * err;
            for i in 0..3 {
                dss[i] += 2.0 * err * de[i];
            }
        }
        let n = self.y.len() as f64;
        let lp = -0.5 * mu * mu / 100.0
            - 0.5 * (phi * phi + theta * theta) / 4.0
            - cauchy_log1p(sigma, 2.5)
            + u
            - n * u
            - 0.5 * ss * inv_var;
        g[0] = -mu / 100.0 - 0.5 * dss[0] * inv_var;
        g[1] = -phi / 4.0 - 0.5 * dss[1] * inv_var;
        g[2] = -theta / 4.0 - 0.5 * dss[2] * inv_var;
        g[3] = -n + ss * inv_var - cauchy_log1p_derivative(sigma, 2.5) * sigma + 1.0;
        lp
    }
}

impl Model for Arma11 {
    fn names(&self) -> Vec<String> {
        ["mu", "phi", "theta", "sigma"].map(String::from).to_vec()
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        vec![x[0], x[1], x[2], positive(x[3])]
    }
}

/// `garch11`: `σ_t² = α₀ + α₁ (y_{t−1} − μ)² + β₁ σ_{t−1}²` with
/// `σ₁ = sigma1` (data), `y_t ~ N(μ, σ_t)`, flat priors on `μ`,
/// `α₀ > 0`, `α₁ ∈ (0, 1)`, `β₁ ∈ (0, 1 − α₁)`. Unconstrained coordinates:
/// `μ, ln α₀, logit α₁, logit(β₁ / (1 − α₁))`.
pub struct Garch11 {
    y: Vec<f64>,
    sigma1: f64,
}

impl Garch11 {
    /// From posteriordb's `garch` data.
    pub fn new(data: &Value) -> Result<Self, String> {
        let y = reals(data, "y")?;
        let sigma1 = field(data, "sigma1")?
            .as_f64()
            .ok_or("`sigma1` is not a number")?;
        if y.len() != int(data, "T")? || y.is_empty() || sigma1.is_nan() || sigma1 <= 0.0 {
            return Err("garch: y must have T ≥ 1 entries and sigma1 > 0".into());
        }
        Ok(Garch11 { y, sigma1 })
    }
}

impl GradientTarget for Garch11 {
    fn dim(&self) -> usize {
        4
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let mu = x[0];
        let alpha0 = positive(x[1]);
        let alpha1 = logistic(x[2]);
        let s = logistic(x[3]);
        let beta1 = (1.0 - alpha1) * s;
        // Log-Jacobian: ln α₀ + ln α₁(1 − α₁) + ln(1 − α₁) + ln s(1 − s).
        let mut lp =
            x[1] + log_logistic_jacobian(x[2]) + (1.0 - alpha1).ln() + log_logistic_jacobian(x[3]);
        // v_t = σ_t² and its sensitivities in (μ, α₀, α₁, β₁).
        let mut v = self.sigma1 * self.sigma1;
        let mut dv = [0.0; 4];
        let mut dl = [0.0; 4]; // d lp / d(μ, α₀, α₁, β₁)
        for t in 0..self.y.len() {
            if t > 0 {
                let r = self.y[t - 1] - mu;
                dv = [
                    -2.0 * alpha1 * r + beta1 * dv[0],
                    1.0 + beta1 * dv[1],
                    r * r + beta1 * dv[2],
                    v + beta1 * dv[3],
                ];
                v = alpha0 + alpha1 * r * r + beta1 * v;
            }
            let e = self.y[t] - mu;
            // ln N(y_t | μ, √v) = −½ ln v − e²/(2v) + const.
            lp += -0.5 * v.ln() - 0.5 * e * e / v;
            let dv_coeff = -0.5 / v + 0.5 * e * e / (v * v);
            for i in 0..4 {
                dl[i] += dv_coeff * dv[i];
            }
            dl[0] += e / v;
        }
        let ds = s * (1.0 - s);
        let da1 = alpha1 * (1.0 - alpha1);
        g[0] = dl[0];
        g[1] = dl[1] * alpha0 + 1.0;
        // β₁ = (1 − α₁) s depends on α₁ too.
        g[2] = (dl[2] - dl[3] * s) * da1 + (1.0 - 2.0 * alpha1) - alpha1;
        g[3] = dl[3] * (1.0 - alpha1) * ds + (1.0 - 2.0 * s);
        lp
    }
}

impl Model for Garch11 {
    fn names(&self) -> Vec<String> {
        ["mu", "alpha0", "alpha1", "beta1"]
            .map(String::from)
            .to_vec()
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        let alpha1 = logistic(x[2]);
        vec![
            x[0],
            positive(x[1]),
            alpha1,
            (1.0 - alpha1) * logistic(x[3]),
        ]
    }
}

// ---- Gaussian process ----------------------------------------------------------

/// `gp_regr`: `y ~ N(0, K)`, `K_ij = α² exp(−(x_i − x_j)²/(2ρ²)) + σ δ_ij`
/// (σ, not σ², as the Stan program has it), `ρ ~ Gamma(25, 4)`,
/// `α ~ N⁺(0, 2)`, `σ ~ N⁺(0, 1)`. Unconstrained coordinates: `ln ρ, ln α, ln σ`.
pub struct GpRegression {
    x: Vec<f64>,
    y: Vec<f64>,
}

impl GpRegression {
    /// From posteriordb's `gp_pois_regr` data (`x`, `y`).
    pub fn new(data: &Value) -> Result<Self, String> {
        let (x, y) = (reals(data, "x")?, reals(data, "y")?);
        if x.len() != int(data, "N")? || y.len() != x.len() || x.is_empty() {
            return Err("gp_regr: x and y must have N ≥ 1 entries".into());
        }
        Ok(GpRegression { x, y })
    }
}

/// Cholesky factor (lower, row-major) of the `n × n` matrix `a`; `None`
/// unless positive definite.
fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s = a[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// `K⁻¹` from its Cholesky factor (solves `L Lᵀ X = I` column by column).
fn inverse_from_cholesky(l: &[f64], n: usize) -> Vec<f64> {
    let mut inv = vec![0.0; n * n];
    let mut z = vec![0.0; n];
    for c in 0..n {
        for i in 0..n {
            let b = if i == c { 1.0 } else { 0.0 };
            z[i] = (b - (0..i).map(|k| l[i * n + k] * z[k]).sum::<f64>()) / l[i * n + i];
        }
        for i in (0..n).rev() {
            let s = z[i]
                - (i + 1..n)
                    .map(|k| l[k * n + i] * inv[k * n + c])
                    .sum::<f64>();
            inv[i * n + c] = s / l[i * n + i];
        }
    }
    inv
}

impl GradientTarget for GpRegression {
    fn dim(&self) -> usize {
        3
    }

    fn log_density_gradient(&self, p: &[f64], g: &mut [f64]) -> f64 {
        let (rho, alpha, sigma) = (positive(p[0]), positive(p[1]), positive(p[2]));
        let n = self.x.len();
        // K, and the squared-exponential part E (K = α² E + σ I).
        let mut e = vec![0.0; n * n];
        let mut k = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let d = self.x[i] - self.x[j];
                e[i * n + j] = (-0.5 * d * d / (rho * rho)).exp();
                k[i * n + j] = alpha * alpha * e[i * n + j] + if i == j { sigma } else { 0.0 };
            }
        }
        let Some(l) = cholesky(&k, n) else {
            return f64::NAN;
        };
        let kinv = inverse_from_cholesky(&l, n);
        let a: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| kinv[i * n + j] * self.y[j]).sum())
            .collect();
        let log_det: f64 = (0..n).map(|i| 2.0 * l[i * n + i].ln()).sum();
        let quad: f64 = a.iter().zip(&self.y).map(|(a, y)| a * y).sum();
        // Priors: Gamma(25, 4) → 24 ln ρ − 4ρ; N(0, 2) → −α²/8; N(0, 1) → −σ²/2;
        // Jacobians ln ρ + ln α + ln σ.
        let lp = 24.0 * rho.ln() - 4.0 * rho - alpha * alpha / 8.0 - sigma * sigma / 2.0
            + p[0]
            + p[1]
            + p[2]
            - 0.5 * quad
            - 0.5 * log_det;
        // d/dθ of −½ yᵀK⁻¹y − ½ ln|K| = ½ aᵀ (dK/dθ) a − ½ tr(K⁻¹ dK/dθ).
        let (mut d_rho, mut d_alpha) = (0.0, 0.0);
        for i in 0..n {
            for j in 0..n {
                let w = 0.5 * (a[i] * a[j] - kinv[i * n + j]);
                let d = self.x[i] - self.x[j];
                d_alpha += w * 2.0 * alpha * e[i * n + j];
                d_rho += w * alpha * alpha * e[i * n + j] * d * d / (rho * rho * rho);
            }
        }
        let d_sigma: f64 = (0..n).map(|i| 0.5 * (a[i] * a[i] - kinv[i * n + i])).sum();
        g[0] = (d_rho + 24.0 / rho - 4.0) * rho + 1.0;
        g[1] = (d_alpha - alpha / 4.0) * alpha + 1.0;
        g[2] = (d_sigma - sigma) * sigma + 1.0;
        lp
    }
}

impl Model for GpRegression {
    fn names(&self) -> Vec<String> {
        ["rho", "alpha", "sigma"].map(String::from).to_vec()
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        x.iter().map(|&u| positive(u)).collect()
    }
}

// ---- mixture -----------------------------------------------------------------------

/// `low_dim_gauss_mix`: `y_n ~ θ N(μ₁, σ₁) + (1 − θ) N(μ₂, σ₂)` with
/// `μ₁ < μ₂` (ordered), `μ ~ N(0, 2)`, `σ ~ N⁺(0, 2)`, `θ ~ Beta(5, 5)`.
/// Unconstrained coordinates: `μ₁, ln(μ₂ − μ₁), ln σ₁, ln σ₂, logit θ`.
pub struct GaussMix {
    y: Vec<f64>,
}

impl GaussMix {
    /// From posteriordb's `low_dim_gauss_mix` data.
    pub fn new(data: &Value) -> Result<Self, String> {
        let y = reals(data, "y")?;
        if y.len() != int(data, "N")? {
            return Err("low_dim_gauss_mix: y must have N entries".into());
        }
        Ok(GaussMix { y })
    }
}

impl GradientTarget for GaussMix {
    fn dim(&self) -> usize {
        5
    }

    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        let mu = [x[0], x[0] + positive(x[1])];
        let sigma = [positive(x[2]), positive(x[3])];
        let theta = logistic(x[4]);
        let mut lp = -(mu[0] * mu[0] + mu[1] * mu[1]) / 8.0
            - (sigma[0] * sigma[0] + sigma[1] * sigma[1]) / 8.0
            + 4.0 * (theta.ln() + (1.0 - theta).ln())
            + x[1]
            + x[2]
            + x[3]
            + log_logistic_jacobian(x[4]);
        let mut d_mu = [-mu[0] / 4.0, -mu[1] / 4.0];
        let mut d_sigma = [-sigma[0] / 4.0, -sigma[1] / 4.0];
        let mut d_theta = 4.0 / theta - 4.0 / (1.0 - theta);
        let (ls0, ls1) = (sigma[0].ln(), sigma[1].ln());
        for &y in &self.y {
            let z0 = (y - mu[0]) / sigma[0];
            let z1 = (y - mu[1]) / sigma[1];
            // log_mix(θ, ln N(y|μ₁,σ₁), ln N(y|μ₂,σ₂)) without the common ½ ln 2π.
            let a = theta.ln() - ls0 - 0.5 * z0 * z0;
            let b = (1.0 - theta).ln() - ls1 - 0.5 * z1 * z1;
            let m = a.max(b);
            let lse = m + ((a - m).exp() + (b - m).exp()).ln();
            lp += lse;
            // Responsibilities of the two components.
            let (w0, w1) = ((a - lse).exp(), (b - lse).exp());
            d_mu[0] += w0 * z0 / sigma[0];
            d_mu[1] += w1 * z1 / sigma[1];
            d_sigma[0] += w0 * (z0 * z0 - 1.0) / sigma[0];
            d_sigma[1] += w1 * (z1 * z1 - 1.0) / sigma[1];
            d_theta += w0 / theta - w1 / (1.0 - theta);
        }
        g[0] = d_mu[0] + d_mu[1];
        g[1] = d_mu[1] * (mu[1] - mu[0]) + 1.0;
        g[2] = d_sigma[0] * sigma[0] + 1.0;
        g[3] = d_sigma[1] * sigma[1] + 1.0;
        g[4] = d_theta * theta * (1.0 - theta) + (1.0 - 2.0 * theta);
        lp
    }
}

impl Model for GaussMix {
    fn names(&self) -> Vec<String> {
        ["mu[1]", "mu[2]", "sigma[1]", "sigma[2]", "theta"]
            .map(String::from)
            .to_vec()
    }

    fn constrain(&self, x: &[f64]) -> Vec<f64> {
        vec![
            x[0],
            x[0] + positive(x[1]),
            positive(x[2]),
            positive(x[3]),
            logistic(x[4]),
        ]
    }
}
