"""A glass pane shattered by a projectile: a steel ball hits a window pane held in its frame at 20 m/s, punches a hole
through it, and cracks run out from the hole and along the frame; shards fly off both faces (peridynamics with
fracture, slow motion).

The pane (soda-lime glass: E 72 GPa, nu 0.22, 2500 kg/m^3; 0.3 m x 0.3 m, 12 mm thick) stands upright in the x-z
plane with its centre at (3, -2, 0.6) m, its outer 1.5 cm clamped (the frame, unbreakable). Bonds break at a stretch
of 0.1 % (about glass's tensile strength of 70 MPa; a fracture energy of a few J/m^2 would give a far smaller critical
stretch at this coarse horizon and turn the pane to dust), with the Silling-Askari compressive bonus (alpha = 1), a
Weibull scatter of the bonds' strength (modulus 6), debris damping and jittered particles. The ball (radius 2 cm,
kinematic: it is not slowed down) flies along +y through the pane's centre. Each frame advances 4 ms / frames of
simulated time (48 frames: 4 ms shown over 2 s).

Run:  python scenes/glass_pane.py --out glass_pane.usdc   or   pdsim run scenes/glass_pane.py --out glass_pane.usdc

Run time (CPU only, the 2-core development machine shared with other jobs, load average 1-6; no GPU measured):
full resolution (5,000 particles, 136 steps per frame) 298 s wall, `/usr/bin/time pdsim run scenes/glass_pane.py
--out glass.usdc --quiet`; preview (PREVIEW: 1,800 particles, 239 steps per frame) 58 s and 84 s in two runs, `python
tools/make_gallery.py --scenes glass_pane`.
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.6])  # centre of the pane [m]
SIZE = 0.3  # edge of the square pane [m]
THICKNESS = 0.012  # [m]
FRAME = 0.015  # width of the clamped rim [m]

PREVIEW = {"spacing": 0.01, "frames": 16}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def build_scene(
    *, spacing: float = 0.006, frames: int = 48, speed: float = 20.0, duration: float = 4.0e-3
) -> pdsim.Scene:
    """The pane at particle ``spacing`` [m] (at most its 12 mm thickness), ``frames`` frames over ``duration`` [s] of
    simulated time, the ball at ``speed`` [m/s]."""
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=duration / frames, name="glass_pane")
    glass = pdsim.Material(
        density=2500.0,
        youngs_modulus=72.0e9,
        poisson_ratio=0.22,
        critical_stretch=1.0e-3,
        compressive_bonus=1.0,
        strength_weibull_modulus=6.0,
        debris_damping=1000.0,
        name="glass",
    )
    shape = pdsim.box((SIZE, THICKNESS, SIZE), center=tuple(CENTER), name="pane")
    pane = scene.add_peridynamic_body(shape, glass, spacing, sampling="jittered")

    def frame(p):
        d = np.abs(p - CENTER)
        return np.maximum(d[:, 0], d[:, 2]) > 0.5 * SIZE - FRAME

    pane.fix(frame)
    pane.set_unbreakable(frame)
    radius = 0.02
    start = CENTER + np.array([0.0, -(radius + 0.5 * THICKNESS + 0.004), 0.0])
    scene.add_collider(pdsim.SphereProjectile(radius, center=tuple(start), velocity=(0.0, speed, 0.0), name="ball"))
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
