"""Measures the constants of the pre-flight's estimates (pdsim/preflight.py, pdsim/sampling.py) on the CPU backend.

Each configuration runs in its own process and reports the peak resident memory of ``Scene.build_solvers`` (after a
tiny build of the same method, so that kernel loading does not count), the particle or element and bond counts and
the solver's stable step; a least-squares fit gives bytes per particle and per bond (peridynamics) and per element
(FEM, vertices included). Also: peak bytes of fill_solid per lattice point, and cache bytes per point and frame.

    python tools/preflight_calibration.py            # a few minutes on two cores

Measured (2 cores, warp 1.19): peridynamics 345 to 372 B per particle + 52 B per bond elastic (+15 B per bond with
fracture and plasticity); FEM about 500 B per element with its vertices; Silling-Askari step 0.55 / 0.92 / 1.76 h /
c_p at horizon factors 1.5 / 3.015 / 6 (about 0.3 m h / c_p); fill_solid 60 to 65 B per lattice point; caches 55 to
85 B per point and frame.

    python tools/preflight_calibration.py --cost [--device cuda] [--write]   # the cost estimates' constants
    python tools/preflight_calibration.py --compare [SCENE ...] [--device cuda]   # the estimates against gallery runs
    python tools/preflight_calibration.py --table [--device cuda]   # a calibration as a markdown table

``--cost`` runs small blocks of each method (peridynamics elastic, with fracture, with plasticity; explicit FEM elastic
and with fracture; a lattice) for a few frames each with the run's profile (pdsim/profile.py), three times each (the
least time of each part kept, as other work on the machine only adds time), and fits with non-negative least squares of
the relative residuals (a small run counts as much as a large one; the build time's of the residuals themselves, as
builds of a few ms are noise), against the pre-flight's own counts (pdsim.cost.body_counts): the step's wall time per
step, per estimated bond visit and per particle, per element and vertex, per lattice point and link; the per-frame time
outside the steps (views, render surfaces, writer) per point of each method and per surface vertex; the build time;
cache bytes per frame; and, in a child process, the host memory of the render surfaces per surface vertex (the peak of
numpy's traced allocations while the first views with their surfaces are built). ``--device cuda`` runs the blocks on
the GPU, with larger blocks added (on a GPU the small ones only time the launches). ``--write`` stores them in the
device kind's file, pdsim/cost_calibration_cpu.json or pdsim/cost_calibration_cuda.json (``--out PATH``: elsewhere),
with the machine, date, command and load average; the worst ratio of each fit is printed. Rerun it (and ``python
tools/errors_catalogue.py``, whose disk message quotes an estimate) on a quiet machine."""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import warp as wp

import pdsim
import pdsim.cost

CHILD = r"""
import json, resource, sys, time
import warp as wp
wp.config.quiet = True
import pdsim
import pdsim.cost
kind, n, m, feat = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
h = 0.01
extra = {"critical_stretch": 0.01} if kind == "pd" and feat != "none" else {}
if kind == "pd" and feat == "all":
    extra["yield_stress"] = 1.0e5
mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, **extra)
def scene(size, cells):
    s = pdsim.Scene(frames=1)
    if kind == "pd":
        s.add_peridynamic_body(pdsim.box((size,) * 3), mat, spacing=h, horizon_factor=m)
    else:
        s.add_fem_body(pdsim.box_tet_mesh((size,) * 3, (cells,) * 3), mat,
                       tensile_strength=1.0e5 if feat != "none" else None)
    return s
scene(0.05, 2).build_solvers(device="cpu")  # kernels loaded
s = scene(n * h, n)
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
solver = s.build_solvers(device="cpu")[0]
rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
b = s.bodies[0]
print(json.dumps(dict(points=solver.point_count, bonds=solver.bond_count, bytes=rss1 - rss0,
                      elements=getattr(b, "element_count", 0), dt=solver.stable_time_step(),
                      cp=mat.p_wave_speed, h=h, m=m)))
"""


def measure(*args) -> dict:
    proc = subprocess.run([sys.executable, "-c", CHILD, *map(str, args)], capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def memory_calibration() -> None:
    pd = [measure("pd", n, m, feat) for n, m, feat in [(32, 3.015, "none"), (32, 1.5, "none"), (48, 1.5, "none"),
                                                       (32, 6.0, "none")]]  # fmt: skip
    a = np.array([[r["points"], r["bonds"]] for r in pd], dtype=float)
    per_particle, per_bond = np.linalg.lstsq(a, np.array([r["bytes"] for r in pd], dtype=float), rcond=None)[0]
    print(f"peridynamics (elastic): {per_particle:.0f} B per particle + {per_bond:.1f} B per bond")
    full = measure("pd", 32, 3.015, "all")
    extra = (full["bytes"] - pd[0]["bytes"]) / full["bonds"]
    print(f"  fracture and plasticity add {extra:.1f} B per bond")
    for r in pd:
        coeff = r["dt"] * r["cp"] / r["h"]
        print(f"  horizon factor {r['m']:.3g}: stable step {coeff:.3g} h / c_p ({coeff / r['m']:.3g} m h / c_p); "
              f"{r['bonds'] / r['points']:.1f} bonds per particle")  # fmt: skip
    for n in (16, 32):
        r = measure("fem", n, 0, "none")
        print(f"FEM {r['elements']} elements: {r['bytes'] / r['elements']:.0f} B per element (vertices included)")

    wp.config.quiet = True

    code = (
        "import resource, pdsim\nfrom pdsim.sampling import fill_solid\nfill_solid(pdsim.box((0.1,) * 3), 0.01)\n"
        "r0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\nfill_solid(pdsim.box((1.0,) * 3), 0.005)\n"
        "print((resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - r0) * 1024 / 200**3)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()[-1]
    print(f"fill_solid: {float(out):.0f} B per lattice point")

    with tempfile.TemporaryDirectory() as tmp:
        scene = pdsim.Scene(frames=4, fps=1000.0)
        mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, critical_stretch=0.01)
        scene.add_peridynamic_body(pdsim.box((0.16,) * 3, center=(0, 0, 1)), mat, spacing=0.01)
        report = scene.run(Path(tmp) / "c.usdc", device="cpu", progress=False)
        size = sum(p.stat().st_size for p in Path(tmp).rglob("*") if p.is_file())
        print(f"cache: {size / (report.particle_count * 5):.0f} B per point and frame ({report.particle_count} points)")


SURFACE_CHILD = r"""
import json, tracemalloc
import warp as wp
wp.config.quiet = True
import pdsim
from pdsim.cost import surface_vertices
mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
def scene(size):
    s = pdsim.Scene(frames=1)
    s.add_peridynamic_body(pdsim.box((size,) * 3), mat, spacing=0.01, horizon_factor=1.5)
    return s
small = scene(0.05).build_solvers(device="cpu")[0]
small.views()  # kernels and the surface code loaded
s = scene(0.4)
solver = s.build_solvers(device="cpu")[0]
tracemalloc.start()  # numpy's host arrays are traced (the solver's are built already)
views = solver.views()
peak = tracemalloc.get_traced_memory()[1]
mesh = [v for v in views if v.name.endswith("_surface")][0]
print(json.dumps(dict(bytes=peak, estimated=surface_vertices(s.bodies[0]), vertices=len(mesh.points))))
"""

FRAMES = 8


def _material(kind: str) -> pdsim.Material:
    extra = {}
    if kind in ("fracture", "plastic"):
        extra = {"critical_stretch": 0.05}
    if kind == "plastic":
        extra["yield_stress"] = 1.0e5
    return pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, **extra)


def _spin(body, center) -> None:
    """Sets ``body`` spinning at SPIN about the vertical axis through ``center`` [m]."""
    r = body.point_rest_positions - center
    body.set_initial_velocity(SPIN * np.column_stack([-r[:, 1], r[:, 0], np.zeros(len(r))]))


def cost_scene(method: str, size: int, variant) -> pdsim.Scene:
    """A block of ``size`` points (or cells) a side on the ground, settling under gravity and spinning about its
    vertical axis at SPIN, as a body in a shot moves (every frame writes new positions, and every FEM step turns its
    elements' corotated frames): peridynamics (variant: (horizon factor, "elastic", "fracture" or "plastic": with
    fracture)), explicit FEM (variant: None, "fracture", "pair": two elastic blocks one spacing apart, which the
    contact between FEM surfaces works on, or "held": one end fixed and the other pulled, the boundary conditions'
    cost); or a lattice pulled at one end (variant: (steps per frame, "elastic" or "fracture": links that can be
    lost, never stretched that far))."""
    scene = pdsim.Scene(frames=FRAMES, fps=200.0)
    h = 0.01
    if method == "pd":
        m, kind = variant
        body = scene.add_peridynamic_body(pdsim.box((size * h,) * 3, center=(0, 0, size * h / 2 + h)),
                                          _material(kind), spacing=h, horizon_factor=m, name="block")  # fmt: skip
        _spin(body, np.array([0.0, 0.0, size * h / 2 + h]))
    elif method == "fem":
        # checked every step, never reached
        strength = {"tensile_strength": 1.0e9} if variant == "fracture" else {}
        # "pair": two blocks side by side, one spacing apart: the contact between FEM surfaces searches every step
        for k in range(2 if variant == "pair" else 1):
            x = k * (size + 1) * h
            center = np.array([x, 0.0, size * h / 2 + h])
            mesh = pdsim.box_tet_mesh((size * h,) * 3, (size,) * 3, center=tuple(center))
            body = scene.add_fem_body(mesh, _material("elastic"), name=f"block{k}" if k else "block", **strength)
            _spin(body, center)
            if variant == "held":
                lo, hi = center - size * h, center + size * h
                body.fix(pdsim.BoxRegion(lo=tuple(lo), hi=(center[0] - 0.4 * size * h, hi[1], hi[2])))
                body.set_velocity(pdsim.BoxRegion(lo=(center[0] + 0.4 * size * h, lo[1], lo[2]), hi=tuple(hi)),
                                  (1.0e-3, 0.0, 0.0))  # fmt: skip
    else:
        steps, kind = variant
        fracture = pdsim.LatticeFracture((10.0 * h,)) if kind == "fracture" else None
        body = pdsim.LatticeBody(pdsim.Lattice.simple_cubic(h), pdsim.box((size * h,) * 3), steps_per_frame=steps,
                                 fracture=fracture, name="block")  # fmt: skip
        x = body.rest_positions[: body.body_count, 0]
        body.clamp(x < x.min() + 1.5 * h)
        body.add_leaders(x > x.max() - 1.5 * h, velocity=(0.001 * h, 0.0, 0.0))
        scene.add_body(body)
    if method != "lattice":
        scene.add_ground_plane(height=0.0)
    return scene


COST_RUNS = [
    ("pd", 6, (3.015, "elastic")),
    ("pd", 10, (3.015, "elastic")),
    ("pd", 16, (3.015, "elastic")),
    ("pd", 20, (1.5, "elastic")),
    ("pd", 14, (2.0, "fracture")),
    ("pd", 18, (3.015, "fracture")),
    ("pd", 14, (2.0, "plastic")),
    ("pd", 16, (3.015, "plastic")),
    ("fem", 4, None),
    ("fem", 8, None),
    ("fem", 14, None),
    ("fem", 20, None),
    ("fem", 6, "fracture"),
    ("fem", 10, "fracture"),
    ("fem", 14, "fracture"),
    ("fem", 20, "fracture"),
    ("fem", 6, "pair"),
    ("fem", 10, "pair"),
    ("fem", 14, "pair"),
    ("fem", 6, "held"),
    ("fem", 12, "held"),
    *[("lattice", n, (steps, kind)) for kind in ("elastic", "fracture") for n, steps in ((6, 20), (12, 20), (24, 40))],
]
SPIN = 2.0  # [rad/s]: the blocks' spin about their vertical axis
METHODS = ("peridynamics", "fem", "lattice")


# added on a GPU, where the small blocks above are bound by the launches: blocks of up to 216,000 particles (26 M
# bonds) and 384,000 elements
CUDA_RUNS = [
    ("pd", 40, (3.015, "elastic")),
    ("pd", 60, (3.015, "elastic")),
    ("pd", 40, (3.015, "fracture")),
    ("pd", 40, (3.015, "plastic")),
    ("fem", 30, None),
    ("fem", 40, None),
    ("fem", 30, "fracture"),
    ("lattice", 60, (40, "elastic")),
    ("lattice", 60, (40, "fracture")),
]


def measure_run(method: str, size: int, variant, device: str = "cpu") -> dict:
    """One profiled run on ``device``: the pre-flight's counts and estimate, the profile's phases, the cache's size
    [B]."""
    from pdsim.preflight import _bonds_per_particle

    scene = cost_scene(method, size, variant)
    counts = [pdsim.cost.body_counts(b, _bonds_per_particle) for b in scene.bodies]
    with tempfile.TemporaryDirectory() as tmp:
        report = scene.run(Path(tmp) / "c.usdc", device=device, progress=False, checkpoint_interval_s=None)
        size_bytes = sum(p.stat().st_size for p in Path(tmp).rglob("*") if p.is_file())
    sec = report.profile["seconds"]
    return {
        "run": f"{method} {size} {variant}",
        "counts": counts,
        "substeps": report.substeps_per_frame,
        "frames": report.profile["frames"],
        "step_seconds": (sec["simulate"] + sec["checks"]) / report.profile["frames"],
        "frame_seconds": (sec["surfaces"] + sec["write"] + sec["other"]) / (report.profile["frames"] + 1),
        "build_seconds": sec["build"],
        "cache_bytes": size_bytes,
        "estimate": report.estimate,
    }


def _total(r) -> dict:
    """A run's counts summed over its bodies (all of one method and features; a "pair" run has two): points, bonds,
    elements, surface and contact vertices summed, ``bodies`` their number, the rest the first body's."""
    out = dict(r["counts"][0])
    for k in ("points", "bonds", "elements", "surface_vertices", "contact_vertices"):
        out[k] = sum(c[k] for c in r["counts"])
    out["bodies"] = len(r["counts"])
    return out


REPEATS = 3  # runs per configuration: the least time of each part is kept (the others' load only adds time)


def best_of(repeats: int, config, device: str = "cpu") -> dict:
    """measure_run ``repeats`` times: the least step, frame and build times."""
    runs = [measure_run(*config, device=device) for _ in range(repeats)]
    best = dict(runs[0])
    for k in ("step_seconds", "frame_seconds", "build_seconds"):
        best[k] = min(r[k] for r in runs)
    return best


def _nnls(rows, y, names, relative: bool = True):
    """Non-negative least squares of ``rows`` x = ``y``, of the relative residuals (a small run counts as much as a
    large one) or, with ``relative`` False, of the residuals themselves (the large runs decide)."""
    from scipy.optimize import nnls

    a = np.asarray(rows, dtype=float)
    y = np.asarray(y, dtype=float)
    weight = 1.0 / np.maximum(np.abs(y), 1.0e-30)[:, None] if relative else np.ones((len(y), 1))
    scale = np.maximum(np.abs(a * weight).max(axis=0), 1.0e-30)  # columns of similar size for the solver
    x, _ = nnls(a * weight / scale, y * weight[:, 0])
    x = x / scale
    fit = a @ x
    worst = float(np.max(np.maximum(fit / y, y / np.maximum(fit, 1.0e-30))))
    print(f"  {', '.join(f'{n} {v:.4g}' for n, v in zip(names, x))} (worst ratio fit/measured {worst:.2f})")
    return dict(zip(names, (float(v) for v in x)))


def cost_calibration(device: str = "cpu", repeats: int = REPEATS) -> dict:
    """Runs COST_RUNS (and CUDA_RUNS on a GPU) on ``device`` after a warm-up run of each method, and fits the
    constants of pdsim/cost.py."""
    wp.config.quiet = True
    kind = pdsim.cost.device_kind(device)
    for method in ("pd", "fem", "lattice"):
        for variant in {"pd": [(3.015, "plastic"), (3.015, "fracture"), (3.015, "elastic")], "fem": [None, "fracture"],
                        "lattice": [(2, "elastic"), (2, "fracture")]}[method]:  # fmt: skip
            measure_run(method, 6, variant, device=device)  # kernels loaded (and, on CUDA, compiled)
    configs = COST_RUNS + (CUDA_RUNS if kind == "cuda" else [])
    runs = []
    for r in configs:
        runs.append(best_of(repeats, r, device))
        print(f"  measured {runs[-1]['run']}", flush=True)
    for r in runs:
        c = _total(r)
        print(f"{r['run']}: {c['points']} points, {c['bonds']:.3g} bonds, {c['elements']} elements, "
              f"{c['surface_vertices']:.0f} surface vertices, {r['substeps']} steps/frame: "
              f"{1e3 * r['step_seconds']:.1f} ms steps + {1e3 * r['frame_seconds']:.1f} ms rest per frame, "
              f"build {r['build_seconds']:.2f} s, cache {r['cache_bytes']} B")  # fmt: skip
    print("step seconds:")
    step = {}
    pd = [r for r in runs if r["counts"][0]["method"] == "peridynamics"]
    rows = []
    for r in pd:
        c = _total(r)
        rows.append([c["bodies"]] + [c["bonds"] * (c["features"] == f) for f in pdsim.cost.PD_FEATURES] + [c["points"]])
    y = [r["step_seconds"] / r["substeps"] for r in pd]
    step.update(_nnls(rows, y, ["pd_step"] + [f"pd_bond_{f}" for f in pdsim.cost.PD_FEATURES] + ["pd_particle"]))
    fem = [r for r in runs if r["counts"][0]["method"] == "fem"]
    y = [r["step_seconds"] / r["substeps"] for r in fem]
    rows = []
    for r in fem:
        c = _total(r)
        contact = pdsim.cost.fem_surface_contact(r["counts"])  # the pairs: contact between surfaces, per body
        rows.append([c["bodies"]] + [c["elements"] * (c["features"] == f) for f in pdsim.cost.FEM_FEATURES]
                    + [c["points"], float(sum(contact)),
                       float(sum(b["contact_vertices"] for b, on in zip(r["counts"], contact) if on))])  # fmt: skip
        rows[-1].append(float(any(b["conditions"] for b in r["counts"])))  # one FEM solver: its conditions
    names = ["fem_step"] + [f"fem_element_{f}" for f in pdsim.cost.FEM_FEATURES] + ["fem_vertex"]
    step.update(_nnls(rows, y, [*names, *pdsim.cost.FEM_CONTACT_TERMS, pdsim.cost.CONDITIONS_TERM]))
    lat = [r for r in runs if r["counts"][0]["method"] == "lattice"]
    y = [r["step_seconds"] / r["counts"][0]["steps"] for r in lat]
    rows = []
    for r in lat:
        c = r["counts"][0]
        cut = float(c["features"] == "fracture")
        rows.append([1.0, c["points"], c["bonds"], cut, cut * c["bonds"]])
    step.update(_nnls(rows, y, ["lattice_step", "lattice_point", "lattice_link", *pdsim.cost.LATTICE_FRACTURE_TERMS]))

    def per_method(r):
        c = _total(r)
        return [1.0] + [c["points"] if c["method"] == m else 0.0 for m in METHODS] + [c["surface_vertices"]]

    names = ["constant", *METHODS, "surface_vertex"]
    print("frame seconds (outside the steps):")
    f = _nnls([per_method(r) for r in runs], [r["frame_seconds"] for r in runs], names)
    print("cache bytes per frame:")
    cb = _nnls([per_method(r) for r in runs], [r["cache_bytes"] / (r["frames"] + 1) for r in runs], names)
    print("build seconds:")
    b = _nnls([[1.0, _total(r)["points"], _total(r)["bonds"], _total(r)["elements"]] for r in runs],
              [r["build_seconds"] for r in runs], ["constant", "point", "bond", "element"],
              relative=False)  # fmt: skip  # builds of a few ms are noise; the long ones matter
    proc = subprocess.run([sys.executable, "-c", SURFACE_CHILD], capture_output=True, text=True, check=True)
    surf = json.loads(proc.stdout.strip().splitlines()[-1])
    per_vertex = surf["bytes"] / surf["estimated"]
    print(f"render surfaces: {per_vertex:.0f} B of host memory per surface vertex ({surf['vertices']} vertices "
          f"written, {surf['estimated']:.0f} counted by the pre-flight)")  # fmt: skip
    on = "the CPU" if kind == "cpu" else wp.get_device(device).name
    return {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.processor() or platform.system()}, "
        f"Warp {wp.config.version} on {on}",
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "command": f"python tools/preflight_calibration.py --cost --device {kind} --write",
        "device": kind,
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "step_seconds": step,
        "frame_seconds": {
            "constant": f["constant"],
            "surface_vertex": f["surface_vertex"],
            "point": {m: f[m] for m in METHODS},
        },
        "build_seconds": b,
        "cache_bytes": {
            "frame": cb["constant"],
            "surface_vertex": cb["surface_vertex"],
            "point": {m: cb[m] for m in METHODS},
        },
        "memory_bytes": {"surface_vertex": per_vertex},
        "runs": [
            {
                k: r[k]
                for k in ("run", "substeps", "frames", "step_seconds", "frame_seconds", "build_seconds", "cache_bytes")
            }
            for r in runs
        ],
    }


COMPARE_SCENES = ("cantilever", "fem_slab_crack", "lattice_3d_tear", "glass_pane")


def compare(names, device: str = "cpu") -> None:
    """Runs each gallery scene at its PREVIEW settings (all its preview frames) on ``device`` and prints a markdown
    table of the pre-flight's estimates against the run: median wall time from one frame's end to the next, the run's
    wall time, the cache's size."""
    import importlib.util
    import time

    scenes = Path(__file__).resolve().parent.parent / "scenes"
    sys.path.insert(0, str(scenes))
    wp.config.quiet = True
    print(f"load average at the start: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("| scene | counts | s/frame est. | s/frame measured (median) | ratio | run est. | run measured | ratio "
          "| cache est. | cache measured | ratio |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in names:
        spec = importlib.util.spec_from_file_location(f"scene_{name}", scenes / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        scene = module.build_scene(**module.PREVIEW)
        stamps: list[float] = []

        def stamp(frame, solvers, stamps=stamps):
            stamps.append(time.perf_counter())

        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / f"{name}.usdc"
            report = scene.run(out, device=device, progress=False, checkpoint_interval_s=None, on_frame=stamp)
            size = out.stat().st_size
        e = report.estimate
        per_frame = float(np.median(np.diff(stamps)))
        counts = f"{report.particle_count:,} points, {report.frames_written - 1} frames x {report.substeps_per_frame}"
        print(f"| {name} | {counts} | {e['seconds_per_frame']:.3f} | {per_frame:.3f} | "
              f"{per_frame / e['seconds_per_frame']:.2f} | {e['total_seconds']:.1f} s | {report.wall_seconds:.1f} s | "
              f"{report.wall_seconds / e['total_seconds']:.2f} | {e['cache_bytes'] / 1e6:.2f} MB | {size / 1e6:.2f} MB "
              f"| {size / e['cache_bytes']:.2f} |", flush=True)  # fmt: skip
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


def calibration_table(d: dict) -> str:
    """The calibration ``d`` (pdsim/cost_calibration_*.json) as a markdown table (docs/benchmarks.md)."""
    s, f, c, b = d["step_seconds"], d["frame_seconds"], d["cache_bytes"], d["build_seconds"]
    p, cp = f["point"], c["point"]
    rows = [
        ("step, per step (peridynamics / FEM / lattice)",
         f"{s['pd_step'] * 1e6:.0f} / {s['fem_step'] * 1e6:.0f} / {s['lattice_step'] * 1e6:.0f} us"),
        ("step, per estimated bond visit: elastic / fracture / plasticity",
         f"{s['pd_bond_elastic'] * 1e9:.3g} / {s['pd_bond_fracture'] * 1e9:.3g} / {s['pd_bond_plastic'] * 1e9:.3g} ns"),
        ("step, per particle (peridynamics)", f"{s['pd_particle'] * 1e9:.3g} ns"),
        ("step, per element: elastic / fracture (explicit FEM)",
         f"{s['fem_element_elastic'] * 1e9:.3g} / {s['fem_element_fracture'] * 1e9:.3g} ns"),
        ("step, per FEM vertex", f"{s['fem_vertex'] * 1e9:.1f} ns"),
        ("step, contact between FEM surfaces: per step / per boundary vertex",
         f"{s.get('fem_contact_step', 0.0) * 1e6:.0f} us / {s.get('fem_contact_vertex', 0.0) * 1e9:.0f} ns"),
        ("step, boundary conditions: per step of a solver holding some",
         f"{s.get('conditions_step', 0.0) * 1e6:.0f} us"),
        ("lattice step, per point / per link", f"{s['lattice_point'] * 1e9:.3g} / {s['lattice_link'] * 1e9:.3g} ns"),
        ("lattice step with link loss, more: per step / per link",
         f"{s.get('lattice_fracture_step', 0.0) * 1e6:.0f} us / {s.get('lattice_fracture_link', 0.0) * 1e9:.3g} ns"),
        ("frame outside the steps: constant", f"{f['constant'] * 1e3:.1f} ms"),
        ("frame outside the steps, per point: peridynamics / FEM / lattice",
         f"{p['peridynamics'] * 1e6:.2f} / {p['fem'] * 1e6:.2f} / {p['lattice'] * 1e6:.2f} us"),
        ("frame outside the steps, per surface vertex", f"{f['surface_vertex'] * 1e6:.1f} us"),
        ("build: constant / per estimated bond / per element",
         f"{b['constant'] * 1e3:.0f} ms / {b['bond'] * 1e9:.0f} ns / {b['element'] * 1e6:.1f} us"),
        ("cache per frame, per point: peridynamics / FEM / lattice",
         f"{cp['peridynamics']:.1f} / {cp['fem']:.1f} / {cp['lattice']:.1f} B"),
        ("cache per frame, per surface vertex", f"{c['surface_vertex']:.0f} B"),
        ("host memory per surface vertex (building the surfaces)", f"{d['memory_bytes']['surface_vertex']:.0f} B"),
    ]  # fmt: skip
    load = ", ".join(str(x) for x in d["load_average"])
    head = [f"Calibration of {d['date']} ({d['machine']}; load average {load} at its end), `{d['command']}`:", "",
            "| constant | value |", "|---|---|"]  # fmt: skip
    return "\n".join(head + [f"| {a} | {v} |" for a, v in rows])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cost", action="store_true", help="measure the cost estimates' constants (pdsim/cost.py)")
    parser.add_argument("--write", action="store_true",
                        help="with --cost: write the device kind's pdsim/cost_calibration_KIND.json")  # fmt: skip
    parser.add_argument("--out", type=Path, help="with --cost --write: write the calibration here instead")
    parser.add_argument("--device", default="cpu", help="the Warp device to measure on (default cpu; cuda)")
    parser.add_argument("--repeats", type=int, default=REPEATS, help=f"runs per configuration (default {REPEATS})")
    parser.add_argument("--compare", nargs="*", metavar="SCENE",
                        help=f"estimates against runs of gallery scenes at their preview settings (default: "
                        f"{' '.join(COMPARE_SCENES)})")  # fmt: skip
    parser.add_argument("--table", action="store_true",
                        help="print the device kind's calibration as a markdown table")  # fmt: skip
    args = parser.parse_args(argv)
    if args.table:
        print(calibration_table(pdsim.cost.calibration_for(args.device)))
        return
    if args.compare is not None:
        compare(args.compare or COMPARE_SCENES, args.device)
        return
    if not args.cost:
        memory_calibration()
        return
    calibration = cost_calibration(args.device, args.repeats)
    text = json.dumps(calibration, indent=1)
    if args.write:
        path = args.out or Path(pdsim.cost.calibration_file(calibration["device"]))
        path.write_text(text + "\n", encoding="utf-8")
        print(f"wrote {path}")
    else:
        print(text)


if __name__ == "__main__":
    main()
