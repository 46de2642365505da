//! Two-stage delayed rejection (Tierney & Mira 1999; spec seed000-ch1-4 §4.9).
//!
//! After a first-stage proposal `y₁ ~ q₁(x → ·)` is rejected, a second
//! proposal `y₂ ~ q₂(x → ·)` is tried and accepted with
//!
//! `α₂ = min(1, π(y₂) q₁(y₂→y₁) q₂(y₂→x) [1 − α₁(y₂→y₁)] /
//!             (π(x) q₁(x→y₁) q₂(x→y₂) [1 − α₁(x→y₁)]))`,
//!
//! which keeps detailed balance. The second kernel here does not depend on
//! `y₁` (the common form: e.g. a smaller random-walk step); the first kernel
//! must provide its proposal density. Everything is in log space, with
//! `ln(1 − α)` by [`crate::math::log1m_exp`].

use crate::chain::{Algorithm, ChainState, StepInfo, Transition};
use crate::kernel::{Kernel, StepObservation};
use crate::math::log1m_exp;
use crate::mh::{accept, mh_log_acceptance};
use crate::sample::Sample;
use crate::stats::Outcome;
use crate::target::{DensityClass, Target};

/// `ln α₂` of the second stage. Arguments: `ln π` at `x`, `y₁`, `y₂`; the
/// first kernel's `ln q₁(x→y₁)`, `ln q₁(y₂→y₁)`, `ln q₁(y₁→y₂)`,
/// `ln q₁(y₁→x)`; and the second kernel's `ln q₂(y₂→x) − ln q₂(x→y₂)`.
#[allow(clippy::too_many_arguments)]
pub fn dr_log_acceptance(
    log_pi_x: f64,
    log_pi_y1: f64,
    log_pi_y2: f64,
    log_q1_x_y1: f64,
    log_q1_y2_y1: f64,
    log_q1_y1_y2: f64,
    log_q1_y1_x: f64,
    log_q2_ratio: f64,
) -> f64 {
    if DensityClass::of(log_pi_y2) != DensityClass::Finite || log_q2_ratio.is_nan() {
        return f64::NEG_INFINITY;
    }
    let (log_a1_forward, _) = mh_log_acceptance(log_pi_x, log_pi_y1, log_q1_y1_x - log_q1_x_y1);
    let (log_a1_reverse, _) = mh_log_acceptance(log_pi_y2, log_pi_y1, log_q1_y1_y2 - log_q1_y2_y1);
    let reverse_rejection = log1m_exp(log_a1_reverse);
    let forward_rejection = log1m_exp(log_a1_forward);
    if reverse_rejection == f64::NEG_INFINITY || forward_rejection == f64::NEG_INFINITY {
        // α₁(y₂→y₁) = 1 makes the reverse path impossible; α₁(x→y₁) = 1 means
        // the second stage is never reached.
        return f64::NEG_INFINITY;
    }
    // Differences of like terms first: with ln π ≈ 1e300 an absolute sum
    // would round the proposal densities away.
    let d = (log_pi_y2 - log_pi_x)
        + (log_q1_y2_y1 - log_q1_x_y1)
        + log_q2_ratio
        + (reverse_rejection - forward_rejection);
    if d.is_nan() {
        return f64::NEG_INFINITY;
    }
    d.min(0.0)
}

/// Delayed rejection with a first kernel `K1` (which must provide its
/// proposal density) and a second kernel `K2`.
#[derive(Clone)]
pub struct DelayedRejection<K1, K2, S, P = ()> {
    first: K1,
    second: K2,
    first_components: usize,
    y1: Option<Sample<S, P>>,
    y2: Option<Sample<S, P>>,
}

impl<K1: Kernel<S, P>, K2: Kernel<S, P>, S, P> DelayedRejection<K1, K2, S, P> {
    /// Two stages: `first`, then `second` after a rejection.
    pub fn new(first: K1, second: K2) -> Self {
        let first_components = first.component_names().len();
        DelayedRejection {
            first,
            second,
            first_components,
            y1: None,
            y2: None,
        }
    }
}

impl<K1, K2, S, P> Algorithm<S, P> for DelayedRejection<K1, K2, S, P>
where
    K1: Kernel<S, P>,
    K2: Kernel<S, P>,
    S: Clone,
    P: Clone,
{
    fn check_initial(&self, state: &S) -> crate::Result<()> {
        self.first.check_state(state)?;
        self.second.check_state(state)
    }

    fn component_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .first
            .component_names()
            .into_iter()
            .map(|n| format!("{n} (stage 1)"))
            .collect();
        names.extend(
            self.second
                .component_names()
                .into_iter()
                .map(|n| format!("{n} (stage 2)")),
        );
        names
    }

    fn step<T: Target<S, Payload = P>>(
        &mut self,
        chain: &mut ChainState<S, P>,
        target: &T,
        observer: &mut dyn FnMut(&Transition<'_, S, P>),
    ) -> StepInfo {
        chain.stats.steps += 1;
        let y1 = self.y1.get_or_insert_with(|| chain.current.clone());
        let p1 = self.first.propose(&chain.current, y1, &mut chain.rng);
        if p1.failed {
            chain.stats.failed += 1;
            chain.stats.record(p1.component, 0.0, false);
            return StepInfo {
                alpha: 0.0,
                outcome: Outcome::Failed,
                component: p1.component,
            };
        }
        if !p1.evaluated {
            y1.reevaluate(target);
        }
        chain.stats.evaluations += 1;
        let (log_a1, class1) =
            mh_log_acceptance(chain.current.log_density, y1.log_density, p1.log_q_ratio);
        chain.stats.record_class(class1);
        let accepted1 = accept(log_a1, &mut chain.rng);
        let alpha1 = log_a1.exp();
        observer(&Transition {
            current: &chain.current,
            proposal: Some(y1),
            alpha: alpha1,
            accepted: accepted1,
            component: p1.component,
        });
        chain.stats.record(p1.component, alpha1, accepted1);
        if accepted1 {
            chain.stats.accepted += 1;
            std::mem::swap(&mut chain.current, y1);
            self.observe(p1.component, alpha1, true, &chain.current.state);
            return StepInfo {
                alpha: alpha1,
                outcome: Outcome::Accepted,
                component: p1.component,
            };
        }

        // Second stage.
        let y2 = self.y2.get_or_insert_with(|| chain.current.clone());
        let p2 = self.second.propose(&chain.current, y2, &mut chain.rng);
        let component2 = self.first_components + p2.component;
        let densities = (
            self.first.log_proposal_density(&chain.current, &y1.state),
            self.first.log_proposal_density(y2, &y1.state),
            self.first.log_proposal_density(y1, &y2.state),
            self.first.log_proposal_density(y1, &chain.current.state),
        );
        let (Some(q_x_y1), Some(q_y2_y1), Some(q_y1_y2), Some(q_y1_x)) = densities else {
            // Without the first kernel's density the second stage is impossible.
            chain.stats.failed += 1;
            chain.stats.record(component2, 0.0, false);
            return StepInfo {
                alpha: 0.0,
                outcome: Outcome::Failed,
                component: component2,
            };
        };
        if p2.failed {
            chain.stats.failed += 1;
            chain.stats.record(component2, 0.0, false);
            return StepInfo {
                alpha: 0.0,
                outcome: Outcome::Failed,
                component: component2,
            };
        }
        if !p2.evaluated {
            y2.reevaluate(target);
        }
        chain.stats.evaluations += 1;
        let class2 = DensityClass::of(y2.log_density);
        chain.stats.record_class(class2);
        let log_a2 = dr_log_acceptance(
            chain.current.log_density,
            y1.log_density,
            y2.log_density,
            q_x_y1,
            q_y2_y1,
            q_y1_y2,
            q_y1_x,
            p2.log_q_ratio,
        );
        let accepted2 = accept(log_a2, &mut chain.rng);
        let alpha2 = log_a2.exp();
        observer(&Transition {
            current: &chain.current,
            proposal: Some(y2),
            alpha: alpha2,
            accepted: accepted2,
            component: component2,
        });
        chain.stats.record(component2, alpha2, accepted2);
        if accepted2 {
            chain.stats.accepted += 1;
            std::mem::swap(&mut chain.current, y2);
        }
        self.observe(component2, alpha2, accepted2, &chain.current.state);
        let outcome = match (accepted2, class2) {
            (true, _) => Outcome::Accepted,
            (false, DensityClass::Invalid) => Outcome::InvalidDensity,
            (false, DensityClass::Zero) => Outcome::OutsideSupport,
            (false, DensityClass::Finite) => Outcome::Rejected,
        };
        StepInfo {
            alpha: alpha2,
            outcome,
            component: component2,
        }
    }

    fn freeze(&mut self) {
        self.first.freeze();
        self.second.freeze();
    }
}

impl<K1: Kernel<S, P>, K2: Kernel<S, P>, S, P> DelayedRejection<K1, K2, S, P> {
    fn observe(&mut self, component: usize, alpha: f64, accepted: bool, state: &S) {
        let first_own = component < self.first_components;
        self.first.observe(&StepObservation {
            component,
            alpha,
            accepted,
            own: first_own,
            state,
        });
        self.second.observe(&StepObservation {
            component: component.saturating_sub(self.first_components),
            alpha,
            accepted,
            own: !first_own,
            state,
        });
    }
}
