"""Wall time of one drop against the triangle count of the dropped object's mesh.

The same torus (trimesh, ``--sections`` sections around the ring and a quarter of those around the tube, about
``sections^2 / 2`` triangles) is dropped onto the ground and shatters, once as it is and once after ``--subdivide``
rounds of trimesh's midpoint subdivision (four triangles for each, the very same surface). The particles, the
material and the drop are the same, so the two runs simulate the same thing; only the input mesh of the render
surfaces differs. Each run is a child process (``--one``) timed from outside its import; the table gives, per mesh,
the triangle count and the wall time of ``Scene.run`` [s]; the line above it the fragments and chips (particles
with damage >= 0.5, each drawn as a cube of the render surface) at the end.

    python tools/bench_triangle_count.py                      # 4,608 and 73,728 triangles
    python tools/bench_triangle_count.py --frames 12 --spacing 0.012
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def torus_shape(sections: int, subdivide: int):
    """The torus (major radius 0.15 m, minor 0.06 m, centre 2 m up) as a pdsim SolidShape, subdivided ``subdivide``
    times."""
    import trimesh

    import pdsim

    mesh = trimesh.creation.torus(
        major_radius=0.15, minor_radius=0.06, major_sections=sections, minor_sections=max(sections // 4, 8)
    )
    for _ in range(subdivide):
        mesh = mesh.subdivide()
    mesh.apply_translation((0.0, 0.0, 0.3))
    return pdsim.shape_from_arrays(mesh.vertices, mesh.faces, name="torus")


def drop_scene(shape, spacing: float, frames: int):
    """The torus falling at 3 m/s onto the ground plane 1 cm below it, brittle, ``frames`` frames of 5 ms."""
    import pdsim

    scene = pdsim.Scene(fps=24, frames=frames, frame_time=0.005, name="torus_drop")
    material = pdsim.Material(
        density=2000.0,
        youngs_modulus=2.0e8,
        poisson_ratio=0.2,
        critical_stretch=0.002,
        debris_damping=60.0,
        name="ceramic",
    )
    body = scene.add_peridynamic_body(shape, material, spacing)
    body.set_initial_velocity((0.0, 0.0, -3.0))
    scene.add_ground_plane(height=float(shape.vertices[:, 2].min()) - 0.01, friction=0.5)
    return scene


def run_one(sections: int, subdivide: int, spacing: float, frames: int) -> dict:
    shape = torus_shape(sections, subdivide)
    scene = drop_scene(shape, spacing, frames)
    seen = {}

    def count(frame, solvers):  # fragments and chips (damage >= 0.5) at each frame's end
        labels = solvers[0].fragment_ids()
        seen["fragments"] = len(np.unique(labels))
        seen["chips"] = int((solvers[0].damage() >= 0.5).sum())

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        report = scene.run(os.path.join(tmp, "drop.usdc"), progress=False, checkpoint_interval_s=None, on_frame=count)
        wall = time.perf_counter() - t0
    return {
        **seen,
        "triangles": len(shape.faces),
        "particles": report.particle_count,
        "wall_s": wall,
        "frames": frames,
        "summary": report.summary,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sections", type=int, default=96, help="sections around the ring (default 96)")
    parser.add_argument("--subdivide", type=int, default=2, help="subdivision rounds of the fine mesh (default 2)")
    parser.add_argument("--spacing", type=float, default=0.02, help="particle spacing [m] (default 0.02)")
    parser.add_argument("--frames", type=int, default=6, help="frames (default 6)")
    parser.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)  # child: subdivision rounds
    args = parser.parse_args(argv)
    if args.one is not None:
        print(json.dumps(run_one(args.sections, args.one, args.spacing, args.frames)))
        return 0
    rows = []
    for sub in (0, args.subdivide):
        cmd = [sys.executable, os.path.abspath(__file__), "--one", str(sub), "--sections", str(args.sections)]
        cmd += ["--spacing", str(args.spacing), "--frames", str(args.frames)]
        out = subprocess.run(cmd, check=True, capture_output=True, text=True, cwd=ROOT).stdout
        rows.append(json.loads(out.strip().splitlines()[-1]))
    print(f"machine: {platform.node()}, {os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"spacing {args.spacing} m, {args.frames} frames, {rows[0]['particles']} particles")
    print(f"at the end: {rows[0]['fragments']} fragments, {rows[0]['chips']} particles with damage >= 0.5")
    print("| triangles | wall [s] |")
    print("|---:|---:|")
    for r in rows:
        print(f"| {r['triangles']} | {r['wall_s']:.1f} |")
    ratio = rows[1]["wall_s"] / rows[0]["wall_s"]
    print(f"ratio fine / coarse: {ratio:.2f}")
    np.testing.assert_equal(rows[0]["particles"], rows[1]["particles"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
