"""A figurine shot as a scene script for ``pdsim run`` (the shot of tools/bench_cleanup.py, with the ground 2 cm
lower): ``../shared/meshes/homer.obj`` (6k triangles) fitted to 30 cm, Y up, ceramic preset at 1 cm spacing (987
particles), hit by a 2.5 cm steel ball at 12 m/s; 6 frames at 24 fps. E.g. where its time goes:

    pdsim run tools/shot_figurine.py --profile --out /tmp/figurine.usdc
"""

from __future__ import annotations

from pathlib import Path

import pdsim
from pdsim import presets

MESH = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "homer.obj"


def build_scene(frames: int = 6, preset: str = "ceramic", spacing: float = 0.01) -> pdsim.Scene:
    """The shot: ``frames`` frames at 24 fps, the figurine of the brittle preset ``preset`` (pdsim.presets) at
    particle ``spacing`` [m]."""
    mesh = pdsim.load_mesh(str(MESH), up_axis="Y", fit_size=0.3, position=(0.0, 0.0, 0.0), name="figurine")
    scene = pdsim.Scene(fps=24, frames=frames, name="figurine")
    scene.add_ground_plane(height=-0.02, friction=0.5)  # 2 cm below: it lands after the hit
    scene.add_peridynamic_body(mesh, presets.preset(preset), spacing=spacing)
    scene.add_rigid_body(
        pdsim.SphereShape(0.025), density=7850.0, position=(-0.13, 0.0, 0.2), velocity=(12.0, 0.0, 0.0), name="ball"
    )
    return scene
