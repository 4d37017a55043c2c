"""A wooden board snapping along its grain: a board with its grain at 30 degrees to its length lies on two trestles
and a rigid ball presses down on its middle (three-point bending) until it breaks; the crack does not run straight
across the board but along the grain, at 30 degrees (peridynamics with anisotropic fracture).

The board (1.2 m x 0.3 m x 6 cm) rests on two rigid boxes 1.0 m apart; a ball of radius 6 cm pushes its centre down
at 0.5 m/s for 12 cm, then stays. The wood is an animation material (soft, E 4 MPa, 600 kg/m^3, so the time step
stays affordable) that is weak across the grain: pdsim.Anisotropy with its axis in the board's plane normal to the
grain, strength_ratio 0.25 (bonds across the grain break at a quarter of the 2 % critical stretch along it) and
stiffness_ratio 0.5. Centred near (3, -2, 0) m, on the ground plane at z = 0. Each frame advances 0.5 s / frames.

At full resolution the board breaks into large pieces along the grain, but a fragment rises faster than the press
moves: the fracture figures and their command are in docs/fracture.md, "Plank".

Run:  python scenes/plank_grain.py --out plank_grain.usdc   or   pdsim run scenes/plank_grain.py --out plank_grain.usdc
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.0])  # the plank's centre on the ground [m]
LENGTH, DEPTH, HEIGHT = 1.2, 0.3, 0.06  # plank [m]: along x, y, z
SPAN = 1.0  # distance between the supports' centres [m]
TRESTLE = (0.08, 0.4, 0.3)  # the two rigid supports (boxes standing on the ground) [m]
ROLLER = 0.06  # radius of the press (a ball) [m]

PREVIEW = {"spacing": 0.02, "frames": 24}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def _at(dx: float, dy: float, dz: float) -> tuple:
    """A point [m] relative to CENTER."""
    return tuple(CENTER + np.array([dx, dy, dz]))


def build_scene(
    *,
    spacing: float = 0.015,
    frames: int = 48,
    speed: float = 0.5,
    stroke: float = 0.12,
    duration: float = 0.5,
    grain_angle: float = 30.0,
) -> pdsim.Scene:
    """The plank at particle ``spacing`` [m]; ``frames`` frames over ``duration`` [s] of simulated time; the press
    moves down at ``speed`` [m/s] for ``stroke`` [m], then stays."""
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=duration / frames, name="plank_grain")
    a = np.radians(grain_angle)
    # weak across the grain: the axis is the in-plane normal of the grain, planes normal to it are weak
    grain = pdsim.Anisotropy(axis=(-np.sin(a), np.cos(a), 0.0), stiffness_ratio=0.5, strength_ratio=0.25)
    wood = pdsim.Material(
        density=600.0, youngs_modulus=4.0e6, poisson_ratio=0.3, critical_stretch=0.02, anisotropy=grain, name="wood"
    )
    z0 = TRESTLE[2] + 0.5 * HEIGHT + 0.002
    shape = pdsim.box((LENGTH, DEPTH, HEIGHT), center=_at(0.0, 0.0, z0), name="plank")
    scene.add_peridynamic_body(shape, wood, spacing, damping=2.0)
    for i, x in enumerate((-0.5 * SPAN, 0.5 * SPAN)):
        box = pdsim.box(TRESTLE, center=_at(x, 0.0, 0.5 * TRESTLE[2]), name=f"support_{i}")
        scene.add_collider(pdsim.MeshCollider(box, friction=0.5, name=f"support_{i}"))
    top = np.array(_at(0.0, 0.0, z0 + 0.5 * HEIGHT + ROLLER + 0.002))
    press = pdsim.sphere(ROLLER, center=tuple(top), name="press")

    def path(t):
        return top - (0.0, 0.0, speed * min(t, stroke / speed))

    scene.add_collider(pdsim.MeshProjectile(press, path=path, friction=0.3, name="press"))
    scene.add_ground_plane(height=CENTER[2], friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
