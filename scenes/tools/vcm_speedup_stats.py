#!/usr/bin/env python3
"""Issue 16's >= 4x question over seeds: the corrected speedup of mcmc-vcm over vcm.

Usage: vcm_speedup_stats.py SCORES.csv [SCORES.csv ...] [--given SEED:SPEEDUP ...]

SCORES.csv are the per-image scores written for docs/vcm.md (columns seed, integrator,
reference, corrected_mse, ...; the rows scored with the second reference, the exact
correction, are used). --given adds seeds whose images are gone, as their speedup
(session 20's seeds 10-13). Prints, per seed set, the mean speedup with its standard
error, the 95% interval with Student's t (K-1 dof), the one-sided p of H0 "mean >= 4",
the geometric mean and, where every seed has scores, the ratio of the seeds' mean
MSEs with its jackknife standard error. No scipy: the t distribution is integrated here.
"""
import csv
import math
import statistics as st
import sys

REF = "long x s21 (second reference)"


def t_pdf(x, k):
    return math.exp(math.lgamma((k + 1) / 2) - math.lgamma(k / 2)) / math.sqrt(k * math.pi) * (1 + x * x / k) ** (-(k + 1) / 2)


def t_cdf(x, k, n=20000):
    """P(T <= x) for Student's t with k dof, by Simpson's rule from 0 to x."""
    h = x / n
    s = t_pdf(0, k) + t_pdf(x, k) + sum((4 if i % 2 else 2) * t_pdf(i * h, k) for i in range(1, n))
    return 0.5 + s * h / 3


def t_ppf(q, k):
    lo, hi = 0.0, 50.0
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if t_cdf(mid, k) < q else (lo, mid)
    return (lo + hi) / 2


def main(argv):
    files = [a for a in argv if not a.startswith("--") and ":" not in a]
    given = {int(a.split(":")[0]): float(a.split(":")[1]) for a in argv if ":" in a}
    mse, cpu = {}, {}
    for f in files:
        for r in csv.DictReader(open(f)):
            if r["reference"] == REF:
                mse[(int(r["seed"]), r["integrator"])] = float(r["corrected_mse"])
                if r.get("cpu_s"):
                    cpu[(int(r["seed"]), r["integrator"])] = float(r["cpu_s"])
    speedup = dict(given)
    for (s, i) in mse:
        if i == "vcm" and (s, "mcmc-vcm") in mse:
            speedup[s] = mse[(s, "vcm")] / mse[(s, "mcmc-vcm")]
    print("per-seed speedup:", {s: round(v, 2) for s, v in sorted(speedup.items())})
    for s in sorted(speedup):
        if (s, "vcm") in cpu and (s, "mcmc-vcm") in cpu:
            c = cpu[(s, "vcm")], cpu[(s, "mcmc-vcm")]
            print(f"seed {s}: CPU s vcm {c[0]:.1f}, mcmc-vcm {c[1]:.1f}; per CPU second {speedup[s] * c[0] / c[1]:.2f}")
    return speedup, mse


def summary(name, seeds, speedup, mse):
    x = [speedup[s] for s in seeds]
    k = len(x)
    m, se = st.mean(x), st.stdev(x) / math.sqrt(k)
    t = t_ppf(0.975, k - 1)
    p = t_cdf((m - 4) / se, k - 1)
    gm = math.exp(st.mean(math.log(v) for v in x))
    line = f"| {name} | {k} | {m:.2f} ± {se:.2f} | {m - t * se:.2f} – {m + t * se:.2f} (t = {t:.2f}) | {p:.3f} | {gm:.2f} |"
    if all((s, "vcm") in mse for s in seeds):
        a = [mse[(s, "vcm")] for s in seeds]
        b = [mse[(s, "mcmc-vcm")] for s in seeds]
        r = st.mean(a) / st.mean(b)
        jk = [st.mean(a[:i] + a[i + 1:]) / st.mean(b[:i] + b[i + 1:]) for i in range(k)]
        jm = st.mean(jk)
        jse = math.sqrt((k - 1) / k * sum((v - jm) ** 2 for v in jk))
        line += f" {r:.2f} ± {jse:.2f} (p = {t_cdf((r - 4) / jse, k - 1):.3f}) |"
    else:
        line += " — |"
    print(line)


if __name__ == "__main__":
    sp, ms = main(sys.argv[1:])
    print("| seeds | K | mean ± SE | 95% interval | one-sided p of H0: mean ≥ 4 | geometric mean | ratio of mean MSEs ± jackknife SE |")
    print("|---|---|---|---|---|---|---|")
    summary("all", sorted(sp), sp, ms)
    summary("with scores (images kept)", sorted(s for s in sp if (s, "vcm") in ms), sp, ms)
