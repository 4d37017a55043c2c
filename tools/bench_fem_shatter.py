"""Where the time goes when an FEM body shatters: a figurine from the public test meshes (../shared/meshes/homer.obj,
fitted to 30 cm, 1 km from the origin) made of a weak brittle material (E = 5 MPa, tensile strength 50 kPa: a 1 %
strain) dropped at 4 m/s onto the ground. The impact strains it about 8 times its strength and it breaks into
thousands of pieces of one or two elements, whose surfaces the contact between FEM pieces (kernels/surface_contact.py)
then searches every step.

The tool times every launch of the contact's vertex-face kernel (``vertex_face_forces``) and, every ``--every``
launches, prints the wall time so far, the seconds spent in those launches, the surface vertices searched, the faces,
the pieces and the pairs deeper than the floor; it stops after ``--launches`` launches.

    python tools/bench_fem_shatter.py                       # edge 4 cm, 1,600 launches (a few minutes)
    python tools/bench_fem_shatter.py --edge 0.03 --launches 800
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import pdsim
from pdsim.kernels import surface_contact as ksf

MESH = Path(__file__).resolve().parent.parent.parent / "shared" / "meshes" / "homer.obj"
OFFSET = np.array([1000.0, -500.0, 0.0])  # far from the origin, as users place things


class _Done(Exception):
    """Raised from the timed launch once enough launches were timed."""


def build_scene(edge: float, mesh_cache: str | None) -> pdsim.Scene:
    """The falling figurine: FEM, fracture on, damping 2 1/s, on a ground plane with friction 0.5."""
    scene = pdsim.Scene(fps=24, frames=1, up_axis="Z", name="fem_shatter")
    scene.add_ground_plane(height=0.0, friction=0.5)
    shape = pdsim.load_mesh(MESH, up_axis="Y", fit_size=0.3, position=OFFSET + np.array([0.0, 0.0, 0.02]))
    material = pdsim.Material(density=2000.0, youngs_modulus=5.0e6, poisson_ratio=0.25, name="weak_ceramic")
    body = scene.add_fem_body(
        shape, material, tensile_strength=5.0e4, damping=2.0, edge_length=edge, mesh_cache=mesh_cache
    )
    body.set_initial_velocity((0.0, 0.0, -4.0))
    return scene


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--edge", type=float, default=0.04, help="fTetWild edge length [m] (default 0.04)")
    parser.add_argument("--launches", type=int, default=1600, help="contact launches to time (default 1600)")
    parser.add_argument("--every", type=int, default=400, help="print every this many launches (default 400)")
    parser.add_argument("--mesh-cache", default=os.path.join(os.path.expanduser("~"), ".cache", "pdsim", "meshes"))
    args = parser.parse_args(argv)
    scene = build_scene(args.edge, args.mesh_cache)
    timed = ksf.vertex_face_forces
    state = {"count": 0, "seconds": 0.0, "start": time.perf_counter()}

    def vertex_face_forces(**arguments):
        t = time.perf_counter()
        timed(**arguments)
        state["seconds"] += time.perf_counter() - t
        state["count"] += 1
        if state["count"] % args.every == 0:
            labels = arguments["m_label"].numpy()
            deep = int((arguments["pair_face"].numpy() >= 0).sum())
            print(
                f"| {state['count']} | {time.perf_counter() - state['start']:.0f} | {state['seconds']:.1f} | "
                f"{len(arguments['v_points'])} | {len(labels)} | {int(labels.max()) + 1} | {deep} |",
                flush=True,
            )
            state["seconds"] = 0.0
        if state["count"] >= args.launches:
            raise _Done

    ksf.vertex_face_forces = vertex_face_forces
    print(
        "| launches | wall [s] | in the last launches [s] | vertices searched | faces | pieces | pairs past the floor |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        try:
            scene.run(os.path.join(tmp, "shatter.usdc"), device="cpu", progress=False, checkpoint_interval_s=None)
        except _Done:
            pass
        finally:
            ksf.vertex_face_forces = timed


if __name__ == "__main__":
    main()
