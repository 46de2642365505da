//! A test family for the Markov-chain driver's exchange path: PSSMLT over
//! the path tracer with a ladder of powers `I(u)^β_l` (`β_0 = 1`), coupled
//! by even–odd swaps; only level 0 is filmed. The powers flatten the
//! target without changing the splats, so level 0's image is PSSMLT's.

use mcmc_core::kernel::Mixture;
use mcmc_core::replica::{EvenOdd, ExchangeContext, ExchangeMove, Schedule};
use mcmc_core::space::TorusPoint;
use mcmc_core::target::{Evaluation, Target};
use mcmc_render::integrators::pt::PathTracer;
use mcmc_render::markov::{ChainFamily, MltError};
use mcmc_render::pss::{Mutation, PATH_CLASSES, PathSample, PssTarget};
use mcmc_render::scene::Scene;

/// `β · ln I(u)`; `−∞` and NaN pass through (`0·(−∞) = −∞`).
pub struct PoweredPss<'a> {
    pub inner: PssTarget<'a, PathTracer>,
    pub beta: f64,
}

impl Target<TorusPoint> for PoweredPss<'_> {
    type Payload = PathSample;

    fn evaluate(&self, state: &TorusPoint) -> Evaluation<PathSample> {
        let e = self.inner.trace(state);
        let log_density = if e.log_density.is_finite() {
            self.beta * e.log_density
        } else {
            e.log_density
        };
        Evaluation::new(log_density, e.payload)
    }
}

/// The ladder. With `blind` the levels swap neighbours without the
/// acceptance test (a control: level 0 then no longer samples `I`).
pub struct TemperedPss<'a> {
    pub levels: Vec<PoweredPss<'a>>,
    pub blind: bool,
}

/// Swaps every neighbour pair after each sweep, always.
struct BlindSwap;

impl<S, P: Clone> ExchangeMove<S, P> for BlindSwap {
    fn name(&self) -> String {
        "blind".into()
    }
    fn schedule(&self) -> Schedule {
        Schedule::AfterAllMutations
    }
    fn exchange(&mut self, _level: Option<usize>, cx: &mut ExchangeContext<'_, S, P>) {
        for i in 1..cx.levels() {
            cx.swap(i - 1, i);
        }
    }
}

impl<'a> TemperedPss<'a> {
    /// PSSMLT over `pt` on `scene` at the inverse temperatures `betas`.
    pub fn new(scene: &'a Scene, pt: PathTracer, betas: &[f64]) -> Self {
        TemperedPss {
            levels: betas
                .iter()
                .map(|&beta| PoweredPss {
                    inner: PssTarget { scene, sampler: pt },
                    beta,
                })
                .collect(),
            blind: false,
        }
    }
}

impl<'a> ChainFamily for TemperedPss<'a> {
    type State = TorusPoint;
    type Target = PoweredPss<'a>;
    type Mutation = Mutation;
    type Kernel = Mixture<TorusPoint, PathSample>;

    fn members(&self) -> usize {
        self.levels.len()
    }
    fn target(&self, member: usize) -> &PoweredPss<'a> {
        &self.levels[member]
    }
    fn kernel(&self, mutation: &Mutation, _member: usize) -> Result<Self::Kernel, MltError> {
        Ok(mutation.kernel()?)
    }
    fn independent_probability(&self, mutation: &Mutation) -> f64 {
        mutation.large_step_probability
    }
    mcmc_render::primary_sample_space_family!();
    fn exchange_move(&self) -> Option<Box<dyn ExchangeMove<TorusPoint, PathSample>>> {
        if self.blind {
            Some(Box::new(BlindSwap))
        } else {
            Some(Box::new(EvenOdd::new()))
        }
    }
    fn image_weight(&self, member: usize) -> f64 {
        if member == 0 { 1.0 } else { 0.0 }
    }
}

/// A tempered family with the `b` of Eq. 5.13's denominator dropped
/// (every level's density taken as normalised): the control of the
/// tempered integrators' agreement tests, which must fail them.
pub struct UnnormalisedMis<F>(pub F);

impl<F: ChainFamily> ChainFamily for UnnormalisedMis<F> {
    type State = F::State;
    type Target = F::Target;
    type Mutation = F::Mutation;
    type Kernel = F::Kernel;
    fn members(&self) -> usize {
        self.0.members()
    }
    fn target(&self, member: usize) -> &F::Target {
        self.0.target(member)
    }
    fn kernel(&self, m: &F::Mutation, member: usize) -> Result<F::Kernel, MltError> {
        self.0.kernel(m, member)
    }
    fn independent_probability(&self, m: &F::Mutation) -> f64 {
        self.0.independent_probability(m)
    }
    fn is_independent(&self, c: usize) -> bool {
        self.0.is_independent(c)
    }
    fn candidate(&self, seed: u64, index: u64) -> F::State {
        self.0.candidate(seed, index)
    }
    fn reference_log_density(&self, s: &F::State) -> f64 {
        self.0.reference_log_density(s)
    }
    fn coordinates(&self, s: &F::State) -> Option<Vec<f64>> {
        self.0.coordinates(s)
    }
    fn exchange_move(&self) -> Option<Box<dyn ExchangeMove<F::State, PathSample>>> {
        self.0.exchange_move()
    }
    fn replica_groups(&self) -> Vec<std::ops::Range<usize>> {
        self.0.replica_groups()
    }
    fn member_log_density(&self, member: usize, p: &PathSample) -> Option<f64> {
        self.0.member_log_density(member, p)
    }
    fn class_weights(
        &self,
        member: usize,
        p: &PathSample,
        b_hat: &[f64],
    ) -> Option<[f64; PATH_CLASSES]> {
        let ones = vec![1.0; b_hat.len()];
        let mut w = self.0.class_weights(member, p, &ones)?;
        // The factor 1/(b_m Σ π_j) with b_m kept.
        w[0] /= b_hat[member];
        Some(w)
    }
}
