//! Our NUTS, adaptive HMC, MALA and H²MC side by side with nuts-rs, in one
//! process, on the same targets: a 100-d correlated Gaussian and a Bayesian
//! logistic regression (d = 25, n = 1000, synthetic data); then our NUTS
//! and nuts-rs only on three posteriordb posteriors of
//! `mcmc_examples::posteriordb` (`arK-arK`, an AR(5) time series,
//! `eight_schools-eight_schools_noncentered`, and `dogs-dogs`, a logistic
//! regression).
//!
//! ```text
//! cargo run --release --example hmc_vs_nuts -- --json
//! cargo run --release --example hmc_vs_nuts -- --chains 4 --warmup 1000 --draws 1000
//! cargo run --release --example hmc_vs_nuts -- --draws 10000 --samplers nuts,hmc,nuts-rs
//! cargo run --release --example hmc_vs_nuts -- --samplers nuts,nuts-rs --nuts-term-buffer 150
//! ```
//!
//! `--targets a,b` runs only the named targets (default all five:
//! `gaussian-100`, `logistic-25`, `arK-arK`,
//! `eight_schools-eight_schools_noncentered`, `dogs-dogs`).
//!
//! `--nuts-term-buffer N` sets our NUTS's final step-size-only warm-up
//! buffer (CmdStan's `term_buffer`; default that of
//! `NutsSettings::default()`), `--nuts-init-buffer N` and `--nuts-window N`
//! its initial step-size-only buffer and first metric window (CmdStan's
//! `init_buffer`, `window`); `--nuts-acceptance stan|symmetric-late` the
//! acceptance statistic its step-size adaptation steers (default
//! `symmetric-late`, `NutsSettings::default()`); `--nuts-metric
//! diagonal|gradient|gradient-early` the metric its warm-up estimates
//! (`MetricAdaptation::Diagonal`, `DiagonalGradient`,
//! `DiagonalGradientEarly`; default `NutsSettings::default()`'s). `--samplers` also takes the warm-up
//! variants `nuts-stan` (CmdStan's 75 / 25 / 50, diagonal metric from the
//! draws, step size restarted at every metric update), `nuts-tb150`
//! (terminal buffer 150), `nuts-early` (10 / 10 / 150: metric windows from
//! early on), `nuts-grad` and `nuts-grad-early` (the same with nuts-rs's
//! metric from draws and gradients, `MetricAdaptation::DiagonalGradient`),
//! all with Stan's restarts, and `nuts-cont-tb50` (75 / 25 / 50 with the
//! default continuous step-size adaptation). `sampling` counts the
//! gradients after warm-up.
//!
//! Every sampler runs `chains` chains one after the other on one thread,
//! each with `warmup` adaptation steps and `draws` kept draws, from a
//! point drawn uniformly in `[−1, 1]^d` (Stan's default; the same point for
//! every sampler). `seconds` is the wall time of warm-up plus sampling;
//! `gradient_evaluations` counts every `∇ln π` (warm-up included; for
//! nuts-rs the sum of its per-draw leapfrog steps); `divergences` are
//! counted after warm-up;
//! `ess_bulk_min` is the smallest bulk ESS over coordinates and `rhat_max`
//! the largest rank-normalised split R-hat (mcmc_core::diagnostics).
//! H²MC also evaluates one Hessian per proposal (`hessian_evaluations`).
//!
//! MALA moves diffusively (in 100 dimensions ≈ 100 steps per independent
//! draw), so it runs `--mala-steps k` (default 20) steps per kept draw and
//! `k × warmup` warm-up steps: with one gradient per step that is 40 000
//! gradients per chain, about the budget of NUTS on the Gaussian.
//!
//! H²MC's Newton proposals hardly depend on the current state, so on the
//! logistic regression its chain sticks wherever the local Gaussian has
//! lighter tails than the posterior (acceptance ≈ 0.4, long rejection
//! runs): it runs `--h2mc-steps k` steps per kept draw after its
//! `warmup` steps at τ = 0.1 (a walk into the bulk whose length need not
//! grow with `k`). The default is 10, but 1 on gaussian-100, where the
//! Newton proposal is the target itself (acceptance 1.000) and a step
//! costs a 100×100 eigendecomposition. Measured on logistic-25 (seeds
//! 2026, 1, 2): R-hat 1.027 at k = 1 (seed 2026); 1.006, 1.010, 1.014 at
//! k = 5; 1.003, 1.006, 1.006 at k = 10.

// Shared with the `hmc` example, which also reads the true coefficients.
#[allow(dead_code)]
#[path = "targets.rs"]
mod targets;

use mcmc_core::adaptation::{
    AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation, WarmupSchedule,
};
use mcmc_core::diagnostics::summarize;
use mcmc_core::fit::NutsSettings;
use mcmc_core::gradient::{Differentiable, GradientPayload, GradientTarget};
use mcmc_core::kernel::{GradientKernelStatistics, H2mc, Hmc, Kernel, Mala, Nuts, Trajectory};
use mcmc_core::prelude::{Chain, MetropolisHastings, stream_rng};
use mcmc_examples::posteriordb;
use nuts_rs::{
    Chain as NutsChain, CpuLogpFunc, CpuMath, DiagNutsSettings, HasDims, LogpError, Settings,
};
use serde::Serialize;
use std::collections::HashMap;
use std::time::Instant;
use targets::{CorrelatedGaussian, LogisticRegression};

#[derive(Serialize)]
struct Run {
    target: String,
    sampler: String,
    seconds: f64,
    gradient_evaluations: u64,
    /// Of `gradient_evaluations`, those spent after warm-up.
    sampling_gradients: u64,
    hessian_evaluations: u64,
    ess_bulk_min: f64,
    rhat_max: f64,
    ess_per_second: f64,
    ess_per_gradient: f64,
    divergences: u64,
    step_size: f64,
    /// Mean Metropolis–Hastings acceptance probability after warm-up, over
    /// every step of every chain (ours only; what MALA's and HMC's step-size
    /// adaptation aims at 0.574 and 0.8).
    accept_mean: Option<f64>,
}

#[derive(Serialize)]
struct Report {
    chains: usize,
    warmup: usize,
    draws: usize,
    runs: Vec<Run>,
}

#[derive(Clone)]
struct Options {
    json: bool,
    chains: usize,
    warmup: usize,
    draws: usize,
    seed: u64,
    hmc_time: Option<f64>,
    h2mc_tau: f64,
    mala_steps: usize,
    /// `None`: 1 on gaussian-100, 10 elsewhere.
    h2mc_steps: Option<usize>,
    nuts_term_buffer: Option<usize>,
    nuts_init_buffer: Option<usize>,
    nuts_window: Option<usize>,
    nuts_acceptance: Option<AcceptanceStatistic>,
    nuts_metric: Option<MetricAdaptation>,
    samplers: Vec<String>,
    targets: Vec<String>,
}

/// Every target of the comparison, in the order they run.
const TARGETS: [&str; 5] = [
    "gaussian-100",
    "logistic-25",
    "arK-arK",
    "eight_schools-eight_schools_noncentered",
    "dogs-dogs",
];

/// Every sampler the comparison knows.
const SAMPLERS: [&str; 5] = ["nuts", "hmc", "mala", "h2mc", "nuts-rs"];

/// Warm-up variants of our NUTS, selectable with `--samplers` beside the
/// default `nuts` (`mcmc_core::fit::NutsSettings::default()`'s warm-up):
/// name, metric, CmdStan's `init_buffer`, `window`, `term_buffer`, and what
/// the step size does at metric updates.
const NUTS_VARIANTS: [(
    &str,
    MetricAdaptation,
    usize,
    usize,
    usize,
    StepSizeAdaptation,
); 6] = [
    ("nuts-stan", MetricAdaptation::Diagonal, 75, 25, 50, RESTART),
    (
        "nuts-tb150",
        MetricAdaptation::Diagonal,
        75,
        25,
        150,
        RESTART,
    ),
    (
        "nuts-early",
        MetricAdaptation::Diagonal,
        10,
        10,
        150,
        RESTART,
    ),
    (
        "nuts-grad",
        MetricAdaptation::DiagonalGradient,
        75,
        25,
        150,
        RESTART,
    ),
    (
        "nuts-grad-early",
        MetricAdaptation::DiagonalGradient,
        10,
        10,
        150,
        RESTART,
    ),
    (
        "nuts-cont-tb50",
        MetricAdaptation::Diagonal,
        75,
        25,
        50,
        CONTINUOUS,
    ),
];
const RESTART: StepSizeAdaptation = StepSizeAdaptation::Restart;
const CONTINUOUS: StepSizeAdaptation = StepSizeAdaptation::Continuous;

fn parse() -> Result<Options, String> {
    let mut o = Options {
        json: false,
        chains: 4,
        warmup: 1000,
        draws: 1000,
        seed: 2026,
        hmc_time: None,
        h2mc_tau: 1.0,
        mala_steps: 20,
        h2mc_steps: None,
        nuts_term_buffer: None,
        nuts_init_buffer: None,
        nuts_window: None,
        nuts_acceptance: None,
        nuts_metric: None,
        samplers: SAMPLERS.map(String::from).to_vec(),
        targets: TARGETS.map(String::from).to_vec(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().ok_or_else(|| format!("{name} needs a value"));
        match a.as_str() {
            "--json" => o.json = true,
            "--chains" => {
                o.chains = value("--chains")?
                    .parse()
                    .map_err(|e| format!("--chains: {e}"))?
            }
            "--warmup" => {
                o.warmup = value("--warmup")?
                    .parse()
                    .map_err(|e| format!("--warmup: {e}"))?
            }
            "--draws" => {
                o.draws = value("--draws")?
                    .parse()
                    .map_err(|e| format!("--draws: {e}"))?
            }
            "--seed" => {
                o.seed = value("--seed")?
                    .parse()
                    .map_err(|e| format!("--seed: {e}"))?
            }
            "--hmc-time" => {
                o.hmc_time = Some(
                    value("--hmc-time")?
                        .parse()
                        .map_err(|e| format!("--hmc-time: {e}"))?,
                )
            }
            "--samplers" => {
                o.samplers = value("--samplers")?.split(',').map(String::from).collect();
                let known =
                    |s: &str| SAMPLERS.contains(&s) || NUTS_VARIANTS.iter().any(|v| v.0 == s);
                if let Some(bad) = o.samplers.iter().find(|s| !known(s)) {
                    let variants: Vec<&str> = NUTS_VARIANTS.iter().map(|v| v.0).collect();
                    return Err(format!(
                        "--samplers: unknown sampler `{bad}` ({}, {})",
                        SAMPLERS.join(", "),
                        variants.join(", ")
                    ));
                }
            }
            "--targets" => {
                o.targets = value("--targets")?.split(',').map(String::from).collect();
                if let Some(bad) = o.targets.iter().find(|t| !TARGETS.contains(&t.as_str())) {
                    return Err(format!(
                        "--targets: unknown target `{bad}` ({})",
                        TARGETS.join(", ")
                    ));
                }
            }
            "--nuts-term-buffer" => {
                o.nuts_term_buffer = Some(
                    value("--nuts-term-buffer")?
                        .parse()
                        .map_err(|e| format!("--nuts-term-buffer: {e}"))?,
                )
            }
            "--nuts-init-buffer" => {
                o.nuts_init_buffer = Some(
                    value("--nuts-init-buffer")?
                        .parse()
                        .map_err(|e| format!("--nuts-init-buffer: {e}"))?,
                )
            }
            "--nuts-window" => {
                o.nuts_window = Some(
                    value("--nuts-window")?
                        .parse()
                        .map_err(|e| format!("--nuts-window: {e}"))?,
                )
            }
            "--nuts-acceptance" => {
                o.nuts_acceptance = Some(match value("--nuts-acceptance")?.as_str() {
                    "stan" => AcceptanceStatistic::Stan,
                    "symmetric-late" => AcceptanceStatistic::SymmetricLate,
                    other => {
                        return Err(format!(
                            "--nuts-acceptance: `{other}` (expected stan or symmetric-late)"
                        ));
                    }
                })
            }
            "--nuts-metric" => {
                o.nuts_metric = Some(match value("--nuts-metric")?.as_str() {
                    "diagonal" => MetricAdaptation::Diagonal,
                    "gradient" => MetricAdaptation::DiagonalGradient,
                    "gradient-early" => MetricAdaptation::DiagonalGradientEarly,
                    other => {
                        return Err(format!(
                            "--nuts-metric: `{other}` (expected diagonal, gradient or gradient-early)"
                        ));
                    }
                })
            }
            "--mala-steps" => {
                o.mala_steps = value("--mala-steps")?
                    .parse()
                    .map_err(|e| format!("--mala-steps: {e}"))?
            }
            "--h2mc-steps" => {
                o.h2mc_steps = Some(
                    value("--h2mc-steps")?
                        .parse()
                        .map_err(|e| format!("--h2mc-steps: {e}"))?,
                )
            }
            "--h2mc-tau" => {
                o.h2mc_tau = value("--h2mc-tau")?
                    .parse()
                    .map_err(|e| format!("--h2mc-tau: {e}"))?
            }
            other => {
                return Err(format!(
                    "unknown argument `{other}` (expected --json, --chains N, --warmup N, --draws N, --seed N, --hmc-time T, --h2mc-tau τ, --h2mc-steps k, --mala-steps k, --nuts-term-buffer N, --nuts-init-buffer N, --nuts-window N, --nuts-acceptance stan|symmetric-late, --nuts-metric diagonal|gradient|gradient-early, --samplers a,b, --targets a,b)"
                ));
            }
        }
    }
    if !(o.h2mc_tau > 0.0 && o.h2mc_tau <= 1.0) {
        return Err("--h2mc-tau must lie in (0, 1]".into());
    }
    if o.mala_steps == 0 {
        return Err("--mala-steps must be at least 1".into());
    }
    if o.h2mc_steps == Some(0) {
        return Err("--h2mc-steps must be at least 1".into());
    }
    if o.chains == 0 || o.draws < 4 {
        return Err("need at least 1 chain and 4 draws".into());
    }
    Ok(o)
}

/// What one of our kernels reports besides its draws.
trait Counted {
    fn counts(&self) -> &GradientKernelStatistics;
    fn step(&self) -> f64;
}
impl<G: GradientTarget> Counted for Hmc<G> {
    fn counts(&self) -> &GradientKernelStatistics {
        self.statistics()
    }
    fn step(&self) -> f64 {
        self.step_size()
    }
}
impl<G: GradientTarget> Counted for Nuts<G> {
    fn counts(&self) -> &GradientKernelStatistics {
        self.statistics()
    }
    fn step(&self) -> f64 {
        self.step_size()
    }
}
impl<G: GradientTarget> Counted for Mala<G> {
    fn counts(&self) -> &GradientKernelStatistics {
        self.statistics()
    }
    fn step(&self) -> f64 {
        self.step_size()
    }
}
impl<G: GradientTarget> Counted for H2mc<G> {
    fn counts(&self) -> &GradientKernelStatistics {
        self.statistics()
    }
    fn step(&self) -> f64 {
        f64::NAN
    }
}

/// What a run counted besides its draws.
struct Counts {
    gradients: u64,
    sampling_gradients: u64,
    hessians: u64,
    divergences: u64,
    step: f64,
    accept_mean: Option<f64>,
}

fn finish(target: &str, sampler: &str, seconds: f64, c: Counts, draws: &[Vec<Vec<f64>>]) -> Run {
    let (ess, rhat) = match summarize(draws) {
        Ok(s) => (
            s.iter().map(|r| r.ess_bulk).fold(f64::INFINITY, f64::min),
            s.iter().map(|r| r.rhat).fold(f64::NEG_INFINITY, f64::max),
        ),
        Err(_) => (f64::NAN, f64::NAN),
    };
    Run {
        target: target.into(),
        sampler: sampler.into(),
        seconds,
        gradient_evaluations: c.gradients,
        sampling_gradients: c.sampling_gradients,
        hessian_evaluations: c.hessians,
        ess_bulk_min: ess,
        rhat_max: rhat,
        ess_per_second: ess / seconds,
        ess_per_gradient: ess / c.gradients as f64,
        divergences: c.divergences,
        step_size: c.step,
        accept_mean: c.accept_mean,
    }
}

/// Runs `o.chains` chains of the kernel `make()` builds: `warmup_steps`
/// warm-up steps, then `o.draws` draws each `thin` steps apart.
fn run_ours<G, K>(
    target_name: &str,
    sampler: &str,
    g: &G,
    make: impl Fn() -> K,
    (warmup_steps, thin): (usize, usize),
    o: &Options,
) -> Run
where
    G: GradientTarget + Clone,
    K: Kernel<Vec<f64>, GradientPayload> + Counted,
{
    let t = Differentiable(g.clone());
    let d = g.dim();
    let start = Instant::now();
    let mut all = Vec::new();
    let (mut grads, mut hessians, mut divergences, mut step) = (0, 0, 0, 0.0);
    let mut sampling_grads = 0;
    let (mut alpha_sum, mut alpha_steps) = (0.0, 0);
    for c in 0..o.chains {
        let mut chain = Chain::new(
            &t,
            initial(d, o.seed, c),
            MetropolisHastings::new(make()),
            stream_rng(o.seed, c as u64),
        )
        .expect("the initial point has a finite density");
        for _ in 0..warmup_steps {
            chain.step(&t);
        }
        chain.freeze();
        let warm_divergences = chain.algorithm().kernel().counts().divergences;
        let warm_gradients = chain.algorithm().kernel().counts().gradient_evaluations;
        let alpha_of = |s: &mcmc_core::stats::ChainStatistics| {
            s.components
                .iter()
                .fold((0.0, 0), |(a, n), c| (a + c.sum_alpha, n + c.proposed))
        };
        let warm_alpha = alpha_of(chain.stats());
        let mut draws = Vec::with_capacity(o.draws);
        for _ in 0..o.draws {
            for _ in 0..thin {
                chain.step(&t);
            }
            draws.push(chain.state().clone());
        }
        let end_alpha = alpha_of(chain.stats());
        alpha_sum += end_alpha.0 - warm_alpha.0;
        alpha_steps += end_alpha.1 - warm_alpha.1;
        let k = chain.algorithm().kernel();
        grads += k.counts().gradient_evaluations + 1;
        sampling_grads += k.counts().gradient_evaluations - warm_gradients;
        if sampler == "h2mc" {
            // One Hessian per proposal (at the proposed state) plus the start.
            hessians += k.counts().trajectories + 1;
        }
        divergences += k.counts().divergences - warm_divergences;
        step = k.step();
        all.push(draws);
    }
    finish(
        target_name,
        sampler,
        start.elapsed().as_secs_f64(),
        Counts {
            gradients: grads,
            sampling_gradients: sampling_grads,
            hessians,
            divergences,
            step,
            accept_mean: Some(alpha_sum / alpha_steps as f64),
        },
        &all,
    )
}

// ---- nuts-rs ---------------------------------------------------------------

#[derive(Debug)]
enum NoError {}
impl std::fmt::Display for NoError {
    fn fmt(&self, _: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {}
    }
}
impl std::error::Error for NoError {}
impl LogpError for NoError {
    fn is_recoverable(&self) -> bool {
        match *self {}
    }
}

/// A gradient target seen by nuts-rs, counting gradient evaluations.
struct NutsTarget<G> {
    g: G,
    evaluations: u64,
}

impl<G: GradientTarget> HasDims for NutsTarget<G> {
    fn dim_sizes(&self) -> HashMap<String, u64> {
        [("unconstrained_parameter".to_string(), self.g.dim() as u64)]
            .into_iter()
            .collect()
    }
}

impl<G: GradientTarget> CpuLogpFunc for NutsTarget<G> {
    type LogpError = NoError;
    type FlowParameters = ();
    type ExpandedVector = Vec<f64>;

    fn dim(&self) -> usize {
        self.g.dim()
    }

    fn logp(&mut self, position: &[f64], gradient: &mut [f64]) -> Result<f64, NoError> {
        self.evaluations += 1;
        Ok(self.g.log_density_gradient(position, gradient))
    }

    fn expand_vector<R: nuts_rs::rand::Rng + ?Sized>(
        &mut self,
        _rng: &mut R,
        array: &[f64],
    ) -> Result<Vec<f64>, nuts_rs::CpuMathError> {
        Ok(array.to_vec())
    }
}

fn run_nuts<G: GradientTarget + Clone>(
    target_name: &str,
    g: &G,
    o: &Options,
) -> Result<Run, String> {
    let d = g.dim();
    let settings = DiagNutsSettings {
        num_tune: o.warmup as u64,
        num_draws: o.draws as u64,
        ..Default::default()
    };
    let start = Instant::now();
    let mut all = Vec::new();
    let (mut grads, mut divergences, mut step) = (0, 0, 0.0);
    let mut sampling_grads = 0;
    for c in 0..o.chains {
        let math = CpuMath::new(NutsTarget {
            g: g.clone(),
            evaluations: 0,
        });
        let mut rng = stream_rng(o.seed ^ 0x5EED, c as u64);
        let mut chain = settings
            .new_chain(c as u64, math, &mut rng)
            .map_err(|e| format!("nuts-rs: {e}"))?;
        chain
            .set_position(&initial(d, o.seed, c))
            .map_err(|e| format!("nuts-rs: {e}"))?;
        let mut draws = Vec::with_capacity(o.draws);
        for i in 0..o.warmup + o.draws {
            let (x, info) = chain.draw().map_err(|e| format!("nuts-rs: {e}"))?;
            grads += info.num_steps;
            if i >= o.warmup {
                sampling_grads += info.num_steps;
                divergences += info.diverging as u64;
                step = info.step_size;
                draws.push(x.to_vec());
            }
        }
        all.push(draws);
    }
    Ok(finish(
        target_name,
        "nuts-rs",
        start.elapsed().as_secs_f64(),
        Counts {
            gradients: grads,
            sampling_gradients: sampling_grads,
            hessians: 0,
            divergences,
            step,
            accept_mean: None,
        },
        &all,
    ))
}

fn main() {
    let o = match parse() {
        Ok(o) => o,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let gauss = CorrelatedGaussian::new(100, 0.5);
    let logistic = LogisticRegression::synthetic(1000, 25, 7);
    let mut runs = Vec::new();
    let on = |t: &str| o.targets.iter().any(|x| x == t);
    if on("gaussian-100") {
        runs.extend(compare(
            "gaussian-100",
            &gauss,
            o.hmc_time.unwrap_or(2.5),
            &o,
        ));
    }
    if on("logistic-25") {
        runs.extend(compare(
            "logistic-25",
            &logistic,
            o.hmc_time.unwrap_or(2.0),
            &o,
        ));
    }
    // Posteriordb posteriors (every target after the first two): the NUTS
    // comparison only (HMC's integration time is hand-chosen per target;
    // MALA and H²MC are compared above).
    let nuts_only = Options {
        samplers: o
            .samplers
            .iter()
            .filter(|s| s.starts_with("nuts"))
            .cloned()
            .collect(),
        ..o.clone()
    };
    for name in TARGETS[2..].iter().copied() {
        if !on(name) {
            continue;
        }
        let p = posteriordb::load(name).unwrap_or_else(|e| fail(&e));
        runs.extend(compare(name, &p.model, 1.0, &nuts_only));
    }
    let report = Report {
        chains: o.chains,
        warmup: o.warmup,
        draws: o.draws,
        runs,
    };
    warn_unconverged(&report.runs, &o);
    if o.json {
        println!(
            "{}",
            serde_json::to_string(&report).expect("plain data serialises")
        );
        return;
    }
    println!(
        "{:<40} {:<8} {:>8} {:>11} {:>11} {:>9} {:>7} {:>9} {:>10} {:>5} {:>8} {:>6}",
        "target",
        "sampler",
        "seconds",
        "gradients",
        "sampling",
        "ESS min",
        "R-hat",
        "ESS/s",
        "ESS/grad",
        "div",
        "step",
        "accept"
    );
    for r in &report.runs {
        println!(
            "{:<40} {:<8} {:>8.3} {:>11} {:>11} {:>9.0} {:>7.3} {:>9.0} {:>10.5} {:>5} {:>8.4} {:>6}",
            r.target,
            r.sampler,
            r.seconds,
            r.gradient_evaluations,
            r.sampling_gradients,
            r.ess_bulk_min,
            r.rhat_max,
            r.ess_per_second,
            r.ess_per_gradient,
            r.divergences,
            r.step_size,
            r.accept_mean.map_or("–".into(), |a| format!("{a:.3}"))
        );
    }
}

/// One line on stderr for every run that has not converged (R-hat ≥ 1.01),
/// naming its gradient budget: a sampler that needs many steps per
/// independent draw (MALA in 100-d) fails by budget, not by adaptation.
fn warn_unconverged(runs: &[Run], o: &Options) {
    for r in runs
        .iter()
        .filter(|r| r.rhat_max >= 1.01 || r.rhat_max.is_nan())
    {
        let hint = if r.sampler == "mala" {
            format!(
                " (MALA at --mala-steps {} — raise it for a larger budget)",
                o.mala_steps
            )
        } else if r.sampler == "h2mc" {
            format!(
                " (H²MC at --h2mc-steps {} — raise it for a larger budget)",
                h2mc_steps(&r.target, o)
            )
        } else {
            String::new()
        };
        eprintln!(
            "note: {} on {}: R-hat {:.3} ≥ 1.01 after {} gradients: not converged at this budget{hint}",
            r.sampler, r.target, r.rhat_max, r.gradient_evaluations
        );
    }
}

/// Chain `c`'s initial point, uniform in `[−1, 1]^d`.
fn initial(d: usize, seed: u64, c: usize) -> Vec<f64> {
    let mut rng = stream_rng(seed ^ 0x1A17, c as u64);
    (0..d)
        .map(|_| 2.0 * mcmc_core::rng::uniform(&mut rng) - 1.0)
        .collect()
}

/// Every selected sampler on one target.
fn compare<G: GradientTarget + Clone>(name: &str, g: &G, time: f64, o: &Options) -> Vec<Run> {
    let w = o.warmup;
    let on = |s: &str| o.samplers.iter().any(|x| x == s);
    let mut runs = Vec::new();
    if on("nuts") {
        let s = NutsSettings::default();
        let tb = o.nuts_term_buffer.unwrap_or(s.term_buffer);
        let schedule = (
            o.nuts_init_buffer.unwrap_or(s.init_buffer),
            o.nuts_window.unwrap_or(s.window),
            tb,
        );
        let acceptance = o.nuts_acceptance.unwrap_or(s.acceptance_statistic);
        let metric = o.nuts_metric.unwrap_or(s.metric);
        let make = || {
            nuts(g.clone(), w, metric, schedule, s.step_size_adaptation)
                .with_acceptance_statistic(acceptance)
        };
        runs.push(run_ours(name, "nuts", g, make, (w, 1), o));
    }
    for (variant, metric, init, window, term, mode) in NUTS_VARIANTS {
        if on(variant) {
            let make = || nuts(g.clone(), w, metric, (init, window, term), mode);
            runs.push(run_ours(name, variant, g, make, (w, 1), o));
        }
    }
    if on("hmc") {
        runs.push(run_ours(
            name,
            "hmc",
            g,
            || hmc(g.clone(), time, w),
            (w, 1),
            o,
        ));
    }
    if on("mala") {
        let k = o.mala_steps;
        runs.push(run_ours(
            name,
            "mala",
            g,
            || mala(g.clone(), w * k),
            (w * k, k),
            o,
        ));
    }
    if on("h2mc") {
        runs.push(run_ours(
            name,
            "h2mc",
            g,
            || h2mc(g.clone(), o.h2mc_tau, w),
            (w, h2mc_steps(name, o)),
            o,
        ));
    }
    if on("nuts-rs") {
        runs.push(run_nuts(name, g, o).unwrap_or_else(|e| fail(&e)));
    }
    runs
}

fn fail(e: &str) -> ! {
    eprintln!("error: {e}");
    std::process::exit(1);
}

/// Our NUTS: warm-up with Stan's step-size heuristic, dual averaging to
/// 0.8 (restarted at metric updates or not, `mode`) and `metric` windows
/// (`schedule` = init / first `window` / `term` buffer, as CmdStan's
/// `init_buffer`, `window`, `term_buffer`); maximum depth 10.
fn nuts<G: GradientTarget>(
    g: G,
    warmup: usize,
    metric: MetricAdaptation,
    (init, window, term): (usize, usize, usize),
    mode: StepSizeAdaptation,
) -> Nuts<G> {
    Nuts::new(g, 1.0)
        .and_then(|n| n.with_warmup(warmup, 0.8, metric))
        .and_then(|n| n.with_warmup_schedule(WarmupSchedule::new(warmup, init, window, term)))
        .map(|n| n.with_step_size_adaptation(mode))
        .expect("valid settings")
}

/// Our adaptive HMC: Stan-style warm-up (dual averaging to 0.8, diagonal
/// metric windows), fixed integration time `time`, step-size jitter 20 %.
fn hmc<G: GradientTarget>(g: G, time: f64, warmup: usize) -> Hmc<G> {
    Hmc::with_trajectory(g, 0.1, Trajectory::Time(time))
        .and_then(|h| h.with_jitter(0.2))
        .and_then(|h| h.with_warmup(warmup, 0.8, MetricAdaptation::Diagonal))
        .expect("valid settings")
}

/// H²MC's steps per kept draw on `target` (see the module comment).
fn h2mc_steps(target: &str, o: &Options) -> usize {
    o.h2mc_steps
        .unwrap_or(if target == "gaussian-100" { 1 } else { 10 })
}

/// H²MC with `tau` (default 1: Newton proposals) after a warm-up of short
/// moves (τ = 0.1) that bring the chain into the bulk.
fn h2mc<G: GradientTarget>(g: G, tau: f64, warmup: usize) -> H2mc<G> {
    H2mc::new(g, tau)
        .and_then(|h| h.with_warmup(warmup, 0.1))
        .expect("valid settings")
}

/// Our adaptive MALA: dual averaging to 0.574, diagonal metric windows
/// growing with the warm-up (`Mala::with_warmup`).
fn mala<G: GradientTarget>(g: G, warmup: usize) -> Mala<G> {
    Mala::new(g, 0.1)
        .and_then(|m| m.with_warmup(warmup, 0.574, MetricAdaptation::Diagonal))
        .expect("valid settings")
}
