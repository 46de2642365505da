#!/usr/bin/env python3
"""Write scenes/textures/grid.png, the small texture of scenes/textured.xml.

An 8x8 8-bit sRGB PNG (standard library only): red grows along x, green along y, blue
falls along x + y, and texel (0, 0) (the top-left of the image, v = 0 in Mitsuba's
convention) is pure yellow, so that a flipped or mirrored lookup is visible in a render.

Usage: python3 scenes/tools/make_test_texture.py [OUT.png]
"""

import struct
import sys
import zlib


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def main() -> None:
    out = sys.argv[1] if len(sys.argv) > 1 else "scenes/textures/grid.png"
    w = h = 8
    rows = b""
    for y in range(h):
        row = bytearray([0])  # filter type: none
        for x in range(w):
            if (x, y) == (0, 0):
                row += bytes([255, 255, 0])
            else:
                row += bytes([30 + 30 * x, 30 + 30 * y, 230 - 14 * (x + y)])
        rows += bytes(row)
    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(rows, 9))
    png += chunk(b"IEND", b"")
    with open(out, "wb") as f:
        f.write(png)


if __name__ == "__main__":
    main()
