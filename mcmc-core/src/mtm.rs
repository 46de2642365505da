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

/// One multiple-try weight `ŵ = π(y)·exp(log_q_term)`, kept as its two
/// parts: sums of weights are formed relative to the largest `ln π` in the
/// sum, so that with `ln π ≈ 1e300` the proposal-density terms are not
/// rounded away.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TryWeight {
    /// `ln π(y)` (`−∞` for zero or invalid densities).
    pub log_pi: f64,
    /// The `ln q` part of `ln ŵ` under the chosen [`Lambda`].
    pub log_q_term: f64,
}

/// The weight `ŵ(x → y)` from `ln π(y)`, `ln q(y→x)` and `ln q(x→y)` (the
/// densities a choice does not use may be anything). A proposal whose
/// density is NaN or `+∞` gets weight zero.
#[inline]
pub fn mtm_weight(lambda: Lambda, log_pi_y: f64, log_q_back: f64, log_q_forward: f64) -> TryWeight {
    let zero = TryWeight {
        log_pi: f64::NEG_INFINITY,
        log_q_term: 0.0,
    };
    if DensityClass::of(log_pi_y) != DensityClass::Finite {
        return zero;
    }
    let log_q_term = match lambda {
        Lambda::One => log_q_back,
        Lambda::InverseProposal => 0.0,
        Lambda::InverseProduct => -log_q_forward,
    };
    if log_q_term.is_nan() || log_q_term == f64::NEG_INFINITY {
        return zero;
    }
    TryWeight {
        log_pi: log_pi_y,
        log_q_term,
    }
}

/// `(r, s)` with `ln Σ ŵ_j = r + s`: `r` is the largest `ln π` of the sum.
fn log_weight_sum(weights: &[TryWeight]) -> (f64, f64) {
    let r = weights
        .iter()
        .map(|w| w.log_pi)
        .fold(f64::NEG_INFINITY, f64::max);
    if r == f64::NEG_INFINITY {
        return (r, f64::NEG_INFINITY);
    }
    let terms: Vec<f64> = weights
        .iter()
        .map(|w| (w.log_pi - r) + w.log_q_term)
        .collect();
    (r, log_sum_exp(&terms))
}

/// Selection log-weights of the tries, shifted by a common constant (the
/// largest `ln π`), for [`sample_log_categorical`].
pub fn mtm_selection_log_weights(weights: &[TryWeight]) -> Vec<f64> {
    let r = weights
        .iter()
        .map(|w| w.log_pi)
        .fold(f64::NEG_INFINITY, f64::max);
    weights
        .iter()
        .map(|w| {
            if w.log_pi == f64::NEG_INFINITY {
                f64::NEG_INFINITY
            } else {
                (w.log_pi - r) + w.log_q_term
            }
        })
        .collect()
}

/// `ln α = min(0, ln Σ ŵ(x→y_j) − ln Σ ŵ(y→x*_j))`.
pub fn mtm_log_acceptance(forward: &[TryWeight], backward: &[TryWeight]) -> f64 {
    let (rf, sf) = log_weight_sum(forward);
    let (rb, sb) = log_weight_sum(backward);
    if sf == f64::NEG_INFINITY || sf.is_nan() || sb.is_nan() {
        return f64::NEG_INFINITY;
    }
    if sb == f64::NEG_INFINITY {
        return 0.0;
    }
    let d = (rf - rb) + (sf - sb);
    if d.is_nan() {
        f64::NEG_INFINITY
    } else {
        d.min(0.0)
    }
}

/// Multiple-try Metropolis over any kernel.
#[derive(Clone)]
pub struct MultipleTry<K, S, P = ()> {
    kernel: K,
    tries: usize,
    lambda: Lambda,
    proposals: Vec<Sample<S, P>>,
    competitors: Vec<Sample<S, P>>,
    forward: Vec<TryWeight>,
    backward: Vec<TryWeight>,
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

    /// `ŵ(from → to)`; `None` when a needed density is missing.
    fn weight(&self, from: &Sample<S, P>, to: &Sample<S, P>) -> Option<TryWeight> {
        let (back, fwd) = match self.lambda {
            Lambda::One => (self.kernel.log_proposal_density(to, &from.state)?, 0.0),
            Lambda::InverseProposal => (0.0, 0.0),
            Lambda::InverseProduct => (0.0, self.kernel.log_proposal_density(from, &to.state)?),
        };
        Some(mtm_weight(self.lambda, to.log_density, back, fwd))
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

    fn check_initial(&self, state: &S) -> crate::Result<()> {
        self.kernel.check_state(state)
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
        let selection = mtm_selection_log_weights(&self.forward);
        let Some(sel) = sample_log_categorical(&selection, uniform(&mut chain.rng)) else {
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
