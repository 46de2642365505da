#!/usr/bin/env python3
"""Write a binary PLY of a wavy N x N grid (2·(N−1)² triangles) with
per-vertex normals and UVs, and a scene that shows it, for the load-time
and memory comparison in docs/performance.md.

    python3 scenes/tools/make_big_mesh.py OUT_DIR [N]   # N = 708: ~1M triangles
"""
import math
import os
import struct
import sys

import numpy as np

out = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 708
os.makedirs(out, exist_ok=True)
u = np.linspace(0.0, 1.0, n, dtype=np.float32)
uu, vv = np.meshgrid(u, u)
x = uu * 2 - 1
z = vv * 2 - 1
y = 0.05 * np.sin(8 * x) * np.cos(8 * z)
# Normal of y = f(x, z): (−f_x, 1, −f_z), normalised.
fx = 0.4 * np.cos(8 * x) * np.cos(8 * z)
fz = -0.4 * np.sin(8 * x) * np.sin(8 * z)
nrm = np.stack([-fx, np.ones_like(fx), -fz], axis=-1)
nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
verts = np.concatenate(
    [np.stack([x, y, z], axis=-1), nrm, np.stack([uu, vv], axis=-1)], axis=-1
).reshape(-1, 8).astype("<f4")
idx = np.arange(n * n, dtype=np.int64).reshape(n, n)
a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
tris = np.concatenate(
    [np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)]
)
faces = np.empty(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
faces["n"] = 3
faces["i"] = tris
path = os.path.join(out, "grid.ply")
with open(path, "wb") as f:
    f.write(
        (
            "ply\nformat binary_little_endian 1.0\n"
            f"element vertex {n * n}\n"
            "property float x\nproperty float y\nproperty float z\n"
            "property float nx\nproperty float ny\nproperty float nz\n"
            "property float u\nproperty float v\n"
            f"element face {len(tris)}\n"
            "property list uchar int vertex_indices\nend_header\n"
        ).encode()
    )
    f.write(verts.tobytes())
    f.write(faces.tobytes())
with open(os.path.join(out, "grid.xml"), "w") as f:
    f.write(
        """<scene version="3.0.0">
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 2, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="64"/></film>
    </sensor>
    <emitter type="constant"/>
    <shape type="ply"><string name="filename" value="grid.ply"/></shape>
</scene>
"""
    )
print(f"{path}: {n * n} vertices, {len(tris)} triangles")
