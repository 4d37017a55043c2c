"""A metal plate dented and torn: a heavy steel ball comes down on a ductile plate clamped in a square frame; the plate
yields and dents under the ball, then tears, and the ball punches a hole through it, throwing off torn fragments
(peridynamics with plasticity and ductile failure, slow motion). At these resolutions the tear is a punched hole with
a raised rim rather than petals, and the torn material leaves as small fragments.

The plate (0.4 m x 0.4 m x 3 cm, a soft ductile animation material: E 1 MPa, yield stress 5 kPa, perfectly plastic,
bonds break past an equivalent plastic strain of 0.5) lies level at (3, -2, 0.5) m, its outer 3 cm clamped and
unbreakable. The ball (radius 6 cm, kinematic: it is not slowed down) comes down on the plate's centre at 3 m/s,
about a tenth of the plate's wave speed. Each frame advances 1/120 s of simulated time (5x slow motion).

Petals need a plate thin against the ball with several particles through it, which is a GPU-sized run; the variants
tried on the CPU (``build_scene(thickness=..., speed=..., metal_options={"hardening_modulus": ...})``) are in
docs/fracture.md, "Metal plate".

Run:  python scenes/metal_dent_tear.py --out metal.usdc   or   pdsim run scenes/metal_dent_tear.py --out metal.usdc
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.5])  # the plate's centre [m]
SIZE, THICKNESS, RIM = 0.4, 0.03, 0.03  # [m]

PREVIEW = {"spacing": 0.015, "frames": 24}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def build_scene(
    *,
    spacing: float = 0.01,
    frames: int = 48,
    speed: float = 3.0,
    thickness: float = THICKNESS,
    radius: float = 0.06,
    metal_options: dict | None = None,
) -> pdsim.Scene:
    """The plate of ``thickness`` [m] at particle ``spacing`` [m] (at most its thickness), the ball of ``radius`` [m]
    at ``speed`` [m/s]; ``frames`` frames of 1/120 s; ``metal_options``: pdsim.Material keywords that replace the
    metal's (e.g. hardening_modulus)."""
    scene = pdsim.Scene(fps=24, time_scale=0.2, frames=frames, name="metal_dent_tear")
    metal = pdsim.Material(
        density=1000.0,
        youngs_modulus=1.0e6,
        poisson_ratio=0.3,
        **{"yield_stress": 5.0e3, "failure_plastic_strain": 0.5, **(metal_options or {})},
        name="ductile_metal",
    )
    shape = pdsim.box((SIZE, SIZE, thickness), center=tuple(CENTER), name="plate")
    plate = scene.add_peridynamic_body(shape, metal, spacing)

    def rim(p):
        d = np.abs(p - CENTER)
        return np.maximum(d[:, 0], d[:, 1]) > 0.5 * SIZE - RIM

    plate.fix(rim)
    plate.set_unbreakable(rim)
    start = CENTER + np.array([0.0, 0.0, 0.5 * thickness + radius + 0.005])
    scene.add_collider(pdsim.SphereProjectile(radius, center=tuple(start), velocity=(0.0, 0.0, -speed), name="ball"))
    scene.add_ground_plane(height=0.0, friction=0.5)
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
