//! CmdStan CSV output read back by ArviZ and cmdstanpy.
//!
//! `tests/cmdstan/fit-{1,2}.csv` are what `mcmc_core::cmdstan` writes for
//! a fixed fit (2 chains of NUTS on a 3-d correlated Gaussian, seed 5);
//! `tests/cmdstan/read_back.py` reads them with `arviz.from_cmdstan` and
//! `cmdstanpy.from_csv` and records what those tools see in
//! `tests/cmdstan/expected.json` (committed; CI needs no Python):
//!
//! ```text
//! MCMC_WRITE_CSV=1 cargo test -p mcmc-core --test cmdstan_csv   # rewrite the CSVs
//! python3 mcmc-core/tests/cmdstan/read_back.py > mcmc-core/tests/cmdstan/expected.json
//! ```
//!
//! This test regenerates the fit, checks that the writer still produces
//! the committed files (elapsed-time lines aside), and compares ArviZ's
//! reading with ours: the draws and sampler statistics ArviZ and cmdstanpy
//! parsed, and ArviZ's summary and E-BFMI against `mcmc_core::diagnostics`.

use mcmc_core::adaptation::{AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation};
use mcmc_core::cmdstan::{vector_names, write_chain};
use mcmc_core::diagnostics::{ess_bulk, rank_normalized_split_rhat};
use mcmc_core::fit::{Fit, NutsSettings, sample_nuts};
use mcmc_core::gradient::GradientTarget;
use std::path::PathBuf;

/// `N(0, Σ)` with `Σ = [[1, .5, 0], [.5, 1, .5], [0, .5, 1]]·diag(1, 2, 3)²`
/// given by its precision.
#[derive(Clone, Copy)]
struct Gauss3;

impl GradientTarget for Gauss3 {
    fn dim(&self) -> usize {
        3
    }
    fn log_density_gradient(&self, x: &[f64], g: &mut [f64]) -> f64 {
        // Inverse of the correlation [[1,.5,0],[.5,1,.5],[0,.5,1]].
        let q = [[1.5, -1.0, 0.5], [-1.0, 2.0, -1.0], [0.5, -1.0, 1.5]];
        let s = [1.0, 2.0, 3.0];
        let z = [x[0] / s[0], x[1] / s[1], x[2] / s[2]];
        let mut lp = 0.0;
        for i in 0..3 {
            let qz: f64 = (0..3).map(|j| q[i][j] * z[j]).sum();
            lp -= 0.5 * z[i] * qz;
            g[i] = -qz / s[i];
        }
        lp
    }
}

fn fit() -> Fit {
    let s = NutsSettings {
        chains: 2,
        warmup: 300,
        draws: 200,
        seed: 5,
        // CmdStan's windows (75 / 25 / 50), step-size restarts, acceptance
        // statistic and metric (`diag_e`): the committed expectations were
        // made with them.
        init_buffer: 75,
        window: 25,
        term_buffer: 50,
        step_size_adaptation: StepSizeAdaptation::Restart,
        acceptance_statistic: AcceptanceStatistic::Stan,
        metric: MetricAdaptation::Diagonal,
        ..Default::default()
    };
    sample_nuts(&Gauss3, &s, None::<fn(usize) -> Vec<f64>>).unwrap()
}

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/cmdstan")
}

fn csv(fit: &Fit, chain: usize) -> String {
    let mut out = Vec::new();
    write_chain(&mut out, fit, chain, "gauss3", &vector_names("theta", 3)).unwrap();
    String::from_utf8(out).unwrap()
}

/// The file without its (run-dependent) elapsed-time lines.
fn without_times(s: &str) -> Vec<&str> {
    s.lines().filter(|l| !l.contains("seconds (")).collect()
}

fn json() -> serde_json::Value {
    let text = std::fs::read_to_string(dir().join("expected.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[track_caller]
fn close(name: &str, ours: f64, theirs: f64, rel: f64) {
    assert!(
        (ours - theirs).abs() <= rel * theirs.abs().max(1e-300),
        "{name}: ours {ours} vs ArviZ/cmdstanpy {theirs}"
    );
}

#[test]
fn the_writer_still_writes_the_committed_files() {
    let fit = fit();
    for c in 0..2 {
        let path = dir().join(format!("fit-{}.csv", c + 1));
        let ours = csv(&fit, c);
        if std::env::var_os("MCMC_WRITE_CSV").is_some() {
            std::fs::write(&path, &ours).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap();
        assert_eq!(without_times(&ours), without_times(&committed), "{path:?}");
    }
}

#[test]
fn arviz_and_cmdstanpy_read_what_we_wrote() {
    let fit = fit();
    let e = json();
    // Draws as ArviZ parsed them: chain × draw × parameter, bit-exact.
    let az = &e["arviz"];
    let draws = az["theta"].as_array().unwrap();
    for (c, chain) in draws.iter().enumerate() {
        for (n, draw) in chain.as_array().unwrap().iter().enumerate() {
            assert_eq!(numbers(draw), fit.chains[c].draws[n], "chain {c} draw {n}");
        }
    }
    // Sampler statistics under ArviZ's names.
    for (c, ch) in fit.chains.iter().enumerate() {
        let col = |name: &str| numbers(&az["sample_stats"][name][c]);
        let st = &ch.statistics;
        assert_eq!(col("lp"), ch.log_density);
        assert_eq!(
            col("acceptance_rate"),
            st.iter().map(|s| s.accept_stat).collect::<Vec<_>>()
        );
        assert_eq!(
            col("step_size"),
            st.iter().map(|s| s.step_size).collect::<Vec<_>>()
        );
        assert_eq!(
            col("tree_depth"),
            st.iter().map(|s| s.tree_depth as f64).collect::<Vec<_>>()
        );
        assert_eq!(
            col("n_steps"),
            st.iter().map(|s| s.n_leapfrog as f64).collect::<Vec<_>>()
        );
        assert_eq!(
            col("diverging"),
            st.iter()
                .map(|s| f64::from(u8::from(s.divergent)))
                .collect::<Vec<_>>()
        );
        assert_eq!(
            col("energy"),
            st.iter().map(|s| s.energy).collect::<Vec<_>>()
        );
        // E-BFMI: ArviZ's bfmi against ours.
        close(
            "E-BFMI",
            ch.e_bfmi().unwrap(),
            numbers(&az["bfmi"])[c],
            1e-10,
        );
    }
    // ArviZ's R-hat and bulk ESS of the parsed draws against ours.
    for i in 0..3 {
        let x: Vec<Vec<f64>> = fit
            .chains
            .iter()
            .map(|c| c.draws.iter().map(|d| d[i]).collect())
            .collect();
        close(
            "R-hat",
            rank_normalized_split_rhat(&x).unwrap(),
            numbers(&az["rhat"])[i],
            1e-8,
        );
        close(
            "bulk ESS",
            ess_bulk(&x).unwrap(),
            numbers(&az["ess_bulk"])[i],
            1e-8,
        );
    }
    // cmdstanpy: column names, adapted step sizes and metric, divergences.
    let cs = &e["cmdstanpy"];
    let columns: Vec<&str> = cs["columns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap())
        .collect();
    assert_eq!(
        columns,
        [
            "lp__",
            "accept_stat__",
            "stepsize__",
            "treedepth__",
            "n_leapfrog__",
            "divergent__",
            "energy__",
            "theta[1]",
            "theta[2]",
            "theta[3]"
        ]
    );
    let steps = numbers(&cs["step_size"]);
    let metric = &cs["metric"];
    for (c, ch) in fit.chains.iter().enumerate() {
        assert_eq!(steps[c], ch.step_size);
        let diag: Vec<f64> = (0..3).map(|i| ch.inverse_metric[i * 3 + i]).collect();
        assert_eq!(numbers(&metric[c]), diag);
    }
    assert_eq!(
        cs["divergences"].as_u64().unwrap() as usize,
        fit.divergences()
    );
    assert_eq!(cs["draws"].as_u64().unwrap(), 200);
}
