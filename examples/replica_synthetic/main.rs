//! The thesis's synthetic replica-exchange study (§5.3.7), reproduced.
//!
//! Scenario 1: 50 Gaussians in [0,1]²; scenario 2: 10 Gaussians in [0,1]⁶.
//! 8 chains with T = 1 … 2500 geometric; Kelemen small step plus a large
//! step with probability 0.3; 10 000 samples per chain after 1 000 burn-in;
//! every algorithm of the thesis; best / average / worst over `--runs` runs
//! of the relative error of ∫π², the missed modes, the modes difference and
//! the swap-change rate, as a markdown table and JSON.
//!
//! ```text
//! cargo run --release -p mcmc-examples --example replica_synthetic -- --runs 100
//! ```
//!
//! `--algorithms "EES,EES (Kou rule)"` runs only the named rows (each row
//! keeps its seed whatever else runs).
//!
//! Choices the thesis leaves open (kept fixed; see docs/replica-exchange.md):
//! - centres uniform in [0.15, 0.85]^d; each covariance `R diag(s²) Rᵀ` with
//!   a uniformly random rotation `R` and standard deviations `s` log-uniform
//!   in [0.005, 0.01] ("highly glossy lobes"); equal weights. The target is
//!   the mixture restricted to [0,1)^d (at T = 1 every centre is ≥ 15σ from the
//!   boundary, so ∫π and ∫π² are the closed-form values over R^d to < 1e-9);
//! - level i is the same mixture with every covariance scaled by T_i (each
//!   component stays a normalised Gaussian), as the thesis tempers lobes;
//! - level i's Kelemen step has s1, s2 scaled by √T_i (s2 capped below 1/2);
//! - a sample belongs to the component with the largest density at it;
//!   "modes diff." is the most minus the least visited mode's share of the
//!   main chain's samples, in percentage points (this reproduces the
//!   thesis's MH figures: 100% when one mode holds every sample);
//! - the target (centres, covariances) is fixed per scenario; runs differ
//!   by seed; plain MH runs one chain with the same 10 000 + 1 000 budget.

use mcmc_core::kernel::{Independent, Mixture, TorusStep};
use mcmc_core::math::log_sum_exp;
use mcmc_core::mh::MetropolisHastings;
use mcmc_core::replica::*;
use mcmc_core::rng::{ChainRng, standard_normal, stream_rng, uniform};
use mcmc_core::runner::run_chains;
use mcmc_core::space::{SmallStep, UnitTorus};
use serde_json::json;
use std::process::ExitCode;

/// One Gaussian component: mean and lower Cholesky factor of Σ.
#[derive(Clone, Debug)]
struct Component {
    mean: Vec<f64>,
    chol: Vec<f64>,
}

#[derive(Clone, Debug)]
struct GaussMixture {
    d: usize,
    components: Vec<Component>,
}

fn cholesky(a: &[f64], d: usize) -> Vec<f64> {
    let mut l = vec![0.0; d * d];
    for i in 0..d {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i * d + k] * l[j * d + k]).sum();
            if i == j {
                l[i * d + i] = (a[i * d + i] - s).sqrt();
            } else {
                l[i * d + j] = (a[i * d + j] - s) / l[j * d + j];
            }
        }
    }
    l
}

/// `ln N(x; 0, L Lᵀ·t)` for lower-triangular `L`.
fn log_gauss(diff: &[f64], chol: &[f64], d: usize, t: f64) -> f64 {
    let mut z = [0.0f64; 8];
    let mut q = 0.0;
    let mut log_det = 0.0;
    let st = t.sqrt();
    for i in 0..d {
        let s: f64 = (0..i).map(|k| chol[i * d + k] * st * z[k]).sum();
        let lii = chol[i * d + i] * st;
        z[i] = (diff[i] - s) / lii;
        q += z[i] * z[i];
        log_det += lii.ln();
    }
    -0.5 * q - log_det - 0.5 * d as f64 * (2.0 * std::f64::consts::PI).ln()
}

impl GaussMixture {
    fn random(d: usize, k: usize, rng: &mut ChainRng) -> Self {
        let components = (0..k)
            .map(|_| {
                let mean: Vec<f64> = (0..d).map(|_| 0.15 + 0.7 * uniform(rng)).collect();
                // Random rotation: Gram–Schmidt on a Gaussian matrix.
                let mut r: Vec<Vec<f64>> = Vec::new();
                while r.len() < d {
                    let mut v: Vec<f64> = (0..d).map(|_| standard_normal(rng)).collect();
                    for u in &r {
                        let p: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
                        v.iter_mut().zip(u).for_each(|(a, b)| *a -= p * b);
                    }
                    let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
                    if n > 1e-6 {
                        r.push(v.iter().map(|a| a / n).collect());
                    }
                }
                let s: Vec<f64> = (0..d)
                    .map(|_| (0.005f64.ln() + uniform(rng) * 2.0f64.ln()).exp())
                    .collect();
                let mut sigma = vec![0.0; d * d];
                for i in 0..d {
                    for j in 0..d {
                        sigma[i * d + j] = (0..d).map(|k| r[k][i] * s[k] * s[k] * r[k][j]).sum();
                    }
                }
                Component {
                    mean,
                    chol: cholesky(&sigma, d),
                }
            })
            .collect();
        GaussMixture { d, components }
    }

    fn component_log_densities(&self, x: &[f64], t: f64, out: &mut Vec<f64>) {
        out.clear();
        let mut diff = [0.0f64; 8];
        for c in &self.components {
            for i in 0..self.d {
                diff[i] = x[i] - c.mean[i];
            }
            out.push(log_gauss(&diff[..self.d], &c.chol, self.d, t));
        }
    }

    /// `ln π_T(x)`, the equal-weight mixture with covariances scaled by `T`.
    fn log_density(&self, x: &[f64], t: f64) -> f64 {
        let mut buf = Vec::with_capacity(self.components.len());
        self.component_log_densities(x, t, &mut buf);
        log_sum_exp(&buf) - (self.components.len() as f64).ln()
    }

    fn mode_of(&self, x: &[f64]) -> usize {
        let mut buf = Vec::with_capacity(self.components.len());
        self.component_log_densities(x, 1.0, &mut buf);
        (0..buf.len())
            .max_by(|&a, &b| buf[a].total_cmp(&buf[b]))
            .unwrap_or(0)
    }

    /// `∫ π²` over R^d in closed form: `(1/K²) Σ_kl N(μ_k − μ_l; 0, Σ_k + Σ_l)`.
    fn integral_of_square(&self) -> f64 {
        let d = self.d;
        let k = self.components.len();
        let cov = |c: &Component| {
            let mut s = vec![0.0; d * d];
            for i in 0..d {
                for j in 0..d {
                    s[i * d + j] = (0..d).map(|m| c.chol[i * d + m] * c.chol[j * d + m]).sum();
                }
            }
            s
        };
        let covs: Vec<Vec<f64>> = self.components.iter().map(cov).collect();
        let mut terms = Vec::with_capacity(k * k);
        for a in 0..k {
            for b in 0..k {
                let sum: Vec<f64> = covs[a].iter().zip(&covs[b]).map(|(x, y)| x + y).collect();
                let l = cholesky(&sum, d);
                let diff: Vec<f64> = (0..d)
                    .map(|i| self.components[a].mean[i] - self.components[b].mean[i])
                    .collect();
                terms.push(log_gauss(&diff, &l, d, 1.0));
            }
        }
        (log_sum_exp(&terms) - 2.0 * (k as f64).ln()).exp()
    }
}

const ALGORITHMS: [&str; 10] = [
    "Metropolis-Hastings",
    "Neighbor swapping",
    "Even-odd swapping",
    "IS Permutations",
    "IS Swaps",
    "Original EEM",
    "Frequent EEM",
    "EES",
    "Adaptive EES",
    // Not in the thesis's tables: EES with Kou et al.'s rule for when jumps
    // start (`JumpRule::CurrentRingFilled`); last, so the rows above keep
    // their seeds.
    "EES (Kou rule)",
];

fn exchange_move(name: &str, levels: usize) -> Box<dyn ExchangeMove<Vec<f64>, ()>> {
    match name {
        "Metropolis-Hastings" | "Neighbor swapping" => Box::new(NeighbourSwap::new()),
        "Even-odd swapping" => Box::new(EvenOdd::new()),
        "IS Permutations" => Box::new(IsPermutation::new(levels).expect("8 levels fit")),
        "IS Swaps" => Box::new(IsSwap::new()),
        "Original EEM" => Box::new(EquiEnergyMove::new(8, RingRange::Observed).expect("valid")),
        "Frequent EEM" => Box::new(FrequentEquiEnergy::new(8, RingRange::Observed).expect("valid")),
        "EES" => {
            Box::new(EquiEnergySampler::new(levels, 8, 0.1, RingRange::Observed).expect("valid"))
        }
        "Adaptive EES" => {
            Box::new(AdaptiveEquiEnergy::new(levels, 16, 0.1, 10_000).expect("valid"))
        }
        "EES (Kou rule)" => Box::new(
            EquiEnergySampler::new(levels, 8, 0.1, RingRange::Observed)
                .expect("valid")
                .with_jump_rule(JumpRule::CurrentRingFilled),
        ),
        _ => unreachable!(),
    }
}

struct Settings {
    runs: usize,
    samples: usize,
    burn_in: usize,
    seed: u64,
    scenarios: Vec<usize>,
    /// Rows to run (all when empty).
    algorithms: Vec<String>,
    json: Option<String>,
}

/// Per-run metrics, in percent.
#[derive(Clone, Copy, Debug)]
struct RunMetrics {
    estimate_diff: f64,
    missed: f64,
    modes_diff: f64,
    change: f64,
}

fn run_once(
    mixture: &GaussMixture,
    truth: f64,
    algorithm: &str,
    settings: &Settings,
    seed: u64,
) -> Result<RunMetrics, String> {
    let d = mixture.d;
    let levels = if algorithm == "Metropolis-Hastings" {
        1
    } else {
        8
    };
    let temps = geometric_temperatures(levels, 2500.0).map_err(|e| e.to_string())?;
    let t2 = temps.clone();
    let m2 = mixture.clone();
    let family = FnFamily::new(levels, move |l: usize, x: &Vec<f64>| {
        m2.log_density(x, t2[l])
    });
    let mut algorithms = Vec::with_capacity(levels);
    for &t in &temps {
        let st = t.sqrt();
        let s2 = (st / 64.0).min(0.45);
        let s1 = (st / 1024.0).min(s2 / 16.0);
        let small = TorusStep::new(SmallStep::Kelemen { s1, s2 }).map_err(|e| e.to_string())?;
        let kernel = Mixture::<Vec<f64>>::new(vec![
            (0.7, Box::new(small)),
            (0.3, Box::new(Independent::new(UnitTorus::new(d)))),
        ])
        .map_err(|e| e.to_string())?;
        algorithms.push(MetropolisHastings::new(kernel));
    }
    // Start every level at the best of 100 uniform points for π_1 (a cheap,
    // common start; burn-in does the rest).
    let mut rng = stream_rng(seed, 1 << 40);
    let start = (0..100)
        .map(|_| (0..d).map(|_| uniform(&mut rng)).collect::<Vec<f64>>())
        .max_by(|a, b| {
            mixture
                .log_density(a, 1.0)
                .total_cmp(&mixture.log_density(b, 1.0))
        })
        .unwrap_or_else(|| vec![0.5; d]);
    let mut re = ReplicaExchange::new(
        family,
        vec![start],
        algorithms,
        exchange_move(algorithm, levels),
        seed,
    )
    .map_err(|e| e.to_string())?;
    for _ in 0..settings.burn_in {
        re.sweep();
    }
    re.freeze();
    let changed_before: u64 = re.statistics().changed.iter().sum();
    let k = mixture.components.len();
    let mut visits = vec![0usize; k];
    let mut sum_pi = 0.0;
    for _ in 0..settings.samples {
        re.sweep();
        let s = re.current(0);
        visits[mixture.mode_of(&s.state)] += 1;
        sum_pi += s.log_density.exp();
    }
    let changed_after: u64 = re.statistics().changed.iter().sum();
    // b = ∫π = 1 (normalised mixture), so the estimate of ∫π² is the mean of π.
    let estimate = sum_pi / settings.samples as f64;
    let n = settings.samples as f64;
    let max = *visits.iter().max().unwrap_or(&0) as f64 / n;
    let min = *visits.iter().min().unwrap_or(&0) as f64 / n;
    Ok(RunMetrics {
        estimate_diff: 100.0 * (estimate - truth).abs() / truth,
        missed: 100.0 * visits.iter().filter(|&&v| v == 0).count() as f64 / k as f64,
        modes_diff: 100.0 * (max - min),
        change: 100.0 * (changed_after - changed_before) as f64
            / (settings.samples as f64 * levels as f64),
    })
}

fn parse() -> Result<Settings, String> {
    let mut s = Settings {
        runs: 100,
        samples: 10_000,
        burn_in: 1_000,
        seed: 2024,
        scenarios: vec![1, 2],
        algorithms: Vec::new(),
        json: None,
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    while i < args.len() {
        let flag = args[i].as_str();
        let value = args
            .get(i + 1)
            .ok_or_else(|| format!("flag {flag} needs a value"))?;
        let num = |v: &str| {
            v.parse::<usize>()
                .map_err(|_| format!("{flag}: expected a non-negative integer, got `{v}`"))
        };
        match flag {
            "--runs" => s.runs = num(value)?,
            "--samples" => s.samples = num(value)?,
            "--burn-in" => s.burn_in = num(value)?,
            "--seed" => s.seed = num(value)? as u64,
            "--scenario" => {
                s.scenarios = match value.as_str() {
                    "1" => vec![1],
                    "2" => vec![2],
                    "both" => vec![1, 2],
                    v => return Err(format!("--scenario: expected 1, 2 or both, got `{v}`")),
                }
            }
            "--json" => s.json = Some(value.clone()),
            "--algorithms" => {
                for name in value.split(',').map(str::trim) {
                    if !ALGORITHMS.contains(&name) {
                        return Err(format!(
                            "--algorithms: unknown algorithm `{name}` (known: {})",
                            ALGORITHMS.join(", ")
                        ));
                    }
                    s.algorithms.push(name.to_string());
                }
            }
            f => {
                return Err(format!(
                    "unknown flag `{f}` (flags: --runs N --samples N --burn-in N --seed N --scenario 1|2|both --algorithms A,B --json PATH)"
                ));
            }
        }
        i += 2;
    }
    if s.runs == 0 || s.samples == 0 {
        return Err("--runs and --samples must be positive".into());
    }
    Ok(s)
}

fn summarize(values: impl Iterator<Item = f64> + Clone) -> (f64, f64, f64) {
    let n = values.clone().count() as f64;
    let min = values.clone().fold(f64::INFINITY, f64::min);
    let max = values.clone().fold(f64::NEG_INFINITY, f64::max);
    (min, values.sum::<f64>() / n, max)
}

fn main() -> ExitCode {
    let settings = match parse() {
        Ok(s) => s,
        Err(e) => {
            eprintln!("replica_synthetic: {e}");
            return ExitCode::FAILURE;
        }
    };
    let mut report = Vec::new();
    for &scenario in &settings.scenarios {
        let (d, k) = if scenario == 1 { (2, 50) } else { (6, 10) };
        let mut rng = stream_rng(settings.seed, 1000 + scenario as u64);
        let mixture = GaussMixture::random(d, k, &mut rng);
        let truth = mixture.integral_of_square();
        println!(
            "\n### Scenario {scenario}: {k} Gaussians in [0,1]^{d} — {} runs, {} samples after {} burn-in\n",
            settings.runs, settings.samples, settings.burn_in
        );
        println!(
            "| Algorithm | Best: est.diff | Best: missed | Best: modes diff | Avg: est.diff | Avg: missed | Avg: modes diff | Worst: est.diff | Worst: missed | Worst: modes diff | Swap-change rate |"
        );
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
        let mut rows = Vec::new();
        for (a, name) in ALGORITHMS.iter().enumerate() {
            if !settings.algorithms.is_empty() && !settings.algorithms.iter().any(|n| n == name) {
                continue;
            }
            let seed = settings.seed ^ ((scenario as u64) << 32) ^ ((a as u64) << 40);
            let results = run_chains(settings.runs, seed, |run, mut r| {
                let run_seed = rand::Rng::next_u64(&mut r) ^ run as u64;
                run_once(&mixture, truth, name, &settings, run_seed)
            });
            let results: Vec<RunMetrics> = match results.into_iter().collect() {
                Ok(v) => v,
                Err(e) => {
                    eprintln!("replica_synthetic: {name}: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let est = summarize(results.iter().map(|r| r.estimate_diff));
            let mis = summarize(results.iter().map(|r| r.missed));
            let mdd = summarize(results.iter().map(|r| r.modes_diff));
            let chg = summarize(results.iter().map(|r| r.change));
            let change = if *name == "Metropolis-Hastings" {
                "—".to_string()
            } else {
                format!("{:.0}%", chg.1)
            };
            println!(
                "| {name} | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {:.3}% | {change} |",
                est.0, mis.0, mdd.0, est.1, mis.1, mdd.1, est.2, mis.2, mdd.2
            );
            rows.push(json!({
                "algorithm": name,
                "estimate_diff_percent": {"best": est.0, "average": est.1, "worst": est.2},
                "missed_modes_percent": {"best": mis.0, "average": mis.1, "worst": mis.2},
                "modes_diff_percent": {"best": mdd.0, "average": mdd.1, "worst": mdd.2},
                "swap_change_percent": if *name == "Metropolis-Hastings" { json!(null) } else { json!(chg.1) },
            }));
        }
        report.push(json!({
            "scenario": scenario,
            "dimension": d,
            "components": k,
            "integral_of_square": truth,
            "runs": settings.runs,
            "samples": settings.samples,
            "burn_in": settings.burn_in,
            "seed": settings.seed,
            "results": rows,
        }));
    }
    let text = serde_json::to_string_pretty(&json!({ "replica_synthetic": report }))
        .unwrap_or_else(|_| "{}".into());
    println!("\n```json\n{text}\n```");
    if let Some(path) = settings.json
        && let Err(e) = std::fs::write(&path, &text)
    {
        eprintln!("replica_synthetic: cannot write {path}: {e}");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
