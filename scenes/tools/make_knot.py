#!/usr/bin/env python3
"""Write scenes/meshes/knot.obj: a smooth trefoil-knot tube for scenes/glass-knot.xml.

The knot is the (2, 3) torus knot x = sin t + 2 sin 2t, y = cos t - 2 cos 2t,
z = -sin 3t, scaled by `scale`, with a circular tube of radius `tube` swept along it
(a rotation-minimising frame by parallel transport, closed up by spreading the frame's
residual twist along the curve). The OBJ has `vn` (the tube's exact normals), so a
smooth dielectric on it focuses light into a large, smooth caustic, the role of the
glass dragon of seed 000's "Dragon" scene (section 5.5). Winding is counter-clockwise
seen from outside. The knot is centred on the origin in the xy plane; the scene file
places it.

Usage: python3 scenes/tools/make_knot.py [--segments 256] [--sides 16] [--scale 0.1]
                                         [--tube 0.045] [--out scenes/meshes/knot.obj]
"""

import argparse
import math


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def unit(a):
    n = math.sqrt(dot(a, a))
    return (a[0] / n, a[1] / n, a[2] / n)


def curve(t, s):
    return (s * (math.sin(t) + 2 * math.sin(2 * t)),
            s * (math.cos(t) - 2 * math.cos(2 * t)),
            s * (-math.sin(3 * t)))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--segments", type=int, default=256)
    ap.add_argument("--sides", type=int, default=16)
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--tube", type=float, default=0.045)
    ap.add_argument("--out", default="scenes/meshes/knot.obj")
    a = ap.parse_args()
    n, m = a.segments, a.sides

    pts = [curve(2 * math.pi * i / n, a.scale) for i in range(n)]
    tangents = [unit(sub(pts[(i + 1) % n], pts[i - 1])) for i in range(n)]
    # Parallel transport of a normal along the curve.
    t0 = tangents[0]
    helper = (0.0, 0.0, 1.0) if abs(t0[2]) < 0.9 else (1.0, 0.0, 0.0)
    normal = unit(cross(t0, helper))
    normals = [normal]
    for i in range(1, n + 1):
        t = tangents[i % n]
        prev = normals[-1]
        prev = sub(prev, tuple(dot(prev, t) * c for c in t))
        normals.append(unit(prev))
    # The frame does not close: spread the residual twist evenly.
    end, start = normals[n], normals[0]
    twist = math.atan2(dot(cross(end, start), tangents[0]), dot(end, start))
    frames = []
    for i in range(n):
        t = tangents[i]
        nn = normals[i]
        bb = cross(t, nn)
        ang = twist * i / n
        c, s = math.cos(ang), math.sin(ang)
        n2 = tuple(c * nn[k] + s * bb[k] for k in range(3))
        b2 = cross(t, n2)
        frames.append((n2, b2))

    verts, vnorms = [], []
    for i in range(n):
        n2, b2 = frames[i]
        for j in range(m):
            phi = 2 * math.pi * j / m
            d = tuple(math.cos(phi) * n2[k] + math.sin(phi) * b2[k] for k in range(3))
            verts.append(tuple(pts[i][k] + a.tube * d[k] for k in range(3)))
            vnorms.append(d)

    def idx(i, j):
        return (i % n) * m + (j % m) + 1

    faces = []
    for i in range(n):
        for j in range(m):
            a0, a1 = idx(i, j), idx(i, j + 1)
            b0, b1 = idx(i + 1, j), idx(i + 1, j + 1)
            faces += [(a0, b0, b1), (a0, b1, a1)]

    # Check the winding once: the first face's geometric normal must point outwards.
    p = [verts[k - 1] for k in faces[0]]
    g = cross(sub(p[1], p[0]), sub(p[2], p[0]))
    if dot(g, vnorms[faces[0][0] - 1]) < 0:
        faces = [(f[0], f[2], f[1]) for f in faces]

    with open(a.out, "w") as f:
        f.write(f"# trefoil knot tube: {n} segments x {m} sides, scale {a.scale}, tube radius "
                f"{a.tube}; written by scenes/tools/make_knot.py\n")
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % v)
        for v in vnorms:
            f.write("vn %.6f %.6f %.6f\n" % v)
        for t in faces:
            f.write("f %d//%d %d//%d %d//%d\n" % (t[0], t[0], t[1], t[1], t[2], t[2]))


if __name__ == "__main__":
    main()
