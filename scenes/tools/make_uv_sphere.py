#!/usr/bin/env python3
"""Write a UV sphere as OBJ with per-vertex normals and texture coordinates
(smooth shading), the interpolated-normal mesh of scenes/door-ajar-real.xml.

    python3 scenes/tools/make_uv_sphere.py scenes/meshes/sphere.obj [RINGS] [SEGMENTS]
"""
import math
import sys

path = sys.argv[1]
rings = int(sys.argv[2]) if len(sys.argv) > 2 else 24
segs = int(sys.argv[3]) if len(sys.argv) > 3 else 48
lines = ["# UV sphere, radius 1, %d rings x %d segments" % (rings, segs)]
for i in range(rings + 1):
    theta = math.pi * i / rings
    for j in range(segs + 1):
        phi = 2 * math.pi * j / segs
        x, y, z = math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi)
        lines.append("v %.6f %.6f %.6f" % (x, y, z))
        lines.append("vn %.6f %.6f %.6f" % (x, y, z))
        lines.append("vt %.6f %.6f" % (j / segs, 1 - i / rings))
w = segs + 1
for i in range(rings):
    for j in range(segs):
        a, b, c, d = i * w + j + 1, i * w + j + 2, (i + 1) * w + j + 1, (i + 1) * w + j + 2
        if i != 0:
            lines.append("f %d/%d/%d %d/%d/%d %d/%d/%d" % (a, a, a, b, b, b, c, c, c))
        if i != rings - 1:
            lines.append("f %d/%d/%d %d/%d/%d %d/%d/%d" % (b, b, b, d, d, d, c, c, c))
open(path, "w").write("\n".join(lines) + "\n")
