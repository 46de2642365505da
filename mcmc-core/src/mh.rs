//! Metropolis–Hastings.

use crate::chain::{Algorithm, ChainState, StepInfo, Transition};
use crate::kernel::{Kernel, StepObservation};
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;
use crate::stats::Outcome;
use crate::target::{DensityClass, Target};

/// `ln α` of a Metropolis–Hastings move from `x` to `y`:
/// `min(0, ln π(y) − ln π(x) + ln q(y→x) − ln q(x→y))`, with the rules
///
/// - `ln π(y)` NaN or `+∞`, or a NaN ratio: the proposal is invalid, `ln α = −∞`;
/// - `ln π(y) = −∞`: `ln α = −∞`;
/// - `ln π(x) = −∞` (a zero-density current state): `ln α = 0`, any valid
///   proposal is accepted (thesis Eq. 3.2);
/// - differences that overflow saturate to the right end.
///
/// Returns `ln α` and the class of the proposal's density.
#[inline]
pub fn mh_log_acceptance(log_pi_x: f64, log_pi_y: f64, log_q_ratio: f64) -> (f64, DensityClass) {
    // The common case first: three finite numbers, where every rule below
    // ends in the same clipped difference (one test instead of six).
    if log_pi_x.is_finite() && log_pi_y.is_finite() && log_q_ratio.is_finite() {
        let d = (log_pi_y - log_pi_x) + log_q_ratio;
        return (if d >= 0.0 { 0.0 } else { d }, DensityClass::Finite);
    }
    let class = DensityClass::of(log_pi_y);
    match class {
        DensityClass::Invalid => return (f64::NEG_INFINITY, class),
        DensityClass::Zero => return (f64::NEG_INFINITY, class),
        DensityClass::Finite => {}
    }
    if log_q_ratio.is_nan() {
        return (f64::NEG_INFINITY, DensityClass::Invalid);
    }
    if log_pi_x == f64::NEG_INFINITY {
        return (0.0, class);
    }
    if log_q_ratio == f64::NEG_INFINITY {
        return (f64::NEG_INFINITY, class);
    }
    if log_q_ratio == f64::INFINITY {
        return (0.0, class);
    }
    let d = (log_pi_y - log_pi_x) + log_q_ratio;
    (if d >= 0.0 { 0.0 } else { d }, class)
}

/// Accepts with probability `exp(log_alpha)`, testing `ln U < ln α` (no
/// `exp` of an unbounded difference).
#[inline]
pub fn accept(log_alpha: f64, rng: &mut ChainRng) -> bool {
    if log_alpha >= 0.0 {
        true
    } else if log_alpha == f64::NEG_INFINITY {
        false
    } else {
        uniform(rng).ln() < log_alpha
    }
}

/// The acceptance probability `α = e^{ln α}` and the decision, with the
/// same outcomes as [`accept`] (and the same uniform drawn, only when
/// `−∞ < ln α < 0`) but testing `U < α`: the step needs `α` for its
/// statistics anyway, so this saves a logarithm per step (and the `exp`
/// when the move is certain).
#[inline]
pub fn accept_probability(log_alpha: f64, rng: &mut ChainRng) -> (f64, bool) {
    if log_alpha >= 0.0 {
        (1.0, true)
    } else if log_alpha == f64::NEG_INFINITY {
        (0.0, false)
    } else {
        let alpha = log_alpha.exp();
        (alpha, uniform(rng) < alpha)
    }
}

/// Metropolis–Hastings with one kernel (use [`crate::kernel::Mixture`] to
/// combine several).
#[derive(Clone, Debug)]
pub struct MetropolisHastings<K, S, P = ()> {
    kernel: K,
    scratch: Option<Sample<S, P>>,
}

impl<K, S, P> MetropolisHastings<K, S, P> {
    /// Metropolis–Hastings with `kernel`.
    pub fn new(kernel: K) -> Self {
        MetropolisHastings {
            kernel,
            scratch: None,
        }
    }

    /// The kernel.
    pub fn kernel(&self) -> &K {
        &self.kernel
    }

    /// The kernel, mutably.
    pub fn kernel_mut(&mut self) -> &mut K {
        &mut self.kernel
    }
}

impl<K, S, P> Algorithm<S, P> for MetropolisHastings<K, S, P>
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

    #[inline]
    fn step<T: Target<S, Payload = P>>(
        &mut self,
        chain: &mut ChainState<S, P>,
        target: &T,
        observer: &mut dyn FnMut(&Transition<'_, S, P>),
    ) -> StepInfo {
        let scratch = self.scratch.get_or_insert_with(|| chain.current.clone());
        let proposal = self.kernel.propose(&chain.current, scratch, &mut chain.rng);
        chain.stats.steps += 1;
        // `outcome` is what the step ends as if the proposal is not accepted.
        let (log_alpha, outcome) = if proposal.failed {
            chain.stats.failed += 1;
            (f64::NEG_INFINITY, Outcome::Failed)
        } else {
            if !proposal.evaluated {
                scratch.reevaluate(target);
            }
            chain.stats.evaluations += 1;
            let (log_alpha, class) = mh_log_acceptance(
                chain.current.log_density,
                scratch.log_density,
                proposal.log_q_ratio,
            );
            chain.stats.record_class(class);
            let outcome = match class {
                DensityClass::Invalid => Outcome::InvalidDensity,
                DensityClass::Zero => Outcome::OutsideSupport,
                DensityClass::Finite => Outcome::Rejected,
            };
            (log_alpha, outcome)
        };
        let (alpha, accepted) = accept_probability(log_alpha, &mut chain.rng);
        observer(&Transition {
            current: &chain.current,
            proposal: (!proposal.failed).then_some(&*scratch),
            alpha,
            accepted,
            component: proposal.component,
        });
        chain.stats.record(proposal.component, alpha, accepted);
        if accepted {
            chain.stats.accepted += 1;
            std::mem::swap(&mut chain.current, scratch);
        }
        self.kernel.observe(&StepObservation {
            component: proposal.component,
            alpha,
            accepted,
            own: true,
            state: &chain.current.state,
        });
        StepInfo {
            alpha,
            outcome: if accepted { Outcome::Accepted } else { outcome },
            component: proposal.component,
        }
    }

    fn freeze(&mut self) {
        self.kernel.freeze();
    }
}
