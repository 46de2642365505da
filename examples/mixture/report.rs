//! Pooling the chains into the printed report.

use std::fmt::Write as _;

use mcmc_core::diagnostics::summarize_chains;
use mcmc_core::stats::ChainStatistics;
use serde::Serialize;

use super::error::ExampleError;
use super::plan::RunPlan;
use super::sampler::ChainRun;

/// Acceptance of one kernel component over the post-burn-in steps.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ComponentAcceptance {
    /// Component name.
    pub name: String,
    /// Proposals it made.
    pub proposed: u64,
    /// Fraction of them accepted (`null` if it made none).
    pub acceptance: f64,
}

/// Exchanges between two levels, pooled over the ladders (post-burn-in).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct SwapAcceptance {
    /// The two levels (0 is the target of interest, the coldest).
    pub levels: [usize; 2],
    /// Exchanges attempted.
    pub attempted: u64,
    /// Fraction of them accepted.
    pub acceptance: f64,
}

/// The report. Per-coordinate fields are vectors of length `d`. A statistic
/// that cannot be estimated (e.g. ESS of a chain that never moved) is NaN,
/// printed as `null` in JSON.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Report {
    /// Target evaluations spent over all chains, start-up included (≤ `--evaluations`).
    pub evaluations: u64,
    /// Wall-clock seconds of sampling (start-up and chains; not parsing or diagnostics).
    pub seconds: f64,
    /// Mean of the post-burn-in draws, pooled over chains.
    pub mean: Vec<f64>,
    /// Mean of the squared coordinates, pooled over chains.
    pub second_moment: Vec<f64>,
    /// Monte Carlo standard error of `mean` (`mcmc_core::diagnostics::mcse_mean`).
    pub mcse_mean: Vec<f64>,
    /// Bulk effective sample size.
    pub ess_bulk: Vec<f64>,
    /// Tail effective sample size.
    pub ess_tail: Vec<f64>,
    /// Rank-normalised split R-hat across the chains.
    pub rhat: Vec<f64>,
    /// Fraction of post-burn-in steps accepted, over all chains.
    pub acceptance: f64,
    /// Fraction of post-burn-in draws nearest (Euclidean) each component's mean.
    pub component_visits: Vec<f64>,
    /// `mh`, `mtm` or `replica`.
    pub sampler: String,
    /// Replica exchange: per-pair exchange rates (absent for MH and MTM).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub swap_acceptance: Option<Vec<SwapAcceptance>>,
    /// Replica exchange: the exchange move.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub exchange_move: Option<String>,
    /// Replica exchange: temperatures of the first ladder at the end (tuned
    /// when the ladder is adaptive).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub temperatures: Option<Vec<f64>>,
    /// `gaussian`, `kelemen` or `adaptive`.
    pub kernel: String,
    /// Number of chains.
    pub chains: usize,
    /// Post-burn-in draws per chain.
    pub draws_per_chain: usize,
    /// Burn-in steps per chain.
    pub burn_in_steps: usize,
    /// Start-up candidates per chain.
    pub startup_candidates: usize,
    /// Target evaluations per step (1, or `2k − 1` for multiple-try).
    pub evaluations_per_step: u64,
    /// Acceptance per kernel component (post-burn-in).
    pub acceptance_by_component: Vec<ComponentAcceptance>,
    /// Proposals outside the support (`ln π = −∞`), all steps.
    pub outside_support: u64,
    /// Proposals with NaN or `+∞` density, all steps.
    pub invalid_density: u64,
}

impl Report {
    /// Pools the chains and computes the diagnostics.
    pub fn new(plan: &RunPlan, runs: &[ChainRun], seconds: f64) -> Result<Self, ExampleError> {
        let dim = runs.first().map_or(0, |r| r.draws.len());
        let mut mean = Vec::with_capacity(dim);
        let mut second_moment = Vec::with_capacity(dim);
        let mut mcse_mean = Vec::with_capacity(dim);
        let mut ess_bulk = Vec::with_capacity(dim);
        let mut ess_tail = Vec::with_capacity(dim);
        let mut rhat = Vec::with_capacity(dim);
        for i in 0..dim {
            let chains: Vec<&[f64]> = runs.iter().map(|r| r.draws[i].as_slice()).collect();
            let s = summarize_chains(&chains)
                .map_err(|e| ExampleError::run(format!("diagnostics of coordinate {i}: {e}")))?;
            let n: usize = chains.iter().map(|c| c.len()).sum();
            let sq: f64 = chains.iter().flat_map(|c| c.iter()).map(|v| v * v).sum();
            mean.push(s.mean);
            second_moment.push(sq / n as f64);
            mcse_mean.push(s.mcse_mean);
            ess_bulk.push(s.ess_bulk);
            ess_tail.push(s.ess_tail);
            rhat.push(s.rhat);
        }
        let mut kept = ChainStatistics::default();
        let mut all = ChainStatistics::default();
        let mut visits = vec![0u64; runs.first().map_or(0, |r| r.visits.len())];
        for r in runs {
            kept.merge(&r.kept);
            all.merge(&r.all);
            for (v, w) in visits.iter_mut().zip(&r.visits) {
                *v += w;
            }
        }
        let total_visits: u64 = visits.iter().sum();
        let swap_acceptance = plan.replica.as_ref().map(|_| {
            let mut pooled: Vec<SwapAcceptance> = Vec::new();
            let mut counts: Vec<(u64, u64)> = Vec::new();
            for r in runs {
                for p in &r.swaps {
                    match pooled.iter().position(|q| q.levels == [p.i, p.j]) {
                        Some(k) => {
                            counts[k].0 += p.attempted;
                            counts[k].1 += p.accepted;
                        }
                        None => {
                            pooled.push(SwapAcceptance {
                                levels: [p.i, p.j],
                                attempted: 0,
                                acceptance: 0.0,
                            });
                            counts.push((p.attempted, p.accepted));
                        }
                    }
                }
            }
            for (q, (attempted, accepted)) in pooled.iter_mut().zip(counts) {
                q.attempted = attempted;
                q.acceptance = accepted as f64 / attempted as f64;
            }
            pooled.sort_by_key(|q| q.levels);
            pooled
        });
        Ok(Report {
            evaluations: runs.iter().map(|r| r.evaluations).sum(),
            seconds,
            mean,
            second_moment,
            mcse_mean,
            ess_bulk,
            ess_tail,
            rhat,
            acceptance: kept.acceptance_rate(),
            component_visits: visits
                .iter()
                .map(|&v| v as f64 / total_visits as f64)
                .collect(),
            sampler: plan.sampler.name().into(),
            swap_acceptance,
            exchange_move: plan.replica.as_ref().map(|r| r.exchange.name().into()),
            temperatures: plan
                .replica
                .as_ref()
                .and(runs.first().map(|r| r.temperatures.clone())),
            kernel: plan.kernel.name().into(),
            chains: plan.chains,
            draws_per_chain: plan.draws,
            burn_in_steps: plan.burn_in_steps,
            startup_candidates: plan.startup_candidates,
            evaluations_per_step: plan.evaluations_per_step,
            acceptance_by_component: kept
                .components
                .iter()
                .map(|c| ComponentAcceptance {
                    name: c.name.clone(),
                    proposed: c.proposed,
                    acceptance: c.acceptance_rate(),
                })
                .collect(),
            outside_support: all.outside_support,
            invalid_density: all.invalid_density,
        })
    }

    /// One JSON object on one line.
    pub fn to_json(&self) -> String {
        // Serialising plain numbers, strings and vectors cannot fail.
        serde_json::to_string(self).unwrap_or_default()
    }

    /// A human-readable table.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} / {}: {} chains × {} draws (burn-in {} steps), {} evaluations in {:.3} s, acceptance {:.3}",
            self.sampler,
            self.kernel,
            self.chains,
            self.draws_per_chain,
            self.burn_in_steps,
            self.evaluations,
            self.seconds,
            self.acceptance
        );
        let _ = writeln!(
            s,
            "{:>5} {:>12} {:>12} {:>10} {:>9} {:>9} {:>7}",
            "coord", "mean", "E[x²]", "mcse", "ess_bulk", "ess_tail", "rhat"
        );
        for i in 0..self.mean.len() {
            let _ = writeln!(
                s,
                "{:>5} {:>12.5} {:>12.5} {:>10.2e} {:>9.0} {:>9.0} {:>7.3}",
                i,
                self.mean[i],
                self.second_moment[i],
                self.mcse_mean[i],
                self.ess_bulk[i],
                self.ess_tail[i],
                self.rhat[i]
            );
        }
        let visits: Vec<String> = self
            .component_visits
            .iter()
            .map(|v| format!("{v:.4}"))
            .collect();
        let _ = writeln!(s, "component visits: [{}]", visits.join(", "));
        s
    }
}
