#!/usr/bin/env python3
"""Usage: uv_sphere_ply.py N OUT.ply -- writes a binary PLY UV sphere of about N*N triangles
(N=1000 gives 998000), used for the 1M-triangle memory figure in docs/performance.md."""
# Writes a binary PLY UV sphere of about n*n triangles (for the 1M-triangle memory figure).
import struct, math, sys
n = int(sys.argv[1]); out = sys.argv[2]
rings = n // 2
verts = []
for i in range(rings + 1):
    th = math.pi * i / rings
    for j in range(n):
        ph = 2 * math.pi * j / n
        verts.append((math.sin(th) * math.cos(ph), math.cos(th), math.sin(th) * math.sin(ph)))
faces = []
for i in range(rings):
    for j in range(n):
        a = i * n + j; b = i * n + (j + 1) % n; c = a + n; d = b + n
        if i != 0: faces.append((a, b, c))
        if i != rings - 1: faces.append((b, d, c))
with open(out, 'wb') as f:
    f.write(f"ply\nformat binary_little_endian 1.0\nelement vertex {len(verts)}\nproperty float x\nproperty float y\nproperty float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n".encode())
    f.write(b''.join(struct.pack('<fff', *v) for v in verts))
    f.write(b''.join(struct.pack('<Biii', 3, *t) for t in faces))
print(len(faces), "triangles")
