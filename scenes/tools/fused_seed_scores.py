#!/usr/bin/env python3
"""Issue 18's verdict over seeds: score the 60 s study's CSVs (fused_s22_study.sh output).

    python3 scenes/tools/fused_seed_scores.py DIR [DIR ...]

Each DIR holds SCENE-seedS-TAG.csv files (TAG: fused, fused_conversion_lazy, mlt, mmlt). The last
row's corrected relMSE of each run is taken. Per scene it prints the per-seed table, and two
readings of the goal ("fused <= 1.2x the better of mlt and mmlt; the worse >= 2x fused"):
the ratio of the seeds' mean errors (the expected error, which weights a bad seed fully) and the
geometric mean of the per-seed ratios (which a single bad seed moves less). Seeds with a missing
run are left out. A second table per scene scores `lazy` alone over every seed where it, mlt
and mmlt ran (session 25 ran no eager `fused`).
"""

import csv
import glob
import math
import os
import sys

TAGS = {"fused": "fused", "fused_conversion_lazy": "lazy", "mlt": "mlt", "mmlt": "mmlt"}


def load(dirs):
    runs = {}
    for d in dirs:
        for path in glob.glob(os.path.join(d, "*-seed*-*.csv")):
            scene, rest = os.path.basename(path)[:-4].split("-seed")
            seed, tag = rest.split("-", 1)
            if tag in TAGS:
                rows = list(csv.DictReader(open(path)))
                runs[(scene, int(seed), TAGS[tag])] = float(rows[-1]["rel_mse_corrected"])
    return runs


def geo(xs):
    return math.exp(sum(math.log(x) for x in xs) / len(xs))


def table(runs, scene, variants):
    """Per-seed table and both readings for the fused VARIANTS, over the seeds where they, mlt
    and mmlt all ran."""
    cols = list(variants) + ["mlt", "mmlt"]
    seeds = sorted(s for s in {k[1] for k in runs if k[0] == scene}
                   if all((scene, s, i) in runs for i in cols))
    if not seeds:
        return
    keys = [f"{f}/better" for f in variants] + [f"worse/{f}" for f in variants]
    print(f"{scene}: seeds {seeds}")
    print("seed | " + " | ".join(cols) + " | " + " | ".join(keys))
    ratios = {k: [] for k in keys}

    def readings(v):
        best, worst = min(v["mlt"], v["mmlt"]), max(v["mlt"], v["mmlt"])
        return ([v[f] / best for f in variants] + [worst / v[f] for f in variants])

    for s in seeds:
        v = {i: runs[(scene, s, i)] for i in cols}
        r = readings(v)
        for k, x in zip(keys, r):
            ratios[k].append(x)
        print(f"{s} | " + " | ".join(f"{v[i]:.3e}" for i in cols) + " | "
              + " | ".join(f"{x:.2f}" for x in r))
    mean = {i: sum(runs[(scene, s, i)] for s in seeds) / len(seeds) for i in cols}
    print("mean | " + " | ".join(f"{mean[i]:.3e}" for i in cols) + " | "
          + " | ".join(f"{x:.2f}" for x in readings(mean)))
    print("geometric mean of the per-seed ratios | " + " | " * len(cols)
          + " | ".join(f"{geo(ratios[k]):.2f}" for k in keys))
    print()


def main():
    runs = load(sys.argv[1:])
    for scene in sorted({k[0] for k in runs}):
        # Both rules where both ran (sessions 22 and 24), then `lazy` over every seed it ran.
        table(runs, scene, ["fused", "lazy"])
        table(runs, scene, ["lazy"])


if __name__ == "__main__":
    main()
