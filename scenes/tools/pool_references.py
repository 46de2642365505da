#!/usr/bin/env python3
"""Pool two independent references of one scene, each with its per-sample variance image.

    python3 scenes/tools/pool_references.py OUT.exr OUT.var.exr \
        R1.exr:VAR1.exr:SPP1:DOF1 R2.exr:VAR2.exr:SPP2:DOF2

Each reference is the mean of SPP samples per pixel; its variance image holds the variance of
one sample (the convention of `average_exr.py --variance` and of `mcmc-render --reference-variance`),
estimated with DOF degrees of freedom (renders - 1). The pooled reference is the spp-weighted mean
(SPP1 + SPP2 samples); the pooled variance image the dof-weighted mean of the two (both estimate
the same per-sample variance). Use it as `--reference OUT.exr --reference-variance OUT.var.exr
--reference-spp SPP1+SPP2`.

The JSON report (beside OUT, .json) gives each reference's floor (mean over pixels and channels
of VAR/SPP, the mean squared error a reference adds to a plain comparison), the pooled floor, and
the check that needs no variance image: for independent references mean (R1 - R2)^2 estimates
V1/SPP1 + V2/SPP2 exactly; its ratio to the value the variance images predict says how far the
variance images read low or high (a heavy-tailed pixel estimate's sample variance over a few
dozen renders tends to read low).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from average_exr import load, save  # noqa: E402


def parse(spec: str) -> dict:
    try:
        img, var, spp, dof = spec.rsplit(":", 3)
        return {"image": img, "variance": var, "spp": float(spp), "dof": float(dof)}
    except ValueError:
        raise SystemExit(f"expected IMAGE:VARIANCE:SPP:DOF, got {spec!r}")


def main() -> int:
    if len(sys.argv) != 5:
        print(__doc__, file=sys.stderr)
        return 2
    out, out_var = sys.argv[1], sys.argv[2]
    refs = [parse(s) for s in sys.argv[3:5]]
    try:
        imgs = [load(r["image"]) for r in refs]
        vars_ = [load(r["variance"]) for r in refs]
    except Exception as e:  # a missing or unreadable EXR: one line, not a traceback
        print(f"cannot read the inputs: {e}", file=sys.stderr)
        return 2
    if any(a.shape != imgs[0].shape for a in imgs + vars_):
        print("the images differ in size", file=sys.stderr)
        return 2
    spp = np.array([r["spp"] for r in refs])
    dof = np.array([r["dof"] for r in refs])
    pooled = (spp[0] * imgs[0] + spp[1] * imgs[1]) / spp.sum()
    pooled_var = (dof[0] * vars_[0] + dof[1] * vars_[1]) / dof.sum()
    save(out, pooled)
    save(out_var, pooled_var)
    floors = [float(np.mean(v) / s) for v, s in zip(vars_, spp)]
    diff2 = float(np.mean((imgs[0] - imgs[1]) ** 2))
    predicted_own = sum(floors)
    predicted_pooled = float(np.mean(pooled_var)) * float(np.sum(1.0 / spp))
    report = {
        "output": out,
        "variance": out_var,
        "inputs": refs,
        "total_spp": float(spp.sum()),
        "floor_mse_inputs": floors,
        "floor_mse_pooled": float(np.mean(pooled_var)) / float(spp.sum()),
        "mean_sq_diff_between_inputs": diff2,
        "predicted_by_own_variance_images": predicted_own,
        "predicted_by_pooled_variance_image": predicted_pooled,
        "ratio_measured_over_pooled_prediction": diff2 / predicted_pooled,
        "means": [[float(v) for v in a.reshape(-1, 3).mean(axis=0)] for a in imgs],
        "mean_pooled": [float(v) for v in pooled.reshape(-1, 3).mean(axis=0)],
    }
    text = json.dumps(report, indent=2) + "\n"
    Path(out).with_suffix(".json").write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
