//! Run statistics of a chain: acceptance per kernel component and the
//! counts of invalid, zero-density and failed proposals.

use crate::target::DensityClass;

/// How one step ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The proposal was accepted.
    Accepted,
    /// The proposal was rejected by the Metropolis–Hastings test.
    Rejected,
    /// The proposal had zero density (`ln π = −∞`) and was rejected.
    OutsideSupport,
    /// The target returned NaN or `+∞` at the proposal; rejected and counted.
    InvalidDensity,
    /// The kernel could not make a proposal; counted as a rejection.
    Failed,
}

/// Counts for one kernel component.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ComponentStatistics {
    /// Component name.
    pub name: String,
    /// Proposals made.
    pub proposed: u64,
    /// Proposals accepted.
    pub accepted: u64,
    /// Sum of acceptance probabilities (a lower-variance acceptance rate).
    pub sum_alpha: f64,
}

impl ComponentStatistics {
    /// Fraction of proposals accepted (NaN before any proposal).
    pub fn acceptance_rate(&self) -> f64 {
        self.accepted as f64 / self.proposed as f64
    }

    /// Mean acceptance probability (NaN before any proposal).
    pub fn mean_alpha(&self) -> f64 {
        self.sum_alpha / self.proposed as f64
    }
}

/// Everything a chain counts while it runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ChainStatistics {
    /// Steps taken.
    pub steps: u64,
    /// Steps whose proposal was accepted.
    pub accepted: u64,
    /// Target evaluations made (proposals, competitors, stages).
    pub evaluations: u64,
    /// Proposals with `ln π` NaN or `+∞` (rejected).
    pub invalid_density: u64,
    /// Proposals with `ln π = −∞` (rejected).
    pub outside_support: u64,
    /// Proposals the kernel could not make.
    pub failed: u64,
    /// Per-component counts.
    pub components: Vec<ComponentStatistics>,
}

impl ChainStatistics {
    /// Statistics for a kernel with the given component names.
    pub fn new(component_names: Vec<String>) -> Self {
        ChainStatistics {
            components: component_names
                .into_iter()
                .map(|name| ComponentStatistics {
                    name,
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }
    }

    /// Overall acceptance rate.
    pub fn acceptance_rate(&self) -> f64 {
        self.accepted as f64 / self.steps as f64
    }

    /// Records one proposal made by `component`.
    #[inline]
    pub fn record(&mut self, component: usize, alpha: f64, accepted: bool) {
        if let Some(c) = self.components.get_mut(component) {
            c.proposed += 1;
            c.accepted += accepted as u64;
            c.sum_alpha += alpha;
        }
    }

    /// Counts a proposal's density class.
    #[inline]
    pub fn record_class(&mut self, class: DensityClass) {
        match class {
            DensityClass::Finite => {}
            DensityClass::Zero => self.outside_support += 1,
            DensityClass::Invalid => self.invalid_density += 1,
        }
    }

    /// Adds another chain's counts (components matched by position).
    pub fn merge(&mut self, other: &ChainStatistics) {
        self.steps += other.steps;
        self.accepted += other.accepted;
        self.evaluations += other.evaluations;
        self.invalid_density += other.invalid_density;
        self.outside_support += other.outside_support;
        self.failed += other.failed;
        if self.components.is_empty() {
            self.components = other.components.clone();
            return;
        }
        for (a, b) in self.components.iter_mut().zip(&other.components) {
            a.proposed += b.proposed;
            a.accepted += b.accepted;
            a.sum_alpha += b.sum_alpha;
        }
    }
}
