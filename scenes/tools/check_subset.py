#!/usr/bin/env python3
"""Check that scene files use only the Mitsuba-XML subset mcmc-render's loader accepts.

The subset (issue 5): shapes obj, ply, rectangle, cube, sphere, disk with to_world and
flip_normals; BSDFs diffuse, conductor, roughconductor, dielectric, roughdielectric,
thindielectric, plastic, roughplastic, twosided, ids and refs; textures bitmap and checkerboard (issue 12); emitters area and point; a perspective sensor with hdrfilm
(box or gaussian rfilter) and an independent sampler; the path integrator; values
rgb, float, integer, boolean, string, point, vector, transform; <default> and <include>.

Every element, plugin type and parameter name is checked against the table below,
which lists what this repository's scenes rely on. Exit status 1 and one line per
problem (file:line: message) if anything falls outside it.

Usage:
    python3 scenes/tools/check_subset.py scenes/*.xml
"""

from __future__ import annotations

import sys
import xml.etree.ElementTree as ET

VALUE_TAGS = {"rgb", "float", "integer", "boolean", "string", "point", "vector", "transform"}
TRANSFORM_OPS = {"translate", "rotate", "scale", "matrix", "lookat"}
SHAPE_COMMON = {"to_world", "flip_normals"}

# plugin kind -> type -> allowed parameter names
PLUGINS: dict[str, dict[str, set[str]]] = {
    "shape": {
        "obj": SHAPE_COMMON | {"filename", "face_normals"},
        "ply": SHAPE_COMMON | {"filename", "face_normals"},
        "rectangle": SHAPE_COMMON,
        "cube": SHAPE_COMMON,
        "sphere": SHAPE_COMMON | {"center", "radius"},
        "disk": SHAPE_COMMON,
    },
    "bsdf": {
        "diffuse": {"reflectance"},
        "conductor": {"eta", "k", "material"},
        "roughconductor": {"eta", "k", "material", "distribution", "alpha"},
        "dielectric": {"int_ior", "ext_ior"},
        "roughdielectric": {"int_ior", "ext_ior", "distribution", "alpha"},
        "thindielectric": {"int_ior", "specular_transmittance"},
        "plastic": {"diffuse_reflectance", "specular_reflectance", "int_ior", "nonlinear"},
        "roughplastic": {"diffuse_reflectance", "distribution", "alpha", "nonlinear"},
        "twosided": set(),
    },
    "emitter": {"area": {"radiance"}, "point": {"intensity", "position", "to_world"}},
    "sensor": {"perspective": {"fov", "fov_axis", "to_world", "near_clip", "far_clip"}},
    "film": {"hdrfilm": {"width", "height"}},
    "rfilter": {"box": set(), "gaussian": set()},
    "sampler": {"independent": {"sample_count"}},
    "integrator": {"path": {"max_depth", "rr_depth"}},
    "texture": {
        "bitmap": {"filename", "filter_type", "wrap_mode", "raw", "to_uv"},
        "checkerboard": {"color0", "color1", "to_uv"},
    },
}
# which nested plugin kinds each kind may hold
CHILDREN = {
    "scene": {"shape", "bsdf", "emitter", "sensor", "integrator", "default", "include"},
    "shape": {"bsdf", "emitter", "ref"},
    "bsdf": {"bsdf", "ref", "texture"},
    "texture": {"texture"},
    "emitter": set(),
    "sensor": {"film", "sampler"},
    "film": {"rfilter"},
    "rfilter": set(),
    "sampler": set(),
    "integrator": set(),
}


class Checker:
    """Walks one parsed scene and collects its problems as `file:line: message` strings."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.problems: list[str] = []
        self.ids: set[str] = set()
        self.refs: list[tuple[str, int]] = []

    def bad(self, line: int, msg: str) -> None:
        self.problems.append(f"{self.path}:{line}: {msg}")

    def element(self, el, kind: str) -> None:
        allowed_params = PLUGINS.get(kind, {}).get(el.get("type", ""), set())
        if kind in PLUGINS:
            t = el.get("type")
            if t not in PLUGINS[kind]:
                self.bad(line(el), f"<{kind} type=\"{t}\"> is outside the supported subset")
                return
        if el.get("id"):
            self.ids.add(el.get("id"))
        for child in el:
            tag = child.tag
            if tag in VALUE_TAGS:
                name = child.get("name")
                if kind == "scene":
                    self.bad(line(child), f"<{tag}> directly under <scene>")
                elif name not in allowed_params:
                    self.bad(line(child), f"parameter '{name}' is not supported on <{kind} type=\"{el.get('type')}\">")
                if tag == "transform":
                    for op in child:
                        if op.tag not in TRANSFORM_OPS:
                            self.bad(line(op), f"transform operation <{op.tag}> is outside the subset")
            elif tag == "ref":
                if "ref" not in CHILDREN.get(kind, set()):
                    self.bad(line(child), f"<ref> inside <{kind}>")
                self.refs.append((child.get("id", ""), line(child)))
            elif tag in ("default", "include"):
                if kind != "scene":
                    self.bad(line(child), f"<{tag}> inside <{kind}>")
            elif tag in CHILDREN.get(kind, set()):
                self.element(child, tag)
            else:
                self.bad(line(child), f"element <{tag}> inside <{kind}> is outside the subset")


LINE = "__line__"


def line(el) -> int:
    """The start line recorded by `parse`."""
    return int(el.get(LINE, "0"))


def parse(path: str):
    """Parse an XML file, recording each element's start line (read it back with `line`)."""
    import xml.parsers.expat as expat

    builder = ET.TreeBuilder()
    p = expat.ParserCreate()

    def start(tag, attrs):
        # C-accelerated Elements take no new attributes, so the line rides in attrib.
        builder.start(tag, {**attrs, LINE: str(p.CurrentLineNumber)})

    p.StartElementHandler = start
    p.EndElementHandler = builder.end
    with open(path, "rb") as f:
        p.Parse(f.read(), True)
    return builder.close()


def main() -> int:
    import xml.parsers.expat as expat

    problems: list[str] = []
    for path in sys.argv[1:]:
        try:
            root = parse(path)
        except (OSError, expat.ExpatError) as e:
            problems.append(f"{path}: cannot parse: {e}")
            continue
        c = Checker(path)
        if root.tag != "scene":
            c.bad(line(root), f"root element is <{root.tag}>, expected <scene>")
        else:
            c.element(root, "scene")
        for ref, ln in c.refs:
            if ref not in c.ids:
                c.bad(ln, f"<ref id=\"{ref}\"> names no object defined in this file")
        problems.extend(c.problems)
        if not c.problems:
            print(f"{path}: ok")
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
