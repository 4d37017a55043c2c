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
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import warp as wp

import pdsim

CHILD = r"""
import json, resource, sys, time
import warp as wp
wp.config.quiet = True
import pdsim
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


def main() -> None:
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


if __name__ == "__main__":
    main()
