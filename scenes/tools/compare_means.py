#!/usr/bin/env python3
"""Compare image means of independent renders against a Mitsuba reference report.

Give it the JSON written by mitsuba_reference.py and K >= 2 EXR files rendered by the
renderer under test with K different seeds (same scene, same defaults). Each EXR's
per-channel mean is one independent estimate; their mean and standard error are set
against Mitsuba's:

    rel_diff[c] = ours[c] / mitsuba[c] - 1
    z[c]        = (ours[c] - mitsuba[c]) / sqrt(se_ours[c]^2 + se_mitsuba[c]^2)

The agreement criterion of issue 5 is |rel_diff| <= 1% on every channel. The z-score
says whether a difference is larger than the noise of both estimates explains
(|z| > 3 means a real difference, however small). Both are printed as JSON; the exit
status is 0 when |rel_diff| <= --tolerance on every channel, 1 otherwise.

Usage:
    python3 scenes/tools/compare_means.py scenes/reference/cornell-box.json ours-0.exr ours-1.exr ...
"""

from __future__ import annotations

import argparse
import json
import math
import sys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reference", help="JSON report from mitsuba_reference.py")
    ap.add_argument("renders", nargs="+", help="EXR renders of the renderer under test, one per seed")
    ap.add_argument("--tolerance", type=float, default=0.01, help="allowed |relative difference| per channel")
    args = ap.parse_args()
    if len(args.renders) < 2:
        raise SystemExit("error: give at least two independent renders to estimate a standard error")

    import mitsuba as mi
    import numpy as np

    mi.set_variant("scalar_rgb")
    with open(args.reference) as f:
        ref = json.load(f)

    means = []
    nonfinite = 0
    for path in args.renders:
        img = np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]
        if img.shape[0] != ref["height"] or img.shape[1] != ref["width"]:
            print(
                f"note: {path} is {img.shape[1]}x{img.shape[0]}, reference is {ref['width']}x{ref['height']}",
                file=sys.stderr,
            )
        bad = ~np.isfinite(img)
        nonfinite += int(bad.sum())
        means.append(np.where(bad, 0.0, img).reshape(-1, 3).mean(axis=0))
    m = np.array(means)
    k = len(means)
    ours = m.mean(axis=0)
    se_ours = m.std(axis=0, ddof=1) / math.sqrt(k)
    theirs = np.array(ref["mean"])
    se_theirs = np.array(ref["se"])
    rel = ours / theirs - 1.0
    z = (ours - theirs) / np.sqrt(se_ours**2 + se_theirs**2)
    ok = bool(np.all(np.abs(rel) <= args.tolerance))
    print(
        json.dumps(
            {
                "reference": args.reference,
                "renders": args.renders,
                "channels": ["R", "G", "B"],
                "ours": ours.tolist(),
                "se_ours": se_ours.tolist(),
                "mitsuba": theirs.tolist(),
                "se_mitsuba": se_theirs.tolist(),
                "rel_diff": rel.tolist(),
                "z": z.tolist(),
                "nonfinite": nonfinite,
                "tolerance": args.tolerance,
                "within_tolerance": ok,
            },
            indent=2,
        )
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
