#!/usr/bin/env python3
"""Write the textures of scenes/normalmap-bumpmap.xml and scenes/mask-leaves.xml
(standard library only):

- scenes/textures/bumps.png: a 32x32 8-bit grey height field (a smooth egg-crate
  pattern, two periods per side, values 40..215), read by `bumpmap`;
- scenes/textures/normals.png: a 32x32 8-bit RGB tangent-space normal map made
  from a tilted ridge pattern, encoded (n + 1) / 2 per channel, read with
  raw = true by `normalmap`. Its normals tilt up to ~35 degrees, in x and y;
- scenes/textures/leaf.png: a 32x32 8-bit grey opacity mask for
  scenes/mask-leaves.xml (read raw): a leaf-shaped ellipse, opaque (255)
  except for a half-transparent (128) band along its midrib and two holes,
  transparent (0) outside.

Usage: python3 scenes/tools/make_perturb_textures.py [OUTDIR]
"""

import math
import struct
import sys
import zlib
from pathlib import Path


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png(path: Path, w: int, h: int, channels: int, pixel) -> None:
    rows = b""
    for y in range(h):
        row = bytearray([0])
        for x in range(w):
            row += bytes(pixel(x, y))
        rows += bytes(row)
    color_type = {1: 0, 3: 2}[channels]
    data = b"\x89PNG\r\n\x1a\n"
    data += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, color_type, 0, 0, 0))
    data += chunk(b"IDAT", zlib.compress(rows, 9))
    data += chunk(b"IEND", b"")
    path.write_bytes(data)


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "scenes/textures")
    n = 32

    def height(x, y):
        s = math.sin(2 * math.pi * 2 * (x + 0.5) / n) * math.sin(2 * math.pi * 2 * (y + 0.5) / n)
        return [round(127.5 + 87.5 * s)]

    png(out / "bumps.png", n, n, 1, height)

    def normal(x, y):
        u, v = (x + 0.5) / n, (y + 0.5) / n
        nx = 0.55 * math.sin(2 * math.pi * 3 * u)
        ny = 0.35 * math.cos(2 * math.pi * 2 * v)
        l = math.sqrt(nx * nx + ny * ny + 1.0)
        return [round(255 * (c / l + 1) / 2) for c in (nx, ny, 1.0)]

    png(out / "normals.png", n, n, 3, normal)

    def leaf(x, y):
        u, v = (x + 0.5) / n - 0.5, (y + 0.5) / n - 0.5
        if (u / 0.45) ** 2 + (v / 0.3) ** 2 > 1.0:
            return [0]
        if (u - 0.15) ** 2 + (v - 0.1) ** 2 < 0.005 or (u + 0.2) ** 2 + (v + 0.08) ** 2 < 0.004:
            return [0]
        if abs(v) < 0.04:
            return [128]
        return [255]

    png(out / "leaf.png", n, n, 1, leaf)


if __name__ == "__main__":
    main()
