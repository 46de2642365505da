//! The Gaussian mixture target: its JSON description, validation and log density.

use std::path::Path;

use mcmc_core::math::log_sum_exp2;
use serde::Deserialize;

use super::error::ExampleError;

const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// One component as written in the file: exactly one of `cov` and `sigma`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ComponentSpec {
    weight: f64,
    mean: Vec<f64>,
    #[serde(default)]
    cov: Option<Vec<Vec<f64>>>,
    #[serde(default)]
    sigma: Option<f64>,
}

/// The file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MixtureSpec {
    components: Vec<ComponentSpec>,
    #[serde(default)]
    bounds: Option<Vec<[f64; 2]>>,
}

/// How a component's covariance is stored for evaluation.
#[derive(Clone, Debug)]
enum Shape {
    /// `σ² I`, kept as `1/σ`.
    Isotropic { inv_sigma: f64 },
    /// `L Lᵀ`, the lower Cholesky factor row-major `d × d`.
    Full { lower: Vec<f64> },
}

/// One validated component.
#[derive(Clone, Debug)]
struct Component {
    weight: f64,
    mean: Vec<f64>,
    shape: Shape,
    /// Per-coordinate variance `Σ_ii`, for the start-up reference measure.
    variance: Vec<f64>,
    /// `ln(w/W) − (d/2) ln 2π − ln |L|`: everything but the quadratic form.
    log_constant: f64,
}

/// A Gaussian mixture `Σ_k w_k N(μ_k, Σ_k)` (weights normalised), optionally
/// truncated to a box: outside the box `ln π = −∞`.
#[derive(Clone, Debug)]
pub struct GaussianMixture {
    dim: usize,
    components: Vec<Component>,
    bounds: Option<Vec<(f64, f64)>>,
}

fn invalid(message: impl Into<String>) -> ExampleError {
    ExampleError::usage(message)
}

/// Lower Cholesky factor of a symmetric positive definite matrix, row-major,
/// or `None` if the matrix is not positive definite.
fn cholesky(a: &[Vec<f64>]) -> Option<Vec<f64>> {
    let d = a.len();
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i * d + k] * l[j * d + k]).sum();
            if i == j {
                let v = a[i][i] - s;
                if !(v > 0.0 && v.is_finite()) {
                    return None;
                }
                l[i * d + i] = v.sqrt();
            } else {
                l[i * d + j] = (a[i][j] - s) / l[j * d + j];
            }
        }
    }
    Some(l)
}

impl GaussianMixture {
    /// Reads and validates a mixture file. Every problem is a usage error
    /// (exit code 2) with a one-line message naming the file.
    pub fn from_file(path: &Path) -> Result<Self, ExampleError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| invalid(format!("cannot read target file {}: {e}", path.display())))?;
        Self::from_json(&text)
            .map_err(|e| invalid(format!("target file {}: {}", path.display(), e.message)))
    }

    /// Parses and validates a mixture from JSON text.
    pub fn from_json(text: &str) -> Result<Self, ExampleError> {
        let spec: MixtureSpec =
            serde_json::from_str(text).map_err(|e| invalid(format!("invalid JSON: {e}")))?;
        Self::from_spec(spec)
    }

    fn from_spec(spec: MixtureSpec) -> Result<Self, ExampleError> {
        let first = spec
            .components
            .first()
            .ok_or_else(|| invalid("`components` must not be empty"))?;
        let dim = first.mean.len();
        if dim == 0 {
            return Err(invalid(
                "component 0: `mean` must have at least one coordinate",
            ));
        }
        let mut total_weight = 0.0;
        for (k, c) in spec.components.iter().enumerate() {
            if !(c.weight.is_finite() && c.weight > 0.0) {
                return Err(invalid(format!(
                    "component {k}: `weight` must be finite and positive, got {}",
                    c.weight
                )));
            }
            total_weight += c.weight;
        }
        if !total_weight.is_finite() {
            return Err(invalid("the sum of the weights overflows"));
        }
        let components = spec
            .components
            .into_iter()
            .enumerate()
            .map(|(k, c)| Component::from_spec(k, c, dim, total_weight))
            .collect::<Result<Vec<_>, _>>()?;
        let bounds = match spec.bounds {
            None => None,
            Some(b) => {
                if b.len() != dim {
                    return Err(invalid(format!(
                        "`bounds` needs one [lo, hi] pair per coordinate ({dim}), got {}",
                        b.len()
                    )));
                }
                for (i, [lo, hi]) in b.iter().enumerate() {
                    if !(lo.is_finite() && hi.is_finite() && lo < hi && (hi - lo).is_finite()) {
                        return Err(invalid(format!(
                            "bounds[{i}] = [{lo}, {hi}]: need finite lo < hi"
                        )));
                    }
                }
                Some(b.into_iter().map(|[lo, hi]| (lo, hi)).collect())
            }
        };
        Ok(GaussianMixture {
            dim,
            components,
            bounds,
        })
    }

    /// Dimension of the space.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of components.
    pub fn len(&self) -> usize {
        self.components.len()
    }

    /// Always false: a valid mixture has at least one component.
    pub fn is_empty(&self) -> bool {
        self.components.is_empty()
    }

    /// The box the target is truncated to, if any.
    pub fn bounds(&self) -> Option<&[(f64, f64)]> {
        self.bounds.as_deref()
    }

    /// Normalised weights.
    pub fn weights(&self) -> impl Iterator<Item = f64> + '_ {
        self.components.iter().map(|c| c.weight)
    }

    /// Component means.
    pub fn means(&self) -> impl Iterator<Item = &[f64]> + '_ {
        self.components.iter().map(|c| c.mean.as_slice())
    }

    /// Per-coordinate mean and variance of the untruncated mixture:
    /// `E x = Σ w μ`, `Var x_i = Σ w (Σ_ii + μ_i²) − (E x_i)²`.
    pub fn untruncated_moments(&self) -> (Vec<f64>, Vec<f64>) {
        let mut mean = vec![0.0; self.dim];
        let mut second = vec![0.0; self.dim];
        for c in &self.components {
            for i in 0..self.dim {
                mean[i] += c.weight * c.mean[i];
                second[i] += c.weight * (c.variance[i] + c.mean[i] * c.mean[i]);
            }
        }
        let var = second
            .iter()
            .zip(&mean)
            .map(|(s, m)| (s - m * m).max(0.0))
            .collect();
        (mean, var)
    }

    /// `ln π(x)` (normalised for the untruncated mixture; `−∞` outside the bounds).
    pub fn log_density(&self, x: &[f64]) -> f64 {
        if x.len() != self.dim {
            return f64::NAN;
        }
        self.log_density_with(|i| x[i])
    }

    /// `ln π` at the point whose coordinates are `coordinate(0..dim)`.
    pub fn log_density_with(&self, coordinate: impl Fn(usize) -> f64) -> f64 {
        if let Some(b) = &self.bounds {
            for (i, &(lo, hi)) in b.iter().enumerate() {
                let v = coordinate(i);
                if !(lo..=hi).contains(&v) {
                    return f64::NEG_INFINITY;
                }
            }
        }
        let mut acc = f64::NEG_INFINITY;
        for c in &self.components {
            acc = log_sum_exp2(acc, c.log_constant - 0.5 * c.quadratic_form(&coordinate));
        }
        acc
    }

    /// Index of the component whose mean is nearest (Euclidean) to `x`.
    pub fn nearest_component(&self, x: &[f64]) -> usize {
        let mut best = (0, f64::INFINITY);
        for (k, c) in self.components.iter().enumerate() {
            let d2: f64 = c.mean.iter().zip(x).map(|(m, v)| (v - m) * (v - m)).sum();
            if d2 < best.1 {
                best = (k, d2);
            }
        }
        best.0
    }
}

impl Component {
    fn from_spec(
        k: usize,
        c: ComponentSpec,
        dim: usize,
        total_weight: f64,
    ) -> Result<Self, ExampleError> {
        if c.mean.len() != dim {
            return Err(invalid(format!(
                "component {k}: `mean` has {} coordinates, component 0 has {dim}",
                c.mean.len()
            )));
        }
        let weight = c.weight / total_weight;
        let (shape, log_det_l, variance) = match (c.cov, c.sigma) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(invalid(format!(
                    "component {k}: give exactly one of `cov` and `sigma`"
                )));
            }
            (None, Some(sigma)) => {
                if !(sigma.is_finite() && sigma > 0.0) {
                    return Err(invalid(format!(
                        "component {k}: `sigma` must be finite and positive, got {sigma}"
                    )));
                }
                let shape = Shape::Isotropic {
                    inv_sigma: 1.0 / sigma,
                };
                (shape, dim as f64 * sigma.ln(), vec![sigma * sigma; dim])
            }
            (Some(cov), None) => {
                if cov.len() != dim || cov.iter().any(|row| row.len() != dim) {
                    return Err(invalid(format!(
                        "component {k}: `cov` must be a {dim}×{dim} matrix"
                    )));
                }
                for (i, row) in cov.iter().enumerate() {
                    for (j, &a) in row.iter().enumerate().take(i) {
                        let b = cov[j][i];
                        if (a - b).abs() > 1e-12 * a.abs().max(b.abs()).max(f64::MIN_POSITIVE) {
                            return Err(invalid(format!(
                                "component {k}: `cov` is not symmetric ([{i}][{j}] = {a}, [{j}][{i}] = {b})"
                            )));
                        }
                    }
                }
                let lower = cholesky(&cov).ok_or_else(|| {
                    invalid(format!("component {k}: `cov` is not positive definite"))
                })?;
                let log_det_l = (0..dim).map(|i| lower[i * dim + i].ln()).sum();
                let variance = (0..dim).map(|i| cov[i][i]).collect();
                (Shape::Full { lower }, log_det_l, variance)
            }
        };
        if c.mean.iter().any(|m| !m.is_finite()) {
            return Err(invalid(format!("component {k}: `mean` must be finite")));
        }
        Ok(Component {
            weight,
            log_constant: weight.ln() - 0.5 * dim as f64 * LN_2PI - log_det_l,
            mean: c.mean,
            shape,
            variance,
        })
    }

    /// `(x − μ)ᵀ Σ⁻¹ (x − μ)`, by forward substitution `L z = x − μ` for a
    /// full covariance (on the stack up to 32 coordinates).
    fn quadratic_form(&self, x: &impl Fn(usize) -> f64) -> f64 {
        let d = self.mean.len();
        match &self.shape {
            Shape::Isotropic { inv_sigma } => (0..d)
                .map(|i| {
                    let z = (x(i) - self.mean[i]) * inv_sigma;
                    z * z
                })
                .sum(),
            Shape::Full { lower } => {
                let mut stack = [0.0; 32];
                let mut heap = Vec::new();
                let z: &mut [f64] = if d <= stack.len() {
                    &mut stack[..d]
                } else {
                    heap.resize(d, 0.0);
                    &mut heap
                };
                let mut q = 0.0;
                for i in 0..d {
                    let row = &lower[i * d..i * d + i];
                    let s: f64 = row.iter().zip(&z[..i]).map(|(l, z)| l * z).sum();
                    z[i] = (x(i) - self.mean[i] - s) / lower[i * d + i];
                    q += z[i] * z[i];
                }
                q
            }
        }
    }
}
