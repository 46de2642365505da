"""Session 14 (docs/relt.md): the squared error of RELT runs split into the
pixels where the light is seen directly and the rest.

Usage: python3 relt-s14-split.py REF.exr DIR
DIR holds NAME-sSEED.exr renders (and .time files: user sys wall seconds)
from relt-s14-split.sh. Light pixels: reference luminance > 5 (on the glass
cube at 128x128 these are the 18 pixels of the emitter; the next brightest
pixel is below 2). Needs numpy and OpenEXR (pip).

Per variant, over seeds: the sum of squared errors over the light pixels
and over the rest (all three channels), the light pixels' summed luminance
(against the reference's), the across-seed variance of each pixel summed
over each set (no reference noise in it), relMSE as `mcmc-render compare`
computes it, and the CPU seconds. Mean ± standard error over seeds.
"""
import collections
import glob
import os
import re
import sys

import numpy as np
import OpenEXR

LUMA = np.array([0.2126, 0.7152, 0.0722])


def load(path):
    return OpenEXR.File(path).parts[0].channels["RGB"].pixels.astype(np.float64)


def mean_se(xs):
    xs = np.asarray(xs, dtype=np.float64)
    se = xs.std(ddof=1) / np.sqrt(len(xs)) if len(xs) > 1 else float("nan")
    return f"{xs.mean():.4g} ± {se:.2g}"


def main():
    ref = load(sys.argv[1])
    runs = collections.defaultdict(dict)
    for path in sorted(glob.glob(os.path.join(sys.argv[2], "*-s*.exr"))):
        m = re.match(r"(.*)-s(\d+)\.exr$", os.path.basename(path))
        if not m or ".replica-" in path:
            continue
        runs[m.group(1)][int(m.group(2))] = path
    ry = ref @ LUMA
    light = ry > 5.0
    print(f"light pixels: {light.sum()}, reference light luminance sum {ry[light].sum():.1f}")
    head = ("variant", "seeds", "SE light", "SE rest", "light Y sum", "var light", "var rest",
            "relMSE", "RMSE", "CPU s")
    print(" | ".join(head))
    for name, seeds in runs.items():
        imgs = [load(p) for _, p in sorted(seeds.items())]
        se_l, se_r, ysum, rel, rmse, cpu = [], [], [], [], [], []
        for (seed, p), im in zip(sorted(seeds.items()), imgs):
            d2 = ((im - ref) ** 2).sum(axis=2)
            se_l.append(d2[light].sum())
            se_r.append(d2[~light].sum())
            ty = im @ LUMA
            ysum.append(ty[light].sum())
            rel.append(((ty - ry) ** 2 / (ry * ry + 0.01)).mean())
            rmse.append(np.sqrt(d2.mean() / 3.0))
            t = p[:-4] + ".time"
            if os.path.exists(t):
                u, s, _ = open(t).read().split()[:3]
                cpu.append(float(u) + float(s))
        stack = np.stack(imgs)
        var = stack.var(axis=0, ddof=1).sum(axis=2) if len(imgs) > 1 else np.zeros(light.shape)
        print(" | ".join([name, str(len(imgs)), mean_se(se_l), mean_se(se_r), mean_se(ysum),
                          f"{var[light].sum():.4g}", f"{var[~light].sum():.4g}", mean_se(rel),
                          mean_se(rmse), mean_se(cpu) if cpu else "-"]))


if __name__ == "__main__":
    main()
