//! Bayesian logistic regression with adaptive HMC, printing a diagnostics
//! summary (mean, MCSE, sd, quantiles, bulk/tail ESS, R-hat) and the
//! sampler statistics (acceptance, divergences, gradient evaluations).
//!
//! ```text
//! cargo run --release --example hmc
//! ```
//!
//! The data (n = 1000, d = 25: an intercept and 24 standard normal
//! features) are generated from known coefficients, so the table can be
//! compared with the truth.

// Shared with hmc_vs_nuts; this example uses only the regression.
#[allow(dead_code)]
#[path = "../hmc_vs_nuts/targets.rs"]
mod targets;

use mcmc_core::adaptation::MetricAdaptation;
use mcmc_core::diagnostics::{SummaryTable, summarize};
use mcmc_core::gradient::Differentiable;
use mcmc_core::kernel::{Hmc, Trajectory};
use mcmc_core::prelude::*;
use mcmc_core::runner::run_chains;
use targets::LogisticRegression;

fn main() -> Result<()> {
    let model = LogisticRegression::synthetic(1000, 25, 7);
    let target = Differentiable(model.clone());
    let (chains, warmup, draws) = (4, 1000, 1000);

    // Each chain: HMC with Stan-style warm-up (dual averaging of the step
    // size towards acceptance 0.8, diagonal metric from Stan's windows),
    // integration time 2, step-size jitter 20 %. Chains run on rayon; the
    // result does not depend on the number of threads.
    let results = run_chains(chains, 2026, |_, rng| -> Result<_> {
        let hmc = Hmc::with_trajectory(model.clone(), 0.1, Trajectory::Time(2.0))?
            .with_jitter(0.2)?
            .with_warmup(warmup, 0.8, MetricAdaptation::Diagonal)?;
        let mut chain = Chain::new(
            &target,
            vec![0.0; model.d],
            MetropolisHastings::new(hmc),
            rng,
        )?;
        for _ in 0..warmup {
            chain.step(&target);
        }
        chain.freeze();
        let mut kept = Vec::with_capacity(draws);
        for _ in 0..draws {
            chain.step(&target);
            kept.push(chain.state().clone());
        }
        let k = chain.algorithm().kernel();
        Ok((
            kept,
            k.statistics().clone(),
            k.step_size(),
            chain.stats().acceptance_rate(),
        ))
    });

    let mut all = Vec::new();
    println!("(counts include warm-up)");
    println!("chain  step size  acceptance  divergences  gradient evaluations");
    for (c, r) in results.into_iter().enumerate() {
        let (kept, stats, step, acc) = r?;
        println!(
            "{c:>5}  {step:>9.4}  {acc:>10.3}  {:>11}  {:>20}",
            stats.divergences, stats.gradient_evaluations
        );
        all.push(kept);
    }
    let summaries = summarize(&all).map_err(|e| CoreError::InvalidParameter {
        name: "draws",
        reason: e.to_string(),
    })?;
    let names: Vec<String> = (0..model.d).map(|j| format!("beta[{j}]")).collect();
    println!();
    print!("{}", SummaryTable::with_names(summaries.clone(), names));
    println!();
    println!("true coefficients vs posterior means (z = (mean − truth)/sd):");
    for (j, s) in summaries.iter().enumerate() {
        let z = (s.mean - model.true_beta[j]) / s.sd;
        println!(
            "beta[{j:>2}] truth {:>7.3}  mean {:>7.3}  z {:>5.2}",
            model.true_beta[j], s.mean, z
        );
    }
    Ok(())
}
