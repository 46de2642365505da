#!/usr/bin/env python3
"""Render a scene with Mitsuba 3 over several independent seeds and report image means.

The per-channel image mean of each seed's render is one independent estimate of the
scene's mean radiance; the spread of those estimates gives the standard error that
our renderer's means are compared against (docs/mitsuba-comparison.md).

Usage:
    python3 scenes/tools/mitsuba_reference.py SCENE.xml --spp N --seeds K --output OUT.exr \
        [-D name=value ...] [--variant scalar_rgb] [--threads T] [--json OUT.json] \
        [--variance VAR.exr]

Prints one JSON object on stdout:
    mean[c]        mean over seeds of the per-seed image mean of channel c (R, G, B)
    se[c]          standard error of mean[c]: sample std over seeds (ddof=1) / sqrt(K)
    rel_se[c]      se[c] / mean[c]
    seed_means     the K per-seed means (so anyone can recompute the above)
    luminance      the same statistics for Rec.709 luminance (0.2126 R + 0.7152 G + 0.0722 B)
    nonfinite      count of NaN/inf pixel values over all seeds (expected 0)
and the settings (scene, spp per seed, seeds, resolution, overrides, Mitsuba version,
variant, thread count, render seconds).

OUT.exr is the average of the K renders (i.e. K*spp samples per pixel), written as
float32 linear RGB. The seeds used are 0..K-1 (Mitsuba's `mi.render(..., seed=k)`).

VAR.exr (optional) is the per-pixel, per-channel variance of ONE sample: the sample
variance over the K seeds' images (ddof=1) times spp. The variance of a pixel of an
N-sample render is VAR/N, so a variance image made with fewer spp (or seeds) than the
reference describes the reference's noise too: divide by the reference's total_spp.
`mcmc-render/tests/mitsuba_scenes.rs` uses it to predict the relMSE between the
reference and our render.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time


def parse_overrides(pairs: list[str]) -> dict[str, str]:
    """Turn ['spp=16', 'max_depth=5'] into {'spp': '16', 'max_depth': '5'}."""
    out: dict[str, str] = {}
    for p in pairs:
        if "=" not in p:
            raise SystemExit(f"error: -D expects name=value, got '{p}'")
        k, v = p.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="Mitsuba 3 XML scene file")
    ap.add_argument("--spp", type=int, required=True, help="samples per pixel of each seed's render")
    ap.add_argument("--seeds", type=int, default=8, help="number of independent seeds (>= 2)")
    ap.add_argument("--output", required=True, help="EXR file receiving the average of all seeds")
    ap.add_argument("-D", dest="defines", action="append", default=[], help="override a <default>, name=value")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--threads", type=int, default=0, help="thread count (0 = Dr.Jit's default, all cores)")
    ap.add_argument("--json", help="also write the JSON report to this file")
    ap.add_argument("--variance", help="also write the per-sample pixel variance to this EXR")
    args = ap.parse_args()

    if args.spp <= 0:
        raise SystemExit("error: --spp must be positive")
    if args.seeds < 2:
        raise SystemExit("error: --seeds must be at least 2 to estimate a standard error")

    import drjit as dr
    import mitsuba as mi
    import numpy as np

    mi.set_variant(args.variant)
    if args.threads > 0:
        dr.set_thread_count(args.threads)

    overrides = parse_overrides(args.defines)
    t0 = time.perf_counter()
    scene = mi.load_file(args.scene, **overrides)
    load_seconds = time.perf_counter() - t0

    sensor = scene.sensors()[0]
    width, height = (int(v) for v in sensor.film().size())

    seed_means = []
    lum_means = []
    nonfinite = 0
    acc = None
    acc2 = None
    render_seconds = 0.0
    w709 = np.array([0.2126, 0.7152, 0.0722])
    for seed in range(args.seeds):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=args.spp, seed=seed)
        img = np.array(img, dtype=np.float64)
        render_seconds += time.perf_counter() - t0
        img = img[..., :3]
        bad = ~np.isfinite(img)
        nonfinite += int(bad.sum())
        img = np.where(bad, 0.0, img)
        m = img.reshape(-1, 3).mean(axis=0)
        seed_means.append(m.tolist())
        lum_means.append(float(m @ w709))
        acc = img if acc is None else acc + img
        acc2 = img * img if acc2 is None else acc2 + img * img
        print(f"seed {seed}: mean {m.tolist()}", file=sys.stderr, flush=True)

    sm = np.array(seed_means)
    k = args.seeds
    mean = sm.mean(axis=0)
    se = sm.std(axis=0, ddof=1) / math.sqrt(k)
    lm = np.array(lum_means)
    lum_mean = float(lm.mean())
    lum_se = float(lm.std(ddof=1) / math.sqrt(k))

    avg = (acc / k).astype(np.float32)
    os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
    mi.Bitmap(avg, pixel_format=mi.Bitmap.PixelFormat.RGB).write(args.output)
    if args.variance:
        seed_var = np.maximum(acc2 - acc * acc / k, 0.0) / (k - 1)
        var1 = (seed_var * args.spp).astype(np.float32)
        mi.Bitmap(var1, pixel_format=mi.Bitmap.PixelFormat.RGB).write(args.variance)

    report = {
        "scene": args.scene,
        "renderer": "mitsuba",
        "mitsuba_version": mi.__version__,
        "variant": args.variant,
        "threads": int(dr.thread_count()),
        "overrides": overrides,
        "width": width,
        "height": height,
        "spp_per_seed": args.spp,
        "seeds": list(range(k)),
        "total_spp": args.spp * k,
        "load_seconds": load_seconds,
        "render_seconds": render_seconds,
        "channels": ["R", "G", "B"],
        "mean": mean.tolist(),
        "se": se.tolist(),
        "rel_se": (se / np.where(mean != 0, mean, np.nan)).tolist(),
        "luminance": {"mean": lum_mean, "se": lum_se, "rel_se": lum_se / lum_mean if lum_mean else None},
        "seed_means": seed_means,
        "nonfinite": nonfinite,
        "output": args.output,
        "variance": args.variance,
    }
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
