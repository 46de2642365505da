use super::{Kernel, Proposal, StepObservation};
use crate::error::{Result, invalid};
use crate::linalg::{add_lower_times, cholesky, log_normal_density};
use crate::rng::{ChainRng, standard_normal, uniform};
use crate::sample::Sample;

/// Adaptive Metropolis (Haario, Saksman & Tamminen 2001) in the safe form of
/// Roberts & Rosenthal (2009):
///
/// `y ~ (1−β)·N(x, (2.38²/d)·Σ_n) + β·N(x, σ₀²·I)`
///
/// where `Σ_n` is the empirical covariance of the chain's history, updated
/// recursively (weights `1/n`, so the adaptation diminishes) and
/// re-factorised every `refactor_every` steps. Until `warm_up` states have
/// been observed only the fixed component is used. Both components are
/// symmetric, so the kernel is. [`Kernel::freeze`] stops the adaptation.
#[derive(Clone, Debug)]
pub struct AdaptiveCovariance {
    dim: usize,
    sigma0: f64,
    beta: f64,
    warm_up: u64,
    refactor_every: u64,
    n: u64,
    mean: Vec<f64>,
    /// Running sum of outer products of deviations (Welford), row-major.
    scatter: Vec<f64>,
    lower: Option<(Vec<f64>, f64)>,
    frozen: bool,
    z: Vec<f64>,
}

impl AdaptiveCovariance {
    /// A kernel for `R^dim` whose fixed component has scale `sigma0`.
    pub fn new(dim: usize, sigma0: f64) -> Result<Self> {
        if dim == 0 {
            return Err(invalid("dim", "must be at least 1"));
        }
        if !(sigma0.is_finite() && sigma0 > 0.0) {
            return Err(invalid(
                "sigma0",
                format!("{sigma0} must be finite and positive"),
            ));
        }
        Ok(AdaptiveCovariance {
            dim,
            sigma0,
            beta: 0.05,
            warm_up: (2 * dim as u64).max(100),
            refactor_every: (dim as u64).max(10),
            n: 0,
            mean: vec![0.0; dim],
            scatter: vec![0.0; dim * dim],
            lower: None,
            frozen: false,
            z: Vec::with_capacity(dim),
        })
    }

    /// Sets the weight `β` of the fixed safety component (default 0.05).
    pub fn with_safety_weight(mut self, beta: f64) -> Result<Self> {
        if !(beta > 0.0 && beta < 1.0) {
            return Err(invalid("beta", "must lie in (0, 1)"));
        }
        self.beta = beta;
        Ok(self)
    }

    /// The current adapted covariance `(2.38²/d)·Σ_n`, if adaptation started.
    pub fn proposal_covariance(&self) -> Option<Vec<Vec<f64>>> {
        self.lower.as_ref()?;
        let d = self.dim;
        let c = 2.38 * 2.38 / d as f64 / (self.n.max(2) - 1) as f64;
        Some(
            (0..d)
                .map(|i| (0..d).map(|j| c * self.scatter[i * d + j]).collect())
                .collect(),
        )
    }

    fn refactor(&mut self) {
        let d = self.dim;
        let c = 2.38 * 2.38 / d as f64 / (self.n - 1) as f64;
        // A tiny ridge keeps the factor defined for degenerate histories.
        let rows: Vec<Vec<f64>> = (0..d)
            .map(|i| {
                (0..d)
                    .map(|j| {
                        c * self.scatter[i * d + j]
                            + if i == j {
                                1e-12 * self.sigma0 * self.sigma0
                            } else {
                                0.0
                            }
                    })
                    .collect()
            })
            .collect();
        if let Ok(f) = cholesky(&rows) {
            self.lower = Some(f);
        }
    }
}

impl<P> Kernel<Vec<f64>, P> for AdaptiveCovariance {
    fn propose(
        &mut self,
        current: &Sample<Vec<f64>, P>,
        proposal: &mut Sample<Vec<f64>, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let out = &mut proposal.state;
        out.clear();
        out.extend_from_slice(&current.state);
        match &self.lower {
            Some((lower, _)) if uniform(rng) >= self.beta => {
                self.z.clear();
                self.z.extend((0..self.dim).map(|_| standard_normal(rng)));
                add_lower_times(lower, &self.z, out);
                Proposal::symmetric(0)
            }
            _ => {
                for o in out.iter_mut() {
                    *o += self.sigma0 * standard_normal(rng);
                }
                Proposal::symmetric(1)
            }
        }
    }

    fn log_proposal_density(&self, from: &Sample<Vec<f64>, P>, to: &Vec<f64>) -> Option<f64> {
        const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_7;
        let diff: Vec<f64> = to.iter().zip(&from.state).map(|(b, a)| b - a).collect();
        let fixed: f64 = diff
            .iter()
            .map(|v| {
                let z = v / self.sigma0;
                -0.5 * z * z - self.sigma0.ln() - LN_SQRT_2PI
            })
            .sum();
        Some(match &self.lower {
            None => fixed,
            Some((lower, log_det)) => {
                let adapted = log_normal_density(lower, *log_det, &diff, &mut Vec::new());
                crate::math::log_sum_exp2((1.0 - self.beta).ln() + adapted, self.beta.ln() + fixed)
            }
        })
    }

    fn is_symmetric(&self) -> bool {
        true
    }

    fn observe(&mut self, obs: &StepObservation<'_, Vec<f64>>) {
        if self.frozen || obs.state.len() != self.dim {
            return;
        }
        self.n += 1;
        let d = self.dim;
        let inv_n = 1.0 / self.n as f64;
        // Welford: delta before and after the mean update.
        self.z.clear();
        self.z
            .extend(obs.state.iter().zip(&self.mean).map(|(x, m)| x - m));
        for (m, dx) in self.mean.iter_mut().zip(&self.z) {
            *m += dx * inv_n;
        }
        for i in 0..d {
            let after_i = obs.state[i] - self.mean[i];
            for j in 0..d {
                self.scatter[i * d + j] += self.z[j] * after_i;
            }
        }
        if self.n >= self.warm_up && self.n.is_multiple_of(self.refactor_every) {
            self.refactor();
        }
    }

    fn freeze(&mut self) {
        self.frozen = true;
    }

    fn component_names(&self) -> Vec<String> {
        vec!["adaptive covariance".into(), "fixed safety step".into()]
    }

    fn check_state(&self, state: &Vec<f64>) -> Result<()> {
        crate::gradient::check_state_dimension(self.dim, state)
    }
}
