#!/usr/bin/env python3
"""Extracts the facts the `posteriordb` example compares against, from a
checkout of https://github.com/stan-dev/posteriordb (git directory given as
the first argument; read with `git show`, nothing is checked out):

- the data set of each posterior (copied verbatim);
- per reference quantity, the mean and sd of posteriordb's reference draws
  (10 chains x 1000 draws of Stan, thinned by 10) and their Monte Carlo
  standard errors, from the bulk ESS posteriordb reports for that quantity:
  mcse_mean = sd / sqrt(ess), mcse_sd = sqrt((m4 - s^4) / ess) / (2 s)
  (delta method on s^2, whose variance is (m4 - s^4)/n for independent
  draws; the reference draws are near-independent: posteriordb checks
  |lag-1 autocorrelation| < 0.05).

`dogs-dogs` (a logistic regression) is read at commit ce288e2 (12 Aug
2022): posteriordb computed its reference draws in April 2020 and removed
them in 0548b9e (15 Aug 2022) together with a fix to the data (the old file
has a 31st dog whose 25 trials are all 0, an artifact of reading the
original table). The data and the draws of ce288e2 belong together: the
reference is Stan's posterior of this model given those 31 rows. No
logistic regression has reference draws at posteriordb's HEAD (v1.0).

Usage: python3 extract.py /work/.mirror/stan-dev+posteriordb/repo
Writes one <posterior>.json per posterior next to this script. Python's
standard library only.
"""
import io, json, math, os, subprocess, sys, zipfile

# The commit of the last posteriordb version with dogs-dogs's reference draws.
DOGS = "ce288e20651cd1b4dcc30586c23a80d52a8f5cbb"

# (file name here, posteriordb posterior whose data we use, posterior whose
# reference draws we use[, git revision; default HEAD])
POSTERIORS = [
    ("eight_schools-eight_schools_noncentered", "eight_schools", "eight_schools-eight_schools_noncentered"),
    # Same model, centred parameterisation: posteriordb has no reference of
    # its own; the posterior of (mu, tau, theta) is the same.
    ("eight_schools-eight_schools_centered", "eight_schools", "eight_schools-eight_schools_noncentered"),
    ("arK-arK", "arK", "arK-arK"),
    ("arma-arma11", "arma", "arma-arma11"),
    ("gp_pois_regr-gp_regr", "gp_pois_regr", "gp_pois_regr-gp_regr"),
    ("gp_pois_regr-gp_pois_regr", "gp_pois_regr", "gp_pois_regr-gp_pois_regr"),
    ("kidiq-kidscore_momiq", "kidiq", "kidiq-kidscore_momiq"),
    ("sblrc-blr", "sblrc", "sblrc-blr"),
    ("low_dim_gauss_mix-low_dim_gauss_mix", "low_dim_gauss_mix", "low_dim_gauss_mix-low_dim_gauss_mix"),
    ("garch-garch11", "garch", "garch-garch11"),
    ("mesquite-logmesquite", "mesquite", "mesquite-logmesquite"),
    # Bernoulli-logit regression; data and draws of commit DOGS (see above).
    ("dogs-dogs", "dogs", "dogs-dogs", DOGS),
]

DB = "posterior_database"


def show(repo, rev, path):
    return subprocess.run(["git", "-C", repo, "show", rev + ":" + path], check=True, capture_output=True).stdout


def unzip_json(blob):
    with zipfile.ZipFile(io.BytesIO(blob)) as z:
        return json.loads(z.read(z.namelist()[0]))


def main(repo):
    here = os.path.dirname(os.path.abspath(__file__))
    for name, data_name, ref_name, *rev in POSTERIORS:
        rev = rev[0] if rev else "HEAD"
        commit = subprocess.run(["git", "-C", repo, "rev-parse", rev], check=True, capture_output=True, text=True).stdout.strip()
        data = unzip_json(show(repo, rev, f"{DB}/data/data/{data_name}.json.zip"))
        chains = unzip_json(show(repo, rev, f"{DB}/reference_posteriors/draws/draws/{ref_name}.json.zip"))
        info = json.loads(show(repo, rev, f"{DB}/reference_posteriors/draws/info/{ref_name}.info.json"))
        diag = info["diagnostics"]
        ess = dict(zip(diag["diagnostic_information"]["names"], diag["effective_sample_size_bulk"]))
        params = []
        for p in chains[0].keys():
            x = [v for c in chains for v in c[p]]
            n = len(x)
            m = sum(x) / n
            var = sum((v - m) ** 2 for v in x) / (n - 1)
            s = math.sqrt(var)
            m4 = sum((v - m) ** 4 for v in x) / n
            e = ess[p]
            params.append({
                "name": p,
                "mean": m,
                "sd": s,
                "mcse_mean": s / math.sqrt(e),
                "mcse_sd": math.sqrt(max(m4 - var * var, 0.0) / e) / (2.0 * s),
                "ess_bulk": e,
            })
        out = {
            "posterior": name,
            "reference_posterior": ref_name,
            "source": f"github.com/stan-dev/posteriordb @ {commit}",
            "reference_draws": n,
            "data": data,
            "reference": params,
        }
        with open(os.path.join(here, name + ".json"), "w") as f:
            json.dump(out, f, indent=1)
            f.write("\n")
        print(name, n, [q["name"] for q in params])


if __name__ == "__main__":
    main(sys.argv[1])
