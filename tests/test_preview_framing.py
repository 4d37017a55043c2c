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


def _box_points(lo, hi):
    return [(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]


def _debris_stage(path, offset):
    """A Z-up stage 1 km from the origin (``offset``): a 10 cm body cube at rest, a 2 cm chip that starts inside it
    and flies 5 m along +x and 2 cm up by frame 2, and pdsim's ground quad (/World/ground, 1 m wide, 1 cm below the
    body: narrower than the chip's flight)."""
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    UsdGeom.Xform.Define(stage, "/World")
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]

    def cube(name, lo, hi, moves=()):
        mesh = UsdGeom.Mesh.Define(stage, f"/World/{name}")
        mesh.GetFaceVertexCountsAttr().Set([4] * 6)
        mesh.GetFaceVertexIndicesAttr().Set([i for f in faces for i in f])
        for frame, shift in enumerate(moves or [(0.0, 0.0, 0.0)]):
            pts = np.array(_box_points(lo, hi)) + offset + np.array(shift)
            mesh.GetPointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]), frame if moves else 0.0)

    cube("body", (0.0, 0.0, 0.0), (0.1, 0.1, 0.1))
    cube("chip", (0.04, 0.04, 0.04), (0.06, 0.06, 0.06), [(0.0, 0.0, 0.0), (2.5, 0.0, 0.01), (5.0, 0.0, 0.02)])
    ground = UsdGeom.Mesh.Define(stage, "/World/ground")
    quad = np.array([(-0.45, -0.45, -0.01), (0.55, -0.45, -0.01), (0.55, 0.55, -0.01), (-0.45, 0.55, -0.01)])
    ground.GetPointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in quad + offset]))
    ground.GetFaceVertexCountsAttr().Set([4])
    ground.GetFaceVertexIndicesAttr().Set([0, 1, 2, 3])
    stage.GetRootLayer().Save()
    return str(path)


def test_default_camera_frames_the_object_and_the_action_near_it(tmp_path):
    """By default (``fit="auto"``) the camera's box is the bodies' box over all frames, as far as half the rest
    pose's largest extent past the rest pose: a chip flying 5 m away leaves the picture instead of shrinking the
    10 cm body to a few pixels (the box reaches 0.15 m along the flight, 5.06 m with ``fit="all"``; 1e-4 m, float32
    points 1 km from the origin). pdsim's ground quad is left out of the box though the chip flies past its edge."""
    offset = np.array([1000.0, -2000.0, 0.0])
    path = _debris_stage(tmp_path / "debris.usda", offset)
    auto = render_cache(path, [2], size=(64, 48), ground=False)
    np.testing.assert_allclose(auto.bounds[0] - offset, [0.0, 0.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(auto.bounds[1] - offset, [0.15, 0.1, 0.1], atol=1e-4)
    whole = render_cache(path, [2], size=(64, 48), ground=False, fit="all")
    np.testing.assert_allclose(whole.bounds[0] - offset, [0.0, 0.0, 0.0], atol=1e-4)
    np.testing.assert_allclose(whole.bounds[1] - offset, [5.06, 0.1, 0.1], atol=1e-4)
    first = render_cache(path, [2], size=(64, 48), ground=False, fit="first")
    np.testing.assert_allclose(first.bounds[1] - offset, [0.1, 0.1, 0.1], atol=1e-4)
    # the body fills far more of the picture with the default camera
    assert np.linalg.norm(auto.camera.eye - auto.camera.target) < 0.1 * np.linalg.norm(
        whole.camera.eye - whole.camera.target
    )


def _falling_cube_stage(path, offset):
    """A Z-up stage 1 km from the origin (``offset``): a 10 cm cube that falls 5 m by frame 2 (no ground: a scene
    without one)."""
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    UsdGeom.Xform.Define(stage, "/World")
    mesh = UsdGeom.Mesh.Define(stage, "/World/block_surface")
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    mesh.GetFaceVertexCountsAttr().Set([4] * 6)
    mesh.GetFaceVertexIndicesAttr().Set([i for f in faces for i in f])
    for frame, drop in enumerate((0.0, 1.0, 5.0)):
        pts = np.array(_box_points((0.0, 0.0, 0.0), (0.1, 0.1, 0.1))) + offset - np.array([0.0, 0.0, drop])
        mesh.GetPointsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]), frame)
    stage.GetRootLayer().Save()
    return str(path)


def test_the_preview_says_when_the_bodies_left_the_automatic_camera(tmp_path):
    """A body that falls 5 m (a scene with no ground) leaves the default camera (the rest pose and half its size
    around it): the still of frame 2 is empty, and ``pdsim preview`` says so and names the --fit options that frame
    it; with ``--fit selected`` the frame shows the body and nothing is said."""
    import subprocess
    import sys

    path = _falling_cube_stage(tmp_path / "falling.usda", np.array([1000.0, -500.0, 0.0]))
    assert not render_cache(path, [2], size=(64, 48)).coverage[0].any()
    assert render_cache(path, [2], size=(64, 48), fit="selected").coverage[0].any()

    def preview(*options):
        out = tmp_path / "still.png"
        args = [sys.executable, "-m", "pdsim.cli", "preview", path, "--frames", "2", "--size", "64x48", "--out", out]
        done = subprocess.run([*map(str, args), *options], capture_output=True, text=True, check=True)
        return done.stdout

    said = preview()
    assert "frame 2 of" in said and "shows nothing of the bodies" in said and "--fit all" in said, said
    assert "nothing of the bodies" not in preview("--fit", "selected")
