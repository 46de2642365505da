#!/usr/bin/env python3
"""Summarise the glass-knot study (issue 15, session 30): corrected relMSE at the last
checkpoint per integrator and seed, upward steps between checkpoints, and the goal's
ratios (tempered-pssmlt over pssmlt-bdpt and over mept) with their mean over seeds.

Usage: python3 summary.py glass-knot-s30-seed1.csv glass-knot-s30-seed2.csv
"""
import csv
import math
import sys
from collections import defaultdict

# Student's t, 97.5% quantile, by degrees of freedom (K - 1).
T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776}

final = defaultdict(dict)  # integrator -> seed file -> corrected relMSE
ups = defaultdict(lambda: [0, 0])  # integrator -> [upward steps, steps]
for path in sys.argv[1:]:
    rows = defaultdict(list)
    with open(path) as f:
        for r in csv.DictReader(f):
            rows[r["integrator"]].append((float(r["seconds"]), float(r["rel_mse_corrected"])))
    for name, pts in rows.items():
        pts.sort()
        final[name][path] = pts[-1][1]
        for (_, a), (_, b) in zip(pts, pts[1:]):
            ups[name][0] += b > a
            ups[name][1] += 1

seeds = sys.argv[1:]
print("integrator | " + " | ".join(seeds) + " | upward steps")
for name in final:
    vals = " | ".join("%.3e" % final[name].get(s, float("nan")) for s in seeds)
    print(f"{name} | {vals} | {ups[name][0]} of {ups[name][1]}")
for other in ["pssmlt-bdpt", "mept"]:
    r = [final["tempered-pssmlt"][s] / final[other][s] for s in seeds]
    line = ", ".join("%.2f" % x for x in r)
    if len(r) > 1:
        m = sum(r) / len(r)
        se = math.sqrt(sum((x - m) ** 2 for x in r) / (len(r) - 1) / len(r))
        t = T975.get(len(r) - 1, 2.0)
        line += "; mean %.2f ± %.2f (95%%: %.2f – %.2f)" % (m, se, m - t * se, m + t * se)
    print(f"tempered-pssmlt / {other}: {line}")
