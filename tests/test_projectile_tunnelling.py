"""Fast projectiles do not pass through thin bodies: the automatic step keeps every projectile's surface within
PROJECTILE_TRAVEL (half a spacing of the finest body) per step (pdsim/timestep.py). CPU backend."""

import math
import os

import numpy as np
import pytest

import pdsim
from pdsim.timestep import PROJECTILE_TRAVEL, projectile_speed, projectile_step_limit

H = 0.01  # plate spacing [m]: 2 particles through a 2 cm plate
X0 = 1000.0  # the plate sits 1 km from the origin


def _plate_scene(speed: float):
    """A 2 cm glass plate (the preset, spacing 1 cm) and a 2 cm sphere 5 mm above it flying down at ``speed`` [m/s]:
    two frames of 1 ms, in each of which the sphere travels ``speed`` x 1 ms."""
    scene = pdsim.Scene(fps=24, frames=2, frame_time=1.0e-3, gravity=(0.0, 0.0, 0.0), name="plate")
    plate = scene.add_peridynamic_body(
        pdsim.box((0.1, 0.1, 0.02), center=(X0, 0.0, 0.0), name="plate"), pdsim.presets.glass(), spacing=H
    )
    scene.add_collider(pdsim.SphereProjectile(0.01, center=(X0, 0.0, 0.025), velocity=(0.0, 0.0, -speed)))
    return scene, plate


def _damage_in_path(scene, plate, tmp_path, **run) -> tuple[float, object]:
    """Mean damage of the plate's particles within the sphere's radius of its path, after the run."""
    seen = {}

    def grab(frame, solvers):
        r = np.linalg.norm(plate.rest_positions[:, :2] - np.array([X0, 0.0]), axis=1)
        seen["path"] = float(solvers[0].damage()[r < 0.01].mean())

    report = scene.run(os.fspath(tmp_path / "plate.usdc"), device="cpu", progress=False, on_frame=grab, **run)
    return seen["path"], report


@pytest.mark.parametrize("speed", [30.0, 3000.0])
def test_a_fast_sphere_breaks_a_thin_plate_as_a_slow_one_does(speed, tmp_path):
    """At 3,000 m/s the sphere travels 3 m a frame: at the stable step alone (1.1e-4 s, 0.33 m a step, 16 plate
    thicknesses) it passed through without touching a particle (damage 0). With the travel limit every particle in
    its path is broken (damage > 0.9), as at 30 m/s; the step is then 0.5 h / 3000 m/s."""
    scene, plate = _plate_scene(speed)
    path, report = _damage_in_path(scene, plate, tmp_path)
    assert path > 0.9
    if speed > 1000.0:
        assert report.dt == pytest.approx(PROJECTILE_TRAVEL * H / speed, rel=1.0e-9)
        assert report.dt < report.stable_dt


def test_the_limit_is_the_fastest_surface_over_the_run():
    """Ballistic speed is largest at the ends of the run (gravity speeds the body up); spin adds |w| R; a scripted
    path is differenced; without projectiles or bodies with a spacing the step is not limited."""
    scene = pdsim.Scene(frames=10, fps=10.0, gravity=(0.0, 0.0, -10.0))
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2), center=(0.0, 0.0, 5.0)), pdsim.presets.clay(), spacing=0.05)
    assert projectile_step_limit(scene, 10) == math.inf
    falling = pdsim.SphereProjectile(0.1, center=(0.0, 0.0, 20.0), velocity=(3.0, 0.0, 0.0), gravity=(0, 0, -10.0))
    assert projectile_speed(falling, 1.0) == pytest.approx(math.hypot(3.0, 10.0), rel=1e-12)  # at t = 1 s
    spinning = pdsim.BoxProjectile((0.2, 0.2, 0.2), center=(3.0, 0.0, 5.0), angular_velocity=(0.0, 0.0, 50.0))
    assert projectile_speed(spinning, 1.0) == pytest.approx(50.0 * math.sqrt(3.0) * 0.1, rel=1e-9)
    circling = pdsim.SphereProjectile(0.1, path=lambda t: (2.0 * math.cos(4.0 * t), 2.0 * math.sin(4.0 * t), 9.0))
    assert projectile_speed(circling, 1.0) == pytest.approx(8.0, rel=1e-3)  # |r w| = 2 x 4 m/s
    scene.add_collider(falling)
    assert projectile_step_limit(scene, 10) == pytest.approx(PROJECTILE_TRAVEL * 0.05 / math.hypot(3.0, 10.0))


def test_a_user_step_past_the_limit_warns_and_tunnels(tmp_path):
    """A user dt of 1e-4 s (about the stable step, what the automatic step was before the limit) lets the 3,000 m/s
    sphere travel 0.3 m a step, 15 plate thicknesses: the run does as asked, with a warning naming the limit, and the
    sphere passes through without touching a particle (damage 0 in its path), which is what the limit prevents."""
    scene, plate = _plate_scene(3000.0)
    with pytest.warns(UserWarning, match="projectile travel more than 0.5 spacings"):
        path, report = _damage_in_path(scene, plate, tmp_path, dt=1.0e-4)
    assert report.dt == pytest.approx(1.0e-4) and path == 0.0
