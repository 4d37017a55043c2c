"""The teaser: a rigid ball shot through four walls (isotropic brittle, anisotropic brittle, isotropic ductile,
anisotropic ductile), in slow motion (120 frames per second of simulated time: 5x slower played at 24 fps).

The brittle walls use the Silling-Askari compressive bonus (alpha = 1): bonds in a compressed neighbourhood get
stronger, so the material under the ball is not crushed to dust. At this resolution (3 particles through a wall)
the brittle walls fail by punching out chunks and debris around the hole rather than by long radial shards; a
finer spacing (run with spacing=0.005 on a GPU) resolves the bending cracks.

Run:  python scenes/four_walls.py --out four_walls.usdc   or   pdsim run scenes/four_walls.py --out four_walls.usdc
"""

import numpy as np

import pdsim

WALL_SIZE = 0.3  # edge of the square walls [m]
WALL_GAP = 0.25  # distance between walls along the shot [m]


def wall_materials():
    """The four materials, in the order the ball meets them."""
    layered = pdsim.Anisotropy(axis=(0.0, 0.0, 1.0), strength_ratio=0.15, stiffness_ratio=0.7)  # horizontal layers
    common = {"density": 1000.0, "youngs_modulus": 1.0e6}
    return [
        pdsim.Material(**common, poisson_ratio=0.25, critical_stretch=0.01, compressive_bonus=1.0, name="brittle"),
        pdsim.Material(
            **common,
            poisson_ratio=0.25,
            critical_stretch=0.01,
            compressive_bonus=1.0,
            anisotropy=layered,
            name="brittle_layered",
        ),
        pdsim.Material(**common, poisson_ratio=0.3, yield_stress=5.0e3, failure_plastic_strain=0.5, name="ductile"),
        pdsim.Material(
            **common,
            poisson_ratio=0.3,
            yield_stress=5.0e3,
            failure_plastic_strain=0.5,
            critical_stretch=0.3,
            anisotropy=layered,
            name="ductile_layered",
        ),
    ]


def add_walls(scene, materials, *, spacing=0.01):
    """Square walls normal to x, clamped (and unbreakable) along their rim, WALL_GAP apart from x = 0."""
    thick = max(0.03, 3.0 * spacing)
    walls = []
    for i, mat in enumerate(materials):
        shape = pdsim.box((thick, WALL_SIZE, WALL_SIZE), center=(WALL_GAP * i, 0.0, 0.0), name=mat.name)
        wall = scene.add_peridynamic_body(shape, mat, spacing)

        def rim(p):
            return np.maximum(np.abs(p[:, 1]), np.abs(p[:, 2])) > 0.5 * WALL_SIZE - 1.5 * spacing

        wall.fix(rim)
        wall.set_unbreakable(rim)
        walls.append(wall)
    return walls


def build_scene(*, spacing=0.01, materials=None, frames=40, speed=3.0) -> pdsim.Scene:
    """The four walls and a rigid ball of radius 5 cm flying along +x at ``speed`` [m/s] (10 % of the walls' wave
    speed: a hard hit); ``materials`` replaces the walls (any number), ``spacing`` is the particle spacing [m]."""
    # 5x slow motion: 1/120 s of simulated time per frame, played at 24 frames per second
    scene = pdsim.Scene(fps=24, time_scale=0.2, frames=frames, gravity=(0.0, 0.0, 0.0), name="four_walls")
    add_walls(scene, materials or wall_materials(), spacing=spacing)
    scene.add_collider(pdsim.SphereProjectile(0.05, center=(-0.15, 0.0, 0.0), velocity=(speed, 0.0, 0.0)))
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
