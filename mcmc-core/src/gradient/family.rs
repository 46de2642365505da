//! A replica family of tempered gradient targets.

use super::{GradientPayload, GradientTarget, Tempered, evaluate_checked};
use crate::error::Result;
use crate::replica::ReplicaFamily;
use crate::sample::Sample;
use crate::target::Evaluation;
use std::cell::RefCell;

thread_local! {
    // Gradient scratch for cross-level densities (the gradient is discarded).
    static SCRATCH: RefCell<Vec<f64>> = const { RefCell::new(Vec::new()) };
}

/// The power family `ln π_β = β ln L + ln prior` over gradient targets, for
/// replica exchange with HMC, MALA or H²MC mutations. Its payload is the
/// **level's** gradient (`β∇ln L + ∇ln prior`), which is what the gradient
/// kernels read; build each level's kernel on [`TemperedFamily::level`].
///
/// ```
/// use mcmc_core::gradient::{FiniteDifference, TemperedFamily};
/// use mcmc_core::replica::ReplicaFamily;
/// let like = FiniteDifference::new(|x: &[f64]| -2.0 * x[0] * x[0], 1);
/// let prior = FiniteDifference::new(|x: &[f64]| -0.5 * x[0] * x[0], 1);
/// let family = TemperedFamily::new(like, prior, &[1.0, 0.25]).unwrap();
/// assert_eq!(family.levels(), 2);
/// let e = family.evaluate(1, &vec![1.0]);
/// assert!((e.log_density + 1.0).abs() < 1e-12); // 0.25·(−2) − 0.5
/// assert!((e.payload.gradient[0] + 2.0).abs() < 1e-6);
/// ```
///
/// On an exchange the sample (state, `ln π`, gradient) moves to its new
/// level and is re-targeted there: its gradient is recomputed for the new
/// β (one gradient evaluation). Momentum needs nothing: the kernels draw it
/// afresh at every proposal. Cross-level densities `ln π_j(x)` cost one
/// evaluation each (the gradient is discarded).
///
/// (The replica module's `PowerFamily` keeps `ln L` and `ln prior` and
/// re-tempers for free, but its payload is not the level's gradient, so the
/// gradient kernels cannot use it.)
#[derive(Clone, Debug)]
pub struct TemperedFamily<L, Q> {
    levels: Vec<Tempered<L, Q>>,
}

impl<L: GradientTarget + Clone, Q: GradientTarget + Clone> TemperedFamily<L, Q> {
    /// Levels `β_1 = 1 ≥ … ≥ β_M ≥ 0` (each in `[0, 1]`).
    pub fn new(likelihood: L, prior: Q, betas: &[f64]) -> Result<Self> {
        if betas.is_empty() {
            return Err(crate::error::invalid("betas", "need at least one level"));
        }
        let levels = betas
            .iter()
            .map(|&b| Tempered::new(likelihood.clone(), prior.clone(), b))
            .collect::<Result<_>>()?;
        Ok(TemperedFamily { levels })
    }

    /// The gradient target of `level`, to build that level's kernel on;
    /// `None` when `level ≥ levels()`.
    pub fn level(&self, level: usize) -> Option<&Tempered<L, Q>> {
        self.levels.get(level)
    }
}

impl<L: GradientTarget, Q: GradientTarget> ReplicaFamily<Vec<f64>> for TemperedFamily<L, Q> {
    type Payload = GradientPayload;

    fn levels(&self) -> usize {
        self.levels.len()
    }

    fn evaluate(&self, level: usize, state: &Vec<f64>) -> Evaluation<GradientPayload> {
        let mut gradient = vec![0.0; state.len()];
        let lp = evaluate_checked(&self.levels[level], state, &mut gradient);
        Evaluation::new(lp, GradientPayload { gradient })
    }

    fn log_density_of(&self, level: usize, sample: &Sample<Vec<f64>, GradientPayload>) -> f64 {
        SCRATCH.with(|s| {
            let mut s = s.borrow_mut();
            s.resize(sample.state.len(), 0.0);
            evaluate_checked(&self.levels[level], &sample.state, &mut s)
        })
    }

    fn retarget(
        &self,
        level: usize,
        sample: &mut Sample<Vec<f64>, GradientPayload>,
        log_density: f64,
    ) {
        sample.payload.gradient.resize(sample.state.len(), 0.0);
        let lp = evaluate_checked(
            &self.levels[level],
            &sample.state,
            &mut sample.payload.gradient,
        );
        sample.log_density = if lp.is_nan() { lp } else { log_density };
    }
}
