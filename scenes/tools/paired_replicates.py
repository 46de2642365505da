#!/usr/bin/env python3
"""Paired differences of SMCMC replicates (docs/smcmc.md, "Session 32").

The glossy/glass-box agreement tests of mcmc-render/tests/smcmc.rs print one
line per replicate, "replicate seed N: [r, g, b]" (the image mean). Runs of
the same seeds that differ only in how the image is developed (the tile
alignment) share their chains, so the per-seed difference measures the
development's effect with far less noise than either run against PT.

    python3 scenes/tools/paired_replicates.py BASE.log [OTHER.log ...]

prints BASE's relative difference from the glossy box's PT reference (its
mean over the replicates and standard error, %), then for each OTHER the
mean of (BASE - OTHER) / reference over the shared seeds and its standard
error (%). Pass REF="r,g,b" to use another reference (the Cornell box's
replicates are compared with their own means instead when REF=self).
"""
import os
import re
import sys

import numpy as np

# PT's image mean of the glossy/glass box (tests/smcmc.rs, glossy_glass_pt()).
GLOSSY_PT = [0.06896990765492372, 0.036968070608204506, 0.012304528440426399]


def replicates(path):
    out = {}
    for line in open(path):
        m = re.match(r"replicate seed (\d+): \[([^\]]+)\]", line)
        if m:
            out[int(m.group(1))] = np.array([float(x) for x in m.group(2).split(",")])
    return out


def main():
    base = replicates(sys.argv[1])
    rows = np.array([base[k] for k in sorted(base)])
    ref_env = os.environ.get("REF", "")
    if ref_env == "self":
        ref = rows.mean(0)
    elif ref_env:
        ref = np.array([float(x) for x in ref_env.split(",")])
    else:
        ref = np.array(GLOSSY_PT)
    rel = rows / ref - 1
    se = rel.std(0, ddof=1) / np.sqrt(len(rel))
    print(f"{sys.argv[1]}: {len(rel)} replicates, rel % {np.round(rel.mean(0) * 100, 3)} ± {np.round(se * 100, 3)}")
    for path in sys.argv[2:]:
        other = replicates(path)
        seeds = sorted(set(other) & set(base))
        d = np.array([(base[k] - other[k]) / ref for k in seeds])
        se = d.std(0, ddof=1) / np.sqrt(len(d))
        print(f"  minus {path}: {len(seeds)} seeds, paired % {np.round(d.mean(0) * 100, 3)} ± {np.round(se * 100, 3)}")


if __name__ == "__main__":
    main()
