//! Multiple-try Metropolis (Liu, Liang & Wong 2000; spec seed000-ch5-6 App. 4.B).
//!
//! One step from `x` with `k` tries:
//! 1. draw `y_1..y_k ~ q(x → ·)`;
//! 2. pick `y = y_J` with probability `∝ ŵ(x → y_j)`;
//! 3. draw competitors `x*_1..x*_{k−1} ~ q(y → ·)` and set `x*_k = x`;
//! 4. accept `y` with `min(1, Σ_j ŵ(x → y_j) / Σ_j ŵ(y → x*_j))`,
//!
//! where `ŵ(x → y) = π(y) q(y → x) λ(x, y)` and `λ` is symmetric and positive
//! wherever `q(y → x) > 0`. All weights are combined by log-sum-exp. The
//! [`Lambda`] choices:
//!
//! | choice | `λ(x,y)` | `ŵ(x→y)` | needs |
//! |---|---|---|---|
//! | [`Lambda::One`] | 1 | `π(y) q(y→x)` | `q` densities |
//! | [`Lambda::InverseProposal`] | `1/q(x→y)` | `π(y)` | a symmetric kernel |
//! | [`Lambda::InverseProduct`] | `1/(q(x→y) q(y→x))` | `π(y)/q(x→y)` | `q` densities |
//!
//! `InverseProposal` is symmetric only when `q` is, which is why it demands a
//! symmetric kernel; it needs no density and is the cheapest. `InverseProduct`
//! gives importance weights. Liu et al. report the choice matters little.
//! The kernel may be asymmetric for `One` and `InverseProduct`.
//! Each step costs `2k − 1` target evaluations.

use crate::chain::{Algorithm, ChainState, StepInfo, Transition};
use crate::error::{CoreError, Result, invalid};
use crate::kernel::{Kernel, StepObservation};
use crate::math::{log_sum_exp, sample_log_categorical};
use crate::mh::accept;
use crate::rng::uniform;
use crate::sample::Sample;
use crate::stats::Outcome;
use crate::target::{DensityClass, Target};

/// The symmetric function `λ` of the multiple-try weights; see the
/// [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lambda {
    /// `λ = 1`: `ŵ(x→y) = π(y) q(y→x)`.
    One,
    /// `λ = 1/q(x→y)` for symmetric kernels: `ŵ(x→y) = π(y)`.
    InverseProposal,
    /// `λ = 1/(q(x→y) q(y→x))`: `ŵ(x→y) = π(y)/q(x→y)`.
    InverseProduct,
}

/// `ln ŵ(x → y)` from `ln π(y)`, `ln q(y→x)` and `ln q(x→y)` (the densities
/// a choice does not use may be anything). A proposal whose density is NaN
/// or `+∞` gets weight zero.
#[inline]
pub fn mtm_log_weight(lambda: Lambda, log_pi_y: f64, log_q_back: f64, log_q_forward: f64) -> f64 {
    if DensityClass::of(log_pi_y) == DensityClass::Invalid {
        return f64::NEG_INFINITY;
    }
    let w = match lambda {
        Lambda::One => log_pi_y + log_q_back,
        Lambda::InverseProposal => log_pi_y,
        Lambda::InverseProduct => log_pi_y - log_q_forward,
    };
    if w.is_nan() { f64::NEG_INFINITY } else { w }
}

/// `ln α = min(0, ln Σ ŵ(x→y_j) − ln Σ ŵ(y→x*_j))`.
pub fn mtm_log_acceptance(forward_log_weights: &[f64], backward_log_weights: &[f64]) -> f64 {
    let f = log_sum_exp(forward_log_weights);
    let b = log_sum_exp(backward_log_weights);
    if f == f64::NEG_INFINITY || f.is_nan() || b.is_nan() {
        return f64::NEG_INFINITY;
    }
    if b == f64::NEG_INFINITY {
        return 0.0;
    }
    (f - b).min(0.0)
}

/// Multiple-try Metropolis over any kernel.
pub struct MultipleTry<K, S, P = ()> {
    kernel: K,
    tries: usize,
    lambda: Lambda,
    proposals: Vec<Sample<S, P>>,
    competitors: Vec<Sample<S, P>>,
    forward: Vec<f64>,
    backward: Vec<f64>,
    /// Kernel component of each try, kept to avoid an allocation per step.
    try_components: Vec<usize>,
}

impl<K: Kernel<S, P>, S, P> MultipleTry<K, S, P> {
    /// `k = tries` proposals per step, weights by `lambda`.
    pub fn new(kernel: K, tries: usize, lambda: Lambda) -> Result<Self> {
        if tries == 0 {
            return Err(invalid("tries", "must be at least 1"));
        }
        if lambda == Lambda::InverseProposal && !kernel.is_symmetric() {
            return Err(CoreError::MissingProposalDensity(
                "multiple-try Metropolis with λ = 1/q (it requires a symmetric kernel; use Lambda::One or InverseProduct)",
            ));
        }
        Ok(MultipleTry {
            kernel,
            tries,
            lambda,
            proposals: Vec::new(),
            competitors: Vec::new(),
            forward: Vec::new(),
            backward: Vec::new(),
            try_components: Vec::new(),
        })
    }

    /// The kernel.
    pub fn kernel(&self) -> &K {
        &self.kernel
    }

    /// Number of tries `k`.
    pub fn tries(&self) -> usize {
        self.tries
    }

    /// `ln ŵ(from → to)`; `None` when a needed density is missing.
    fn weight(&self, from: &Sample<S, P>, to: &Sample<S, P>) -> Option<f64> {
        let (back, fwd) = match self.lambda {
            Lambda::One => (self.kernel.log_proposal_density(to, &from.state)?, 0.0),
            Lambda::InverseProposal => (0.0, 0.0),
            Lambda::InverseProduct => (0.0, self.kernel.log_proposal_density(from, &to.state)?),
        };
        Some(mtm_log_weight(self.lambda, to.log_density, back, fwd))
    }
}

impl<K, S, P> Algorithm<S, P> for MultipleTry<K, S, P>
where
    K: Kernel<S, P>,
    S: Clone,
    P: Clone,
{
    fn component_names(&self) -> Vec<String> {
        self.kernel.component_names()
    }

    fn step<T: Target<S, Payload = P>>(
        &mut self,
        chain: &mut ChainState<S, P>,
        target: &T,
        observer: &mut dyn FnMut(&Transition<'_, S, P>),
    ) -> StepInfo {
        let k = self.tries;
        if self.proposals.len() != k {
            self.proposals = vec![chain.current.clone(); k];
            self.competitors = vec![chain.current.clone(); k.saturating_sub(1)];
        }
        chain.stats.steps += 1;
        let fail = |chain: &mut ChainState<S, P>, component: usize| {
            chain.stats.failed += 1;
            chain.stats.record(component, 0.0, false);
            StepInfo {
                alpha: 0.0,
                outcome: Outcome::Failed,
                component,
            }
        };

        // 1. k proposals from x.
        self.try_components.clear();
        for j in 0..k {
            let p = self
                .kernel
                .propose(&chain.current, &mut self.proposals[j], &mut chain.rng);
            if p.failed {
                return fail(chain, p.component);
            }
            if !p.evaluated {
                self.proposals[j].reevaluate(target);
            }
            chain.stats.evaluations += 1;
            chain
                .stats
                .record_class(DensityClass::of(self.proposals[j].log_density));
            self.try_components.push(p.component);
        }
        self.forward.clear();
        for j in 0..k {
            match self.weight(&chain.current, &self.proposals[j]) {
                Some(w) => self.forward.push(w),
                None => return fail(chain, self.try_components[j]),
            }
        }

        // 2. Select y ∝ ŵ.
        let Some(sel) = sample_log_categorical(&self.forward, uniform(&mut chain.rng)) else {
            // Every try had zero weight: nothing can be accepted.
            observer(&Transition {
                current: &chain.current,
                proposal: Some(&self.proposals[0]),
                alpha: 0.0,
                accepted: false,
                component: self.try_components[0],
            });
            chain.stats.record(self.try_components[0], 0.0, false);
            return StepInfo {
                alpha: 0.0,
                outcome: Outcome::Rejected,
                component: self.try_components[0],
            };
        };
        let component = self.try_components[sel];

        // 3. k − 1 competitors from y, plus x itself.
        let y = &self.proposals[sel];
        for j in 0..k - 1 {
            let p = self
                .kernel
                .propose(y, &mut self.competitors[j], &mut chain.rng);
            if p.failed {
                return fail(chain, component);
            }
            if !p.evaluated {
                self.competitors[j].reevaluate(target);
            }
            chain.stats.evaluations += 1;
        }
        self.backward.clear();
        for j in 0..k - 1 {
            match self.weight(y, &self.competitors[j]) {
                Some(w) => self.backward.push(w),
                None => return fail(chain, component),
            }
        }
        match self.weight(y, &chain.current) {
            Some(w) => self.backward.push(w),
            None => return fail(chain, component),
        }

        // 4. Accept.
        let log_alpha = mtm_log_acceptance(&self.forward, &self.backward);
        let accepted = accept(log_alpha, &mut chain.rng);
        let alpha = log_alpha.exp();
        observer(&Transition {
            current: &chain.current,
            proposal: Some(y),
            alpha,
            accepted,
            component,
        });
        chain.stats.record(component, alpha, accepted);
        if accepted {
            chain.stats.accepted += 1;
            std::mem::swap(&mut chain.current, &mut self.proposals[sel]);
        }
        self.kernel.observe(&StepObservation {
            component,
            alpha,
            accepted,
            own: true,
            state: &chain.current.state,
        });
        StepInfo {
            alpha,
            outcome: if accepted {
                Outcome::Accepted
            } else {
                Outcome::Rejected
            },
            component,
        }
    }

    fn freeze(&mut self) {
        self.kernel.freeze();
    }
}
