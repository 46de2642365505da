#!/usr/bin/env python3
"""relMSE against a noisy reference, with the reference's own share taken out, and a
bias/noise split over independent renders (issue 15: "report the regularisation bias
against the reference separately from the noise").

    python3 scenes/tools/bias_noise.py REF.exr REF.var.exr REF_SPP IN1.exr [IN2.exr ...]

REF.var.exr is mitsuba_reference.py's per-sample, per-channel variance image; the
reference pixel's luminance variance is taken as (sum_c w_c sigma_c)^2 / REF_SPP (fully
correlated channels: an upper bound, so `excess` below errs low). relMSE is mcmc-render's
(luminance, (t - r)^2 / (r^2 + 0.01), averaged over pixels). For each input:

    rel_mse         against the reference
    floor           the reference's own expected share: mean(var_ref / (r^2 + 0.01))
    excess          rel_mse - floor (the render's own error, in expectation)

With K >= 2 inputs (independent renders of one integrator, different seeds):

    noise           mean over pixels of the across-seed variance of one render (ddof=1)
                    / (r^2 + 0.01): one render's variance share
    mean_rel_mse    relMSE of the K renders' pixel mean against the reference
    bias            mean_rel_mse - noise/K - floor: the squared bias share (can come out
                    slightly negative from noise; K = 2 resolves only biases that are
                    large against noise/K)

Needs numpy and mitsuba (EXR input, via average_exr.py's loader). Prints JSON.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from average_exr import load, luminance, rel_mse  # noqa: E402

W = np.array([0.212671, 0.715160, 0.072169])


def main() -> int:
    if len(sys.argv) < 5:
        print(__doc__, file=sys.stderr)
        return 2
    ref_path, var_path, spp, inputs = sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4:]
    ref = load(ref_path)
    r = luminance(ref)
    denom = r * r + 0.01
    sigma = np.sqrt(np.maximum(load(var_path), 0.0))
    floor = float(np.mean((sigma @ W) ** 2 / spp / denom))
    imgs = [load(p) for p in inputs]
    out = {"reference": ref_path, "floor": floor, "renders": []}
    for p, img in zip(inputs, imgs):
        e = rel_mse(img, ref)
        out["renders"].append({"file": p, "rel_mse": e, "excess": e - floor})
    k = len(imgs)
    if k >= 2:
        lum = luminance(np.stack(imgs))
        noise = float(np.mean(lum.var(axis=0, ddof=1) / denom))
        mean_e = rel_mse(np.mean(np.stack(imgs), axis=0), ref)
        out.update(
            {
                "k": k,
                "noise": noise,
                "mean_rel_mse": mean_e,
                "bias": mean_e - noise / k - floor,
            }
        )
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
