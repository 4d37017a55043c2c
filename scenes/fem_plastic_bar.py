"""A soft metal-like rod bent permanently: clamped at its base, its top is pushed sideways, then let go; the rod
springs back only partly and keeps a bend (tetrahedral FEM with the slides' plasticity rule, implicit integrator).

The rod (radius 4 cm, height 1 m, meshed by fTetWild) stands on the ground, its lowest 5 cm clamped. Its top 5 cm are
pushed along x at 0.6 m/s for 0.75 s (0.45 m) and then released. The input surface of the rod is embedded in the
tetrahedra and written as "rod_render"; the simulation surface is "rod". Backward Euler at 100 x the explicit step
damps the fast vibrations, which a slow plastic bend does not need.

Run:  python scenes/fem_plastic_bar.py --out bar.usdc      or      pdsim run scenes/fem_plastic_bar.py --out bar.usdc
"""

import os

import pdsim
from pdsim.fem import FemBody, FemPlasticity

MESH_CACHE = os.path.join(os.path.expanduser("~"), ".cache", "pdsim", "meshes")  # fTetWild output varies per run


PREVIEW = {"edge_length": 0.04, "frames": 36}  # tools/make_gallery.py and tests/test_gallery.py: a quick run


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
        render_mesh=True,
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
