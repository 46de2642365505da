#!/usr/bin/env python3
"""Session 25: how long `fused` chains sit on paths that fail the round trip, from the sidecars.

    python3 scenes/tools/fused_lazy_dwell.py DIR [DIR ...]

Reads DIR/*/fused.json (eager) and DIR/*/fused_conversion_lazy.json (the 60 s study's
sidecars, fused_s22_study.sh). Under `lazy` a path-space move can reach a path whose
conversion fails (set B); a primary-sample move drawn there is refused (component "pss:
current path not convertible (lazy)"), so the chain leaves B only by path-space moves, which
the exact (eager) rule never lets into B. Each refused move is one step spent on an
unconverted path of B: refused / mutations is a lower bound on that share of the chain's steps
(its image mass, MMLT's splats being equal per step), refused / (primary-sample share of the
proposals) an estimate. For `eager` the same estimate from "path: current path not
invertible" (path-space moves refused at traced states whose path fails) is the share of steps
on traced paths of B, which the exact chain does visit.
"""

import glob
import json
import os
import sys


def main():
    print("run | rule | mutations | failed conversions | refused moves | lower bound | estimate")
    for d in sys.argv[1:]:
        for path in sorted(glob.glob(os.path.join(d, "*", "fused*.json"))):
            st = json.load(open(path))["statistics"]
            f = st["fused"]
            pss = sum(x["pss_proposals"] for x in f["per_depth"])
            moves = pss + sum(x["path_proposals"] for x in f["per_depth"])
            rt = f["round_trip_failures"]
            lazy = f["conversion"] == "lazy"
            if lazy:
                refused = rt["pss: current path not convertible (lazy)"]
                failed, share = f["deferred_conversion_failures"], pss / moves
            else:
                refused = rt["path: current path not invertible"]
                failed, share = "—", 1 - pss / moves
            m = st["mutations"]
            print(f"{os.path.basename(os.path.dirname(path))} | {f['conversion']} | {m} | {failed} | "
                  f"{refused} | {refused / m:.1e} | {refused / share / m:.1e}")


if __name__ == "__main__":
    main()
