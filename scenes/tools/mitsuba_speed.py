#!/usr/bin/env python3
"""Measure Mitsuba 3 path-tracing throughput (samples per second) on a scene.

Only the render call is timed: the scene is loaded first, then `mi.render` is called
`--repeats` times (each a full image at the scene's spp) and every call is timed
with a wall clock. Samples per call = width * height * spp. The process CPU time
consumed during each call is reported too: cpu_seconds / wall_seconds is the number
of cores Mitsuba actually kept busy (about 2 on a 2-core machine when nothing else runs),
and samples per CPU-second is the throughput per busy core.
The 1/5/15-minute load averages before and after are recorded, because on a shared
machine other processes steal cycles and lower the figure.

Usage:
    python3 scenes/tools/mitsuba_speed.py SCENE.xml [--repeats 3] [--threads T] \
        [-D name=value ...] [--variant scalar_rgb] [--json OUT.json] [--ours PATH/TO/mcmc-render]

With --ours, our renderer is measured in the same run, interleaved with Mitsuba
(Mitsuba, ours, Mitsuba, ours, ...) so that load from other processes hits both alike.
Each of our runs is
    mcmc-render render SCENE.xml --integrator pt --spp SPP --seed I --threads T --out TMP.exr --quiet [-D ...]
and its samples/s is read from the JSON sidecar TMP.json (`samples_per_second`), the
statistic issue 5 asks the CLI to write. The ratio ours/Mitsuba of the medians is reported.
(Exercised against the CLI of the render-core branch at commit dfd803e, before its merge.)

The scene's own <default> values (spp, max_depth, width, height) are used unless
overridden with -D, so the numbers refer to the same settings our renderer reads
from the same file. Prints one JSON object on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo, or the platform string elsewhere."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def run_ours(binary: str, scene: str, spp: int, seed: int, threads: int, overrides: dict[str, str]) -> dict:
    """Render once with our CLI and return its JSON sidecar."""
    import resource
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "speed.exr")
        cmd = [binary, "render", scene, "--integrator", "pt", "--spp", str(spp), "--seed", str(seed)]
        cmd += ["--threads", str(threads), "--out", out, "--quiet"]
        for k, v in overrides.items():
            cmd += ["-D", f"{k}={v}"]
        # CPU time of the child (whole process: start-up and file output
        # included, so slightly pessimistic for us).
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(cmd, capture_output=True, text=True)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if done.returncode != 0:
            raise SystemExit(f"error: {' '.join(cmd)} failed: {done.stderr.strip()}")
        with open(os.path.join(tmp, "speed.json")) as f:
            report = json.load(f)
        report["process_cpu_seconds"] = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        return report


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="Mitsuba 3 XML scene file")
    ap.add_argument("--repeats", type=int, default=3, help="timed render calls (>= 1)")
    ap.add_argument("--warmup", type=int, default=1, help="untimed render calls before timing")
    ap.add_argument("--threads", type=int, default=0, help="thread count (0 = Dr.Jit's default, all cores)")
    ap.add_argument("-D", dest="defines", action="append", default=[], help="override a <default>, name=value")
    ap.add_argument("--variant", default="scalar_rgb")
    ap.add_argument("--json", help="also write the JSON report to this file")
    ap.add_argument("--ours", help="path to the mcmc-render binary, to measure it side by side")
    args = ap.parse_args()
    if args.repeats < 1:
        raise SystemExit("error: --repeats must be at least 1")

    import drjit as dr
    import mitsuba as mi

    mi.set_variant(args.variant)
    if args.threads > 0:
        dr.set_thread_count(args.threads)

    overrides = {}
    for p in args.defines:
        if "=" not in p:
            raise SystemExit(f"error: -D expects name=value, got '{p}'")
        k, v = p.split("=", 1)
        overrides[k.strip()] = v.strip()

    t0 = time.perf_counter()
    scene = mi.load_file(args.scene, **overrides)
    load_seconds = time.perf_counter() - t0

    sensor = scene.sensors()[0]
    width, height = (int(v) for v in sensor.film().size())
    spp = int(sensor.sampler().sample_count())
    integrator = scene.integrator()
    samples = width * height * spp

    for i in range(args.warmup):
        mi.render(scene, seed=1000 + i)

    # Other processes share the cores: the load average before and after tells how much.
    load_before = os.getloadavg()
    threads = args.threads if args.threads > 0 else int(dr.thread_count())
    walls, cpus, ours = [], [], []
    for i in range(args.repeats):
        c0 = time.process_time()
        t0 = time.perf_counter()
        img = mi.render(scene, seed=i)
        # Scalar variants return a finished tensor; touching it makes sure nothing is pending.
        _ = img.shape
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        if args.ours:
            ours.append(run_ours(args.ours, args.scene, spp, i, threads, overrides))

    rates = [samples / w for w in walls]
    report = {
        "scene": args.scene,
        "renderer": "mitsuba",
        "mitsuba_version": mi.__version__,
        "variant": args.variant,
        "integrator": str(integrator).splitlines()[0].rstrip("["),
        "integrator_repr": " ".join(str(integrator).split()),
        "overrides": overrides,
        "width": width,
        "height": height,
        "spp": spp,
        "samples_per_render": samples,
        "threads": int(dr.thread_count()),
        "machine": {"cpu": cpu_model(), "logical_cpus": os.cpu_count(), "python": platform.python_version()},
        "load_seconds": load_seconds,
        "loadavg_before": list(load_before),
        "loadavg_after": list(os.getloadavg()),
        "render_seconds": walls,
        "cpu_seconds": cpus,
        "busy_cores": [c / w for c, w in zip(cpus, walls)],
        "samples_per_second": rates,
        "samples_per_second_median": statistics.median(rates),
        "samples_per_second_best": max(rates),
        # Samples per CPU-second of the whole process: insensitive to how many cores other
        # jobs left free, so comparable across runs on a busy machine (multiply by the
        # thread count for what an idle machine would give if threads scale perfectly).
        "samples_per_cpu_second_median": statistics.median(samples / c for c in cpus if c > 0),
    }
    if args.ours:
        our_rates = [o["samples_per_second"] for o in ours]
        our_cpu = [o["process_cpu_seconds"] for o in ours]
        report["ours"] = {
            "binary": args.ours,
            "runs": ours,
            "cpu_seconds": our_cpu,
            "samples_per_cpu_second_median": statistics.median(samples / c for c in our_cpu if c > 0),
            "samples_per_second_median": statistics.median(our_rates),
            "speedup_over_mitsuba_median": statistics.median(our_rates) / statistics.median(rates),
        }
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
