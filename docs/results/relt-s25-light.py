"""Session 25 (docs/relt.md, issue 14): where RELT's image-mean excess sits.

The "light" pixels are those whose reference value (R+G+B) exceeds 15: on
the 128x128 water box the 18 pixels where the ceiling light is seen directly
(the next brightest pixel is below 5). Every figure is R+G+B summed over a
set of pixels, relative to the reference's sum over the whole image (so the
light part and the rest part add up to the image-mean excess). Mean ± the
standard error over seeds; 95% intervals with Student's t (n-1 dof).

Usage (needs numpy and OpenEXR from pip):
  relt-s25-light.py split REF IMG...            light/rest split of single images
  relt-s25-light.py seeds REF DIR NAME...       DIR/NAME-sSEED.exr (+ .replica-*.exr) over seeds
  relt-s25-light.py pair REF DIR A B SEEDS      paired A-B on seeds "1,2,3"
  relt-s25-light.py crop REF GLOB...            renders of the crop window x 57..70, y 13..23
"""
import glob
import re
import sys
from math import sqrt

import numpy as np
import OpenEXR

REPLICAS = ["uniform", "full", "indirect", "specific"]
# Two-sided 95% Student t quantiles by degrees of freedom.
T95 = {1: 12.71, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
       9: 2.262, 10: 2.228, 11: 2.201, 12: 2.179, 13: 2.160, 14: 2.145, 15: 2.131}


def load(path):
    return OpenEXR.File(path).parts[0].channels["RGB"].pixels.astype(np.float64).sum(axis=2)


def stat(xs):
    x = np.asarray(xs) * 100
    n = len(x)
    if n < 2:
        return "%+.2f%% (n=1)" % x.mean()
    se = x.std(ddof=1) / sqrt(n)
    return "%+.2f ± %.2f%% (95%% ±%.2f, n=%d)" % (x.mean(), se, T95.get(n - 1, 2.0) * se, n)


def split(ref_path, images):
    ref = load(ref_path)
    light = ref > 15
    total = ref.sum()
    print("reference: %d light pixels, %.3f of the image sum" % (light.sum(), ref[light].sum() / total))
    for p in images:
        im = load(p)
        print("%-50s total %+.2f%%  light part %+.2f%% (light itself %+.2f%%)  rest part %+.2f%%" % (
            p[-50:], 100 * (im.sum() / total - 1), 100 * (im[light].sum() - ref[light].sum()) / total,
            100 * (im[light].sum() / ref[light].sum() - 1), 100 * (im[~light].sum() - ref[~light].sum()) / total))


def runs(d, name):
    for f in sorted(glob.glob(f"{d}/{name}-s*.json")):
        yield int(re.search(r"-s(\d+)\.json$", f).group(1)), f[:-5]


def seeds(ref_path, d, names):
    ref = load(ref_path)
    light = ref > 15
    total = ref.sum()
    for name in names:
        rows = list(runs(d, name))
        print(f"== {name}: seeds {[s for s, _ in rows]}")
        ims = [load(b + ".exr") for _, b in rows]
        print(" total     ", stat([im.sum() / total - 1 for im in ims]))
        print(" light part", stat([(im[light].sum() - ref[light].sum()) / total for im in ims]))
        print(" rest part ", stat([(im[~light].sum() - ref[~light].sum()) / total for im in ims]))
        for r in REPLICAS:
            layers = [load(f"{b}.replica-{r}.exr") for _, b in rows]
            print("  %-9s share of the reference sum: light %s, rest %s" % (
                r, stat([x[light].sum() / total for x in layers]), stat([x[~light].sum() / total for x in layers])))


def pair(ref_path, d, a, b, seed_list):
    ref = load(ref_path)
    light = ref > 15
    total = ref.sum()
    diffs = []
    for s in seed_list:
        x, y = load(f"{d}/{a}-s{s}.exr"), load(f"{d}/{b}-s{s}.exr")
        diffs.append(((x[light].sum() - y[light].sum()) / total, (x[~light].sum() - y[~light].sum()) / total))
    diffs = np.array(diffs)
    print(f"{a} - {b}, light part:", " ".join("%+.2f" % (100 * v) for v in diffs[:, 0]), "->", stat(diffs[:, 0]))
    print(f"{a} - {b}, rest part: ", stat(diffs[:, 1]))


def crop(ref_path, patterns):
    ref = load(ref_path)[13:24, 57:71]
    inner = np.zeros_like(ref, bool)
    inner[2:-2, 2:-2] = True  # at least the filter radius (2 px) from the crop's border
    light = (ref > 15) & inner
    rest = inner & ~light
    print("crop 14x11: %d inner pixels, %d of them light" % (inner.sum(), light.sum()))
    for pat in patterns:
        ims = [load(f) for f in sorted(glob.glob(pat))]
        if ims:
            lt = [im[light].sum() / ref[light].sum() - 1 for im in ims]
            print("%-28s light %s   inner rest %s" % (pat, stat(lt), stat([im[rest].sum() / ref[rest].sum() - 1 for im in ims])))
            print("%28s per run: %s" % ("", " ".join("%+.1f" % (100 * v) for v in lt)))


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "split":
        split(args[0], args[1:])
    elif cmd == "seeds":
        seeds(args[0], args[1], args[2:])
    elif cmd == "pair":
        pair(args[0], args[1], args[2], args[3], [int(s) for s in args[4].split(",")])
    elif cmd == "crop":
        crop(args[0], args[1:])
    else:
        sys.exit(__doc__)
