"""Dynamic rigid bodies in the cache: a transform over the body's rest mesh, sampled every frame, with the body's
velocity and angular velocity (docs/cache_format.md); the cache imports through Blender (``bpy``) with the ball
moving over the frames. Also: a run with a rigid body resumes from its checkpoint bit for bit."""

from __future__ import annotations

import json
import subprocess
import textwrap

import numpy as np
import pytest
from test_cache_pack import _blender_python

import pdsim
from pdsim.rigid import SphereShape

FRAMES = 4
V0 = 10.0  # m/s


def _scene():
    """A steel ball at 10 m/s into a small elastic block, in space; 4 frames of 2 ms."""
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0), fps=24, frames=FRAMES, frame_time=2.0e-3, name="rigid")
    material = pdsim.Material(density=2400.0, youngs_modulus=3.0e7, poisson_ratio=0.2, name="elastic")
    scene.add_peridynamic_body(pdsim.box((0.1, 0.1, 0.1)), material, 0.025, name="block")
    scene.add_rigid_body(
        SphereShape(0.02),
        density=7850.0,
        position=(-0.12, 0.0, 0.0),
        velocity=(V0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 3.0),
        name="ball",
    )
    return scene


def test_a_rigid_body_is_written_as_a_transform_with_its_velocities(tmp_path):
    """/World/colliders/ball: the rest mesh once, xformOp:translate and orient every frame (the ball moves by its
    velocity, 2 cm per frame before it touches the block, and a new pose every frame), pdsim:velocity [m/s per
    played second: x frame_time x fps] and pdsim:angularVelocity [degrees per played second] every frame, the last
    one slowed by the block."""
    from pxr import Usd, UsdGeom

    out = tmp_path / "rigid.usdc"
    _scene().run(out, progress=False, checkpoint_interval_s=None)
    stage = Usd.Stage.Open(str(out))
    prim = stage.GetPrimAtPath("/World/colliders/ball")
    assert prim and prim.IsA(UsdGeom.Mesh)
    translate = prim.GetAttribute("xformOp:translate")
    xs = [np.asarray(translate.Get(f)) for f in range(FRAMES + 1)]
    assert xs[0] == pytest.approx([-0.12, 0.0, 0.0], abs=1e-12)
    assert xs[1][0] - xs[0][0] == pytest.approx(V0 * 2.0e-3, rel=1e-6)
    scale = 2.0e-3 * 24.0
    assert len({tuple(x) for x in xs}) == FRAMES + 1  # a new pose every frame
    assert np.asarray(prim.GetAttribute("pdsim:velocity").Get(FRAMES))[0] < V0 * scale * 0.9  # the block slowed it
    v = np.asarray(prim.GetAttribute("pdsim:velocity").Get(1))
    assert v == pytest.approx([V0 * scale, 0.0, 0.0], rel=1e-6, abs=1e-9)
    w = np.asarray(prim.GetAttribute("pdsim:angularVelocity").Get(1))
    assert w == pytest.approx([0.0, 0.0, np.degrees(3.0) * scale], rel=1e-5, abs=1e-9)
    points = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(0))
    assert np.linalg.norm(points, axis=1).max() == pytest.approx(0.02, rel=1e-6)
    assert len(prim.GetAttribute("xformOp:orient").GetTimeSamples()) == FRAMES + 1


def _ball_samples(stage) -> dict:
    """{attribute name: [its value at each frame 0..FRAMES]} of the time-sampled attributes of /World/colliders/ball
    (quaternions as (x, y, z, w))."""
    out = {}
    for attr in stage.GetPrimAtPath("/World/colliders/ball").GetAttributes():
        if attr.GetNumTimeSamples() == 0:
            continue
        values = [attr.Get(f) for f in range(FRAMES + 1)]
        if hasattr(values[0], "GetReal"):
            values = [[*q.GetImaginary(), q.GetReal()] for q in values]
        out[attr.GetName()] = [np.asarray(v, dtype=np.float64) for v in values]
    return out


def test_each_frame_holds_the_rigid_body_state_of_that_frame(tmp_path):
    """The pose, velocity and angular velocity written for frame f are the ball's state at the end of frame f (read
    by ``on_frame``), for every frame, with the frame written while the next one simulates (the surface thread, the
    default): the written values are copies, not views of the live state, which the CPU's ``numpy()`` returns. The
    ball hits the block in frame 3, so a value written one frame late differs."""
    from pxr import Usd

    scene = _scene()
    ball = scene.colliders[0]
    seen = {}

    def on_frame(frame, solvers):
        seen[frame] = ball.state_values()

    scene.run(tmp_path / "r.usdc", progress=False, checkpoint_interval_s=None, on_frame=on_frame)
    samples = _ball_samples(Usd.Stage.Open(str(tmp_path / "r.usdc")))
    scale = 2.0e-3 * 24.0  # frame_time x fps: the cache's velocities are per played second
    assert sorted(seen) == list(range(1, FRAMES + 1))
    for f, s in seen.items():
        assert samples["xformOp:translate"][f] == pytest.approx(s["position"], abs=1e-12)
        assert samples["xformOp:orient"][f] == pytest.approx(s["orientation"], abs=1e-6)
        assert samples["pdsim:velocity"][f] == pytest.approx(s["velocity"] * scale, rel=1e-6, abs=1e-9)
        omega = np.degrees(s["angular_velocity"]) * scale
        assert samples["pdsim:angularVelocity"][f] == pytest.approx(omega, rel=1e-5, abs=1e-6)
    assert not np.allclose(seen[3]["velocity"], seen[2]["velocity"])  # the hit is in frame 3


def test_a_run_with_a_rigid_body_resumes_bit_for_bit(tmp_path):
    """Stopped after frame 2 (its checkpoint) and resumed: every attribute of the ball at every frame and the
    block's points of the last frame equal those of an uninterrupted run, bit for bit."""
    from pxr import Usd

    whole = tmp_path / "whole.usdc"
    _scene().run(whole, progress=False, checkpoint_interval_s=None)
    part = tmp_path / "part.usdc"

    class Stop:
        requested, signal = False, 15

    stop = Stop()

    def on_frame(frame, solvers):
        stop.requested = frame == 2

    with pytest.raises(KeyboardInterrupt):
        _scene().run(part, progress=False, checkpoint_interval_s=0.0, stop=stop, on_frame=on_frame, layout="clips")
    _scene().run(part, progress=False, resume=True, checkpoint_interval_s=0.0, layout="clips")
    a, b = Usd.Stage.Open(str(whole)), Usd.Stage.Open(str(part))
    ball_a, ball_b = _ball_samples(a), _ball_samples(b)
    assert {"xformOp:translate", "xformOp:orient", "pdsim:velocity", "pdsim:angularVelocity"} <= set(ball_a)
    assert set(ball_a) == set(ball_b)
    for name, values in ball_a.items():
        for f in range(FRAMES + 1):
            assert np.array_equal(values[f], ball_b[name][f]), (name, f)
    va = np.asarray(a.GetPrimAtPath("/World/block").GetAttribute("points").Get(FRAMES))
    vb = np.asarray(b.GetPrimAtPath("/World/block").GetAttribute("points").Get(FRAMES))
    assert np.array_equal(va, vb)


BLENDER = _blender_python()

IMPORT = textwrap.dedent(
    """
    import json, sys
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=sys.argv[1]) == {"FINISHED"}
    scene = bpy.context.scene
    out = {"range": [scene.frame_start, scene.frame_end], "location": []}
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ob = bpy.data.objects["ball"]
        out["location"].append(list(ob.evaluated_get(depsgraph).matrix_world.translation))
    print("RESULT " + json.dumps(out))
    """
)


@pytest.mark.skipif(
    BLENDER is None, reason="bpy is not installed (or PDSIM_BLENDER_PYTHON names no interpreter with it)"
)
def test_blender_imports_the_rigid_ball_moving_over_every_frame(tmp_path):
    """bpy's USD import: frames 0..4, the ball object at the cache's translation on every frame (1e-5 m)."""
    from pxr import Usd

    out = tmp_path / "rigid.usdc"
    _scene().run(out, progress=False, checkpoint_interval_s=None)
    done = subprocess.run([BLENDER, "-c", IMPORT, str(out)], capture_output=True, text=True, timeout=600, check=True)
    result = json.loads(done.stdout.split("RESULT ", 1)[1].splitlines()[0])
    assert result["range"] == [0, FRAMES]
    stage = Usd.Stage.Open(str(out))
    translate = stage.GetPrimAtPath("/World/colliders/ball").GetAttribute("xformOp:translate")
    for frame, location in enumerate(result["location"]):
        assert location == pytest.approx(list(translate.Get(frame)), abs=1e-5)
    assert max(abs(x[0] - result["location"][0][0]) for x in result["location"]) > 0.02  # it moves
