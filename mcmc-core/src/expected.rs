//! Expected values ("Rao–Blackwellised" estimates): every step contributes
//! `α·f(y) + (1 − α)·f(x)` whatever the decision (Veach 1997, p. 357), which
//! lowers variance, especially where `π` is small.

use crate::chain::Transition;
use crate::sample::Sample;

/// Running mean of a vector-valued function under expected-value weighting.
///
/// ```
/// use mcmc_core::prelude::*;
/// let target = |x: &[f64]| -0.5 * x[0] * x[0];
/// let mh = MetropolisHastings::new(GaussianRandomWalk::isotropic(2.0).unwrap());
/// let mut chain = Chain::new(&target, vec![0.0], mh, stream_rng(3, 0)).unwrap();
/// let mut second_moment = RaoBlackwellMean::new(1);
/// for _ in 0..20_000 {
///     chain.step_with(&target, |t| second_moment.add(t, |s| [s.state[0] * s.state[0]]));
/// }
/// assert!((second_moment.mean()[0] - 1.0).abs() < 0.1);
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct RaoBlackwellMean {
    sum: Vec<f64>,
    steps: u64,
}

impl RaoBlackwellMean {
    /// An accumulator for a function with `dim` outputs.
    pub fn new(dim: usize) -> Self {
        RaoBlackwellMean {
            sum: vec![0.0; dim],
            steps: 0,
        }
    }

    /// Adds one transition: `α·f(proposal) + (1 − α)·f(current)`. A failed
    /// proposal puts all weight on the current state.
    pub fn add<S, P, V: AsRef<[f64]>>(
        &mut self,
        t: &Transition<'_, S, P>,
        f: impl Fn(&Sample<S, P>) -> V,
    ) {
        let fx = f(t.current);
        let (alpha, fy) = match t.proposal {
            Some(y) if t.alpha > 0.0 => (t.alpha, Some(f(y))),
            _ => (0.0, None),
        };
        self.add_weighted(alpha, fx.as_ref(), fy.as_ref().map(|v| v.as_ref()));
    }

    /// Adds `α·f_proposal + (1 − α)·f_current` directly.
    pub fn add_weighted(&mut self, alpha: f64, f_current: &[f64], f_proposal: Option<&[f64]>) {
        for (i, s) in self.sum.iter_mut().enumerate() {
            let mut v = (1.0 - alpha) * f_current[i];
            if let Some(fy) = f_proposal {
                v += alpha * fy[i];
            }
            *s += v;
        }
        self.steps += 1;
    }

    /// The estimate.
    pub fn mean(&self) -> Vec<f64> {
        self.sum.iter().map(|s| s / self.steps as f64).collect()
    }

    /// Steps accumulated.
    pub fn steps(&self) -> u64 {
        self.steps
    }
}
