"""A fast ball against a wall that cannot break, in a set away from the origin, defaults on (contact, automatic
step): nothing passes through silently.

- A steel peridynamic ball (r = 3 cm, h = 1 cm) at 200 m/s against a clamped, unbreakable steel wall (3 cm thick):
  the ball is stopped and thrown back (its mean velocity after 1 ms points back, at least 20 % of the impact speed)
  and no ball particle reaches the wall's far face; the same ball against a soft wall (E = 1e7 Pa, wave speed
  35 m/s, far below the impact speed) is caught in it: the wall bulges, the ball stays on the near side of the
  wall's far particles and has lost at least half its speed after 1 ms (measured: 64 %; 94 % after 2 ms).
- A kinematic projectile (a collider moving on its prescribed path, infinitely heavy) driven at 200 m/s into the
  same unbreakable clamped wall cannot be stopped: the run stops with the watchdog's error naming the wall, instead
  of the projectile passing through the wall without a word.
"""

import numpy as np
import pytest

import pdsim
from pdsim.errors import InstabilityError
from pdsim.output.usd_files import world_points

SHIFT = np.array([10.0, 5.0, 2.0])  # a set position in metres, away from the origin
SPEED = 200.0
START = tuple(SHIFT + np.array([-0.07, 0.0, 0.0]))  # the ball's centre: 4 cm of air before the wall


def _wall(scene, youngs_modulus):
    material = pdsim.Material(density=7800.0, youngs_modulus=youngs_modulus, poisson_ratio=0.3, name="wall_material")
    wall = scene.add_peridynamic_body(pdsim.box((0.03, 0.12, 0.12), center=tuple(SHIFT), name="wall"), material, 0.01)
    wall.fix(lambda p: np.maximum(np.abs(p[:, 1] - SHIFT[1]), np.abs(p[:, 2] - SHIFT[2])) > 0.045)  # the rim
    return wall


def _scene():
    return pdsim.Scene(fps=24, frames=1, frame_time=1.0e-3, gravity=(0.0, 0.0, 0.0), name="impact")


def _read(path, name, frame):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    points = UsdGeom.Points(stage.GetPrimAtPath(f"/World/{name}"))
    # velocities are stored per second of playback: a frame plays 1 / timeCodesPerSecond s and simulates 1 ms
    velocity = np.asarray(points.GetVelocitiesAttr().Get(frame), dtype=np.float64)
    velocity *= (1.0 / stage.GetTimeCodesPerSecond()) / 1.0e-3
    return world_points(points.GetPrim(), frame), velocity  # through the prim's double translate


@pytest.mark.parametrize("youngs_modulus", [2.0e11, 1.0e7])
def test_fast_ball_does_not_pass_through_an_unbreakable_wall(tmp_path, youngs_modulus):
    scene = _scene()
    wall = _wall(scene, youngs_modulus)
    steel = pdsim.Material(density=7800.0, youngs_modulus=2.0e11, poisson_ratio=0.3, name="steel")
    ball = scene.add_peridynamic_body(pdsim.sphere(0.03, center=START, name="ball"), steel, 0.01)
    ball.set_initial_velocity((SPEED, 0.0, 0.0))
    assert not wall.fractures
    out = tmp_path / "impact.usdc"
    scene.run(str(out), progress=False)
    ball_x, ball_v = _read(out, "ball", 1)
    wall_x, _ = _read(out, "wall", 1)
    back_face = SHIFT[0] + 0.01  # the wall's far particle layer at rest
    mean_v = ball_v[:, 0].mean()
    if youngs_modulus > 1.0e9:
        assert mean_v < -0.2 * SPEED, mean_v  # thrown back
        assert ball_x[:, 0].max() < back_face, ball_x[:, 0].max()
    else:
        assert abs(mean_v) < 0.5 * SPEED, mean_v  # being caught
        assert wall_x[:, 0].max() > back_face + 0.02  # the wall bulges around it
        assert ball_x[:, 0].max() < wall_x[:, 0].max()  # the wall's far particles stay ahead of the ball


def test_kinematic_projectile_into_an_unbreakable_wall_stops_with_a_message(tmp_path):
    scene = _scene()
    _wall(scene, 2.0e11)
    scene.add_collider(pdsim.SphereProjectile(0.03, center=START, velocity=(SPEED, 0, 0)))
    with pytest.raises(InstabilityError, match="wall") as info:
        scene.run(str(tmp_path / "projectile.usdc"), progress=False)
    assert "passed through each other" in str(info.value)
