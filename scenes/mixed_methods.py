"""Two methods in one scene: a brittle peridynamic ball hits a hard-rubber block simulated with the tetrahedral FEM;
the ball chips where it strikes and bounces off while the block, dented for a moment, rocks on the ground
(contact between the methods: pdsim.contact.MethodContact, on automatically when a scene holds both).

The block (0.5 m x 0.3 m x 0.2 m, E 10 MPa, nu 0.4, 1000 kg/m^3; a structured mesh of 6 tetrahedra per cell,
explicit integrator) rests on the ground near (3, -2, 0) m. The ball (radius 8 cm, a brittle animation material: E 5
MPa, critical stretch 0.03 % with Weibull scatter of modulus 4 and the compressive bonus) comes down on the block's
top at 5 m/s, 45 degrees from the vertical. Each frame advances 1/120 s of simulated time (5x slow motion).

Run:  python scenes/mixed_methods.py --out mixed.usdc   or   pdsim run scenes/mixed_methods.py --out mixed.usdc
"""

import numpy as np

import pdsim

BLOCK_CENTER = np.array([3.0, -2.0, 0.1])  # [m]
BLOCK_SIZE = (0.5, 0.3, 0.2)  # [m]
RADIUS = 0.08  # the ball [m]

PREVIEW = {"spacing": 0.02, "cells": 2, "frames": 24}  # tools/make_gallery.py and tests/test_gallery.py


def build_scene(*, spacing: float = 0.0125, cells: int = 4, frames: int = 48, speed: float = 5.0) -> pdsim.Scene:
    """The ball at particle ``spacing`` [m], the block with ``cells`` mesh cells per 10 cm, the ball at ``speed``
    [m/s]; ``frames`` frames of 1/120 s."""
    scene = pdsim.Scene(fps=24, time_scale=0.2, frames=frames, name="mixed_methods")
    rubber = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.4, name="hard_rubber")
    counts = tuple(max(1, round(10.0 * s * cells)) for s in BLOCK_SIZE)
    mesh = pdsim.box_tet_mesh(BLOCK_SIZE, counts, center=tuple(BLOCK_CENTER), name="block")
    scene.add_body(pdsim.FemBody(mesh, rubber, damping=2.0, name="block"))
    brittle = pdsim.Material(
        density=1000.0,
        youngs_modulus=5.0e6,
        poisson_ratio=0.25,
        critical_stretch=3.0e-4,
        compressive_bonus=1.0,
        strength_weibull_modulus=4.0,
        debris_damping=20.0,
        name="brittle",
    )
    direction = np.array([1.0, 0.0, -1.0]) / np.sqrt(2.0)
    top = BLOCK_CENTER + np.array([0.0, 0.0, 0.5 * BLOCK_SIZE[2]])
    start = top + np.array([-0.1, 0.0, RADIUS + 0.01])
    ball = scene.add_peridynamic_body(pdsim.sphere(RADIUS, center=tuple(start), name="ball"), brittle, spacing)
    ball.set_initial_velocity(tuple(speed * direction))
    scene.add_ground_plane(height=0.0, friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
