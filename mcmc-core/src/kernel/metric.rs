//! Mass matrices (metrics) of Hamiltonian kernels.
//!
//! The metric is stored as the inverse mass matrix `M⁻¹` (an estimate of
//! the target's covariance, Stan's convention): momenta are drawn from
//! `N(0, M)`, the kinetic energy is `½ pᵀ M⁻¹ p` and positions move with
//! velocity `M⁻¹ p`.

use crate::error::{Result, invalid};
use crate::linalg::{cholesky, log_normal_density};
use crate::rng::{ChainRng, standard_normal};

#[derive(Clone, Debug, PartialEq)]
enum Shape {
    Diagonal {
        inv_mass: Vec<f64>,
        // 1/sqrt(inv_mass): momentum scales.
        momentum_scale: Vec<f64>,
    },
    Dense {
        // Row-major `M⁻¹`.
        inv_mass: Vec<f64>,
        // Lower Cholesky factor of `M⁻¹`.
        lower: Vec<f64>,
        log_det_lower: f64,
    },
}

/// A diagonal or dense mass matrix, given by its inverse `M⁻¹`.
///
/// ```
/// use mcmc_core::kernel::Metric;
/// let unit = Metric::identity(3);
/// let diag = Metric::diagonal(vec![1.0, 4.0]).unwrap();
/// let dense = Metric::dense(&[vec![1.0, 0.5], vec![0.5, 1.0]]).unwrap();
/// assert_eq!(unit.dim(), 3);
/// # let _ = (diag, dense);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct Metric {
    shape: Shape,
}

impl Metric {
    /// The unit metric on `R^d`.
    pub fn identity(d: usize) -> Self {
        Metric {
            shape: Shape::Diagonal {
                inv_mass: vec![1.0; d],
                momentum_scale: vec![1.0; d],
            },
        }
    }

    /// A diagonal metric with inverse masses (target variances) `inv_mass`.
    pub fn diagonal(inv_mass: Vec<f64>) -> Result<Self> {
        if inv_mass.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(invalid(
                "inv_mass",
                "every inverse mass must be finite and positive",
            ));
        }
        let momentum_scale = inv_mass.iter().map(|v| 1.0 / v.sqrt()).collect();
        Ok(Metric {
            shape: Shape::Diagonal {
                inv_mass,
                momentum_scale,
            },
        })
    }

    /// A dense metric with inverse mass matrix (target covariance) `rows`.
    pub fn dense(rows: &[Vec<f64>]) -> Result<Self> {
        let (lower, log_det_lower) = cholesky(rows)?;
        let inv_mass = rows.iter().flatten().copied().collect();
        Ok(Metric {
            shape: Shape::Dense {
                inv_mass,
                lower,
                log_det_lower,
            },
        })
    }

    /// Appends the metric for checkpoints: 1 when dense, then `M⁻¹`
    /// (its diagonal, or all of it row-major), bit for bit.
    pub(crate) fn words(&self, out: &mut Vec<u64>) {
        let (dense, inv_mass) = match &self.shape {
            Shape::Diagonal { inv_mass, .. } => (0, inv_mass),
            Shape::Dense { inv_mass, .. } => (1, inv_mass),
        };
        out.push(dense);
        crate::checkpoint::put_f64s(out, inv_mass);
    }

    /// The metric of dimension `d` [`Self::words`] wrote at the front of
    /// `input` (rebuilt by [`Self::diagonal`] or [`Self::dense`], which
    /// give the saved metric's bits and refuse a non-positive one).
    pub(crate) fn from_words(input: &mut &[u64], d: usize) -> Option<Metric> {
        use crate::checkpoint::{take_f64s, take_word};
        match take_word(input)? {
            0 => Metric::diagonal(take_f64s(input, d)?).ok(),
            1 => {
                let m = take_f64s(input, d * d)?;
                let rows: Vec<Vec<f64>> = m.chunks(d.max(1)).map(<[f64]>::to_vec).collect();
                Metric::dense(&rows).ok()
            }
            _ => None,
        }
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => inv_mass.len(),
            Shape::Dense { lower, .. } => (lower.len() as f64).sqrt().round() as usize,
        }
    }

    /// True for a dense metric.
    pub fn is_dense(&self) -> bool {
        matches!(self.shape, Shape::Dense { .. })
    }

    /// The diagonal of `M⁻¹`.
    pub fn inverse_mass_diagonal(&self) -> Vec<f64> {
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => inv_mass.clone(),
            Shape::Dense { inv_mass, .. } => {
                let d = self.dim();
                (0..d).map(|i| inv_mass[i * d + i]).collect()
            }
        }
    }

    /// `M⁻¹` as a dense row-major `d×d` matrix.
    pub fn inverse_mass_matrix(&self) -> Vec<f64> {
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => {
                let d = inv_mass.len();
                let mut m = vec![0.0; d * d];
                for i in 0..d {
                    m[i * d + i] = inv_mass[i];
                }
                m
            }
            Shape::Dense { inv_mass, .. } => inv_mass.clone(),
        }
    }

    /// `M⁻¹`'s diagonal when the metric is diagonal (for fused loops).
    #[inline]
    pub(crate) fn diagonal_inverse_mass(&self) -> Option<&[f64]> {
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => Some(inv_mass),
            Shape::Dense { .. } => None,
        }
    }

    /// Draws `p ~ N(0, M)` into `p`.
    pub(crate) fn sample_momentum(&self, rng: &mut ChainRng, p: &mut [f64]) {
        match &self.shape {
            Shape::Diagonal { momentum_scale, .. } => {
                for (pi, s) in p.iter_mut().zip(momentum_scale) {
                    *pi = s * standard_normal(rng);
                }
            }
            Shape::Dense { lower, .. } => {
                // M⁻¹ = L Lᵀ, so p = L⁻ᵀ z has covariance (L Lᵀ)⁻¹ = M.
                for pi in p.iter_mut() {
                    *pi = standard_normal(rng);
                }
                solve_upper_transposed_in_place(lower, p);
            }
        }
    }

    /// `v = M⁻¹ p`.
    #[inline]
    pub(crate) fn velocity(&self, p: &[f64], v: &mut [f64]) {
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => {
                for ((vi, pi), m) in v.iter_mut().zip(p).zip(inv_mass) {
                    *vi = m * pi;
                }
            }
            Shape::Dense { inv_mass, .. } => {
                let d = p.len();
                for i in 0..d {
                    let row = &inv_mass[i * d..(i + 1) * d];
                    v[i] = row.iter().zip(p).map(|(a, b)| a * b).sum();
                }
            }
        }
    }

    /// Kinetic energy `½ pᵀ M⁻¹ p`, using `v` as scratch.
    #[inline]
    pub(crate) fn kinetic(&self, p: &[f64], v: &mut [f64]) -> f64 {
        self.velocity(p, v);
        0.5 * p.iter().zip(v.iter()).map(|(a, b)| a * b).sum::<f64>()
    }

    /// `ln N(r; 0, M⁻¹)`.
    pub(crate) fn log_normal(&self, r: &[f64]) -> f64 {
        const LN_2PI: f64 = 1.837_877_066_409_345_5;
        match &self.shape {
            Shape::Diagonal { inv_mass, .. } => {
                let mut s = 0.0;
                for (ri, m) in r.iter().zip(inv_mass) {
                    s += ri * ri / m + m.ln();
                }
                -0.5 * (s + r.len() as f64 * LN_2PI)
            }
            Shape::Dense {
                lower,
                log_det_lower,
                ..
            } => {
                let mut scratch = Vec::with_capacity(r.len());
                log_normal_density(lower, *log_det_lower, r, &mut scratch)
            }
        }
    }
}

/// Solves `Lᵀ p = z` in place for row-major lower-triangular `L`.
fn solve_upper_transposed_in_place(l: &[f64], p: &mut [f64]) {
    let d = p.len();
    for i in (0..d).rev() {
        let mut s = p[i];
        for k in i + 1..d {
            s -= l[k * d + i] * p[k];
        }
        p[i] = s / l[i * d + i];
    }
}
