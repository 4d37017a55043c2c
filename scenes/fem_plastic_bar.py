"""A soft metal-like rod bent permanently: clamped at its base, its top is pushed sideways, then let go; the rod springs
back only partly and keeps a bend (tetrahedral FEM with FemPlasticity's yield / creep / max rule, implicit integrator).

The rod (radius 4 cm, height 1 m, meshed by fTetWild) stands on the ground, its lowest 5 cm clamped. Its top 5 cm are
pushed along x at 0.6 m/s for 0.75 s (0.45 m) and then released; being moved as one piece, the top stays upright, so
the rod takes an S-shaped bend, sharpest just above the clamp, where the bending moment is largest. A render surface
of the rod (a cylinder with a ring of vertices every centimetre, `render_surface`) is embedded in the tetrahedra
and written as "rod_render"; the simulation surface is "rod". Backward Euler at 100 x the explicit step damps the fast
vibrations, which a slow plastic bend does not need.

Run:  python scenes/fem_plastic_bar.py --out bar.usdc      or      pdsim run scenes/fem_plastic_bar.py --out bar.usdc
"""

import os

import numpy as np
import trimesh

import pdsim
from pdsim.fem import FemBody, FemPlasticity

MESH_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "pdsim", "meshes")  # fTetWild output varies per run


PREVIEW = {"edge_length": 0.04, "frames": 36}  # tools/make_gallery.py and tests/test_gallery.py: a quick run


def render_surface(radius: float, height: float, *, rings: int = 100, sections: int = 48) -> pdsim.SolidShape:
    """The rod's render surface: a cylinder standing on z = 0 with a ring of vertices every height / rings (the
    surface of pdsim.cylinder has vertices at its two ends only, so embedded in the tetrahedra it would stay straight
    between them however the rod bends)."""
    z = np.linspace(0.0, height, rings + 1)
    profile = np.column_stack([np.r_[0.0, np.full(rings + 1, radius), 0.0], np.r_[0.0, z, height]])
    mesh = trimesh.creation.revolve(profile, sections=sections)
    return pdsim.shape_from_arrays(mesh.vertices, mesh.faces, name="rod")


def build_scene(*, edge_length: float = 0.025, frames: int = 72) -> pdsim.Scene:
    scene = pdsim.Scene(fps=24, frames=frames, up_axis="Z", name="fem_plastic_bar")
    material = pdsim.Material(density=2700.0, youngs_modulus=1.0e8, poisson_ratio=0.33, name="soft_metal")
    rod = pdsim.cylinder(0.04, 1.0, center=(0.0, 0.0, 0.5), axis="z", sections=48, name="rod")
    body = FemBody(
        rod,
        material,
        edge_length=edge_length,
        measure="corotated",
        integrator="implicit",
        implicit_step_ratio=100.0,
        plasticity=FemPlasticity(yield_strain=0.01, creep=8.0, max_strain=0.3),
        damping=3.0,
        render_mesh=render_surface(0.04, 1.0),
        mesh_cache=MESH_CACHE,
    )
    body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(1.0, 1.0, 0.05)))
    body.set_velocity(pdsim.BoxRegion(lo=(-1.0, -1.0, 0.95), hi=(1.0, 1.0, 2.0)), (0.6, 0.0, 0.0), release=0.75)
    scene.add_body(body)
    scene.add_ground_plane(height=0.0, friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)  # accepts the same options as `pdsim run`
