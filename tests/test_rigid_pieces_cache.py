"""Rigid fragments of the hand-off (pdsim/peridynamics/handoff.py) in the cache: each one a rigid piece
``/World/<body>_pieces/piece_<id>``, a static mesh in its body frame under a transform sampled every frame, with
``pdsim:velocity`` and ``pdsim:angularVelocity`` (docs/cache_format.md), hidden before it appears; the body's surface
loses those faces. Also: a shot with a dynamic ball and rigid pieces imports through Blender (``bpy``) with every
frame, the pieces move, and their transforms are sampled between frames (what Cycles' motion blur reads).

The scene is tests/test_rigid_handoff.py's notched block thrown spinning at the ground: its two halves go rigid in
flight (frame 2) and land."""

from __future__ import annotations

import json
import subprocess
import textwrap

import numpy as np
import pytest
from test_cache_pack import _blender_python
from test_rigid_handoff import SPACING, _pieces

from pdsim.peridynamics.handoff import quat_matrix
from pdsim.rigid import SphereShape

FRAMES = 8
BLENDER = _blender_python()


def _read(path) -> dict:
    """The cache read with usd-core: per piece its translations, orientations (x, y, z, w), velocities, angular
    velocities and visibility per frame, its rest points and face count; the surface's face count per frame; the
    block's particle positions and fragment ids per frame."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    end = int(stage.GetEndTimeCode())
    frames = range(end + 1)
    out = {"fps": stage.GetTimeCodesPerSecond(), "pieces": {}}
    group = stage.GetPrimAtPath("/World/block_pieces")
    for prim in group.GetChildren() if group else []:
        q = [prim.GetAttribute("xformOp:orient").Get(f) for f in frames]
        out["pieces"][prim.GetName()] = {
            "translate": np.array([list(prim.GetAttribute("xformOp:translate").Get(f)) for f in frames]),
            "orient": np.array([[*q_.GetImaginary(), q_.GetReal()] for q_ in q]),
            "velocity": np.array([list(prim.GetAttribute("pdsim:velocity").Get(f) or (np.nan,) * 3) for f in frames]),
            "angular": np.array(
                [list(prim.GetAttribute("pdsim:angularVelocity").Get(f) or (np.nan,) * 3) for f in frames]
            ),
            "visible": [UsdGeom.Imageable(prim).ComputeVisibility(f) != UsdGeom.Tokens.invisible for f in frames],
            "points": np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64),
            "faces": len(UsdGeom.Mesh(prim).GetFaceVertexCountsAttr().Get()),
            "crack": len(prim.GetChild("crack").GetAttribute("indices").Get()),
        }
    surface = UsdGeom.Mesh(stage.GetPrimAtPath("/World/block_surface"))
    out["surface_faces"] = [len(surface.GetFaceVertexCountsAttr().Get(f) or []) for f in frames]
    crack = stage.GetPrimAtPath("/World/block_surface/crack").GetAttribute("indices")
    out["surface_crack"] = [len(crack.Get(f) or []) for f in frames]
    block = stage.GetPrimAtPath("/World/block")
    xf = UsdGeom.XformCache()
    out["particles"], out["fragment"] = [], []
    for f in frames:
        xf.SetTime(f)
        m = np.array(xf.GetLocalToWorldTransform(block), dtype=np.float64)
        p = np.array(UsdGeom.Points(block).GetPointsAttr().Get(f), dtype=np.float64)
        out["particles"].append(p @ m[:3, :3] + m[3, :3])
        out["fragment"].append(np.array(UsdGeom.PrimvarsAPI(block).GetPrimvar("fragment").Get(f)))
    return out


@pytest.fixture(scope="module")
def pieces_cache(tmp_path_factory):
    path = tmp_path_factory.mktemp("pieces") / "pieces.usdc"
    _pieces(frames=FRAMES).run(path, device="cpu", progress=False, checkpoint_interval_s=None)
    return _read(path)


def _rotation_angle(qa, qb) -> float:
    """The angle [rad] of the rotation from unit quaternion qa to qb (x, y, z, w)."""
    return 2.0 * float(np.arccos(min(1.0, abs(float(np.dot(qa, qb))))))


def test_rigid_fragments_are_written_as_pieces_with_transforms_and_velocities(pieces_cache):
    """Two pieces (the halves), hidden before the hand-off frame and shown from it on; they take every face of the
    surface (the surface's face count before equals the pieces' total, and the surface has none left), their crack
    faces in their ``crack`` subset (as many as the surface had); from the
    hand-off on, pdsim:velocity equals the central difference of the translation (per played second, 1 % of the
    speed) and |pdsim:angularVelocity| the rate of turn of the orientation (degrees per played second, 2 %), over
    the frames in flight."""
    c = pieces_cache
    assert len(c["pieces"]) == 2
    first = {name: p["visible"].index(True) for name, p in c["pieces"].items()}
    assert len(set(first.values())) == 1
    hand = next(iter(first.values()))
    assert 0 < hand < FRAMES - 3
    for p in c["pieces"].values():
        assert not any(p["visible"][:hand]) and all(p["visible"][hand:])
    assert c["surface_faces"][hand - 1] == sum(p["faces"] for p in c["pieces"].values()) > 0
    assert c["surface_faces"][hand:] == [0] * (FRAMES + 1 - hand)
    assert c["surface_crack"][hand - 1] == sum(p["crack"] for p in c["pieces"].values()) > 0
    fps = c["fps"]
    for p in c["pieces"].values():
        for f in (hand + 1, hand + 2):
            central = 0.5 * (p["translate"][f + 1] - p["translate"][f - 1]) * fps
            assert np.linalg.norm(p["velocity"][f] - central) < 0.01 * np.linalg.norm(central)
            turn = np.degrees(_rotation_angle(p["orient"][f - 1], p["orient"][f + 1])) * 0.5 * fps
            assert abs(np.linalg.norm(p["angular"][f]) - turn) < 0.02 * turn and turn > 10.0


def test_rigid_pieces_ride_their_particles(pieces_cache):
    """At the last frame each piece's mesh, placed by its transform, encloses its fragment's particles (all inside
    its bounding box, 1e-4 m) and its bounding box is centred on theirs (1e-4 m, h/100); placed by the hand-off
    frame's transform instead it misses them by more than h (so the pose matters)."""
    c = pieces_cache
    last = FRAMES
    x, frag = c["particles"][last], c["fragment"][last]
    for name, p in c["pieces"].items():
        mine = x[frag == int(name.split("_")[1])]
        assert len(mine) > 0
        hand = p["visible"].index(True)
        for f, ok in ((last, True), (hand, False)):
            world = p["points"] @ quat_matrix(p["orient"][f]).T + p["translate"][last if ok else f]
            inside = np.all((mine >= world.min(0) - 1e-4) & (mine <= world.max(0) + 1e-4))
            near = np.linalg.norm(world.min(0) + world.max(0) - mine.min(0) - mine.max(0)) / 2
            if ok:
                assert inside and near < 0.01 * SPACING, (name, near)
            else:
                assert near > SPACING, (name, near)


BLENDER_IMPORT = textwrap.dedent(
    """
    import json, sys
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=sys.argv[1]) == {"FINISHED"}
    scene = bpy.context.scene
    out = {"range": [scene.frame_start, scene.frame_end], "objects": {}}
    names = [ob.name for ob in scene.objects if ob.name.startswith("piece_") or ob.name == "ball"]
    for name in names:
        ob = bpy.data.objects[name]
        out["objects"][name] = {"constraints": [c.type for c in ob.constraints], "location": [], "half": []}
    for frame in range(scene.frame_start, scene.frame_end + 1):
        for sub, key in ((0.0, "location"), (0.5, "half")):
            scene.frame_set(frame, subframe=sub)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            for name in names:
                m = bpy.data.objects[name].evaluated_get(depsgraph).matrix_world
                out["objects"][name][key].append(list(m.translation))
    print("RESULT " + json.dumps(out))
    """
)


@pytest.mark.skipif(
    BLENDER is None, reason="bpy is not installed (or PDSIM_BLENDER_PYTHON names no interpreter with it)"
)
def test_blender_imports_a_ball_and_rigid_pieces_moving_with_transforms_between_frames(tmp_path):
    """A dynamic rigid ball (Scene.add_rigid_body) falling beside the pieces: bpy's USD import reads frames
    0..FRAMES; the ball and both pieces are objects driven by a Transform Cache constraint, at the cache's
    translation on every frame from the pieces' hand-off on (1e-5 m); the pieces move (more than 1 cm); between two
    frames (subframe 0.5) a piece's transform lies between its poses at the two frames (what Cycles samples over
    the shutter for motion blur)."""
    from pxr import Usd

    scene = _pieces(frames=FRAMES)
    scene.add_rigid_body(SphereShape(0.01), density=7850.0, position=(0.15, 0.0, 0.05), name="ball")
    out = tmp_path / "shot.usdc"
    scene.run(out, device="cpu", progress=False, checkpoint_interval_s=None)
    done = subprocess.run(
        [BLENDER, "-c", BLENDER_IMPORT, str(out)], capture_output=True, text=True, timeout=600, check=False
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    result = json.loads(done.stdout.split("RESULT ", 1)[1].splitlines()[0])
    assert result["range"] == [0, FRAMES]
    objects = result["objects"]
    stage = Usd.Stage.Open(str(out))
    pieces = [p.GetName() for p in stage.GetPrimAtPath("/World/block_pieces").GetChildren()]
    assert len(pieces) == 2 and set(pieces) | {"ball"} <= set(objects)
    ball = np.array(objects["ball"]["location"])
    assert ball[0][2] - ball[-1][2] > 0.5 * 9.81 * (FRAMES * 5.0e-3) ** 2 * 0.9  # it falls
    for name in pieces:
        o = objects[name]
        assert "TRANSFORM_CACHE" in o["constraints"], o["constraints"]
        prim = stage.GetPrimAtPath(f"/World/block_pieces/{name}")
        translate = prim.GetAttribute("xformOp:translate")
        visible = [prim.GetAttribute("visibility").Get(f) != "invisible" for f in range(FRAMES + 1)]
        hand = visible.index(True)
        loc, half = np.array(o["location"]), np.array(o["half"])
        for f in range(hand, FRAMES + 1):
            assert loc[f] == pytest.approx(list(translate.Get(f)), abs=1e-5)
        assert np.linalg.norm(loc[FRAMES] - loc[hand]) > 0.01
        for f in range(hand, FRAMES):
            step = loc[f + 1] - loc[f]
            assert np.linalg.norm(half[f] - loc[f] - 0.5 * step) < 0.05 * np.linalg.norm(step) + 1e-6
