#!/usr/bin/env python3
"""Session 20, docs/smcmc.md: SMCMC's shifts on the 64x64 tilted glossy-glass box
against a PT reference, per region (glass sphere, caustic, brightest 5%, rest).

Usage: failure_modes.py DIR OUT_CSV OUT_PNG [SHIFTS]
DIR holds ref.exr (PT), mask.exr (the sphere as an emitter, max_depth 1) and
SHIFT-SEED.exr for SHIFT in SHIFTS (comma-separated; default bdpt,cmmlt,ummlt)
and SEED in 1, 2, 3 (the commands are in docs/smcmc.md). Needs numpy and the
OpenEXR bindings."""
import struct, sys, zlib
import Imath, OpenEXR
import numpy as np

SEEDS = (1, 2, 3)


def read(path):
    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    pt = Imath.PixelType(Imath.PixelType.FLOAT)
    return np.stack([np.frombuffer(f.channel(c, pt), dtype=np.float32).reshape(h, w) for c in "RGB"], -1).astype(np.float64)


def lum(im):
    return im @ np.array([0.2126, 0.7152, 0.0722])


def write_png(path, rgb8):
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[y].tobytes() for y in range(h))

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    open(path, "wb").write(png + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def to8(im, exposure=2.0, scale=4):
    x = np.clip(im * exposure, 0, 1)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    v = (x * 255 + 0.5).astype(np.uint8)
    return np.repeat(np.repeat(v, scale, 0), scale, 1)


def main(d, out_csv, out_png, shifts="bdpt,cmmlt,ummlt"):
    shifts = shifts.split(",")
    ref, mask = read(f"{d}/ref.exr"), read(f"{d}/mask.exr")[..., 0]
    L = lum(ref)
    sphere = mask > 0.99  # pixels that see only the sphere
    caustic = (L > 0.3) & ~sphere  # the focused light under the sphere
    outside = (mask < 0.01) & ~caustic
    bright = outside & (L >= np.quantile(L[outside], 0.95))
    regions = {"image": np.ones_like(sphere), "sphere": sphere, "caustic": caustic, "bright": bright, "rest": outside & ~bright}
    print("pixels:", {k: int(v.sum()) for k, v in regions.items()})
    rows = ["shift,seed," + ",".join(f"{k}_rel_pct" for k in regions) + ",relmse"]
    for sh in shifts:
        for seed in SEEDS:
            im = lum(read(f"{d}/{sh}-{seed}.exr"))
            rel = [100 * (im[r].mean() / L[r].mean() - 1) for r in regions.values()]
            relmse = np.mean((im - L) ** 2 / (L**2 + 1e-2))
            rows.append(f"{sh},{seed}," + ",".join(f"{v:.2f}" for v in rel) + f",{relmse:.5f}")
    open(out_csv, "w").write("\n".join(rows) + "\n")
    print("\n".join(rows))
    # Rows seeds 1 and 2: reference | each shift, the lit rows 0..39, x4.
    white = lambda h, w: np.full((h, w, 3), 255, np.uint8)
    strips = []
    for seed in SEEDS[:2]:
        tiles = [to8(im[:40]) for im in [ref] + [read(f"{d}/{sh}-{seed}.exr") for sh in shifts]]
        parts = sum([[t, white(t.shape[0], 4)] for t in tiles], [])[:-1]
        strips += [np.concatenate(parts, 1), white(4, sum(p.shape[1] for p in parts))]
    write_png(out_png, np.concatenate(strips[:-1], 0))


if __name__ == "__main__":
    main(*sys.argv[1:5])
