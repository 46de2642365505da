//! `mcmc_core::diagnostics` checked against ArviZ on fixed arrays.
//!
//! `tests/arviz/expected.json` holds the draws and ArviZ's results; it was produced by
//! `tests/arviz/generate_expected.py` (versions recorded in the file). The computations are
//! deterministic, so agreement is required to 1e-8 relative: the only differences left are
//! floating-point summation order and the last bits of Φ⁻¹ and the FFT.

use std::path::Path;
use std::time::Instant;

use mcmc_core::diagnostics::{
    self, DiagnosticsError, Summary, SummaryTable, autocorrelation, autocovariance,
};
use serde_json::Value;

/// Relative tolerance for deterministic agreement with ArviZ.
const REL_TOL: f64 = 1e-8;

fn expected_json() -> Value {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("arviz/expected.json");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).expect("expected.json is valid JSON")
}

fn draws_of(set: &Value) -> Vec<Vec<f64>> {
    set["draws"]
        .as_array()
        .expect("draws array")
        .iter()
        .map(|chain| {
            chain
                .as_array()
                .expect("chain array")
                .iter()
                .map(|x| x.as_f64().expect("finite draw"))
                .collect()
        })
        .collect()
}

/// ArviZ's NaN is stored as JSON null.
fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array().expect("array").iter().map(num).collect()
}

/// Asserts `actual` agrees with `expected` to `REL_TOL` relative to `scale` (NaN must match
/// NaN), collecting failures rather than stopping at the first.
fn check(failures: &mut Vec<String>, what: &str, actual: f64, expected: f64, scale: f64) {
    let ok = if expected.is_nan() {
        actual.is_nan()
    } else {
        (actual - expected).abs() <= REL_TOL * scale.abs()
    };
    if !ok {
        failures.push(format!("{what}: rust {actual:e} vs arviz {expected:e}"));
    }
}

fn check_rel(failures: &mut Vec<String>, what: &str, actual: f64, expected: f64) {
    check(failures, what, actual, expected, expected);
}

#[test]
fn versions_are_recorded() {
    let json = expected_json();
    for key in ["arviz", "numpy", "scipy"] {
        assert!(
            json["versions"][key].is_string(),
            "missing version of {key}"
        );
    }
}

#[test]
fn every_estimator_matches_arviz() {
    let json = expected_json();
    let lags: Vec<usize> = json["lags"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_u64().unwrap() as usize)
        .collect();
    let probs = nums(&json["quantile_probs"]);
    let mut failures = Vec::new();
    let sets = json["sets"].as_object().expect("sets");
    assert!(sets.len() >= 9, "all reference sets present");
    for (name, set) in sets {
        let chains = draws_of(set);
        let e = &set["expected"];
        let mut c = |what: &str, actual: f64, expected: &Value| {
            check_rel(
                &mut failures,
                &format!("{name}/{what}"),
                actual,
                num(expected),
            );
        };
        c(
            "rhat_rank",
            diagnostics::rank_normalized_split_rhat(&chains).unwrap(),
            &e["rhat_rank"],
        );
        c(
            "rhat_split",
            diagnostics::split_rhat(&chains).unwrap(),
            &e["rhat_split"],
        );
        c(
            "rhat_z_scale",
            diagnostics::z_scale_split_rhat(&chains).unwrap(),
            &e["rhat_z_scale"],
        );
        c(
            "rhat_folded",
            diagnostics::folded_split_rhat(&chains).unwrap(),
            &e["rhat_folded"],
        );
        c(
            "ess_bulk",
            diagnostics::ess_bulk(&chains).unwrap(),
            &e["ess_bulk"],
        );
        c(
            "ess_tail",
            diagnostics::ess_tail(&chains).unwrap(),
            &e["ess_tail"],
        );
        c(
            "ess_mean",
            diagnostics::ess_mean(&chains).unwrap(),
            &e["ess_mean"],
        );
        c(
            "ess_sd",
            diagnostics::ess_sd(&chains).unwrap(),
            &e["ess_sd"],
        );
        c(
            "ess_identity",
            diagnostics::ess_unsplit(&chains).unwrap(),
            &e["ess_identity"],
        );
        c(
            "mcse_mean",
            diagnostics::mcse_mean(&chains).unwrap(),
            &e["mcse_mean"],
        );
        c(
            "mcse_sd",
            diagnostics::mcse_sd(&chains).unwrap(),
            &e["mcse_sd"],
        );
        for (i, &p) in probs.iter().enumerate() {
            c(
                &format!("ess_quantile({p})"),
                diagnostics::ess_quantile(&chains, p).unwrap(),
                &e["ess_quantile"][i],
            );
            c(
                &format!("mcse_quantile({p})"),
                diagnostics::mcse_quantile(&chains, p).unwrap(),
                &e["mcse_quantile"][i],
            );
        }

        // The summary must agree with the individual estimators' reference values.
        let s: Summary = diagnostics::summarize_chains(&chains).unwrap();
        c("summary.mean", s.mean, &e["mean"]);
        c("summary.sd", s.sd, &e["sd"]);
        c("summary.mcse_mean", s.mcse_mean, &e["mcse_mean"]);
        c("summary.mcse_sd", s.mcse_sd, &e["mcse_sd"]);
        c("summary.ess_bulk", s.ess_bulk, &e["ess_bulk"]);
        c("summary.ess_tail", s.ess_tail, &e["ess_tail"]);
        c("summary.rhat", s.rhat, &e["rhat_rank"]);
        c("summary.q5", s.q5, &e["quantile"][0]);
        c("summary.q50", s.q50, &e["quantile"][1]);
        c("summary.q95", s.q95, &e["quantile"][2]);

        // FFT round-off is relative to γ̂(0) (resp. ρ̂(0) = 1), not to the value at lag k, which
        // can be near zero for long lags.
        let acov = autocovariance(&chains[0]).unwrap();
        let acorr = autocorrelation(&chains[0]).unwrap();
        let acov_expected = nums(&e["autocov_chain0"]);
        let acorr_expected = nums(&e["autocorr_chain0"]);
        for (i, &k) in lags.iter().enumerate() {
            let what = format!("{name}/autocov[{k}]");
            check(
                &mut failures,
                &what,
                acov[k],
                acov_expected[i],
                acov_expected[0],
            );
            let what = format!("{name}/autocorr[{k}]");
            check(&mut failures, &what, acorr[k], acorr_expected[i], 1.0);
        }
    }
    assert!(
        failures.is_empty(),
        "{} mismatches:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// `summarize` on a chains × draws × coordinates array against `arviz.summary`.
#[test]
fn summarize_matches_arviz_summary() {
    let json = expected_json();
    let summary = &json["summary"];
    let sets: Vec<Vec<Vec<f64>>> = summary["sets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| draws_of(&json["sets"][n.as_str().unwrap()]))
        .collect();
    let (n_chains, n_draws) = (sets[0].len(), sets[0][0].len());
    let stacked: Vec<Vec<Vec<f64>>> = (0..n_chains)
        .map(|c| {
            (0..n_draws)
                .map(|t| sets.iter().map(|s| s[c][t]).collect())
                .collect()
        })
        .collect();
    let rows = diagnostics::summarize(&stacked).unwrap();
    assert_eq!(rows.len(), sets.len());
    let columns = &summary["columns"];
    let mut failures = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        let fields = [
            ("mean", row.mean),
            ("sd", row.sd),
            ("mcse_mean", row.mcse_mean),
            ("mcse_sd", row.mcse_sd),
            ("ess_bulk", row.ess_bulk),
            ("ess_tail", row.ess_tail),
            ("r_hat", row.rhat),
        ];
        for (col, actual) in fields {
            let expected = num(&columns[col][i]);
            check_rel(&mut failures, &format!("x[{i}].{col}"), actual, expected);
        }
    }
    assert!(
        failures.is_empty(),
        "{} mismatches:\n{}",
        failures.len(),
        failures.join("\n")
    );
    let names: Vec<&str> = summary["sets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    let table = SummaryTable::with_names(rows, names);
    println!("{table}");
}

/// The documented degenerate behaviour: constant draws give NaN (where ArviZ 0.23 reports
/// the draw count as ESS, posterior reports NA); too-short or ragged input is an error.
#[test]
fn degenerate_input() {
    let constant = vec![vec![1.5; 20]; 3];
    assert!(diagnostics::ess_bulk(&constant).unwrap().is_nan());
    assert!(diagnostics::ess_tail(&constant).unwrap().is_nan());
    assert!(diagnostics::ess_mean(&constant).unwrap().is_nan());
    assert!(
        diagnostics::rank_normalized_split_rhat(&constant)
            .unwrap()
            .is_nan()
    );
    assert!(diagnostics::mcse_mean(&constant).unwrap().is_nan());
    let s = diagnostics::summarize_chains(&constant).unwrap();
    assert_eq!((s.mean, s.sd), (1.5, 0.0));
    assert!(s.ess_bulk.is_nan() && s.rhat.is_nan());

    assert_eq!(
        diagnostics::ess_bulk(&[vec![0.0, 1.0, 2.0]]),
        Err(DiagnosticsError::TooFewDraws { draws: 3, min: 4 })
    );
    assert!(matches!(
        diagnostics::ess_tail(&[vec![0.0; 5], vec![0.0; 6]]),
        Err(DiagnosticsError::UnequalLengths { chain: 1, .. })
    ));
    assert!(matches!(
        diagnostics::mcse_mean(&[vec![0.0, 1.0, f64::NEG_INFINITY, 2.0]]),
        Err(DiagnosticsError::NonFinite { draw: 2, .. })
    ));
}

/// SplitMix64: a fixed, dependency-free stream for the large-input test.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        // 53 random bits in (0, 1).
        ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// Standard normal by Box–Muller.
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.next_f64(), self.next_f64());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// CPU time consumed so far by the calling thread, from Linux's schedstat (ns); `None`
/// elsewhere. Unlike wall time it is not inflated when other processes share the cores.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// Runs `f`, returning its value and "wall ms / CPU ms" for the report.
fn timed<T>(f: impl FnOnce() -> T) -> (T, String) {
    let cpu = thread_cpu_ns();
    let start = Instant::now();
    let value = f();
    let wall = start.elapsed().as_secs_f64() * 1e3;
    let cpu = match (cpu, thread_cpu_ns()) {
        (Some(a), Some(b)) => format!("{:.0} ms", (b - a) as f64 / 1e6),
        _ => "n/a".to_string(),
    };
    (value, format!("{wall:.0} ms wall / {cpu} CPU"))
}

/// `chains` independent stationary AR(1) chains `x_t = ρ x_{t−1} + sqrt(1 − ρ²) ε_t`.
fn ar1_chains(rng: &mut SplitMix, chains: usize, draws: usize, rho: f64) -> Vec<Vec<f64>> {
    let innov = (1.0 - rho * rho).sqrt();
    (0..chains)
        .map(|_| {
            let mut x = rng.normal();
            (0..draws)
                .map(|_| {
                    x = rho * x + innov * rng.normal();
                    x
                })
                .collect()
        })
        .collect()
}

/// The MCSE is calibrated: over independent replicates of a target with known mean 0, the
/// z-scores `mean / mcse_mean` have variance ≈ 1 (and mean ≈ 0).
///
/// R = 400 replicates of 4 × 500 draws of an AR(1) with ρ = 0.5 (ESS ≈ 667, so the
/// Student-t inflation of the z variance, ≈ 1 + 2/ESS, is negligible). For normal z the
/// sample variance has SE sqrt(2/(R − 1)) ≈ 0.071, and the sample mean SE 1/√R = 0.05; the
/// bounds 0.3 and 0.2 are ≈ 4 SE. If the ESS ignored the autocorrelation (ESS = N), var(z)
/// would be τ = 3 and the test would fail.
#[test]
fn mcse_mean_is_calibrated() {
    let replicates = 400;
    let mut rng = SplitMix(0xCA11_B8A7);
    let z: Vec<f64> = (0..replicates)
        .map(|_| {
            let chains = ar1_chains(&mut rng, 4, 500, 0.5);
            let mean = chains.iter().flatten().sum::<f64>() / 2000.0;
            mean / diagnostics::mcse_mean(&chains).unwrap()
        })
        .collect();
    let r = replicates as f64;
    let z_mean = z.iter().sum::<f64>() / r;
    let z_var = z.iter().map(|v| (v - z_mean).powi(2)).sum::<f64>() / (r - 1.0);
    println!("z mean {z_mean:.4}, z variance {z_var:.4}");
    assert!(z_mean.abs() < 0.2, "mean of z {z_mean}");
    assert!((z_var - 1.0).abs() < 0.3, "variance of z {z_var}");
}

/// 10⁶ draws (4 chains of an AR(1) with ρ = 0.5) are handled quickly and the ESS is right.
///
/// For an AR(1), τ = (1 + ρ)/(1 − ρ) = 3, so ESS = N/3 = 333 333. The relative standard
/// error of an integrated-autocorrelation-time estimate truncated at window M is about
/// sqrt(2(2M + 1)/N) (Sokal 1997, Eq. 3.19); Geyer's sequence stops at M ≈ 10–20 lags here,
/// so the relative SE is ≤ sqrt(2·41/10⁶) ≈ 0.9 %. The bound 5 % is > 5 SE. The rank
/// normalisation of a Gaussian marginal is close to the identity, so the bulk ESS has the
/// same target. The time is printed (see the report), not asserted.
#[test]
fn million_draws_ess_is_fast_and_right() {
    let (chains, draws, rho) = (4, 250_000, 0.5f64);
    let mut rng = SplitMix(0x5EED_D1A6);
    let data = ar1_chains(&mut rng, chains, draws, rho);
    let n = (chains * draws) as f64;
    let theory = n * (1.0 - rho) / (1.0 + rho);

    let (ess_mean, t_mean) = timed(|| diagnostics::ess_mean(&data).unwrap());
    let (ess_bulk, t_bulk) = timed(|| diagnostics::ess_bulk(&data).unwrap());
    let (ess_tail, t_tail) = timed(|| diagnostics::ess_tail(&data).unwrap());
    let (rhat, t_rhat) = timed(|| diagnostics::rank_normalized_split_rhat(&data).unwrap());
    let (summary, t_summary) = timed(|| diagnostics::summarize_chains(&data).unwrap());
    println!(
        "1e6 draws (4 x 250000), wall / thread CPU time:\n  ess_mean {ess_mean:.1}: {t_mean}\n  \
         ess_bulk {ess_bulk:.1}: {t_bulk}\n  ess_tail {ess_tail:.1}: {t_tail}\n  \
         rank R-hat {rhat:.5}: {t_rhat}\n  summarize_chains: {t_summary}\n  (theory ESS {theory:.0})"
    );
    for (what, ess) in [
        ("mean", ess_mean),
        ("bulk", ess_bulk),
        ("summary bulk", summary.ess_bulk),
    ] {
        assert!(
            (ess / theory - 1.0).abs() < 0.05,
            "{what}: {ess} vs {theory}"
        );
    }
    // Independent chains of the same stationary process: R-hat ≈ 1 (its SE at this N is ~1e-3).
    assert!(summary.rhat < 1.01, "rhat {}", summary.rhat);
}
