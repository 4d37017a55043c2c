"""A glass pane shattered by a projectile: a steel ball hits a window pane held in its frame at 20 m/s; the pane bows,
cracks run out from the ball, and the glass breaks into shards that fall out of the frame while the ball punches
through (peridynamics with fracture, slow motion).

The pane (soda-lime glass: E 72 GPa, nu 0.22, 2500 kg/m^3; 0.3 m x 0.3 m, 12 mm thick) stands upright in the x-z
plane with its centre at (3, -2, 0.6) m, its outer 1.5 cm clamped (the frame, unbreakable). Bonds break at a stretch
of 0.1 % (about glass's tensile strength of 70 MPa; a fracture energy of a few J/m^2 would give a far smaller
critical stretch at this coarse horizon and turn the pane to dust), with the full Silling-Askari compressive bonus
capped at 3 s_c (alpha = 1, Material.compressive_bonus_cap = 3), a Weibull scatter of the bonds' strength (modulus
4, seed 7), jittered particles (jitter 0.5, seed 3) and debris damping of 2.5e4 / s (c dt 0.01 at the full
resolution's step, 0.026 at the preview's; docs/fracture.md). The ball (radius 2 cm, kinematic: it is not slowed
down) flies along +y through the pane's centre. Each frame advances 4 ms / frames of simulated time (48 frames: 4 ms
shown over 2 s).

At full resolution (spacing 4 mm, 3 particles through the pane) the pane breaks into shards; at the preview spacing
(10 mm, 1.2 particles through) it does not shatter. Limits: the pane bows by centimetres before it cracks through
(real glass cracks at a few millimetres), since the capped bonus still lets glass beside compressed bonds stretch to
4 s_c and the horizon is as long as the pane is thick; fragments can fly back faster than the ball, and the figures
move with the seeds. The fracture figures, the limits and how the settings were found: docs/fracture.md, "Glass
pane"; the full resolution in pictures: docs/gallery/glass_pane_full.png and docs/gallery/glass_pane_full.gif.

Run:  python scenes/glass_pane.py --out glass_pane.usdc   or   pdsim run scenes/glass_pane.py --out glass_pane.usdc
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.6])  # centre of the pane [m]
SIZE = 0.3  # edge of the square pane [m]
THICKNESS = 0.012  # [m]
FRAME = 0.015  # width of the clamped rim [m]
# The brittle-pattern settings (docs/fracture.md): the full compressive bonus capped at 3 s_c (shards instead of dust;
# docs/fracture.md, "Glass pane"), Weibull strength scatter of modulus 4 (seed 7, as the teaser's wall), and debris
# damping c = 2.5e4 / s, c dt = 0.01 at the full resolution's step (4.0e-7 s; 0.026 at the preview's 1.04e-6 s).
PATTERN = {
    "compressive_bonus": 1.0,
    "compressive_bonus_cap": 3.0,
    "strength_weibull_modulus": 4.0,
    "strength_seed": 7,
    "debris_damping": 2.5e4,
}
SAMPLING = {"sampling": "jittered", "jitter": 0.5}  # with sampling_seed (build_scene): jittered particles

PREVIEW = {"spacing": 0.01, "frames": 16}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def build_scene(
    *,
    spacing: float = 0.004,
    frames: int = 48,
    speed: float = 20.0,
    duration: float = 4.0e-3,
    thickness: float = THICKNESS,
    size: float = SIZE,
    radius: float = 0.02,
    glass_options: dict | None = None,
    sampling_seed: int = 3,
) -> pdsim.Scene:
    """The pane at particle ``spacing`` [m] (at most its ``thickness`` [m]), ``frames`` frames over ``duration`` [s]
    of simulated time, the ball of ``radius`` [m] at ``speed`` [m/s]; ``size`` [m]: the pane's edge;
    ``glass_options``: pdsim.Material keywords that replace the glass's PATTERN settings (or add to them);
    ``sampling_seed``: the seed of the particles' jitter."""
    scene = pdsim.Scene(fps=24, frames=frames, frame_time=duration / frames, name="glass_pane")
    glass = pdsim.Material(
        density=2500.0,
        youngs_modulus=72.0e9,
        poisson_ratio=0.22,
        critical_stretch=1.0e-3,
        **{**PATTERN, **(glass_options or {})},
        name="glass",
    )
    shape = pdsim.box((size, thickness, size), center=tuple(CENTER), name="pane")
    pane = scene.add_peridynamic_body(shape, glass, spacing, **SAMPLING, sampling_seed=sampling_seed)

    def frame(p):
        d = np.abs(p - CENTER)
        return np.maximum(d[:, 0], d[:, 2]) > 0.5 * size - FRAME

    pane.fix(frame)
    pane.set_unbreakable(frame)
    start = CENTER + np.array([0.0, -(radius + 0.5 * thickness + 0.004), 0.0])
    scene.add_collider(pdsim.SphereProjectile(radius, center=tuple(start), velocity=(0.0, speed, 0.0), name="ball"))
    return scene


if __name__ == "__main__":
    from pdsim.cli import run_script

    run_script(build_scene)
