"""The teaser: a rigid ball shot through four walls (isotropic brittle, anisotropic brittle, isotropic ductile,
anisotropic ductile), in slow motion (120 frames per second of simulated time: 5x slower played at 24 fps).

The brittle walls use the Silling-Askari compressive bonus (alpha = 1): bonds in a compressed neighbourhood get
stronger, so the material under the ball is not crushed to dust. They also use the three settings that make a
brittle body break into shards rather than dust (docs/fracture.md measures each): a Weibull scatter of the bonds'
strength (modulus 4), jittered particles (no lattice planes for the cracks to follow) and debris damping (particles
that lost most of their bonds stop rattling and do not fly off). At this resolution (3 particles through a wall)
the brittle walls fail by punching out a plug and a few shards around the hole rather than by long radial shards; a
finer spacing (run with spacing=0.005 on a GPU) should resolve the bending cracks.

Run:  python scenes/four_walls.py --out four_walls.usdc   or   pdsim run scenes/four_walls.py --out four_walls.usdc
"""

import dataclasses

import numpy as np

import pdsim

WALL_SIZE = 0.3  # edge of the square walls [m]
WALL_GAP = 0.25  # distance between walls along the shot [m]


# Fracture-pattern settings of the brittle walls (docs/fracture.md, tools/fracture_patterns.py): bond strength
# scatter, debris damping and jittered particles.
BRITTLE_PATTERN = {"strength_weibull_modulus": 4.0, "strength_seed": 7, "debris_damping": 60.0}
BRITTLE_SAMPLING = {"sampling": "jittered", "jitter": 0.5, "sampling_seed": 3}


def wall_materials():
    """The four materials, in the order the ball meets them."""
    layered = pdsim.Anisotropy(axis=(0.0, 0.0, 1.0), strength_ratio=0.15, stiffness_ratio=0.7)  # horizontal layers
    common = {"density": 1000.0, "youngs_modulus": 1.0e6}
    brittle = {**common, "poisson_ratio": 0.25, "critical_stretch": 0.01, "compressive_bonus": 1.0, **BRITTLE_PATTERN}
    return [
        pdsim.Material(**brittle, name="brittle"),
        pdsim.Material(**brittle, anisotropy=layered, name="brittle_layered"),
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


def wall_body_options(material):
    """Particle placement of a wall: jittered for the brittle walls (BRITTLE_SAMPLING), the simple-cubic lattice for
    the ductile ones."""
    return dict(BRITTLE_SAMPLING) if material.yield_stress is None else {}


def add_walls(scene, materials, *, spacing=0.01, body_options=None):
    """Square walls normal to x, clamped (and unbreakable) along their rim, WALL_GAP apart from x = 0.
    ``body_options``: PeridynamicBody keywords for every wall (default: :func:`wall_body_options` per material)."""
    thick = max(0.03, 3.0 * spacing)
    walls = []
    for i, mat in enumerate(materials):
        shape = pdsim.box((thick, WALL_SIZE, WALL_SIZE), center=(WALL_GAP * i, 0.0, 0.0), name=mat.name)
        options = wall_body_options(mat) if body_options is None else body_options
        wall = scene.add_peridynamic_body(shape, mat, spacing, **options)

        def rim(p):
            return np.maximum(np.abs(p[:, 1]), np.abs(p[:, 2])) > 0.5 * WALL_SIZE - 1.5 * spacing

        wall.fix(rim)
        wall.set_unbreakable(rim)
        walls.append(wall)
    return walls


PREVIEW = {"spacing": 0.015}  # tools/make_gallery.py and tests/test_gallery.py: a coarser, quicker run


def build_scene(
    *, spacing=0.01, materials=None, frames=40, speed=3.0, body_options=None, retardation_time=0.0
) -> pdsim.Scene:
    """The four walls and a rigid ball of radius 5 cm flying along +x at ``speed`` [m/s] (10 % of the walls' wave
    speed: a hard hit); ``materials`` replaces the walls (any number), ``spacing`` is the particle spacing [m],
    ``body_options`` replaces the walls' PeridynamicBody keywords (see add_walls); ``retardation_time`` [s]: the
    brittle walls' internal damping (Material.retardation_time; none by default)."""
    # 5x slow motion: 1/120 s of simulated time per frame, played at 24 frames per second
    scene = pdsim.Scene(fps=24, time_scale=0.2, frames=frames, gravity=(0.0, 0.0, 0.0), name="four_walls")
    materials = materials or wall_materials()
    if retardation_time:
        materials = [
            m if m.yields else dataclasses.replace(m, retardation_time=retardation_time) for m in materials
        ]  # fmt: skip
    add_walls(scene, materials, spacing=spacing, body_options=body_options)
    scene.add_collider(pdsim.SphereProjectile(0.05, center=(-0.15, 0.0, 0.0), velocity=(speed, 0.0, 0.0)))
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
