//! A fit as one NumPy `.npz` archive: a columnar file that `numpy.load`
//! reads directly and ArviZ takes through `az.from_dict`.
//!
//! Every array has shape `(chains, draws)`: one per parameter (named as
//! given) and one per sampler statistic, named as CmdStan names its
//! columns — `lp__`, `accept_stat__`, `stepsize__`, `energy__` (float64),
//! `treedepth__`, `n_leapfrog__`, `divergent__` (int64, `divergent__` 0 or
//! 1). Entries are stored uncompressed, as `np.savez` writes them.
//!
//! ```python
//! import numpy as np, arviz as az
//! d = np.load("fit.npz")
//! idata = az.from_dict(
//!     posterior={k: d[k] for k in ["mu", "tau"]},
//!     sample_stats={"lp": d["lp__"], "energy": d["energy__"],
//!                   "diverging": d["divergent__"].astype(bool),
//!                   "tree_depth": d["treedepth__"], "step_size": d["stepsize__"]})
//! ```

use crate::fit::Fit;
use npyz::WriterBuilder;
use std::io::{self, Seek, Write};
use std::path::Path;

/// One `(chains, draws)` array into the archive.
fn array<W: Write + Seek, T: npyz::Serialize + npyz::AutoSerialize + Copy>(
    zip: &mut zip::ZipWriter<W>,
    name: &str,
    shape: [u64; 2],
    values: impl Iterator<Item = T>,
) -> io::Result<()> {
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Stored)
        .large_file(true);
    zip.start_file(npyz::npz::file_name_from_array_name(name), options)
        .map_err(io::Error::other)?;
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&shape)
        .writer(&mut *zip)
        .begin_nd()?;
    w.extend(values)?;
    w.finish()
}

/// Writes the draws and sampler statistics of `fit` to `out` as `.npz`;
/// `names` names the parameters (one per coordinate). Errors: I/O, or as
/// many names as coordinates not given (`InvalidInput`).
pub fn write_npz<W: Write + Seek>(out: W, fit: &Fit, names: &[String]) -> io::Result<()> {
    let d = fit
        .chains
        .first()
        .and_then(|c| c.draws.first())
        .map_or(0, Vec::len);
    if names.len() != d {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} names for {d} parameters", names.len()),
        ));
    }
    let chains = fit.chains.len() as u64;
    let draws = fit.chains.first().map_or(0, |c| c.draws.len()) as u64;
    let shape = [chains, draws];
    let mut zip = zip::ZipWriter::new(out);
    for (i, name) in names.iter().enumerate() {
        let v = fit
            .chains
            .iter()
            .flat_map(|c| c.draws.iter().map(move |x| x[i]));
        array(&mut zip, name, shape, v)?;
    }
    let stats = |f: fn(&crate::kernel::NutsDrawStatistics) -> f64| {
        fit.chains
            .iter()
            .flat_map(move |c| c.statistics.iter().map(f))
    };
    let lp = fit
        .chains
        .iter()
        .flat_map(|c| c.log_density.iter().copied());
    array(&mut zip, "lp__", shape, lp)?;
    array(&mut zip, "accept_stat__", shape, stats(|s| s.accept_stat))?;
    array(&mut zip, "stepsize__", shape, stats(|s| s.step_size))?;
    array(&mut zip, "energy__", shape, stats(|s| s.energy))?;
    let ints = |f: fn(&crate::kernel::NutsDrawStatistics) -> i64| {
        fit.chains
            .iter()
            .flat_map(move |c| c.statistics.iter().map(f))
    };
    array(
        &mut zip,
        "treedepth__",
        shape,
        ints(|s| s.tree_depth as i64),
    )?;
    array(
        &mut zip,
        "n_leapfrog__",
        shape,
        ints(|s| s.n_leapfrog as i64),
    )?;
    array(
        &mut zip,
        "divergent__",
        shape,
        ints(|s| i64::from(s.divergent)),
    )?;
    zip.finish().map_err(io::Error::other)?.flush()
}

/// [`write_npz`] to the file `path`.
pub fn write_npz_file(path: &Path, fit: &Fit, names: &[String]) -> io::Result<()> {
    let file = io::BufWriter::new(std::fs::File::create(path)?);
    write_npz(file, fit, names)
}
