"""A glass pane holed by a projectile: a steel ball hits a window pane held in its frame at 20 m/s; the pane bows, the
ball punches a hole through it, and the glass around the hole breaks up; cracks run a little way out from the hole
(peridynamics with fracture, slow motion).

The pane (soda-lime glass: E 72 GPa, nu 0.22, 2500 kg/m^3; 0.3 m x 0.3 m, 12 mm thick) stands upright in the x-z
plane with its centre at (3, -2, 0.6) m, its outer 1.5 cm clamped (the frame, unbreakable). Bonds break at a stretch
of 0.1 % (about glass's tensile strength of 70 MPa; a fracture energy of a few J/m^2 would give a far smaller critical
stretch at this coarse horizon and turn the pane to dust), with the Silling-Askari compressive bonus (alpha = 1), a
Weibull scatter of the bonds' strength (modulus 4), jittered particles and debris damping of 1e4 / s (c dt about
0.01 at the preview's step, 0.006 at the full resolution's; docs/fracture.md). The ball (radius 2 cm, kinematic: it
is not slowed down) flies along +y through the pane's centre. Each frame advances 4 ms / frames of simulated time (48
frames: 4 ms shown over 2 s).

Limits. With 1 to 2 particles through the pane (spacing 10 mm and 6 mm) the pane does not shatter into shards: what
breaks out of the hole is single particles and pairs (dust: 100 % of the broken-out material at both spacings; 49 and
89 particles), and the debris damping keeps it slow at the preview spacing (fastest fragment back towards the shooter
4.9 m/s, ball 20 m/s) but not at the full one (20.3 m/s; measured with tools/fracture_patterns.py's fragment_metrics,
2026-12-02). Why (21 variants measured the same day, with the peridynamic dilatation's former directional factor,
which then left 57 % dust and a few cone-shaped shards of 37-46 particles at the full spacing): a rigid ball is a
curvature the glass cannot follow (the glass under a sphere of radius R pushed along the shot stretches by about
r^2 / (2 R^2), 125 s_c at r = R / 2), so everything it touches breaks at any spacing; bounding the compressive bonus
(Material.compressive_bonus_cap 0.25-3) turns the footprint into dust. A slowed elastic steel ball (a peridynamic
body, 0.26 or 2.1 kg) bounces off with the full bonus and pushes through a pulverised footprint with a bounded one;
no run formed radial cracks, since the horizon (3 h = 18-30 mm) is longer than the pane is thick and damage spreads
over it instead of localising. A 4 mm spacing (3 particles through, 16,875 particles, 461 s of simulation) gave larger
pieces (142, 93, 53 particles) but 67 % dust and 63 m/s back: shards need a horizon well under the ball's radius and
several particles through the thickness (GPU resolution, not measured).

A thicker pane does not shatter either (2026-12-02, second round, spacing 10 mm, 16 frames, the teaser's pattern
settings: `python tools/fracture_patterns.py --scene scenes/glass_pane.py --scene-args '{"spacing": 0.01, "frames":
16, "thickness": 0.03, "radius": 0.05}' --plane 0 2 --centre 3 -2 0.6 --half-width 0.1 --variants all "all, no
bonus"`, and the same with "speed": 2.0, "duration": 0.008 and "radius" 0.05 or 0.15). A 30 mm pane (3 particles
through) hit by a 5 cm ball at 20 m/s, as the teaser's wall is: with the full compressive bonus, which holds sheared
glass together (docs/fracture.md), the glass under the ball tents forward and frees one plug of 216 particles (so
19.7 % dust, but single particles spall back at up to 88 m/s, 4.4 times the ball; another seed, tried outside the
tool, freed no plug at all); without the bonus the ball punches out a plug of dust (100 % of 421 particles). At 2
m/s over 8 ms (ball radius 5 or 15 cm) the bonus keeps the pane whole (it bends, nothing breaks out) and without it
the ball punches out dust (100 % and 97 %). No run formed radial cracks: the load that bends a 30 mm pane to its
strength (tens of kN) sits on a contact a few millimetres across, smaller than a particle, so the particles under
the ball fail before the plate bends. A prototype (not kept) that took the bonus from the particle's dilatation
instead of its most compressed bond, so that the stretched face of a bent plate gets none, gave the same plug or
tent.

Run:  python scenes/glass_pane.py --out glass_pane.usdc   or   pdsim run scenes/glass_pane.py --out glass_pane.usdc

Run time (CPU only, the 2-core development machine; no GPU measured): full resolution (5,000 particles, 136 steps per
frame) 378 s wall, 668 MB peak memory, `/usr/bin/time -v pdsim run scenes/glass_pane.py --out glass.usdc --quiet`,
2026-12-02, load average 0.2-1.5 (the fragments' surface rebuilds take most of it: the simulation alone is about 65 s);
preview (PREVIEW: 1,800 particles, 239 steps per frame): `python tools/make_gallery.py --scenes glass_pane`, time in
docs/gallery.md.
"""

import numpy as np

import pdsim

CENTER = np.array([3.0, -2.0, 0.6])  # centre of the pane [m]
SIZE = 0.3  # edge of the square pane [m]
THICKNESS = 0.012  # [m]
FRAME = 0.015  # width of the clamped rim [m]
# The brittle-pattern settings (docs/fracture.md): compressive bonus, Weibull strength scatter of modulus 4, and debris
# damping c = 1e4 / s, about 0.01 / dt at the preview step (1.05e-6 s; 0.006 / dt at the full resolution's 6.3e-7 s).
PATTERN = {"compressive_bonus": 1.0, "strength_weibull_modulus": 4.0, "debris_damping": 1.0e4}

PREVIEW = {"spacing": 0.01, "frames": 16}  # tools/make_gallery.py and tests/test_gallery.py: a coarse quick run


def build_scene(
    *,
    spacing: float = 0.006,
    frames: int = 48,
    speed: float = 20.0,
    duration: float = 4.0e-3,
    thickness: float = THICKNESS,
    size: float = SIZE,
    radius: float = 0.02,
    glass_options: dict | None = None,
) -> pdsim.Scene:
    """The pane at particle ``spacing`` [m] (at most its ``thickness`` [m]), ``frames`` frames over ``duration`` [s]
    of simulated time, the ball of ``radius`` [m] at ``speed`` [m/s]; ``size`` [m]: the pane's edge;
    ``glass_options``: pdsim.Material keywords that replace the glass's PATTERN settings (or add to them)."""
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
    pane = scene.add_peridynamic_body(shape, glass, spacing, sampling="jittered")

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
