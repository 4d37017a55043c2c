"""The shipped default scene: a soft cantilever clamped at one end, sagging and oscillating under gravity.

Sized so that ``pdsim run`` finishes in well under two minutes on two CPU cores, first kernel compile included
(README.md gives the measured time). ``scenes/cantilever.py`` is the same scene as a runnable script.
"""

from __future__ import annotations

from .geometry import box
from .materials import Material
from .regions import BoxRegion
from .scene import Scene


def build_scene() -> Scene:
    """The cantilever: a 1 x 0.2 x 0.2 m peridynamic beam (spacing 25 mm, E = 2 MPa) clamped over its first 0.1 m,
    1 m above a ground plane, 72 frames at 24 fps."""
    scene = Scene(fps=24, frames=72, up_axis="Z", name="cantilever")
    material = Material(density=1000.0, youngs_modulus=2.0e6, poisson_ratio=0.3, name="soft_solid")
    length, width, thickness = 1.0, 0.2, 0.2
    beam = scene.add_peridynamic_body(
        box((length, width, thickness), center=(0.5 * length, 0.0, 1.0), name="beam"),
        material,
        spacing=0.025,
        damping=1.0,
    )
    beam.fix(BoxRegion(lo=(-1.0, -1.0, 0.0), hi=(0.1, 1.0, 2.0)))  # the clamped end: first 0.1 m
    scene.add_ground_plane(height=0.0)
    return scene
