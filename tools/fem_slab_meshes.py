"""The gallery's cracking slab (scenes/fem_slab_crack.py at its PREVIEW settings: 24 frames, fTetWild edge 5 cm) on
other tetrahedral meshes of the same surface: fTetWild's output varies from run to run and with its thread count,
and a mesh with one small element forces a much smaller stable step unless the mass scaling lifts it (FemBody
mass_scaling; ``--mass-scaling 0`` runs without). For each mesh the tool prints its element count, its smallest
element height over the median, its stable step (the smallest element's, or the mass scaling's floor), how far
the preview run gets (every frame, or the watchdog's stop with its frame and reason), its face-connected pieces at
the last frame (and how many are single elements) and its wall time.

    python tools/fem_slab_meshes.py --mesh docs/data/fem_slab_small_element.vtu   # the kept mesh
    python tools/fem_slab_meshes.py --make 6 --threads 16 --keep /tmp/slabs        # new meshes, each run
    python tools/fem_slab_meshes.py --mesh docs/data/fem_slab_small_element.vtu --contact off
    python tools/fem_slab_meshes.py --make 4 --threads 1 --frames 8                  # the pieces after 8 frames
    python tools/fem_slab_meshes.py --mesh tests/data/fem_slab_small_elements_ftetwild.vtu --mass-scaling 0

docs/data/fem_slab_small_element.vtu is such a mesh (2,721 elements, smallest height 0.028 of the median, made by
fTetWild with 16 threads on a 2-core machine); docs/fem_fracture.md, "Pieces in contact", gives its runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scenes"))

import fem_slab_crack  # scenes/ (put on the path above)

from pdsim.checks import check_range
from pdsim.errors import InstabilityError
from pdsim.fem.fracture import element_pieces
from pdsim.fem.mesh import element_heights, tetrahedralize, write_tet_mesh
from pdsim.fem.mesh_files import load_tet_mesh


def run_mesh(mesh, contact: bool = True, frames: int | None = None, mass_scaling: float | None = None) -> dict:
    """The preview run of the slab on ``mesh`` (``frames``: that many of its frames; None: all 24; ``mass_scaling``:
    the slab's FemBody mass_scaling, None for its default): its figures, its outcome and its face-connected pieces at
    the last frame (count, and how many are single elements)."""
    heights = element_heights(mesh.vertices, mesh.tets)
    scene = fem_slab_crack.build_scene(mesh=mesh, frames=frames or fem_slab_crack.PREVIEW["frames"])
    if mass_scaling is not None:
        scene.bodies[0].mass_scaling = check_range("mass_scaling", mass_scaling, 0.0, 1.0, lo_open=False)
    if not contact:
        scene.enable_contact(False)
    (solver,) = scene.build_solvers(device="cpu")
    row = {
        "elements": len(mesh.tets),
        "smallest_height_over_median": float(heights.min() / np.median(heights)),
        "stable_step": float(solver.stable_time_step()),
    }
    last = {}

    def pieces(frame, solvers):
        _, labels = element_pieces(solvers[0].tets)
        sizes = np.bincount(labels)
        last.update(pieces=len(sizes), single=int((sizes == 1).sum()))

    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        try:
            scene.run(os.path.join(tmp, "slab.usdc"), progress=False, on_frame=pieces)
            row["outcome"] = f"all {scene.frames} frames"
        except InstabilityError as error:
            row["outcome"] = f"stopped: {str(error).split(';')[0]}"
    row["seconds"] = time.perf_counter() - start
    row.update(last)
    return row


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", action="append", default=[], help="a ready mesh file (repeatable)")
    parser.add_argument("--make", type=int, default=0, help="make this many new fTetWild meshes of the slab")
    parser.add_argument("--threads", type=int, default=0, help="fTetWild threads for --make (0: all cores)")
    parser.add_argument("--keep", help="folder to keep the new meshes in (.vtu)")
    parser.add_argument("--contact", choices=("on", "off"), default="on")
    parser.add_argument("--frames", type=int, help="run only this many of the preview's 24 frames")
    parser.add_argument("--mass-scaling", type=float, help="the slab's FemBody mass_scaling (default: its own)")
    args = parser.parse_args(argv)
    meshes = [(path, load_tet_mesh(path, name="slab")) for path in args.mesh]
    for k in range(args.make):
        mesh = tetrahedralize(
            fem_slab_crack.slab_with_hole(), edge_length=fem_slab_crack.PREVIEW["edge_length"], threads=args.threads
        )
        label = f"made {k}"
        if args.keep:
            os.makedirs(args.keep, exist_ok=True)
            label = os.path.join(args.keep, f"slab_{k}.vtu")
            write_tet_mesh(mesh, label)
        meshes.append((label, mesh))
    print("| mesh | elements | smallest height / median | stable step [s] | contact | preview run | pieces "
          "(single elements) | wall [s] |")  # fmt: skip
    print("|---|---:|---:|---:|---|---|---:|---:|")
    for label, mesh in meshes:
        r = run_mesh(mesh, contact=args.contact == "on", frames=args.frames, mass_scaling=args.mass_scaling)
        print(
            f"| {label} | {r['elements']} | {r['smallest_height_over_median']:.3f} | {r['stable_step']:.3g} | "
            f"{args.contact} | {r['outcome']} | {r.get('pieces', '-')} ({r.get('single', '-')}) | "
            f"{r['seconds']:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
