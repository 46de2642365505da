#!/usr/bin/env python3
"""Where an image's error against a reference sits: relMSE (mcmc-render's definition, luminance,
(t - r)^2 / (r^2 + 0.01)), the share of it in a rectangle, the rectangle's mean against the
reference's (over its pixels darker than --dark), the rest of the image's mean ratio, and the
pixels that contribute most.

    python3 scenes/tools/region_error.py REF.exr TEST.exr [TEST2.exr ...] \
        [--rect Y0 Y1 X0 X1] [--dark 0.09] [--top 6]

Defaults: the rectangle and threshold used for caustic-sds at 128x96 in docs/path-space.md
(Session 35): rows 60-96, columns 30-110, pixels with reference luminance < 0.09 (the floor in the
glass ball's shadow, lit by the L S D S E caustic seen through the pane).

Needs numpy and the OpenEXR Python package.
"""

from __future__ import annotations

import argparse

import numpy as np
import OpenEXR


def load(path: str) -> np.ndarray:
    with OpenEXR.File(path) as f:
        ch = f.channels()
        if "RGB" in ch:
            return np.asarray(ch["RGB"].pixels, dtype=np.float64)
        return np.stack([np.asarray(ch[c].pixels, dtype=np.float64) for c in "RGB"], -1)


def luminance(x: np.ndarray) -> np.ndarray:
    return x[..., 0] * 0.212671 + x[..., 1] * 0.715160 + x[..., 2] * 0.072169


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reference")
    ap.add_argument("tests", nargs="+")
    ap.add_argument("--rect", nargs=4, type=int, default=[60, 96, 30, 110], metavar=("Y0", "Y1", "X0", "X1"))
    ap.add_argument("--dark", type=float, default=0.09)
    ap.add_argument("--top", type=int, default=6)
    a = ap.parse_args()
    r = luminance(load(a.reference))
    y0, y1, x0, x1 = a.rect
    rect = np.zeros_like(r, bool)
    rect[y0:y1, x0:x1] = True
    region = rect & (r < a.dark)
    for path in a.tests:
        t = luminance(load(path))
        e = (t - r) ** 2 / (r**2 + 0.01)
        print(
            f"{path}: relMSE {e.mean():.4g}; region ({region.sum()} px) share {e[region].sum() / e.sum():.2f}, "
            f"mean ratio {t[region].mean() / r[region].mean():.3f}; rest mean ratio {t[~region].mean() / r[~region].mean():.4f}"
        )
        width = r.shape[1]
        for i in np.argsort(e.ravel())[::-1][: a.top]:
            y, x = divmod(int(i), width)
            print(f"  pixel ({y}, {x}): reference {r[y, x]:.3f}, test {t[y, x]:.3f}, relMSE share {e[y, x] / e.sum():.4f}")


if __name__ == "__main__":
    main()
