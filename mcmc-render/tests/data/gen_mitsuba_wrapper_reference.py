"""Generates mitsuba_wrapper_reference.csv: Mitsuba 3 (scalar_rgb) values of
the BSDF wrappers `normalmap`, `bumpmap` and `mask` at known surface points,
which tests/bsdf_mitsuba_wrappers.rs compares mcmc-render's against.

Run from this directory:  python3 gen_mitsuba_wrapper_reference.py
(needs `pip install mitsuba==3.9.1 numpy`; the CSV records the version).

Each surface point is given in world coordinates: geometric normal `ng`,
shading normal `ns`, UV and the surface derivatives dp/du, dp/dv (Mitsuba's
shading frame is then built by `initialize_sh_frame`: s along dp/du). The
maps are 4x4 bitmaps (bilinear, repeat, raw) whose texels are written to
the CSV as `texel` rows, so that the Rust test builds the same images.
Directions are written in world coordinates; each renderer expresses them
in its own shading frame.

Per row: Mitsuba's value `eval` and `pdf` with `si.wi = wo`, `wo = wi`
(our naming: `wo` the side the path arrived from, `wi` the sampled one) in
radiance mode, the same with the two directions swapped (radiance mode),
and Mitsuba's importance-mode value (recorded, not expected to match: see
the test). For `mask`, the null lobe's sample at u_lobe = 0.999.
"""

import csv
import math

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

GOLD_ETA = [0.143, 0.374, 1.442]
GOLD_K = [3.983, 2.385, 1.603]


def rgb(v):
    return {"type": "rgb", "value": v}


NESTED = {
    "diffuse": {"type": "diffuse", "reflectance": rgb([0.2, 0.5, 0.8])},
    "roughplastic": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3,
                     "diffuse_reflectance": rgb([0.2, 0.5, 0.8])},
    "roughconductor": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.2,
                       "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K)},
    "roughdielectric": {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.3,
                        "int_ior": 1.5, "ext_ior": 1.0},
}

BUMP_SCALE = 0.5


def texels():
    rng = np.random.default_rng(20261125)
    # Heights: coloured, so that the luminance weighting is exercised.
    bump = rng.uniform(0.0, 1.0, (4, 4, 3)).astype(np.float32)
    # Normals with positive z, encoded as (n + 1) / 2.
    n = np.concatenate([rng.normal(0.0, 0.45, (4, 4, 2)), np.ones((4, 4, 1))], axis=2)
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    normal = ((n + 1.0) / 2.0).astype(np.float32)
    return {"bump": bump, "normal": normal}


def bitmap(a):
    return {"type": "bitmap", "bitmap": mi.Bitmap(a), "raw": True,
            "filter_type": "bilinear", "wrap_mode": "repeat"}


def configs(tex):
    c = {}
    for name, nested in NESTED.items():
        c[f"normalmap_{name}"] = {"type": "normalmap", "normalmap": bitmap(tex["normal"]), "bsdf": nested}
    for name in ["diffuse", "roughplastic", "roughconductor"]:
        c[f"bumpmap_{name}"] = {"type": "bumpmap", "arbitrary": bitmap(tex["bump"]),
                                "scale": BUMP_SCALE, "bsdf": NESTED[name]}
    c["mask_diffuse"] = {"type": "mask", "opacity": 0.3, "bsdf": NESTED["diffuse"]}
    c["mask_roughplastic"] = {"type": "mask", "opacity": 0.7, "bsdf": NESTED["roughplastic"]}
    c["mask_bumpmap_roughplastic"] = {"type": "mask", "opacity": 0.6,
                                      "bsdf": c["bumpmap_roughplastic"]}
    return c


def normalize(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


# (uv, ng, ns, dp_du, dp_dv): a flat point, a point whose shading normal
# differs from the geometric one (interpolated normals), and one with UVs
# outside [0, 1] (repeat wrap).
POINTS = [
    ((0.3, 0.6), normalize([0.2, -0.3, 1.0]), normalize([0.2, -0.3, 1.0]),
     [1.0, 0.3, 0.2], [0.1, 1.0, -0.15]),
    ((0.71, 0.12), normalize([0.0, 0.0, 1.0]), normalize([0.25, 0.1, 1.0]),
     [0.8, -0.2, 0.1], [0.3, 1.2, 0.05]),
    ((1.37, -0.45), normalize([-0.1, 0.4, 1.0]), normalize([-0.15, 0.3, 1.0]),
     [0.0, 1.1, -0.4], [-0.9, 0.0, -0.1]),
]


def unit(rng):
    z = rng.uniform(-1, 1)
    phi = rng.uniform(0, 2 * math.pi)
    r = math.sqrt(max(0.0, 1 - z * z))
    return np.array([r * math.cos(phi), r * math.sin(phi), z])


def interaction(point):
    uv, ng, ns, du, dv = point
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(*uv)
    si.n = mi.Normal3f(*ng)
    si.sh_frame = mi.Frame3f(mi.Normal3f(*ns))
    si.dp_du = mi.Vector3f(*du)
    si.dp_dv = mi.Vector3f(*dv)
    si.initialize_sh_frame()
    return si


def main():
    tex = texels()
    rng = np.random.default_rng(20261126)
    rows = []
    for name, d in configs(tex).items():
        bsdf = mi.load_dict(d)
        for p, point in enumerate(POINTS):
            si = interaction(point)
            ns = point[2]
            for i in range(24):
                wo = unit(rng)
                if i % 2 == 0:
                    # wo mostly above the surface, wi near its mirror image
                    # (glossy lobes), both sides of the tilted planes.
                    if wo @ ns < 0 and i % 4 == 0:
                        wo = -wo
                    wi = 2 * (wo @ ns) * ns - wo + rng.normal(0, 0.25, 3)
                    if i % 8 == 6:
                        wi = -wi  # transmission side
                else:
                    wi = unit(rng)
                wi = normalize(wi)

                def ev(a, b, mode):
                    ctx = mi.BSDFContext(mode)
                    s = mi.SurfaceInteraction3f(si)
                    s.wi = si.to_local(mi.Vector3f(*a))
                    w = si.to_local(mi.Vector3f(*b))
                    f = bsdf.eval(ctx, s, w)
                    return [f[0], f[1], f[2], bsdf.pdf(ctx, s, w)]

                rad = ev(wo, wi, mi.TransportMode.Radiance)
                swapped = ev(wi, wo, mi.TransportMode.Radiance)
                imp = ev(wo, wi, mi.TransportMode.Importance)
                null = [0.0] * 7
                if name.startswith("mask"):
                    s = mi.SurfaceInteraction3f(si)
                    s.wi = si.to_local(mi.Vector3f(*wo))
                    bs, w = bsdf.sample(mi.BSDFContext(), s, 0.999, mi.Point2f(0.3, 0.6))
                    wow = si.to_world(bs.wo)
                    null = [wow[0], wow[1], wow[2], w[0], w[1], w[2], bs.pdf]
                rows.append([name, p, *wo, *wi, *rad, *swapped, *imp, *null])
    with open("mitsuba_wrapper_reference.csv", "w", newline="") as fh:
        fh.write(f"# Mitsuba {mi.__version__} scalar_rgb, generated by gen_mitsuba_wrapper_reference.py\n")
        fh.write(f"# bump scale {BUMP_SCALE}\n")
        w = csv.writer(fh)
        for p, (uv, ng, ns, du, dv) in enumerate(POINTS):
            w.writerow(["point", p] + [f"{float(x):.9g}" for x in [*uv, *ng, *ns, *du, *dv]])
        for tname, a in tex.items():
            for y in range(a.shape[0]):
                for x in range(a.shape[1]):
                    w.writerow(["texel", tname, x, y] + [f"{float(c):.9g}" for c in a[y, x]])
        w.writerow(["config", "point", "wo_x", "wo_y", "wo_z", "wi_x", "wi_y", "wi_z",
                    "f_r", "f_g", "f_b", "pdf", "sw_f_r", "sw_f_g", "sw_f_b", "sw_pdf",
                    "imp_f_r", "imp_f_g", "imp_f_b", "imp_pdf",
                    "null_x", "null_y", "null_z", "null_w_r", "null_w_g", "null_w_b", "null_pdf"])
        for r in rows:
            w.writerow([r[0], r[1]] + [f"{float(x):.9g}" for x in r[2:]])


if __name__ == "__main__":
    main()
