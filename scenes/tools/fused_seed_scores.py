#!/usr/bin/env python3
"""Issue 18's verdict over seeds: score the 60 s study's CSVs (fused_s22_study.sh output).

    python3 scenes/tools/fused_seed_scores.py DIR [DIR ...]

Each DIR holds SCENE-seedS-TAG.csv files (TAG: fused, fused_conversion_lazy, mlt, mmlt). The last
row's corrected relMSE of each run is taken. Per scene it prints the per-seed table, and two
readings of the goal ("fused <= 1.2x the better of mlt and mmlt; the worse >= 2x fused"):
the ratio of the seeds' mean errors (the expected error, which weights a bad seed fully) and the
geometric mean of the per-seed ratios (which a single bad seed moves less). Seeds with a missing
run are left out.
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


def main():
    runs = load(sys.argv[1:])
    for scene in sorted({k[0] for k in runs}):
        seeds = sorted(s for s in {k[1] for k in runs if k[0] == scene}
                       if all((scene, s, i) in runs for i in TAGS.values()))
        print(f"{scene}: seeds {seeds}")
        print("seed | fused | lazy | mlt | mmlt | fused/better | lazy/better | worse/fused | worse/lazy")
        ratios = {"fb": [], "lb": [], "wf": [], "wl": []}
        for s in seeds:
            v = {i: runs[(scene, s, i)] for i in TAGS.values()}
            best, worst = min(v["mlt"], v["mmlt"]), max(v["mlt"], v["mmlt"])
            r = {"fb": v["fused"] / best, "lb": v["lazy"] / best,
                 "wf": worst / v["fused"], "wl": worst / v["lazy"]}
            for k in r:
                ratios[k].append(r[k])
            print(f"{s} | " + " | ".join(f"{v[i]:.3e}" for i in TAGS.values()) + " | "
                  + " | ".join(f"{r[k]:.2f}" for k in ("fb", "lb", "wf", "wl")))
        mean = {i: sum(runs[(scene, s, i)] for s in seeds) / len(seeds) for i in TAGS.values()}
        best, worst = min(mean["mlt"], mean["mmlt"]), max(mean["mlt"], mean["mmlt"])
        print("mean | " + " | ".join(f"{mean[i]:.3e}" for i in TAGS.values()) + " | "
              + " | ".join(f"{x:.2f}" for x in (mean["fused"] / best, mean["lazy"] / best,
                                                 worst / mean["fused"], worst / mean["lazy"])))
        print("geometric mean of the per-seed ratios | | | | | "
              + " | ".join(f"{geo(ratios[k]):.2f}" for k in ("fb", "lb", "wf", "wl")))
        print()


if __name__ == "__main__":
    main()
