#!/usr/bin/env python3
"""Print Markdown tables of the Mitsuba reports in scenes/reference/ (for docs/mitsuba-comparison.md).

Usage:
    python3 scenes/tools/reference_table.py scenes/reference/*.json

Reports written by mitsuba_reference.py go into a means table (mean +- SE per channel,
relative SE); reports written by mitsuba_speed.py go into a speed table.
"""

from __future__ import annotations

import json
import os
import sys


def fmt(m: float, se: float) -> str:
    return f"{m:.5f} ± {se:.5f}"


def main() -> int:
    means, speeds = [], []
    for path in sys.argv[1:]:
        with open(path) as f:
            r = json.load(f)
        (speeds if "samples_per_second" in r else means).append((os.path.basename(path), r))

    if means:
        print("| report | scene | size | spp × seeds | R | G | B | rel. SE (R, G, B) | NaN/inf |")
        print("|---|---|---|---|---|---|---|---|---|")
        for name, r in means:
            rel = ", ".join(f"{100 * x:.2f}%" for x in r["rel_se"])
            cells = [fmt(m, s) for m, s in zip(r["mean"], r["se"])]
            print(
                f"| {name} | {os.path.basename(r['scene'])} | {r['width']}×{r['height']} | "
                f"{r['spp_per_seed']} × {len(r['seeds'])} | {' | '.join(cells)} | {rel} | {r['nonfinite']} |"
            )
        print()
    if speeds:
        print(
            "| report | scene | size | spp | max_depth | threads | load avg (1 min) | busy cores | "
            "samples/s (median) | best | samples per CPU-second |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for name, r in speeds:
            busy = sorted(r["busy_cores"])[len(r["busy_cores"]) // 2]
            depth = r["integrator_repr"].split("max_depth = ")[1].split(",")[0] if "max_depth" in r["integrator_repr"] else "?"
            print(
                f"| {name} | {os.path.basename(r['scene'])} | {r['width']}×{r['height']} | {r['spp']} | {depth} | "
                f"{r['threads']} | {r['loadavg_before'][0]:.1f} | {busy:.2f} | "
                f"{r['samples_per_second_median']:,.0f} | {r['samples_per_second_best']:,.0f} | "
                f"{r.get('samples_per_cpu_second_median', float('nan')):,.0f} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
