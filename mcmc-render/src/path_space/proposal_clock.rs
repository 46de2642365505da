//! Time spent in each mutation type's proposals, for the sidecar's
//! per-type rates (`mutation_types`).
//!
//! Reading the clock is not free: on the shared machine a pair of
//! `Instant::now()` calls costs about 0.7 µs (measured; `tsc` clock source
//! behind the sandbox), against 2–20 µs for a whole mutation. Timing every
//! proposal would slow the chains by up to a third, so [`Timed`] times one
//! proposal in [`STRIDE`] of each type (every `STRIDE`-th call on that
//! kernel; the choice does not touch the chain's random numbers, so images
//! stay bit-identical) and scales: a type's proposal time is estimated as
//! its mean timed duration, less the clock's own cost measured at start-up
//! ([`clock_cost`]), times its number of proposals.
//!
//! A proposal's time is the mutation's `propose`: drawing, tracing, the
//! path's evaluation and both transition densities. The Metropolis–Hastings
//! decision and the splatting of the two states come after it and are
//! shared by every type; they are the run's time outside all types.

use super::state::Path;
use crate::pss::PathSample;
use mcmc_core::kernel::{Kernel, Proposal, StepObservation};
use mcmc_core::rng::ChainRng;
use mcmc_core::sample::Sample;
use serde_json::{Value, json};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

/// One proposal in `STRIDE` of each type is timed.
pub const STRIDE: u64 = 32;

/// Proposal counts and sampled times per mutation type, summed over every
/// chain and thread of a run (each kernel adds its own when dropped).
#[derive(Debug, Default)]
pub struct ProposalClock {
    types: Mutex<Vec<TypeTime>>,
}

/// One type's totals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TypeTime {
    /// The type's name (its component 0 in the statistics).
    pub name: String,
    /// Proposals made.
    pub proposals: u64,
    /// Proposals timed.
    pub timed: u64,
    /// Their summed duration (s), the clock's cost included.
    pub timed_seconds: f64,
}

impl TypeTime {
    /// Estimated mean duration (s) of one of this type's proposals: the
    /// timed ones' mean less the clock's own cost (see the module docs);
    /// `None` when none was timed.
    pub fn mean_seconds(&self) -> Option<f64> {
        (self.timed > 0).then(|| (self.timed_seconds / self.timed as f64 - clock_cost()).max(0.0))
    }
}

/// The mean duration (s) of an `Instant::now()` / `elapsed()` pair around
/// nothing: what each timed interval over-counts. Measured once.
pub fn clock_cost() -> f64 {
    static COST: OnceLock<f64> = OnceLock::new();
    *COST.get_or_init(|| {
        const N: u32 = 2000;
        let mut sum = 0.0;
        for _ in 0..N {
            sum += Instant::now().elapsed().as_secs_f64();
        }
        sum / f64::from(N)
    })
}

impl ProposalClock {
    /// A clock with no types yet.
    pub fn new() -> Arc<ProposalClock> {
        Arc::new(ProposalClock::default())
    }

    fn add(&self, t: &TypeTime) {
        let mut types = self.types.lock().unwrap_or_else(|p| p.into_inner());
        match types.iter_mut().find(|e| e.name == t.name) {
            Some(e) => {
                e.proposals += t.proposals;
                e.timed += t.timed;
                e.timed_seconds += t.timed_seconds;
            }
            None => types.push(t.clone()),
        }
    }

    /// The totals so far, one per type, in the order types were first
    /// added.
    pub fn totals(&self) -> Vec<TypeTime> {
        self.types.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

/// A mutation `K` whose proposals are counted and sampled into a
/// [`ProposalClock`] (flushed when the kernel is dropped).
pub struct Timed<K> {
    inner: K,
    clock: Arc<ProposalClock>,
    own: TypeTime,
}

impl<K> Timed<K> {
    /// `inner`, timed into `clock` under the name `name` (its component 0).
    pub fn new(inner: K, name: String, clock: Arc<ProposalClock>) -> Self {
        Timed {
            inner,
            clock,
            own: TypeTime {
                name,
                ..TypeTime::default()
            },
        }
    }
}

impl<K> Drop for Timed<K> {
    fn drop(&mut self) {
        if self.own.proposals > 0 {
            self.clock.add(&self.own);
        }
    }
}

impl<'s, K: Kernel<Path<'s>, PathSample>> Kernel<Path<'s>, PathSample> for Timed<K> {
    fn propose(
        &mut self,
        current: &Sample<Path<'s>, PathSample>,
        proposal: &mut Sample<Path<'s>, PathSample>,
        rng: &mut ChainRng,
    ) -> Proposal {
        self.own.proposals += 1;
        if !self.own.proposals.is_multiple_of(STRIDE) {
            return self.inner.propose(current, proposal, rng);
        }
        let start = Instant::now();
        let p = self.inner.propose(current, proposal, rng);
        self.own.timed_seconds += start.elapsed().as_secs_f64();
        self.own.timed += 1;
        p
    }

    fn log_proposal_density(
        &self,
        from: &Sample<Path<'s>, PathSample>,
        to: &Path<'s>,
    ) -> Option<f64> {
        self.inner.log_proposal_density(from, to)
    }

    fn is_symmetric(&self) -> bool {
        self.inner.is_symmetric()
    }

    fn observe(&mut self, observation: &StepObservation<'_, Path<'s>>) {
        self.inner.observe(observation)
    }

    fn freeze(&mut self) {
        self.inner.freeze()
    }

    fn component_names(&self) -> Vec<String> {
        self.inner.component_names()
    }

    fn check_state(&self, state: &Path<'s>) -> mcmc_core::Result<()> {
        self.inner.check_state(state)
    }

    fn state_words(&self, out: &mut Vec<u64>) {
        self.inner.state_words(out)
    }

    fn restore_words(&mut self, input: &mut &[u64]) -> bool {
        self.inner.restore_words(input)
    }
}

/// The sidecar's `mutation_types`: per type, from the chains' component
/// statistics (`(name, proposed, accepted)`; a type's failure components
/// are named `"TYPE: reason"`) and `clock`'s sampled times;
/// `run_seconds` is the chains' wall-clock time. A type's
/// `proposal_seconds` is its mean proposal time times its proposals
/// (summed over threads, so comparable with `threads × run_seconds`).
pub fn mutation_types(
    components: impl IntoIterator<Item = (String, u64, u64)>,
    clock: &ProposalClock,
    run_seconds: f64,
) -> Value {
    let times = clock.totals();
    // (name, proposals, accepted, proposals per failure reason)
    type Counts = (String, u64, u64, Vec<(String, u64)>);
    let mut types: Vec<Counts> = Vec::new();
    for (name, proposed, accepted) in components {
        match name.split_once(": ") {
            Some((ty, reason)) => {
                if let Some(t) = types.iter_mut().find(|t| t.0 == ty) {
                    t.1 += proposed;
                    t.3.push((reason.to_string(), proposed));
                }
            }
            None => types.push((name, proposed, accepted, Vec::new())),
        }
    }
    let per_second = |n: f64, s: f64| if s > 0.0 { n / s } else { 0.0 };
    Value::Array(
        types
            .into_iter()
            .filter(|t| t.1 > 0)
            .map(|(name, proposals, accepted, invalid)| {
                let time = times.iter().find(|t| t.name == name);
                let mean = time.and_then(TypeTime::mean_seconds);
                let seconds = mean.map_or(0.0, |m| m * proposals as f64);
                json!({
                    "name": name,
                    "proposals": proposals,
                    "accepted": accepted,
                    "acceptance": accepted as f64 / proposals as f64,
                    "invalid": invalid.iter().map(|r| r.1).sum::<u64>(),
                    "invalid_by_reason": invalid
                        .iter()
                        .filter(|r| r.1 > 0)
                        .map(|(r, n)| (r.clone(), json!(n)))
                        .collect::<serde_json::Map<_, _>>(),
                    "timed_proposals": time.map_or(0, |t| t.timed),
                    "mean_proposal_seconds": mean,
                    "proposal_seconds": seconds,
                    "proposals_per_second": per_second(proposals as f64, seconds),
                    "proposals_per_second_of_run": per_second(proposals as f64, run_seconds),
                })
            })
            .collect(),
    )
}
