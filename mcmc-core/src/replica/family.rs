//! Replica families: `M` densities `π_1 … π_M` over one state space, `π_1`
//! being the target of interest, and the ladders that parametrise them.
//!
//! Levels are general densities (the renderer roughens BSDFs per level);
//! [`PowerFamily`] is the standard tempering `ln π_β = β ln L + ln prior`.

use crate::error::{Result, invalid};
use crate::sample::Sample;
use crate::target::{Evaluation, Target};

/// `M` unnormalised densities over one state space. Level 0 is `π_1`, the
/// target of interest; higher levels are "hotter" (flatter).
///
/// Exchange moves read `ln π_i(x_j)` entries through
/// [`ReplicaFamily::log_density_of`] and never more than they need.
pub trait ReplicaFamily<S> {
    /// What an evaluation carries besides `ln π` (kept with the state).
    type Payload: Clone;

    /// Number of levels `M ≥ 1`.
    fn levels(&self) -> usize;

    /// Evaluates `ln π_level(state)` and its payload.
    fn evaluate(&self, level: usize, state: &S) -> Evaluation<Self::Payload>;

    /// `ln π_level(x)` for a sample a chain holds (evaluated for some level).
    /// Families whose payload determines every level cheaply (powers of
    /// one density) override this to avoid a new evaluation.
    fn log_density_of(&self, level: usize, sample: &Sample<S, Self::Payload>) -> f64 {
        self.evaluate(level, &sample.state).log_density
    }

    /// Makes `sample` a sample of `level` after an exchange moved it there:
    /// its `log_density` becomes `log_density` (= `ln π_level(x)`, already
    /// computed by the move) and its payload is refreshed. The default
    /// re-evaluates the payload; families whose payload does not depend on
    /// the level override this with a plain assignment.
    fn retarget(&self, level: usize, sample: &mut Sample<S, Self::Payload>, log_density: f64) {
        let e = self.evaluate(level, &sample.state);
        sample.payload = e.payload;
        sample.log_density = if e.log_density.is_nan() {
            e.log_density
        } else {
            log_density
        };
    }

    /// True when [`ReplicaFamily::log_density_of`] at a level other than the
    /// sample's own is free (no target evaluation); used for statistics only.
    fn cross_densities_are_cheap(&self) -> bool {
        false
    }
}

/// A family whose levels are set by numbers that a schedule can tune (the
/// inverse temperatures of a [`PowerFamily`]).
pub trait TunableFamily<S>: ReplicaFamily<S> {
    /// The current parameters, one per level (for a power family, `β_i`).
    fn parameters(&self) -> Vec<f64>;
    /// Replaces the parameters (validated as at construction).
    fn set_parameters(&mut self, parameters: Vec<f64>) -> Result<()>;
}

/// One level of a family seen as a plain [`Target`] (what a chain's
/// mutation algorithm needs).
#[derive(Debug)]
pub struct LevelTarget<'a, F: ?Sized> {
    /// The family.
    pub family: &'a F,
    /// The level, 0-based.
    pub level: usize,
}

impl<S, F: ReplicaFamily<S> + ?Sized> Target<S> for LevelTarget<'_, F> {
    type Payload = F::Payload;

    #[inline]
    fn evaluate(&self, state: &S) -> Evaluation<F::Payload> {
        self.family.evaluate(self.level, state)
    }
}

/// `β·ln L + ln prior` with the conventions every tempering must respect:
/// `0·(−∞) = −∞` (a state impossible under the likelihood stays impossible
/// at `β = 0`, the drjacoby#90 bug), a `−∞` prior gives `−∞`, and NaN or
/// `+∞` in either part gives NaN (an invalid evaluation, rejected).
#[inline]
pub fn tempered_log_density(beta: f64, log_likelihood: f64, log_prior: f64) -> f64 {
    if log_likelihood.is_nan()
        || log_prior.is_nan()
        || log_likelihood == f64::INFINITY
        || log_prior == f64::INFINITY
    {
        return f64::NAN;
    }
    if log_likelihood == f64::NEG_INFINITY || log_prior == f64::NEG_INFINITY {
        return f64::NEG_INFINITY;
    }
    beta * log_likelihood + log_prior
}

/// What a [`PowerFamily`] keeps with each state: both parts of the density,
/// so that re-tempering a state to another level costs no evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct Tempered<P> {
    /// `ln L(x)`.
    pub log_likelihood: f64,
    /// `ln prior(x)`.
    pub log_prior: f64,
    /// The likelihood's own payload (e.g. a gradient).
    pub inner: P,
}

/// A flat prior, `ln prior = 0` everywhere.
#[derive(Clone, Copy, Debug, Default)]
pub struct FlatPrior;

impl<S> Target<S> for FlatPrior {
    type Payload = ();
    #[inline]
    fn evaluate(&self, _state: &S) -> Evaluation<()> {
        Evaluation::density(0.0)
    }
}

/// The power (tempering) family `ln π_β = β·ln L + ln prior`, with
/// `β_1 = 1 ≥ β_2 ≥ … ≥ β_M ≥ 0`. `β = 0` samples the prior.
///
/// ```
/// use mcmc_core::replica::{PowerFamily, ReplicaFamily, geometric_temperatures, betas_from_temperatures};
/// let t = geometric_temperatures(4, 1000.0).unwrap();
/// let family = PowerFamily::without_prior(|x: &[f64]| -0.5 * x[0] * x[0], betas_from_temperatures(&t)).unwrap();
/// assert_eq!(family.levels(), 4);
/// ```
#[derive(Clone, Debug)]
pub struct PowerFamily<L, Q = FlatPrior> {
    log_likelihood: L,
    log_prior: Q,
    betas: Vec<f64>,
}

fn validate_betas(betas: &[f64]) -> Result<()> {
    if betas.is_empty() {
        return Err(invalid("betas", "a family needs at least one level"));
    }
    if betas[0] != 1.0 {
        return Err(invalid(
            "betas",
            format!(
                "level 1 is the target of interest and must have β = 1, got {}",
                betas[0]
            ),
        ));
    }
    if betas
        .iter()
        .any(|b| !(b.is_finite() && (0.0..=1.0).contains(b)))
    {
        return Err(invalid("betas", "every β must lie in [0, 1]"));
    }
    if betas.windows(2).any(|w| w[1] > w[0]) {
        return Err(invalid("betas", "β must not increase with the level"));
    }
    Ok(())
}

impl<L, Q> PowerFamily<L, Q> {
    /// `ln π_β = β·ln L + ln prior` for each `β` in `betas` (`betas[0] = 1`,
    /// non-increasing, in `[0, 1]`).
    pub fn new(log_likelihood: L, log_prior: Q, betas: Vec<f64>) -> Result<Self> {
        validate_betas(&betas)?;
        Ok(PowerFamily {
            log_likelihood,
            log_prior,
            betas,
        })
    }

    /// The inverse temperatures.
    pub fn betas(&self) -> &[f64] {
        &self.betas
    }
}

impl<L> PowerFamily<L, FlatPrior> {
    /// `ln π_β = β·ln π` (flat prior): classic tempering `π^{1/T}`.
    pub fn without_prior(log_target: L, betas: Vec<f64>) -> Result<Self> {
        PowerFamily::new(log_target, FlatPrior, betas)
    }
}

impl<S, L, Q> ReplicaFamily<S> for PowerFamily<L, Q>
where
    L: Target<S>,
    Q: Target<S, Payload = ()>,
{
    type Payload = Tempered<L::Payload>;

    fn levels(&self) -> usize {
        self.betas.len()
    }

    fn evaluate(&self, level: usize, state: &S) -> Evaluation<Self::Payload> {
        let lp = self.log_prior.evaluate(state).log_density;
        let Evaluation {
            log_density: ll,
            payload: inner,
        } = self.log_likelihood.evaluate(state);
        Evaluation::new(
            tempered_log_density(self.betas[level], ll, lp),
            Tempered {
                log_likelihood: ll,
                log_prior: lp,
                inner,
            },
        )
    }

    #[inline]
    fn log_density_of(&self, level: usize, sample: &Sample<S, Self::Payload>) -> f64 {
        tempered_log_density(
            self.betas[level],
            sample.payload.log_likelihood,
            sample.payload.log_prior,
        )
    }

    #[inline]
    fn retarget(&self, _level: usize, sample: &mut Sample<S, Self::Payload>, log_density: f64) {
        sample.log_density = log_density;
    }

    fn cross_densities_are_cheap(&self) -> bool {
        true
    }
}

impl<S, L, Q> TunableFamily<S> for PowerFamily<L, Q>
where
    L: Target<S>,
    Q: Target<S, Payload = ()>,
{
    fn parameters(&self) -> Vec<f64> {
        self.betas.clone()
    }

    fn set_parameters(&mut self, parameters: Vec<f64>) -> Result<()> {
        if parameters.len() != self.betas.len() {
            return Err(invalid(
                "betas",
                "a schedule must keep the number of levels",
            ));
        }
        validate_betas(&parameters)?;
        self.betas = parameters;
        Ok(())
    }
}

/// A family given by a closure `(level, &state) ↦ ln π_level(state)`, for
/// levels that are not powers of one density (e.g. mixtures whose
/// covariances widen with the temperature).
///
/// ```
/// use mcmc_core::replica::{FnFamily, ReplicaFamily};
/// let f = FnFamily::new(3, |level: usize, x: &usize| -((*x as f64) / (1.0 + level as f64)));
/// assert_eq!(f.evaluate(1, &4).log_density, -2.0);
/// ```
#[derive(Clone, Debug)]
pub struct FnFamily<F> {
    levels: usize,
    f: F,
}

impl<F> FnFamily<F> {
    /// A family of `levels` densities given by `f(level, state)`.
    pub fn new(levels: usize, f: F) -> Self {
        FnFamily { levels, f }
    }
}

impl<S, F: Fn(usize, &S) -> f64> ReplicaFamily<S> for FnFamily<F> {
    type Payload = ();

    fn levels(&self) -> usize {
        self.levels
    }

    #[inline]
    fn evaluate(&self, level: usize, state: &S) -> Evaluation<()> {
        Evaluation::density((self.f)(level, state))
    }

    #[inline]
    fn retarget(&self, _level: usize, sample: &mut Sample<S, ()>, log_density: f64) {
        sample.log_density = log_density;
    }
}

/// Geometric temperatures `T_i = T_max^{(i−1)/(M−1)}`, `T_1 = 1`, as in the
/// thesis (8 chains up to `T = 2500`). `M = 1` gives `[1]`.
pub fn geometric_temperatures(levels: usize, t_max: f64) -> Result<Vec<f64>> {
    if levels == 0 {
        return Err(invalid("levels", "a ladder needs at least one level"));
    }
    if !(t_max.is_finite() && t_max >= 1.0) {
        return Err(invalid(
            "t_max",
            format!("the hottest temperature must be finite and ≥ 1, got {t_max}"),
        ));
    }
    if levels == 1 {
        return Ok(vec![1.0]);
    }
    let top = (levels - 1) as f64;
    Ok((0..levels)
        .map(|i| {
            if i == 0 {
                1.0
            } else {
                t_max.powf(i as f64 / top)
            }
        })
        .collect())
}

/// Validates user-given temperatures: `T_1 = 1`, non-decreasing, `T ≥ 1`
/// (`+∞` allowed for the prior, `β = 0`).
pub fn validate_temperatures(temperatures: &[f64]) -> Result<()> {
    if temperatures.first() != Some(&1.0) {
        return Err(invalid("temperatures", "the ladder must start at T = 1"));
    }
    if temperatures.iter().any(|t| t.is_nan() || *t < 1.0) {
        return Err(invalid("temperatures", "every temperature must be ≥ 1"));
    }
    if temperatures.windows(2).any(|w| w[1] < w[0]) {
        return Err(invalid("temperatures", "temperatures must not decrease"));
    }
    Ok(())
}

/// `β_i = 1/T_i` (`T = ∞` gives `β = 0`).
pub fn betas_from_temperatures(temperatures: &[f64]) -> Vec<f64> {
    temperatures.iter().map(|t| 1.0 / t).collect()
}

/// Per-level kernel scales: `scale_i = base·√T_i`. A level tempered by
/// `π^{1/T}` (or a Gaussian whose covariance grows by `T`) is `√T` times
/// wider, so a random walk keeps roughly the same acceptance with a step
/// `√T` times longer. Callers on the unit torus should cap the result.
pub fn kernel_scales(base: f64, temperatures: &[f64]) -> Vec<f64> {
    temperatures.iter().map(|t| base * t.sqrt()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ladders_and_betas_are_validated() {
        let t = geometric_temperatures(8, 2500.0).unwrap();
        assert_eq!(t[0], 1.0);
        assert!((t[7] - 2500.0).abs() < 1e-9);
        assert!((t[1] - 2500f64.powf(1.0 / 7.0)).abs() < 1e-12);
        assert_eq!(geometric_temperatures(1, 10.0).unwrap(), vec![1.0]);
        assert!(geometric_temperatures(0, 10.0).is_err());
        assert!(geometric_temperatures(3, 0.5).is_err());
        assert!(geometric_temperatures(3, f64::NAN).is_err());
        assert!(validate_temperatures(&[1.0, 2.0, f64::INFINITY]).is_ok());
        assert!(validate_temperatures(&[2.0, 3.0]).is_err());
        assert!(validate_temperatures(&[1.0, 3.0, 2.0]).is_err());
        assert_eq!(
            betas_from_temperatures(&[1.0, f64::INFINITY]),
            vec![1.0, 0.0]
        );
        let ll = |x: &[f64]| -x[0] * x[0];
        assert!(PowerFamily::without_prior(ll, vec![]).is_err());
        assert!(PowerFamily::without_prior(ll, vec![0.5]).is_err());
        assert!(PowerFamily::without_prior(ll, vec![1.0, 0.2, 0.5]).is_err());
        assert!(PowerFamily::without_prior(ll, vec![1.0, -0.1]).is_err());
        assert!(PowerFamily::without_prior(ll, vec![1.0, 0.0]).is_ok());
        assert_eq!(kernel_scales(0.5, &[1.0, 4.0]), vec![0.5, 1.0]);
    }

    #[test]
    fn power_family_retargets_without_evaluating() {
        use std::cell::Cell;
        let calls = Cell::new(0);
        let ll = |x: &[f64]| {
            calls.set(calls.get() + 1);
            -x[0]
        };
        let f = PowerFamily::without_prior(ll, vec![1.0, 0.25]).unwrap();
        let e = f.evaluate(0, &vec![2.0]);
        let mut s = Sample {
            state: vec![2.0],
            log_density: e.log_density,
            payload: e.payload,
        };
        assert_eq!(calls.get(), 1);
        let hot = f.log_density_of(1, &s);
        f.retarget(1, &mut s, hot);
        assert_eq!(s.log_density, -0.5);
        assert_eq!(calls.get(), 1, "re-tempering must not evaluate the target");
    }
}
