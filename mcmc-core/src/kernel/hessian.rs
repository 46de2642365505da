//! Hessian-informed Gaussian proposals (H²MC style; Li et al. 2015, spec
//! seed000-ch5-6 App. 4.A.2, Eq. 4.20).
//!
//! Around `x` the target is modelled to second order,
//! `ln π(x + δ) ≈ ln π(x) + gᵀδ − ½ δᵀ A δ` with `g = ∇ln π(x)` and
//! `A = −∇²ln π(x)`. Hamiltonian dynamics with mass matrix `A` under this
//! model have an analytic solution: every direction oscillates with unit
//! frequency, and after time `θ` the position is a linear map of the
//! Gaussian momentum. The proposal is therefore Gaussian,
//!
//! `y ~ N(x + (1 − cos θ) A⁻¹ g, sin²θ A⁻¹)`,
//!
//! with `θ = τ·π/2`; `τ = 1` is the Newton proposal `N(x + A⁻¹g, A⁻¹)`
//! (an exact independence sampler on a Gaussian target). The MH ratio uses
//! the reverse density `q(y → x)` built from the model around `y`.
//!
//! **Indefinite Hessians** (documented rule): `A = Q diag(λ) Qᵀ` is replaced
//! by `Q diag(max(|λ_i|, c)) Qᵀ`, where the floor is
//! `c = max(min_curvature, 10⁻¹⁰ · max|λ|)`. Directions of negative
//! curvature keep their curvature magnitude as scale (as SoftAbs metrics
//! do); flat directions get variance at most `1/c`. The proposal stays a
//! proper Gaussian, so the MH correction remains exact.
//!
//! The Hessian comes from [`GradientTarget::hessian`] or, when the target
//! has none, from central differences of the gradient (`2d` gradient
//! evaluations, counted). The eigendecomposition costs `O(d³)` per proposal;
//! the kernel caches it for the current and the last proposed state, so a
//! step costs one decomposition.

use super::{GradientKernelStatistics, Kernel, Proposal};
use crate::error::{Result, invalid};
use crate::gradient::{
    GradientPayload, GradientTarget, check_dimension, evaluate_checked, hessian_from_gradient,
};
use crate::rng::{ChainRng, standard_normal};
use crate::sample::Sample;
use nalgebra::{DMatrix, SymmetricEigen};

const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The Gaussian proposal around one point.
#[derive(Clone, Debug)]
struct LocalGaussian {
    eigenvectors: DMatrix<f64>,
    // Standard deviations along the eigenvectors: sin θ / sqrt(a_i).
    scale: Vec<f64>,
    mean: Vec<f64>,
    log_norm: f64,
}

impl LocalGaussian {
    fn log_density(&self, y: &[f64]) -> f64 {
        let d = y.len();
        let mut q = 0.0;
        for j in 0..d {
            let mut w = 0.0;
            for i in 0..d {
                w += self.eigenvectors[(i, j)] * (y[i] - self.mean[i]);
            }
            let z = w / self.scale[j];
            q += z * z;
        }
        -0.5 * q + self.log_norm
    }
}

/// H²MC-style Hessian-informed Gaussian proposal; see the [module docs](self).
///
/// ```
/// use mcmc_core::prelude::*;
/// use mcmc_core::gradient::{Differentiable, FiniteDifference};
/// use mcmc_core::kernel::H2mc;
/// let g = FiniteDifference::new(|x: &[f64]| -0.5 * (x[0] * x[0] + 4.0 * x[1] * x[1]), 2);
/// let target = Differentiable(g);
/// let k = H2mc::new(g, 1.0).unwrap();
/// let mut chain = Chain::new(&target, vec![1.0, 1.0], MetropolisHastings::new(k), stream_rng(1, 0)).unwrap();
/// for _ in 0..20 { chain.step(&target); }
/// // On a Gaussian the Newton proposal is exact: everything is accepted.
/// assert!(chain.stats().acceptance_rate() > 0.9);
/// ```
#[derive(Clone, Debug)]
pub struct H2mc<G> {
    target: G,
    dim: usize,
    theta: f64,
    min_curvature: f64,
    // Remaining warm-up steps and the warm-up θ (see `with_warmup`).
    warmup: Option<(usize, f64)>,
    stats: GradientKernelStatistics,
    at_current: Option<(Vec<f64>, LocalGaussian)>,
    at_proposal: Option<(Vec<f64>, LocalGaussian)>,
    hessian: Vec<f64>,
}

impl<G: GradientTarget> H2mc<G> {
    /// A Hessian-informed proposal integrating for `θ = τ·π/2`, `τ ∈ (0, 1]`.
    pub fn new(target: G, tau: f64) -> Result<Self> {
        if !(tau > 0.0 && tau <= 1.0) {
            return Err(invalid("tau", format!("{tau} must lie in (0, 1]")));
        }
        check_dimension(&target)?;
        let dim = target.dim();
        Ok(H2mc {
            target,
            dim,
            theta: tau * std::f64::consts::FRAC_PI_2,
            min_curvature: 1e-8,
            warmup: None,
            stats: GradientKernelStatistics::default(),
            at_current: None,
            at_proposal: None,
            hessian: vec![0.0; dim * dim],
        })
    }

    /// The curvature floor `c` of the indefinite-Hessian rule (default 1e-8).
    pub fn with_min_curvature(mut self, c: f64) -> Result<Self> {
        if !(c.is_finite() && c > 0.0) {
            return Err(invalid("min_curvature", "must be finite and positive"));
        }
        self.min_curvature = c;
        Ok(self)
    }

    /// Uses `τ = warmup_tau` for the first `iterations` steps, then the
    /// constructor's τ. Far from the mode the local quadratic model is poor
    /// and long moves (τ near 1) are almost always rejected; short ones
    /// reach the bulk first. The switch happens after warm-up (or at
    /// [`Kernel::freeze`]), so sampling is an exact Markov chain.
    pub fn with_warmup(mut self, iterations: usize, warmup_tau: f64) -> Result<Self> {
        if !(warmup_tau > 0.0 && warmup_tau <= 1.0) {
            return Err(invalid(
                "warmup_tau",
                format!("{warmup_tau} must lie in (0, 1]"),
            ));
        }
        if iterations > 0 {
            self.warmup = Some((iterations, warmup_tau * std::f64::consts::FRAC_PI_2));
        }
        Ok(self)
    }

    /// The θ in use now.
    fn current_theta(&self) -> f64 {
        self.warmup.map_or(self.theta, |(_, t)| t)
    }

    fn end_warmup(&mut self) {
        if self.warmup.take().is_some() {
            // Cached proposals were built with the warm-up θ.
            self.at_current = None;
            self.at_proposal = None;
        }
    }

    /// Gradient evaluations, invalid and outside-support proposals.
    pub fn statistics(&self) -> &GradientKernelStatistics {
        &self.stats
    }

    /// The local Gaussian at `x` with gradient `g`; `None` if the Hessian is
    /// not finite.
    fn local(&self, x: &[f64], g: &[f64], hessian: &mut [f64]) -> (Option<LocalGaussian>, u64) {
        let d = self.dim;
        let mut evaluations = 0;
        if !self.target.hessian(x, hessian) {
            evaluations = 2 * d as u64;
            if !hessian_from_gradient(&self.target, x, hessian) {
                return (None, evaluations);
            }
        }
        if !hessian.iter().all(|v| v.is_finite()) || !g.iter().all(|v| v.is_finite()) {
            return (None, evaluations);
        }
        let a = DMatrix::from_fn(d, d, |i, j| {
            -0.5 * (hessian[i * d + j] + hessian[j * d + i])
        });
        let eig = SymmetricEigen::new(a);
        let max_abs = eig.eigenvalues.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let floor = self.min_curvature.max(1e-10 * max_abs);
        let curv: Vec<f64> = eig.eigenvalues.iter().map(|l| l.abs().max(floor)).collect();
        let (s, c) = self.current_theta().sin_cos();
        let q = eig.eigenvectors;
        // mean = x + (1 − cos θ) Q diag(1/a) Qᵀ g
        let mut mean = x.to_vec();
        for j in 0..d {
            let mut w = 0.0;
            for i in 0..d {
                w += q[(i, j)] * g[i];
            }
            let w = (1.0 - c) * w / curv[j];
            for i in 0..d {
                mean[i] += q[(i, j)] * w;
            }
        }
        let scale: Vec<f64> = curv.iter().map(|a| s / a.sqrt()).collect();
        let log_norm = -scale.iter().map(|v| v.ln()).sum::<f64>() - 0.5 * d as f64 * LN_2PI;
        if !(log_norm.is_finite() && mean.iter().all(|v| v.is_finite())) {
            return (None, evaluations);
        }
        (
            Some(LocalGaussian {
                eigenvectors: q,
                scale,
                mean,
                log_norm,
            }),
            evaluations,
        )
    }
}

impl<G: GradientTarget> Kernel<Vec<f64>, GradientPayload> for H2mc<G> {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, GradientPayload>,
        proposal: &mut Sample<Vec<f64>, GradientPayload>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let d = self.dim;
        if current.state.len() != d || current.payload.gradient.len() != d {
            return Proposal::failed(0);
        }
        self.stats.trajectories += 1;
        // The decomposition at x: cached from the last step when possible.
        if self
            .at_current
            .as_ref()
            .is_none_or(|(s, _)| *s != current.state)
        {
            if self
                .at_proposal
                .as_ref()
                .is_some_and(|(s, _)| *s == current.state)
            {
                self.at_current = self.at_proposal.take();
            } else {
                let mut h = std::mem::take(&mut self.hessian);
                let (local, evals) = self.local(&current.state, &current.payload.gradient, &mut h);
                self.hessian = h;
                self.stats.gradient_evaluations += evals;
                match local {
                    Some(l) => self.at_current = Some((current.state.clone(), l)),
                    None => {
                        self.stats.invalid += 1;
                        return Proposal::failed(0);
                    }
                }
            }
        }
        let Some((_, fwd)) = &self.at_current else {
            return Proposal::failed(0);
        };
        // y = mean + Q diag(scale) z
        proposal.state.clear();
        proposal.state.extend_from_slice(&fwd.mean);
        for j in 0..d {
            let z = fwd.scale[j] * standard_normal(rng);
            for i in 0..d {
                proposal.state[i] += fwd.eigenvectors[(i, j)] * z;
            }
        }
        let log_q_forward = fwd.log_density(&proposal.state);
        proposal.payload.gradient.resize(d, 0.0);
        let lp = if proposal.state.iter().all(|v| v.is_finite()) {
            evaluate_checked(
                &self.target,
                &proposal.state,
                &mut proposal.payload.gradient,
            )
        } else {
            f64::NAN
        };
        self.stats.gradient_evaluations += 1;
        proposal.log_density = lp;
        let mut result = Proposal {
            log_q_ratio: 0.0,
            component: 0,
            evaluated: true,
            failed: false,
        };
        if lp == f64::NEG_INFINITY {
            self.stats.outside_support += 1;
            return result;
        }
        if !lp.is_finite() {
            self.stats.invalid += 1;
            proposal.log_density = f64::NAN;
            return result;
        }
        let mut h = std::mem::take(&mut self.hessian);
        let (back, evals) = self.local(&proposal.state, &proposal.payload.gradient, &mut h);
        self.hessian = h;
        self.stats.gradient_evaluations += evals;
        match back {
            Some(back) => {
                result.log_q_ratio = back.log_density(&current.state) - log_q_forward;
                self.at_proposal = Some((proposal.state.clone(), back));
            }
            None => {
                // No reverse density: the move cannot be corrected.
                self.stats.invalid += 1;
                proposal.log_density = f64::NAN;
            }
        }
        result
    }

    fn log_proposal_density(
        &self,
        from: &Sample<Vec<f64>, GradientPayload>,
        to: &Vec<f64>,
    ) -> Option<f64> {
        if from.state.len() != self.dim || from.payload.gradient.len() != self.dim {
            return None;
        }
        let mut h = vec![0.0; self.dim * self.dim];
        let (local, _) = self.local(&from.state, &from.payload.gradient, &mut h);
        local.map(|l| l.log_density(to))
    }

    fn observe(&mut self, observation: &super::StepObservation<'_, Vec<f64>>) {
        if !observation.own {
            return;
        }
        if let Some((left, _)) = &mut self.warmup {
            *left -= 1;
            if *left == 0 {
                self.end_warmup();
            }
        }
    }

    fn freeze(&mut self) {
        self.end_warmup();
    }

    fn component_names(&self) -> Vec<String> {
        vec!["h2mc".to_string()]
    }

    fn check_state(&self, state: &Vec<f64>) -> Result<()> {
        crate::gradient::check_state_dimension(self.dim, state)
    }
}
