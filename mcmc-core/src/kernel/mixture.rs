use super::{Enumerated, Kernel, Proposal, StepObservation};
use crate::error::{Result, invalid};
use crate::math::{log_sum_exp, sample_log_categorical};
use crate::rng::{ChainRng, uniform};
use crate::sample::Sample;
use std::borrow::Cow;
use std::sync::Arc;

/// A boxed kernel that can move between threads.
pub type BoxedKernel<S, P> = Box<dyn Kernel<S, P> + Send>;

/// State-dependent selection probabilities: `x ↦ (p_1(x), …, p_K(x))`.
pub type SelectionFn<S> = Arc<dyn Fn(&S) -> Vec<f64> + Send + Sync>;

enum Selection<S> {
    /// Fixed probabilities, kept as their logarithms: `ln p_k` is computed
    /// once here instead of into a new vector on every proposal (an
    /// allocation and `K` logarithms per step, 1–3% of a renderer chain's
    /// time; the values are the same, so the chain is unchanged).
    Fixed(Vec<f64>),
    StateDependent(SelectionFn<S>),
}

/// A mixture of kernels: component `k` is chosen with probability `p_k`,
/// which may depend on the current state.
///
/// With state-dependent probabilities the step is the component-wise
/// Metropolis–Hastings move: choosing `k` at `x` and proposing `y ~ q_k(x,·)`
/// is accepted with `π(y) p_k(y) q_k(y→x) / (π(x) p_k(x) q_k(x→y))`, so the
/// selection probabilities enter the reported ratio. Each component move
/// satisfies detailed balance, hence so does the mixture.
///
/// ```
/// use mcmc_core::kernel::{Independent, Mixture, TorusStep};
/// use mcmc_core::space::UnitTorus;
/// // PSSMLT's mutation: a large step with probability 0.3, else Kelemen's small step.
/// let kernel = Mixture::<Vec<f64>>::new(vec![
///     (0.7, Box::new(TorusStep::kelemen())),
///     (0.3, Box::new(Independent::new(UnitTorus::new(2)))),
/// ]).unwrap();
/// # let _ = kernel;
/// ```
pub struct Mixture<S, P = ()> {
    components: Vec<BoxedKernel<S, P>>,
    offsets: Vec<usize>,
    selection: Selection<S>,
}

impl<S, P> Mixture<S, P> {
    /// A mixture with fixed probabilities (normalised here).
    pub fn new(components: Vec<(f64, BoxedKernel<S, P>)>) -> Result<Self> {
        if components.is_empty() {
            return Err(invalid("components", "a mixture needs at least one kernel"));
        }
        let total: f64 = components.iter().map(|(w, _)| *w).sum();
        if components
            .iter()
            .any(|(w, _)| !(w.is_finite() && *w >= 0.0))
            || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
        {
            return Err(invalid(
                "weights",
                "must be finite, non-negative, not all zero",
            ));
        }
        let (weights, kernels): (Vec<f64>, Vec<_>) =
            components.into_iter().map(|(w, k)| (w / total, k)).unzip();
        let log_weights = weights.iter().map(|p| p.ln()).collect();
        Ok(Self::build(kernels, Selection::Fixed(log_weights)))
    }

    /// A mixture whose probabilities depend on the state. `selection` must
    /// return one non-negative weight per component (normalised here).
    pub fn state_dependent(
        components: Vec<BoxedKernel<S, P>>,
        selection: impl Fn(&S) -> Vec<f64> + Send + Sync + 'static,
    ) -> Result<Self> {
        if components.is_empty() {
            return Err(invalid("components", "a mixture needs at least one kernel"));
        }
        Ok(Self::build(
            components,
            Selection::StateDependent(Arc::new(selection)),
        ))
    }

    fn build(components: Vec<BoxedKernel<S, P>>, selection: Selection<S>) -> Self {
        let mut offsets = Vec::with_capacity(components.len());
        let mut next = 0;
        for c in &components {
            offsets.push(next);
            next += c.component_names().len();
        }
        Mixture {
            components,
            offsets,
            selection,
        }
    }

    /// `ln p_k(x)` for every component (borrowed when they are fixed).
    fn log_probabilities(&self, state: &S) -> Cow<'_, [f64]> {
        let raw = match &self.selection {
            Selection::Fixed(log_w) => return Cow::Borrowed(log_w),
            Selection::StateDependent(f) => f(state),
        };
        let bad =
            raw.len() != self.components.len() || raw.iter().any(|w| !(w.is_finite() && *w >= 0.0));
        let total: f64 = raw.iter().sum();
        if bad || total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            // An invalid selection at this state: no component can be chosen.
            return Cow::Owned(vec![f64::NEG_INFINITY; self.components.len()]);
        }
        Cow::Owned(raw.iter().map(|w| (w / total).ln()).collect())
    }

    fn owner_of(&self, component: usize) -> usize {
        self.offsets
            .iter()
            .rposition(|&o| o <= component)
            .unwrap_or(0)
    }
}

impl<S, P> Kernel<S, P> for Mixture<S, P> {
    fn propose(
        &mut self,
        current: &Sample<S, P>,
        proposal: &mut Sample<S, P>,
        rng: &mut ChainRng,
    ) -> Proposal {
        let (k, log_p_k) = {
            let log_p = self.log_probabilities(&current.state);
            let Some(k) = sample_log_categorical(&log_p, uniform(rng)) else {
                return Proposal::failed(0);
            };
            (k, log_p[k])
        };
        let mut p = self.components[k].propose(current, proposal, rng);
        p.component += self.offsets[k];
        if p.failed {
            return p;
        }
        if let Selection::StateDependent(_) = self.selection {
            let back = self.log_probabilities(&proposal.state)[k];
            p.log_q_ratio += back - log_p_k;
        }
        p
    }

    fn log_proposal_density(&self, from: &Sample<S, P>, to: &S) -> Option<f64> {
        let log_p = self.log_probabilities(&from.state);
        let mut terms = Vec::with_capacity(self.components.len());
        for (c, lp) in self.components.iter().zip(log_p.iter()) {
            terms.push(lp + c.log_proposal_density(from, to)?);
        }
        Some(log_sum_exp(&terms))
    }

    fn is_symmetric(&self) -> bool {
        matches!(self.selection, Selection::Fixed(_))
            && self.components.iter().all(|c| c.is_symmetric())
    }

    fn observe(&mut self, obs: &StepObservation<'_, S>) {
        let owner = self.owner_of(obs.component);
        for (k, c) in self.components.iter_mut().enumerate() {
            c.observe(&StepObservation {
                component: obs.component - self.offsets[owner].min(obs.component),
                alpha: obs.alpha,
                accepted: obs.accepted,
                own: obs.own && k == owner,
                state: obs.state,
            });
        }
    }

    fn freeze(&mut self) {
        for c in &mut self.components {
            c.freeze();
        }
    }

    fn state_words(&self, out: &mut Vec<u64>) {
        // The selection is fixed or a function of the state: only the
        // components keep state.
        for c in &self.components {
            c.state_words(out);
        }
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        self.components.iter_mut().all(|c| c.restore_words(input))
    }

    fn check_state(&self, state: &S) -> crate::Result<()> {
        self.components
            .iter()
            .try_for_each(|c| c.check_state(state))
    }

    fn component_names(&self) -> Vec<String> {
        self.components
            .iter()
            .flat_map(|c| c.component_names())
            .collect()
    }

    fn enumerate(&self, from: &Sample<S, P>) -> Option<Vec<Enumerated<S>>> {
        let log_p = self.log_probabilities(&from.state);
        let mut out = Vec::new();
        for (k, c) in self.components.iter().enumerate() {
            if log_p[k] == f64::NEG_INFINITY {
                continue;
            }
            for mut e in c.enumerate(from)? {
                e.probability *= log_p[k].exp();
                e.component += self.offsets[k];
                if let Selection::StateDependent(_) = self.selection {
                    e.log_q_ratio += self.log_probabilities(&e.state)[k] - log_p[k];
                }
                out.push(e);
            }
        }
        Some(out)
    }
}
