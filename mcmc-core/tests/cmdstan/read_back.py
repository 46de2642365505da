#!/usr/bin/env python3
"""Read the CmdStan CSV files mcmc-core wrote back with ArviZ and cmdstanpy.

The files `fit-1.csv` and `fit-2.csv` next to this script are written by
`mcmc_core::cmdstan` (see `mcmc-core/tests/cmdstan_csv.rs`). This script
records what ArviZ and cmdstanpy parse from them; the Rust test checks that
against the fit it regenerates. Run (needs `pip install "arviz<0.24" cmdstanpy`):

    python3 mcmc-core/tests/cmdstan/read_back.py > mcmc-core/tests/cmdstan/expected.json

Tested with ArviZ 0.23.4, cmdstanpy 1.3.2, numpy 2.4.6.
"""

import json
import os
import sys
import warnings

warnings.filterwarnings("ignore")

import arviz as az  # noqa: E402
import cmdstanpy  # noqa: E402
import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
FILES = [os.path.join(HERE, f"fit-{c}.csv") for c in (1, 2)]


def floats(a):
    return np.asarray(a, dtype=float).tolist()


def main():
    idata = az.from_cmdstan(posterior=FILES)
    post = idata.posterior
    stats = idata.sample_stats
    summary = az.summary(idata, var_names=["theta"], kind="diagnostics", round_to="none")
    out = {
        "versions": {
            "arviz": az.__version__,
            "cmdstanpy": cmdstanpy.__version__,
            "numpy": np.__version__,
        },
        "arviz": {
            "theta": floats(post["theta"].values),
            "sample_stats": {
                name: floats(stats[name].values)
                for name in [
                    "lp",
                    "acceptance_rate",
                    "step_size",
                    "tree_depth",
                    "n_steps",
                    "diverging",
                    "energy",
                ]
            },
            "bfmi": floats(az.bfmi(idata)),
            "rhat": floats(summary["r_hat"].values),
            "ess_bulk": floats(summary["ess_bulk"].values),
        },
    }
    fit = cmdstanpy.from_csv(path=FILES)
    out["cmdstanpy"] = {
        "columns": list(fit.column_names),
        "step_size": floats(fit.step_size),
        "metric": floats(fit.inv_metric),
        "divergences": int(np.sum(fit.divergences)),
        "draws": int(fit.num_draws_sampling),
    }
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
