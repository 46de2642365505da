#!/usr/bin/env python3
"""Write scenes/meshes/ring.obj: a faceted ring (a polygonal tube wall) for scenes/ring.xml.

The ring stands on the plane y = 0 around the y axis: `facets` flat quads make the
inner wall (normals towards the axis), `facets` more the outer wall (normals away from
it), and the top rim is a band of quads between them (normal +y). There is no bottom
(it rests on the floor). Every face is flat, so the ring is faceted as in the thesis's
Ring scene (seed 000, §5.5), and the OBJ has no `vn`: each triangle gets its geometric
normal. Vertex winding is counter-clockwise seen from the side the normal points to.

Usage: python3 scenes/tools/make_ring.py [--facets 48] [--radius 0.6] [--thickness 0.03]
                                         [--height 0.3] [--out scenes/meshes/ring.obj]
"""

import argparse
import math


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--facets", type=int, default=48)
    ap.add_argument("--radius", type=float, default=0.6, help="inner radius")
    ap.add_argument("--thickness", type=float, default=0.03)
    ap.add_argument("--height", type=float, default=0.3)
    ap.add_argument("--out", default="scenes/meshes/ring.obj")
    a = ap.parse_args()
    n, r0, r1, h = a.facets, a.radius, a.radius + a.thickness, a.height

    verts = []  # four rings of n vertices: inner bottom, inner top, outer bottom, outer top
    for r, y in ((r0, 0.0), (r0, h), (r1, 0.0), (r1, h)):
        for i in range(n):
            phi = 2.0 * math.pi * i / n
            verts.append((r * math.cos(phi), y, r * math.sin(phi)))

    def idx(ring: int, i: int) -> int:
        return ring * n + (i % n) + 1  # OBJ indices start at 1

    faces = []
    for i in range(n):
        ib0, ib1 = idx(0, i), idx(0, i + 1)
        it0, it1 = idx(1, i), idx(1, i + 1)
        ob0, ob1 = idx(2, i), idx(2, i + 1)
        ot0, ot1 = idx(3, i), idx(3, i + 1)
        # Inner wall (normal towards the axis).
        faces += [(ib0, it1, it0), (ib0, ib1, it1)]
        # Outer wall (normal away from the axis).
        faces += [(ob0, ot1, ob1), (ob0, ot0, ot1)]
        # Top rim (normal +y).
        faces += [(it0, ot1, ot0), (it0, it1, ot1)]

    with open(a.out, "w") as f:
        f.write(f"# faceted ring: {n} facets, inner radius {r0}, thickness {a.thickness}, "
                f"height {h}; written by scenes/tools/make_ring.py\n")
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % v)
        for t in faces:
            f.write("f %d %d %d\n" % t)


if __name__ == "__main__":
    main()
