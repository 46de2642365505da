"""Generates mitsuba_bsdf_reference.csv: Mitsuba 3 (scalar_rgb) BSDF values
that tests/bsdf_mitsuba.rs compares mcmc-render's BSDFs against.

Run from this directory:  python3 gen_mitsuba_bsdf_reference.py
(needs `pip install mitsuba`; the CSV records the Mitsuba version used).

Mitsuba's naming is the reverse of ours: its `si.wi` is our `wo` (the
direction the path arrived from) and its `wo` is our `wi`; its `eval`
includes the cosine of our `wi`.
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


CONFIGS = {
    "diffuse": {"type": "diffuse", "reflectance": rgb([0.2, 0.5, 0.8])},
    "twosided_diffuse": {"type": "twosided", "b": {"type": "diffuse", "reflectance": rgb([0.2, 0.5, 0.8])}},
    "mirror": {"type": "conductor"},
    "gold": {"type": "conductor", "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K)},
    "glass": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0},
}
for dist in ["beckmann", "ggx"]:
    for (au, av) in [(0.05, 0.05), (0.3, 0.3), (0.1, 0.5)]:
        tag = f"{dist}_{au}_{av}"
        CONFIGS[f"roughconductor_{tag}"] = {
            "type": "roughconductor", "distribution": dist, "alpha_u": au, "alpha_v": av,
            "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K),
        }
        CONFIGS[f"twosided_roughconductor_{tag}"] = {
            "type": "twosided",
            "b": {"type": "roughconductor", "distribution": dist, "alpha_u": au, "alpha_v": av,
                  "eta": rgb(GOLD_ETA), "k": rgb(GOLD_K)},
        }
        CONFIGS[f"roughdielectric_{tag}"] = {
            "type": "roughdielectric", "distribution": dist, "alpha_u": au, "alpha_v": av,
            "int_ior": 1.5, "ext_ior": 1.0,
        }

# Coated and thin models (appended after the others, so that the random
# directions of the earlier configurations stay as they were).
CONFIGS["plastic"] = {"type": "plastic", "diffuse_reflectance": rgb([0.2, 0.5, 0.8])}
CONFIGS["plasticnl"] = {
    "type": "plastic", "diffuse_reflectance": rgb([0.2, 0.5, 0.8]), "nonlinear": True,
    "specular_reflectance": rgb([0.9, 0.7, 0.5]), "int_ior": 1.9,
}
for dist, a in [("beckmann", 0.1), ("ggx", 0.3), ("beckmann", 0.5)]:
    CONFIGS[f"roughplastic_{dist}_{a}_{a}"] = {
        "type": "roughplastic", "distribution": dist, "alpha": a,
        "diffuse_reflectance": rgb([0.2, 0.5, 0.8]),
    }
CONFIGS["roughplasticnl_ggx_0.2_0.2"] = {
    "type": "roughplastic", "distribution": "ggx", "alpha": 0.2, "nonlinear": True,
    "diffuse_reflectance": rgb([0.2, 0.5, 0.8]), "specular_reflectance": rgb([0.9, 0.7, 0.5]),
    "int_ior": 1.9,
}
CONFIGS["roughplastichidden_beckmann_0.2_0.2"] = {
    "type": "roughplastic", "distribution": "beckmann", "alpha": 0.2, "sample_visible": False,
    "diffuse_reflectance": rgb([0.2, 0.5, 0.8]),
}
CONFIGS["thindielectric"] = {"type": "thindielectric", "int_ior": 1.5, "ext_ior": 1.0}
CONFIGS["thindielectric_tinted"] = {
    "type": "thindielectric", "int_ior": 1.9, "ext_ior": 1.0,
    "specular_reflectance": rgb([0.9, 0.7, 0.5]), "specular_transmittance": rgb([0.3, 0.6, 0.9]),
}


def unit(rng):
    z = rng.uniform(-1, 1)
    phi = rng.uniform(0, 2 * math.pi)
    r = math.sqrt(max(0.0, 1 - z * z))
    return [r * math.cos(phi), r * math.sin(phi), z]


def main():
    rng = np.random.default_rng(20261122)
    rows = []
    for name, d in CONFIGS.items():
        bsdf = mi.load_dict(d)
        for i in range(48):
            wo = unit(rng)
            if i % 3 == 0:
                # Near-specular pairs, where glossy lobes are not negligible.
                wi = [-wo[0] + rng.normal(0, 0.1), -wo[1] + rng.normal(0, 0.1), wo[2]]
            elif i % 3 == 1:
                # Near-refraction pairs (straight through, perturbed).
                wi = [-wo[0] * 0.7 + rng.normal(0, 0.1), -wo[1] * 0.7 + rng.normal(0, 0.1), -wo[2]]
            else:
                wi = unit(rng)
            n = math.sqrt(sum(c * c for c in wi))
            wi = [c / n for c in wi]
            for mode_name, mode in [("radiance", mi.TransportMode.Radiance), ("importance", mi.TransportMode.Importance)]:
                ctx = mi.BSDFContext(mode)
                si = mi.SurfaceInteraction3f()
                si.wi = mi.Vector3f(wo)
                f = bsdf.eval(ctx, si, mi.Vector3f(wi))
                pdf = bsdf.pdf(ctx, si, mi.Vector3f(wi))
                # Delta models: record the deterministic sample for two lobe choices.
                s_rows = []
                for u_lobe in [0.01, 0.99]:
                    bs, w = bsdf.sample(ctx, si, u_lobe, mi.Point2f(0.3, 0.6))
                    s_rows.append([u_lobe, bs.wo[0], bs.wo[1], bs.wo[2], w[0], w[1], w[2], bs.pdf, float(bs.pdf > 0)])
                rows.append([name, mode_name, *wo, *wi, f[0], f[1], f[2], pdf, *s_rows[0], *s_rows[1]])
    with open("mitsuba_bsdf_reference.csv", "w", newline="") as fh:
        fh.write(f"# Mitsuba {mi.__version__} scalar_rgb, generated by gen_mitsuba_bsdf_reference.py\n")
        w = csv.writer(fh)
        w.writerow(["config", "mode", "wo_x", "wo_y", "wo_z", "wi_x", "wi_y", "wi_z", "f_cos_r", "f_cos_g", "f_cos_b", "pdf",
                    "s0_ulobe", "s0_wi_x", "s0_wi_y", "s0_wi_z", "s0_w_r", "s0_w_g", "s0_w_b", "s0_pdf", "s0_valid",
                    "s1_ulobe", "s1_wi_x", "s1_wi_y", "s1_wi_z", "s1_w_r", "s1_w_g", "s1_w_b", "s1_pdf", "s1_valid"])
        for r in rows:
            w.writerow([r[0], r[1]] + [f"{float(x):.9g}" for x in r[2:]])


if __name__ == "__main__":
    main()
