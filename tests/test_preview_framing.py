"""The preview's automatic camera frames the bodies over the shot: projectiles and colliders (the prims under
/World/colliders) are left out of the box it fits, unless a camera is given."""

import numpy as np

import pdsim
from pdsim.preview import render_cache


def _cache(path, projectile: bool):
    """A PD block (0.1 m, h = 2.5 cm) at rest without gravity, and optionally a sphere projectile starting 1 m from it
    at 50 m/s (12.5 m away by the last frame, 0.25 s)."""
    scene = pdsim.Scene(fps=24.0, frames=6, gravity=(0.0, 0.0, 0.0), name="framing")
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25)
    scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1)), mat, 0.025, name="block")
    if projectile:
        scene.add_collider(pdsim.SphereProjectile(0.05, center=(1.0, 0.0, 0.0), velocity=(50.0, 0.0, 0.0), name="ball"))
    scene.run(str(path), progress=False, device="cpu")
    return str(path)


def test_camera_frames_the_bodies_not_the_projectile(tmp_path):
    """With and without a projectile flying 1 m to 13.5 m from the block, the automatic camera and the box it fits
    are the same (1e-9 m); the box holds the block (0.1 m across, plus the particles' radii) and not the projectile's
    flight (12.5 m); a camera given as a spec is used as given."""
    alone = render_cache(_cache(tmp_path / "alone.usda", False), [6], size=(64, 48))
    shot = render_cache(_cache(tmp_path / "shot.usda", True), [6], size=(64, 48))
    lo, hi = shot.bounds
    assert float(np.max(hi - lo)) < 0.2
    np.testing.assert_allclose(shot.bounds, alone.bounds, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(shot.camera.eye, alone.camera.eye, rtol=0.0, atol=1e-9)
    given = render_cache(str(tmp_path / "shot.usda"), [6], size=(64, 48), camera="eye=20,-5,2:target=7,0,0")
    np.testing.assert_allclose(given.camera.eye, [20.0, -5.0, 2.0])
    np.testing.assert_allclose(given.camera.target, [7.0, 0.0, 0.0])
