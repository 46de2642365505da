#!/usr/bin/env python3
"""Checks that Mitsuba 3 reads the Mitsuba 0.6 test fixture
mcmc-render/tests/scenes/cornell-box-0.6.xml as it reads
scenes/cornell-box.xml: both are rendered (scalar_rgb, same seed, small
film) and the images must be equal value for value. This is the
independent check that the 0.6 file says what the Mitsuba 3 file says,
as Mitsuba 3's own upgrade reads it; our loader's reading of it is tested
in mcmc-render/tests/scene_upgrade.rs. Run from the repository root:

    python3 scenes/tools/check_legacy_scene.py
"""

import mitsuba as mi

mi.set_variant("scalar_rgb")

PAIRS = [("scenes/cornell-box.xml", "mcmc-render/tests/scenes/cornell-box-0.6.xml")]


def render(path):
    scene = mi.load_file(path, spp=4, width=48, height=48)
    return list(mi.render(scene, seed=7).array)


for new, old in PAIRS:
    a, b = render(new), render(old)
    assert len(a) == len(b) and a == b, f"{old} renders differently from {new}"
    # Control: a different seed changes the image (the comparison can fail).
    c = list(mi.render(mi.load_file(new, spp=4, width=48, height=48), seed=8).array)
    assert c != a
    print(f"{old}: Mitsuba 3 renders it exactly as {new} ({len(a)} values)")
