//! Targets: unnormalised densities, always handled as `ln π`.
//!
//! An evaluation yields `ln π(x)` and a payload kept with the state (a
//! renderer's splats, a gradient, …). `ln π = −∞` means "outside the support".
//! NaN or `+∞` is an invalid evaluation: a proposal that produces one is
//! rejected and counted, and an initial state that produces one is refused.

/// The result of evaluating a target at a state.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation<P> {
    /// `ln π(x)`, `−∞` outside the support.
    pub log_density: f64,
    /// What the evaluation produced besides the density.
    pub payload: P,
}

impl<P> Evaluation<P> {
    /// An evaluation with a payload.
    #[inline]
    pub fn new(log_density: f64, payload: P) -> Self {
        Evaluation {
            log_density,
            payload,
        }
    }

    /// Classifies the log density.
    pub fn class(&self) -> DensityClass {
        DensityClass::of(self.log_density)
    }
}

impl Evaluation<()> {
    /// An evaluation without payload.
    #[inline]
    pub fn density(log_density: f64) -> Self {
        Evaluation {
            log_density,
            payload: (),
        }
    }
}

/// What a log density value means to a sampler.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DensityClass {
    /// Finite: an ordinary state in the support.
    Finite,
    /// `−∞`: outside the support (zero density).
    Zero,
    /// NaN or `+∞`: an error of the target; the proposal is rejected and counted.
    Invalid,
}

impl DensityClass {
    /// Classifies `ln π`.
    #[inline]
    pub fn of(log_density: f64) -> Self {
        if log_density.is_finite() {
            DensityClass::Finite
        } else if log_density == f64::NEG_INFINITY {
            DensityClass::Zero
        } else {
            DensityClass::Invalid
        }
    }
}

/// An unnormalised density over states of type `S`.
///
/// Plain closures are targets with no ceremony:
///
/// ```
/// use mcmc_core::target::Target;
/// let standard_normal = |x: &[f64]| -0.5 * x.iter().map(|v| v * v).sum::<f64>();
/// let e = standard_normal.evaluate(&vec![1.0, 0.0]);
/// assert_eq!(e.log_density, -0.5);
/// ```
pub trait Target<S: ?Sized> {
    /// What an evaluation carries besides `ln π`; kept with the state.
    type Payload: Clone;

    /// Evaluates `ln π(state)` and its payload.
    fn evaluate(&self, state: &S) -> Evaluation<Self::Payload>;
}

impl<F> Target<Vec<f64>> for F
where
    F: Fn(&[f64]) -> f64,
{
    type Payload = ();

    #[inline]
    fn evaluate(&self, state: &Vec<f64>) -> Evaluation<()> {
        Evaluation::density(self(state))
    }
}

impl<F> Target<usize> for F
where
    F: Fn(usize) -> f64,
{
    type Payload = ();

    #[inline]
    fn evaluate(&self, state: &usize) -> Evaluation<()> {
        Evaluation::density(self(*state))
    }
}

/// Adapts a closure over `&S` to a [`Target`] without payload, for state
/// types that have no blanket closure implementation.
///
/// ```
/// use mcmc_core::target::{FnTarget, Target};
/// let t = FnTarget(|x: &(i32, i32)| -((x.0 * x.0 + x.1 * x.1) as f64));
/// assert_eq!(t.evaluate(&(1, 1)).log_density, -2.0);
/// ```
#[derive(Clone, Copy, Debug)]
pub struct FnTarget<F>(pub F);

impl<S, F> Target<S> for FnTarget<F>
where
    F: Fn(&S) -> f64,
{
    type Payload = ();

    #[inline]
    fn evaluate(&self, state: &S) -> Evaluation<()> {
        Evaluation::density((self.0)(state))
    }
}
