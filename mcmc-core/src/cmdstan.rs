//! CmdStan-format CSV output of a [`Fit`]: one file per chain that
//! `arviz.from_cmdstan` and `cmdstanpy.from_csv` read.
//!
//! Layout (CmdStan 2.3x `sample` output): `#` comment lines with the run's
//! configuration (`method = sample`, `num_samples`, `num_warmup`,
//! `save_warmup = 0`, `thin = 1`, `adapt delta`, `algorithm = hmc`,
//! `engine = nuts`, `max_depth`, `metric`, `id`, `seed`), the header
//! `lp__,accept_stat__,stepsize__,treedepth__,n_leapfrog__,divergent__,energy__`
//! followed by the parameter columns, the adaptation block (step size and
//! the inverse metric), one row per kept draw, and the elapsed times.
//! Numbers are written with Rust's shortest round-trip formatting, so the
//! draws read back bit-exactly. `lp__` is our `ln π`, i.e. Stan's `lp__` up
//! to an additive constant.
//!
//! Parameter names follow CmdStan: a vector `theta` of length 3 is
//! `theta.1,theta.2,theta.3` (see [`vector_names`]).

use crate::adaptation::MetricAdaptation;
use crate::fit::{ChainFit, Fit};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// CmdStan's column names for a vector parameter: `name.1 … name.len`.
pub fn vector_names(name: &str, len: usize) -> Vec<String> {
    (1..=len).map(|i| format!("{name}.{i}")).collect()
}

/// Writes chain `chain` of `fit` as CmdStan CSV to `out`. `names` are the
/// parameter columns (one per coordinate); `model` is the model name
/// written in the header comment.
pub fn write_chain<W: Write>(
    mut out: W,
    fit: &Fit,
    chain: usize,
    model: &str,
    names: &[String],
) -> io::Result<()> {
    let c: &ChainFit = fit.chains.get(chain).ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "chain {chain} does not exist (the fit has {})",
                fit.chains.len()
            ),
        )
    })?;
    let d = c.draws.first().map_or(names.len(), Vec::len);
    if names.len() != d {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} parameter names for {d} coordinates", names.len()),
        ));
    }
    if let Some(bad) = names
        .iter()
        .find(|n| n.is_empty() || n.contains([',', '\n', '"']))
    {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("parameter name {bad:?} is empty or holds a comma, quote or newline"),
        ));
    }
    let s = &fit.settings;
    let metric = match s.metric {
        MetricAdaptation::Dense => "dense_e",
        _ if c.dense_metric => "dense_e",
        _ => "diag_e",
    };
    writeln!(out, "# stan_version_major = 2")?;
    writeln!(out, "# stan_version_minor = 36")?;
    writeln!(out, "# stan_version_patch = 0")?;
    writeln!(out, "# model = {model}")?;
    writeln!(out, "# method = sample (Default)")?;
    writeln!(out, "#   sample")?;
    writeln!(out, "#     num_samples = {}", s.draws)?;
    writeln!(out, "#     num_warmup = {}", s.warmup)?;
    writeln!(out, "#     save_warmup = 0 (Default)")?;
    writeln!(out, "#     thin = 1 (Default)")?;
    writeln!(out, "#     adapt")?;
    writeln!(out, "#       engaged = {}", u8::from(s.warmup > 0))?;
    writeln!(out, "#       delta = {}", s.target_accept)?;
    writeln!(out, "#     algorithm = hmc (Default)")?;
    writeln!(out, "#       hmc")?;
    writeln!(out, "#         engine = nuts (Default)")?;
    writeln!(out, "#           nuts")?;
    writeln!(out, "#             max_depth = {}", s.max_depth)?;
    writeln!(out, "#         metric = {metric}")?;
    writeln!(out, "#         stepsize = {}", s.initial_step_size)?;
    writeln!(out, "#     num_chains = 1 (Default)")?;
    writeln!(out, "# id = {}", chain + 1)?;
    writeln!(out, "# random")?;
    writeln!(out, "#   seed = {}", s.seed)?;
    writeln!(out, "# output")?;
    writeln!(out, "#   sig_figs = -1 (Default)")?;
    writeln!(out, "# sampler = mcmc-core NUTS")?;
    write!(
        out,
        "lp__,accept_stat__,stepsize__,treedepth__,n_leapfrog__,divergent__,energy__"
    )?;
    for n in names {
        write!(out, ",{n}")?;
    }
    writeln!(out)?;
    writeln!(out, "# Adaptation terminated")?;
    writeln!(out, "# Step size = {}", c.step_size)?;
    if c.dense_metric {
        writeln!(out, "# Elements of inverse mass matrix:")?;
        for row in c.inverse_metric.chunks(d.max(1)) {
            writeln!(out, "# {}", join(row))?;
        }
    } else {
        writeln!(out, "# Diagonal elements of inverse mass matrix:")?;
        let diag: Vec<f64> = (0..d).map(|i| c.inverse_metric[i * d + i]).collect();
        writeln!(out, "# {}", join(&diag))?;
    }
    for ((x, lp), st) in c.draws.iter().zip(&c.log_density).zip(&c.statistics) {
        write!(
            out,
            "{lp},{},{},{},{},{},{}",
            st.accept_stat,
            st.step_size,
            st.tree_depth,
            st.n_leapfrog,
            u8::from(st.divergent),
            st.energy
        )?;
        for v in x {
            write!(out, ",{v}")?;
        }
        writeln!(out)?;
    }
    let (warm, sample) = c.seconds;
    writeln!(out, "# ")?;
    writeln!(out, "#  Elapsed Time: {warm} seconds (Warm-up)")?;
    writeln!(out, "#                {sample} seconds (Sampling)")?;
    writeln!(out, "#                {} seconds (Total)", warm + sample)?;
    writeln!(out, "# ")?;
    out.flush()
}

/// Writes every chain of `fit` to `{dir}/{model}-{c}.csv` (`c` from 1, as
/// CmdStan numbers chains) and returns the paths.
pub fn write_fit(dir: &Path, fit: &Fit, model: &str, names: &[String]) -> io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    (0..fit.chains.len())
        .map(|c| {
            let path = dir.join(format!("{model}-{}.csv", c + 1));
            let file = io::BufWriter::new(std::fs::File::create(&path)?);
            write_chain(file, fit, c, model, names)?;
            Ok(path)
        })
        .collect()
}

fn join(values: &[f64]) -> String {
    values
        .iter()
        .map(|v| v.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}
