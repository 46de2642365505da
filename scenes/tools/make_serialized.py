#!/usr/bin/env python3
"""Writes the `.serialized` test meshes of mcmc-render/tests/data/serialized/
(and the same meshes as OBJ), then checks every one with Mitsuba 3's own
`serialized` plugin.

The writer follows the format as Mitsuba 3 documents it for its
`serialized` shape plugin: per shape a uint16 format id 0x041C and a uint16
version (3 or 4), then a zlib stream with uint32 flags, (version 4) the
NUL-terminated shape name, uint64 vertex and triangle counts, positions,
optional normals, texture coordinates and vertex colours (float32 or
float64 by the flags) and uint32 triangle indices; the file ends with each
shape's byte offset (uint64 in version 4, uint32 in version 3) and the
uint32 shape count. All little-endian.

Mitsuba 3 is the independent reader: each shape of each file is loaded by
`mi.load_dict({"type": "serialized", ...})` and its vertex positions,
texture coordinates and faces must equal what was written (bit for bit: every coordinate is chosen
to be exact in float32). Run from the repository root:

    python3 scenes/tools/make_serialized.py

Needs only the standard library and `pip install mitsuba` (scalar_rgb).
"""

import math
import os
import struct
import zlib

OUT = os.path.join("mcmc-render", "tests", "data", "serialized")

HAS_NORMALS = 0x0001
HAS_TEXCOORDS = 0x0002
HAS_COLORS = 0x0008
SINGLE = 0x1000
DOUBLE = 0x2000


def f32(x):
    """x rounded to float32 (so text and binary copies agree exactly)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def bumpy_patch(n=6):
    """An n×n grid over [-1, 1]² with a dyadic height field, smooth normals."""
    pos, nrm, uv, idx = [], [], [], []
    for j in range(n + 1):
        for i in range(n + 1):
            x = -1 + 2 * i / n
            y = -1 + 2 * j / n
            # Heights on a 1/64 grid: exact in float32.
            z = round(16 * (0.25 * math.sin(2 * x) * math.cos(3 * y))) / 64
            pos.append((f32(x), f32(y), z))
            uv.append((i / n, j / n))
    for j in range(n + 1):
        for i in range(n + 1):
            # Normal from central differences of the grid (any unit-ish
            # vector will do: both copies carry the same float32 values).
            def h(a, b):
                a = min(max(a, 0), n)
                b = min(max(b, 0), n)
                return pos[b * (n + 1) + a][2]

            dx = (h(i + 1, j) - h(i - 1, j)) * n / 4
            dy = (h(i, j + 1) - h(i, j - 1)) * n / 4
            ln = math.sqrt(dx * dx + dy * dy + 1)
            nrm.append((f32(-dx / ln), f32(-dy / ln), f32(1 / ln)))
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            idx.append((a, a + 1, a + n + 2))
            idx.append((a, a + n + 2, a + n + 1))
    return pos, nrm, uv, idx


def tetrahedron():
    pos = [(0.5, 0.0, 0.0), (-0.25, 0.5, 0.0), (-0.25, -0.5, 0.0), (0.0, 0.0, 0.75)]
    idx = [(0, 2, 1), (0, 1, 3), (1, 2, 3), (2, 0, 3)]
    return pos, None, None, idx


def shape_stream(version, name, pos, nrm, uv, idx, double=False, colors=False):
    flags = DOUBLE if double else SINGLE
    if nrm is not None:
        flags |= HAS_NORMALS
    if uv is not None:
        flags |= HAS_TEXCOORDS
    if colors:
        flags |= HAS_COLORS
    fmt = "<d" if double else "<f"
    body = bytearray(struct.pack("<I", flags))
    if version == 4:
        body += name.encode() + b"\0"
    body += struct.pack("<QQ", len(pos), len(idx))
    for arr in (pos, nrm, uv):
        if arr is not None:
            for v in arr:
                for c in v:
                    body += struct.pack(fmt, c)
    if colors:
        for k in range(len(pos)):
            for c in (k / len(pos), 0.5, 1.0):
                body += struct.pack(fmt, c)
    for t in idx:
        body += struct.pack("<III", *t)
    return struct.pack("<HH", 0x041C, version) + zlib.compress(bytes(body), 9)


def write_file(path, version, shapes, **kw):
    data = bytearray()
    offsets = []
    for name, (pos, nrm, uv, idx) in shapes:
        offsets.append(len(data))
        data += shape_stream(version, name, pos, nrm, uv, idx, **kw)
    word = "<Q" if version == 4 else "<I"
    for o in offsets:
        data += struct.pack(word, o)
    data += struct.pack("<I", len(offsets))
    with open(path, "wb") as f:
        f.write(data)


def write_obj(path, pos, nrm, idx):
    with open(path, "w") as f:
        f.write("# written by scenes/tools/make_serialized.py\n")
        for p in pos:
            f.write("v %.9g %.9g %.9g\n" % p)
        if nrm is not None:
            for n in nrm:
                f.write("vn %.9g %.9g %.9g\n" % n)
        for t in idx:
            a, b, c = (i + 1 for i in t)
            if nrm is not None:
                f.write("f %d//%d %d//%d %d//%d\n" % (a, a, b, b, c, c))
            else:
                f.write("f %d %d %d\n" % (a, b, c))


def check_with_mitsuba(path, index, pos, uv, idx):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    shape = mi.load_dict({"type": "serialized", "filename": path, "shape_index": index})
    params = mi.traverse(shape)
    got_pos = list(params["vertex_positions"])
    got_idx = list(params["faces"])
    want_pos = [c for p in pos for c in p]
    want_idx = [i for t in idx for i in t]
    assert got_pos == want_pos, f"{path}@{index}: positions differ"
    assert got_idx == want_idx, f"{path}@{index}: faces differ"
    if uv is not None:
        got_uv = list(params["vertex_texcoords"])
        want_uv = [f32(c) for t in uv for c in t]
        assert got_uv == want_uv, f"{path}@{index}: texture coordinates differ"
    print(f"{path}@{index}: Mitsuba 3 reads {len(pos)} vertices, {len(idx)} triangles: equal")


def main():
    os.makedirs(OUT, exist_ok=True)
    patch = bumpy_patch()
    tet = tetrahedron()
    files = {
        # Version 4, float32, with normals and UVs; two shapes.
        "meshes-v4.serialized": (4, {}),
        # Version 3, float64, UVs and vertex colours; two shapes.
        "meshes-v3-double.serialized": (3, {"double": True, "colors": True}),
    }
    for name, (version, kw) in files.items():
        path = os.path.join(OUT, name)
        shapes = [("patch", patch), ("tetrahedron", tet)]
        if version == 3:
            # No normals in this file: the reader must compute them.
            shapes = [("patch", (patch[0], None, patch[2], patch[3])), ("tetrahedron", tet)]
        write_file(path, version, shapes, **kw)
        for i, (_, (pos, _, uv, idx)) in enumerate(shapes):
            check_with_mitsuba(path, i, pos, uv, idx)
    write_obj(os.path.join(OUT, "patch.obj"), patch[0], patch[1], patch[3])
    write_obj(os.path.join(OUT, "patch-no-normals.obj"), patch[0], None, patch[3])
    write_obj(os.path.join(OUT, "tetrahedron.obj"), tet[0], None, tet[3])


if __name__ == "__main__":
    main()
