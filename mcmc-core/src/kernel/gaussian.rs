use super::{Kernel, Proposal};
use crate::error::{Result, invalid};
use crate::linalg::{add_lower_times, cholesky, log_normal_density};
use crate::rng::{ChainRng, standard_normal};
use crate::sample::Sample;

#[derive(Clone, Debug)]
enum Shape {
    Isotropic(f64),
    Diagonal(Vec<f64>),
    Full { lower: Vec<f64>, log_det: f64 },
}

/// Gaussian random walk on `R^d`: `y = x + L z`, `z ~ N(0, I)`. Symmetric.
///
/// ```
/// use mcmc_core::kernel::GaussianRandomWalk;
/// let isotropic = GaussianRandomWalk::isotropic(0.5).unwrap();
/// let full = GaussianRandomWalk::with_covariance(&[vec![1.0, 0.5], vec![0.5, 2.0]]).unwrap();
/// # let _ = (isotropic, full);
/// ```
#[derive(Clone, Debug)]
pub struct GaussianRandomWalk {
    shape: Shape,
    z: Vec<f64>,
}

impl GaussianRandomWalk {
    /// Independent `N(0, σ²)` steps in every coordinate.
    pub fn isotropic(sigma: f64) -> Result<Self> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(invalid(
                "sigma",
                format!("{sigma} must be finite and positive"),
            ));
        }
        Ok(GaussianRandomWalk {
            shape: Shape::Isotropic(sigma),
            z: Vec::new(),
        })
    }

    /// Independent `N(0, σ_i²)` steps per coordinate.
    pub fn diagonal(sigmas: Vec<f64>) -> Result<Self> {
        if sigmas.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(invalid("sigmas", "every scale must be finite and positive"));
        }
        Ok(GaussianRandomWalk {
            shape: Shape::Diagonal(sigmas),
            z: Vec::new(),
        })
    }

    /// Steps `N(0, Σ)` with a full covariance given as rows.
    pub fn with_covariance(covariance: &[Vec<f64>]) -> Result<Self> {
        let (lower, log_det) = cholesky(covariance)?;
        Ok(GaussianRandomWalk {
            shape: Shape::Full { lower, log_det },
            z: Vec::new(),
        })
    }

    /// Multiplies every step by `factor` (the covariance by `factor²`),
    /// e.g. after a tempering ladder moved the kernel's level; a factor
    /// that is not finite and positive leaves the kernel unchanged.
    pub fn scale(&mut self, factor: f64) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        match &mut self.shape {
            Shape::Isotropic(s) => *s *= factor,
            Shape::Diagonal(s) => s.iter_mut().for_each(|v| *v *= factor),
            Shape::Full { lower, log_det } => {
                lower.iter_mut().for_each(|v| *v *= factor);
                // log_det is ln|L|, L d×d lower triangular.
                *log_det += (lower.len().isqrt() as f64) * factor.ln();
            }
        }
    }

    /// The dimension the kernel was built for (`None` for an isotropic
    /// walk, which moves any dimension).
    pub fn dim(&self) -> Option<usize> {
        match &self.shape {
            Shape::Isotropic(_) => None,
            Shape::Diagonal(s) => Some(s.len()),
            Shape::Full { lower, .. } => Some(lower.len().isqrt()),
        }
    }

    /// Writes `current + step` into `out`.
    #[inline(always)]
    pub(crate) fn step_into(&mut self, current: &[f64], out: &mut Vec<f64>, rng: &mut ChainRng) {
        // One pass that copies and perturbs, into a buffer that already
        // has the right length after the first step (no memcpy call and no
        // capacity check: in 1-d those cost more than the arithmetic).
        out.resize(current.len(), 0.0);
        // The normals are drawn through a local copy of the generator (the
        // same words in the same order, so the same bits): through `rng`
        // the compiler must store its state after every draw, as `out`
        // might alias it (the uniform walk's note, `uniform.rs`).
        match &self.shape {
            Shape::Isotropic(s) => {
                let mut words = rng.clone();
                for (o, c) in out.iter_mut().zip(current) {
                    *o = c + s * standard_normal(&mut words);
                }
                *rng = words;
            }
            Shape::Diagonal(s) => {
                let mut words = rng.clone();
                for ((o, c), s) in out.iter_mut().zip(current).zip(s) {
                    *o = c + s * standard_normal(&mut words);
                }
                *rng = words;
            }
            Shape::Full { lower, .. } => full_step_into(lower, &mut self.z, current, out, rng),
        }
    }

    /// `ln q(from → to)`.
    pub(crate) fn log_density(&self, from: &[f64], to: &[f64]) -> f64 {
        const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_7;
        match &self.shape {
            Shape::Isotropic(s) => from
                .iter()
                .zip(to)
                .map(|(a, b)| {
                    let z = (b - a) / s;
                    -0.5 * z * z - s.ln() - LN_SQRT_2PI
                })
                .sum(),
            Shape::Diagonal(s) => from
                .iter()
                .zip(to)
                .zip(s)
                .map(|((a, b), s)| {
                    let z = (b - a) / s;
                    -0.5 * z * z - s.ln() - LN_SQRT_2PI
                })
                .sum(),
            Shape::Full { lower, log_det } => {
                let diff: Vec<f64> = to.iter().zip(from).map(|(b, a)| b - a).collect();
                log_normal_density(lower, *log_det, &diff, &mut Vec::new())
            }
        }
    }
}

/// `out = current + L z` for the full shape; out of line, so that
/// [`GaussianRandomWalk::step_into`] stays small enough to be inlined
/// into the step for the isotropic and diagonal shapes (it was not, in a
/// build without link-time optimisation).
fn full_step_into(
    lower: &[f64],
    z: &mut Vec<f64>,
    current: &[f64],
    out: &mut [f64],
    rng: &mut ChainRng,
) {
    out.copy_from_slice(current);
    z.clear();
    z.extend((0..current.len()).map(|_| standard_normal(rng)));
    add_lower_times(lower, z, out);
}

impl<P> Kernel<Vec<f64>, P> for GaussianRandomWalk {
    // Always inlined: left to LLVM (test profile, no LTO) the step kept it
    // as an out-of-line call; inlined, its register saves and restores go
    // and the step's loads and stores around it simplify: 292 → 253
    // instructions per 1-d MH step (callgrind, `docs/performance.md`).
    // The arithmetic is unchanged, so are the bits (step checksums equal).
    #[inline(always)]
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, P>,
        proposal: &mut Sample<Vec<f64>, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.step_into(&current.state, &mut proposal.state, rng);
        Proposal::symmetric(0)
    }

    fn log_proposal_density(&self, from: &Sample<Vec<f64>, P>, to: &Vec<f64>) -> Option<f64> {
        Some(self.log_density(&from.state, to))
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn component_names(&self) -> Vec<String> {
        vec!["gaussian random walk".into()]
    }

    fn check_state(&self, state: &Vec<f64>) -> Result<()> {
        match self.dim() {
            Some(d) => crate::gradient::check_state_dimension(d, state),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scaling by `f` is the walk of covariance `f²Σ`, for every shape
    /// (the full shape's cached `ln|L|` included).
    #[test]
    fn scaling_equals_building_with_the_scaled_covariance() {
        let f: f64 = 1.7;
        let cov = [vec![1.0, 0.5], vec![0.5, 2.0]];
        let scaled: Vec<Vec<f64>> = cov
            .iter()
            .map(|r| r.iter().map(|v| v * f * f).collect())
            .collect();
        let pairs = [
            (
                GaussianRandomWalk::with_covariance(&cov).unwrap(),
                GaussianRandomWalk::with_covariance(&scaled).unwrap(),
            ),
            (
                GaussianRandomWalk::diagonal(vec![0.3, 2.0]).unwrap(),
                GaussianRandomWalk::diagonal(vec![0.3 * f, 2.0 * f]).unwrap(),
            ),
            (
                GaussianRandomWalk::isotropic(0.3).unwrap(),
                GaussianRandomWalk::isotropic(0.3 * f).unwrap(),
            ),
        ];
        for (mut a, b) in pairs {
            a.scale(f);
            let (x, y) = ([0.1, -0.2], [0.9, 1.4]);
            let (da, db) = (a.log_density(&x, &y), b.log_density(&x, &y));
            assert!((da - db).abs() < 1e-12, "{da} vs {db}");
        }
    }
}
