#!/usr/bin/env python3
"""Write the lat-long environment map that scenes/envmap-spheres.xml uses.

A 64x32 float32 EXR (row 0 at the +y pole, Mitsuba's lat-long layout): a
blue sky brightening towards the horizon, a dim brown ground, and a small
bright "sun" about 2 texels across at (u, v) = (0.3, 0.28), so that
importance sampling matters. Needs only Mitsuba 3 (no numpy):

    python3 scenes/tools/make_envmap.py scenes/textures/sky.exr
"""
import math
import sys

import mitsuba as mi

mi.set_variant("scalar_rgb")

W, H = 64, 32
data = []
for y in range(H):
    v = (y + 0.5) / H
    for x in range(W):
        u = (x + 0.5) / W
        if v < 0.5:
            t = v / 0.5  # 0 at the zenith, 1 at the horizon
            r, g, b = 0.25 + 0.55 * t, 0.45 + 0.4 * t, 0.9 + 0.1 * t
        else:
            r, g, b = 0.12, 0.09, 0.06
        du = min(abs(u - 0.3), 1 - abs(u - 0.3)) * W
        dv = (v - 0.28) * H
        if du * du + dv * dv < 1.2:
            r, g, b = 60.0, 55.0, 45.0
        data += [r, g, b]
mi.Bitmap(mi.TensorXf(data, (H, W, 3))).write(sys.argv[1])
