#!/usr/bin/env python3
"""RMSE and relMSE of our EXR and SmallVCM's PFM against one reference (issue #16).

SmallVCM writes its PFM rows bottom to top in its own raster order, which is our
image flipped vertically; this script flips it back. Prints, per image, the
channel means relative to the reference, RMSE over all channels and pixels, and
relMSE = mean over pixels of (luminance difference)^2 / (reference luminance^2 + 0.01)
(the definition `mcmc-render compare` and `convergence` use).

Usage: python3 scenes/tools/smallvcm_rmse.py REFERENCE.exr OURS.exr SMALLVCM.pfm [...]
"""
import sys

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")


def load(path):
    img = np.array(mi.Bitmap(path), dtype=np.float64)[:, :, :3]
    return img[::-1] if path.endswith(".pfm") else img


def lum(img):
    return img @ np.array([0.212671, 0.715160, 0.072169])


ref = load(sys.argv[1])
for path in sys.argv[2:]:
    img = load(path)
    rmse = float(np.sqrt(np.mean((img - ref) ** 2)))
    rel = float(np.mean((lum(img) - lum(ref)) ** 2 / (lum(ref) ** 2 + 0.01)))
    means = img.mean(axis=(0, 1)) / ref.mean(axis=(0, 1)) - 1
    print(f"{path}: RMSE {rmse:.5f}, relMSE {rel:.5f}, means vs reference "
          + ", ".join(f"{100 * m:+.2f}%" for m in means))
