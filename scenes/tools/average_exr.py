#!/usr/bin/env python3
"""Average K >= 2 independent renders (EXR) of one scene into a reference, and estimate its error.

Each input is one render with its own seed and its `mcmc-render` JSON sidecar beside it
(same name, .json). The output EXR is the pixel-wise mean (float32 RGB). The JSON report
gives the per-render statistics, the image means, and the reference's own relMSE, estimated
from the spread between the inputs: for K independent renders of equal variance v per pixel,
the mean has variance v/K, and the unbiased per-pixel estimate of v is the sample variance
over the K renders; relMSE uses mcmc-render's definition (luminance, (t - r)^2 / (r^2 + 0.01),
with r the average). Optionally compares another reference (e.g. Mitsuba's) with the average.

    python3 scenes/tools/average_exr.py OUT.exr IN1.exr IN2.exr [...] [--compare OTHER.exr] \
        [--variance VAR.exr]

--variance writes the per-pixel, per-channel variance of ONE sample (the convention of
mitsuba_reference.py --variance and of `mcmc-render convergence --reference-variance`): the
sample variance over the K renders (ddof=1) times their spp, which must be equal. The average
OUT has `total_spp` samples per pixel (in the JSON), so its own pixel variance is
VAR / total_spp: pass `--reference-variance VAR.exr --reference-spp TOTAL_SPP`.

Needs numpy and, for EXR input/output, mitsuba (variant scalar_rgb) or else the OpenEXR
Python package.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

try:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
except ImportError:  # OpenEXR reads and writes the same RGB EXRs
    mi = None
    import OpenEXR


def load(path: str) -> np.ndarray:
    if mi is not None:
        return np.array(mi.Bitmap(path), dtype=np.float64)[..., :3]
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.array(ch["RGB"].pixels, dtype=np.float64)[..., :3]
        return np.stack([np.array(ch[c].pixels, dtype=np.float64) for c in "RGB"], axis=-1)


def save(path: str, rgb: np.ndarray) -> None:
    """Writes a float32 RGB EXR."""
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    if mi is not None:
        mi.Bitmap(rgb, mi.Bitmap.PixelFormat.RGB).write(path)
        return
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(path)


def luminance(a: np.ndarray) -> np.ndarray:
    return 0.212671 * a[..., 0] + 0.715160 * a[..., 1] + 0.072169 * a[..., 2]


def rel_mse(test: np.ndarray, ref: np.ndarray) -> float:
    t, r = luminance(test), luminance(ref)
    return float(np.mean((t - r) ** 2 / (r * r + 0.01)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="output EXR (the JSON report goes beside it)")
    ap.add_argument("inputs", nargs="+", help="independent renders (EXR), K >= 2")
    ap.add_argument("--compare", help="another reference to compare with the average")
    ap.add_argument("--variance", help="also write the per-sample pixel variance to this EXR")
    args = ap.parse_args()
    if len(args.inputs) < 2:
        print("need at least two independent renders to estimate the error", file=sys.stderr)
        return 2
    imgs = [load(p) for p in args.inputs]
    if any(i.shape != imgs[0].shape for i in imgs):
        print("the renders differ in size", file=sys.stderr)
        return 2
    k = len(imgs)
    stack = np.stack(imgs)
    avg = stack.mean(axis=0)
    save(args.out, avg)

    # Unbiased per-pixel variance of one render's luminance, then of the mean.
    lum = luminance(stack)
    var_mean = lum.var(axis=0, ddof=1) / k
    r = luminance(avg)
    own = float(np.mean(var_mean / (r * r + 0.01)))

    renders = []
    for p in args.inputs:
        side = Path(p).with_suffix(".json")
        info = json.loads(side.read_text()) if side.exists() else {}
        renders.append({"file": p, **{key: info.get(key) for key in
                        ("integrator", "seed", "seconds", "samples", "spp", "samples_per_second",
                         "threads", "nonfinite_samples")}})
    if args.variance:
        spps = {x["spp"] for x in renders}
        if len(spps) != 1 or None in spps:
            print(f"--variance needs renders of one spp with JSON sidecars, got {spps}", file=sys.stderr)
            return 2
        save(args.variance, stack.var(axis=0, ddof=1) * spps.pop())
    report = {
        "output": args.out,
        "variance": args.variance,
        "inputs": renders,
        "total_spp": sum(x["spp"] or 0 for x in renders),
        "mean": [float(v) for v in avg.reshape(-1, 3).mean(axis=0)],
        "input_means": [[float(v) for v in i.reshape(-1, 3).mean(axis=0)] for i in imgs],
        "rel_mse_between_first_two": rel_mse(imgs[0], imgs[1]),
        "rel_mse_estimated_own": own,
    }
    if args.compare:
        other = load(args.compare)
        report["compared_with"] = args.compare
        report["rel_mse_of_compared_against_this"] = rel_mse(other, avg)
        report["compared_mean"] = [float(v) for v in other.reshape(-1, 3).mean(axis=0)]
    text = json.dumps(report, indent=2) + "\n"
    Path(args.out).with_suffix(".json").write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
