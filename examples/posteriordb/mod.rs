//! Reference posteriors from posteriordb (github.com/stan-dev/posteriordb):
//! our NUTS ([`mcmc_core::fit::sample_nuts`]) on each posterior, its means
//! and standard deviations compared with posteriordb's reference draws.
//!
//! Each model's log density and gradient are written by hand from its Stan
//! program ([`models`]); the data and the reference means, sds and their
//! Monte Carlo standard errors are facts from posteriordb, committed in
//! `reference/` (extracted by `reference/extract.py`).
//!
//! Per posterior and reported quantity the comparison is the z-score
//! `(ours − reference) / √(MCSE_ours² + MCSE_ref²)`, for the mean and for the
//! sd (our MCSEs: [`mcmc_core::diagnostics::Summary`]). Also reported: ESS
//! per gradient evaluation (smallest bulk ESS over quantities divided by
//! every gradient evaluation, warm-up included), divergences after warm-up,
//! the largest R-hat.

pub mod models;
pub mod transforms;

use mcmc_core::cmdstan::write_fit;
use mcmc_core::diagnostics::summarize;
use mcmc_core::fit::{Fit, NutsSettings, sample_nuts};
use mcmc_core::gradient::GradientTarget;
use mcmc_core::npz::write_npz_file;
use models::{
    Ark, Arma11, EightSchools, Garch11, GaussMix, GpRegression, LinearRegression,
    LogisticRegression, Model,
};
use serde::Serialize;
use serde_json::Value;
use std::path::Path;
use std::sync::Arc;

/// One reported quantity's reference values.
#[derive(Clone, Debug)]
pub struct Reference {
    /// posteriordb's name (`theta[1]`, `sigma`, …).
    pub name: String,
    /// Mean of the reference draws.
    pub mean: f64,
    /// Standard deviation of the reference draws.
    pub sd: f64,
    /// Monte Carlo standard error of `mean`.
    pub mcse_mean: f64,
    /// Monte Carlo standard error of `sd`.
    pub mcse_sd: f64,
}

/// A posterior: the hand-written model and posteriordb's reference.
#[derive(Clone)]
pub struct Posterior {
    /// posteriordb's name (`<data>-<model>`).
    pub name: &'static str,
    /// The model (unconstrained log density, gradient, constrained quantities).
    pub model: Arc<dyn Model>,
    /// Reference values, in the order of `model.names()`.
    pub reference: Vec<Reference>,
    /// True for the centred eight schools, whose funnel makes NUTS diverge:
    /// its divergences are the expected finding, not a failure.
    pub expect_divergences: bool,
}

/// The reference files, compiled in: (posterior, JSON).
const FILES: [(&str, &str); 11] = [
    (
        "eight_schools-eight_schools_noncentered",
        include_str!("reference/eight_schools-eight_schools_noncentered.json"),
    ),
    (
        "eight_schools-eight_schools_centered",
        include_str!("reference/eight_schools-eight_schools_centered.json"),
    ),
    ("arK-arK", include_str!("reference/arK-arK.json")),
    ("arma-arma11", include_str!("reference/arma-arma11.json")),
    (
        "garch-garch11",
        include_str!("reference/garch-garch11.json"),
    ),
    (
        "gp_pois_regr-gp_regr",
        include_str!("reference/gp_pois_regr-gp_regr.json"),
    ),
    (
        "kidiq-kidscore_momiq",
        include_str!("reference/kidiq-kidscore_momiq.json"),
    ),
    ("sblrc-blr", include_str!("reference/sblrc-blr.json")),
    (
        "mesquite-logmesquite",
        include_str!("reference/mesquite-logmesquite.json"),
    ),
    (
        "low_dim_gauss_mix-low_dim_gauss_mix",
        include_str!("reference/low_dim_gauss_mix-low_dim_gauss_mix.json"),
    ),
    // The reference of posteriordb commit ce288e2 with that commit's data
    // (posteriordb removed both in 2022; `reference/extract.py` says why).
    ("dogs-dogs", include_str!("reference/dogs-dogs.json")),
];

/// Names of every posterior, in the order they run.
pub fn names() -> Vec<&'static str> {
    FILES.iter().map(|(n, _)| *n).collect()
}

/// The model of posterior `name` on posteriordb's `data`.
fn model(name: &str, data: &Value) -> Result<Arc<dyn Model>, String> {
    Ok(match name {
        "eight_schools-eight_schools_noncentered" => Arc::new(EightSchools::new(data, false)?),
        "eight_schools-eight_schools_centered" => Arc::new(EightSchools::new(data, true)?),
        "arK-arK" => Arc::new(Ark::new(data)?),
        "arma-arma11" => Arc::new(Arma11::new(data)?),
        "garch-garch11" => Arc::new(Garch11::new(data)?),
        "gp_pois_regr-gp_regr" => Arc::new(GpRegression::new(data)?),
        "kidiq-kidscore_momiq" => Arc::new(LinearRegression::kidscore_momiq(data)?),
        "sblrc-blr" => Arc::new(LinearRegression::blr(data)?),
        "mesquite-logmesquite" => Arc::new(LinearRegression::logmesquite(data)?),
        "low_dim_gauss_mix-low_dim_gauss_mix" => Arc::new(GaussMix::new(data)?),
        "dogs-dogs" => Arc::new(LogisticRegression::dogs(data)?),
        other => return Err(format!("unknown posterior `{other}`")),
    })
}

/// Loads posterior `name` (one of [`names`]).
pub fn load(name: &str) -> Result<Posterior, String> {
    let (name, json) = FILES
        .iter()
        .find(|(n, _)| *n == name)
        .ok_or_else(|| format!("unknown posterior `{name}` (known: {})", names().join(", ")))?;
    let file: Value =
        serde_json::from_str(json).map_err(|e| format!("reference/{name}.json: {e}"))?;
    let data = file
        .get("data")
        .ok_or_else(|| format!("reference/{name}.json: no `data`"))?;
    let model = model(name, data).map_err(|e| format!("reference/{name}.json: {e}"))?;
    let refs = file
        .get("reference")
        .and_then(Value::as_array)
        .ok_or_else(|| format!("reference/{name}.json: no `reference` array"))?;
    let reference = model
        .names()
        .iter()
        .map(|q| {
            let r = refs
                .iter()
                .find(|r| r.get("name").and_then(Value::as_str) == Some(q))
                .ok_or_else(|| format!("reference/{name}.json: no reference for `{q}`"))?;
            let num = |k: &str| {
                r.get(k)
                    .and_then(Value::as_f64)
                    .ok_or_else(|| format!("reference/{name}.json: `{q}` has no `{k}`"))
            };
            Ok(Reference {
                name: q.clone(),
                mean: num("mean")?,
                sd: num("sd")?,
                mcse_mean: num("mcse_mean")?,
                mcse_sd: num("mcse_sd")?,
            })
        })
        .collect::<Result<_, String>>()?;
    Ok(Posterior {
        name,
        model,
        reference,
        expect_divergences: *name == "eight_schools-eight_schools_centered",
    })
}

/// One quantity's comparison.
#[derive(Clone, Debug, Serialize)]
pub struct Comparison {
    /// Quantity name.
    pub name: String,
    /// Reference mean and its MCSE.
    pub reference_mean: f64,
    /// MCSE of the reference mean.
    pub reference_mcse_mean: f64,
    /// Our mean.
    pub mean: f64,
    /// Our MCSE of the mean.
    pub mcse_mean: f64,
    /// `(mean − reference_mean) / √(mcse_mean² + reference_mcse_mean²)`.
    pub z_mean: f64,
    /// Reference sd.
    pub reference_sd: f64,
    /// MCSE of the reference sd.
    pub reference_mcse_sd: f64,
    /// Our sd.
    pub sd: f64,
    /// Our MCSE of the sd.
    pub mcse_sd: f64,
    /// `(sd − reference_sd) / √(mcse_sd² + reference_mcse_sd²)`.
    pub z_sd: f64,
    /// Our bulk ESS.
    pub ess_bulk: f64,
    /// Our rank-normalised split R-hat.
    pub rhat: f64,
}

/// One posterior's result.
#[derive(Clone, Debug, Serialize)]
pub struct PosteriorReport {
    /// posteriordb's name.
    pub posterior: String,
    /// Unconstrained dimension.
    pub dim: usize,
    /// Gradient evaluations, warm-up included, over all chains.
    pub gradient_evaluations: u64,
    /// Smallest bulk ESS over the reported quantities.
    pub ess_bulk_min: f64,
    /// `ess_bulk_min / gradient_evaluations`.
    pub ess_per_gradient: f64,
    /// Divergent transitions after warm-up, over all chains.
    pub divergences: usize,
    /// Whether divergences are the expected finding (centred eight schools).
    pub divergences_expected: bool,
    /// Largest |z| over means and sds.
    pub max_abs_z: f64,
    /// Largest R-hat.
    pub rhat_max: f64,
    /// Wall-clock seconds (warm-up and sampling, chains in parallel).
    pub seconds: f64,
    /// Per quantity.
    pub quantities: Vec<Comparison>,
    /// Per chain: what the warm-up ended with and how sampling went.
    pub chains: Vec<ChainReport>,
}

/// One chain's adapted step size, metric and sampling statistics: where
/// divergences come from (one chain with a large step, or all chains).
#[derive(Clone, Debug, Serialize)]
pub struct ChainReport {
    /// Step size after warm-up.
    pub step_size: f64,
    /// Diagonal of `M⁻¹` after warm-up, on the unconstrained coordinates.
    pub inverse_metric_diagonal: Vec<f64>,
    /// Divergent transitions after warm-up.
    pub divergences: usize,
    /// Mean `accept_stat` after warm-up (the adaptation's target is
    /// `adapt_delta`).
    pub accept_stat_mean: f64,
    /// Mean leapfrog steps per draw after warm-up.
    pub leapfrog_mean: f64,
}

/// Runs NUTS on `posterior` with `settings` and compares with the
/// reference; returns the report and the fit with its draws mapped to the
/// reported (constrained) quantities, for [`write_outputs`].
pub fn run(
    posterior: &Posterior,
    settings: &NutsSettings,
) -> Result<(PosteriorReport, Fit), String> {
    let clock = std::time::Instant::now();
    let mut fit = sample_nuts(&posterior.model, settings, None::<fn(usize) -> Vec<f64>>)
        .map_err(|e| format!("{}: {e}", posterior.name))?;
    let seconds = clock.elapsed().as_secs_f64();
    let constrained: Vec<Vec<Vec<f64>>> = fit
        .chains
        .iter()
        .map(|c| {
            c.draws
                .iter()
                .map(|x| posterior.model.constrain(x))
                .collect()
        })
        .collect();
    let summary = summarize(&constrained).map_err(|e| format!("{}: {e}", posterior.name))?;
    let quantities: Vec<Comparison> = posterior
        .reference
        .iter()
        .zip(&summary)
        .map(|(r, s)| Comparison {
            name: r.name.clone(),
            reference_mean: r.mean,
            reference_mcse_mean: r.mcse_mean,
            mean: s.mean,
            mcse_mean: s.mcse_mean,
            z_mean: (s.mean - r.mean) / s.mcse_mean.hypot(r.mcse_mean),
            reference_sd: r.sd,
            reference_mcse_sd: r.mcse_sd,
            sd: s.sd,
            mcse_sd: s.mcse_sd,
            z_sd: (s.sd - r.sd) / s.mcse_sd.hypot(r.mcse_sd),
            ess_bulk: s.ess_bulk,
            rhat: s.rhat,
        })
        .collect();
    let ess_bulk_min = quantities
        .iter()
        .map(|q| q.ess_bulk)
        .fold(f64::INFINITY, f64::min);
    let gradient_evaluations = fit.gradient_evaluations();
    for (c, draws) in fit.chains.iter_mut().zip(constrained) {
        c.draws = draws;
    }
    let d = posterior.model.dim();
    let chains = fit
        .chains
        .iter()
        .map(|c| {
            let n = c.statistics.len().max(1) as f64;
            ChainReport {
                step_size: c.step_size,
                inverse_metric_diagonal: (0..d).map(|i| c.inverse_metric[i * d + i]).collect(),
                divergences: c.divergences(),
                accept_stat_mean: c.statistics.iter().map(|s| s.accept_stat).sum::<f64>() / n,
                leapfrog_mean: c.leapfrog_steps() as f64 / n,
            }
        })
        .collect();
    let report = PosteriorReport {
        posterior: posterior.name.to_string(),
        dim: posterior.model.dim(),
        gradient_evaluations,
        ess_bulk_min,
        ess_per_gradient: ess_bulk_min / gradient_evaluations as f64,
        divergences: fit.divergences(),
        divergences_expected: posterior.expect_divergences,
        max_abs_z: quantities
            .iter()
            .flat_map(|q| [q.z_mean.abs(), q.z_sd.abs()])
            .fold(0.0, f64::max),
        rhat_max: quantities
            .iter()
            .map(|q| q.rhat)
            .fold(f64::NEG_INFINITY, f64::max),
        seconds,
        quantities,
        chains,
    };
    Ok((report, fit))
}

/// Writes `fit` (constrained draws) of `posterior` to `dir` as CmdStan CSV
/// files `<posterior>-<chain>.csv` and one `<posterior>.npz`.
pub fn write_outputs(dir: &Path, posterior: &Posterior, fit: &Fit) -> Result<(), String> {
    let names: Vec<String> = posterior.model.names();
    let fail = |e: std::io::Error| format!("{}: {e}", dir.display());
    // CmdStan spells `theta[1]` as `theta.1` (ArviZ rebuilds vectors from it).
    let cmdstan: Vec<String> = names
        .iter()
        .map(|n| n.replace('[', ".").replace(']', ""))
        .collect();
    write_fit(dir, fit, posterior.name, &cmdstan).map_err(fail)?;
    write_npz_file(&dir.join(format!("{}.npz", posterior.name)), fit, &names).map_err(fail)
}
