//! `.npz` output read back by numpy.
//!
//! `tests/npz/fit.npz` is what `mcmc_core::npz` writes for a fixed fit
//! (2 chains of NUTS on a 3-d AR(1) Gaussian, seed 9);
//! `tests/npz/read_back.py` reads it with `numpy.load` — the arrays ArviZ's
//! `az.from_dict` takes — and records what numpy sees in
//! `tests/npz/expected.json` (committed; CI needs no Python):
//!
//! ```text
//! MCMC_WRITE_NPZ=1 cargo test -p mcmc-core --test npz   # rewrite fit.npz
//! python3 mcmc-core/tests/npz/read_back.py > mcmc-core/tests/npz/expected.json
//! ```
//!
//! This test regenerates the fit, checks that the writer still produces
//! the committed bytes, and compares numpy's reading with the fit.

use mcmc_core::adaptation::{AcceptanceStatistic, MetricAdaptation, StepSizeAdaptation};
use mcmc_core::fit::{Fit, NutsSettings, sample_nuts};
use mcmc_core::npz::write_npz;
use serde_json::Value;
use std::io::Cursor;
use std::path::PathBuf;

mod common;
use common::Ar1Gaussian;

fn fit() -> Fit {
    let s = NutsSettings {
        chains: 2,
        warmup: 200,
        draws: 100,
        seed: 9,
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
    sample_nuts(&Ar1Gaussian::new(3, 0.5), &s, None::<fn(usize) -> Vec<f64>>).unwrap()
}

fn names() -> Vec<String> {
    vec!["x.1".into(), "x.2".into(), "x.3".into()]
}

fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/npz")
}

/// The fit's values of array `name`, chain-major (numpy's C order).
fn values(fit: &Fit, name: &str) -> Vec<f64> {
    let per_draw = |c: &mcmc_core::fit::ChainFit, t: usize| -> f64 {
        let s = &c.statistics[t];
        match name {
            "lp__" => c.log_density[t],
            "accept_stat__" => s.accept_stat,
            "stepsize__" => s.step_size,
            "energy__" => s.energy,
            "treedepth__" => s.tree_depth as f64,
            "n_leapfrog__" => s.n_leapfrog as f64,
            "divergent__" => f64::from(u8::from(s.divergent)),
            x => c.draws[t][x[2..].parse::<usize>().unwrap() - 1],
        }
    };
    fit.chains
        .iter()
        .flat_map(|c| (0..c.draws.len()).map(move |t| per_draw(c, t)))
        .collect()
}

#[test]
fn npz_reads_back_in_numpy() {
    let fit = fit();
    let mut bytes = Cursor::new(Vec::new());
    write_npz(&mut bytes, &fit, &names()).unwrap();
    let bytes = bytes.into_inner();
    let path = dir().join("fit.npz");
    if std::env::var_os("MCMC_WRITE_NPZ").is_some() {
        std::fs::write(&path, &bytes).unwrap();
    }
    assert!(
        std::fs::read(&path).unwrap() == bytes,
        "the writer no longer produces the committed fit.npz"
    );
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap())
            .unwrap();
    let arrays = expected["arrays"].as_object().unwrap();
    assert_eq!(arrays.len(), 3 + 7, "numpy saw {:?}", arrays.keys());
    for (name, a) in arrays {
        let v = values(&fit, name);
        assert_eq!(a["shape"], serde_json::json!([2, 100]), "{name}");
        let int = ["treedepth__", "n_leapfrog__", "divergent__"].contains(&name.as_str());
        assert_eq!(a["dtype"], if int { "<i8" } else { "<f8" }, "{name}");
        // Elements are read bit-exactly; numpy sums pairwise, we in order,
        // so the sums agree to rounding (≈ 200 terms × 1e-16 relative).
        assert_eq!(a["first"].as_f64().unwrap(), v[0], "{name}[0, 0]");
        assert_eq!(
            a["last"].as_f64().unwrap(),
            v[v.len() - 1],
            "{name}[-1, -1]"
        );
        let sum: f64 = v.iter().sum();
        let scale: f64 = v.iter().map(|x| x.abs()).sum::<f64>().max(1.0);
        assert!(
            (a["sum"].as_f64().unwrap() - sum).abs() <= 1e-12 * scale,
            "{name}: numpy sum {} vs {sum}",
            a["sum"]
        );
    }
}

/// Control: the comparison tells coordinates apart — `x.2`'s values do not
/// pass for numpy's `x.1`.
#[test]
fn comparison_detects_a_swapped_column() {
    let fit = fit();
    let expected: Value =
        serde_json::from_str(&std::fs::read_to_string(dir().join("expected.json")).unwrap())
            .unwrap();
    let x1 = &expected["arrays"]["x.1"];
    let v = values(&fit, "x.2");
    assert_ne!(x1["first"].as_f64().unwrap(), v[0]);
    assert_ne!(x1["sum"].as_f64().unwrap(), v.iter().sum::<f64>());
}

/// A wrong number of names is an error, not a malformed archive.
#[test]
fn name_count_must_match() {
    let fit = fit();
    let mut out = Cursor::new(Vec::new());
    let e = write_npz(&mut out, &fit, &names()[..2]).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
}
