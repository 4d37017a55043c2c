"""A cache you can send anywhere (docs/cache_format.md): the default one-file layout, the clip layout, `pdsim pack`,
the refusal of a clip cache whose folder is missing, and exact placement far from the origin.

- The default scene's `.usdc`, copied alone to another folder, opens through `pxr` with every frame and every body's
  points, imports through `bpy` (Blender as a Python module, in the interpreter `PDSIM_BLENDER_PYTHON` names, else
  this one; skipped when none has bpy) with every frame, and `pdsim preview` renders it.
- A clip-layout cache with its folder removed makes `pdsim preview` exit non-zero with a one-line message naming the
  folder to copy; `pdsim pack` packs a clip cache into a file that plays every attribute as the clip cache does.
- Packing refuses cleanly (one line) when the disk has too little room, and the earlier cache stays byte for byte.
- A body at x = 1e6 m: its cache points (world space through the prim's double transform) match the same body at the
  origin, shifted, within 1e-4 m.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from test_resume_cache import _as_comparable, _pd_bar

from pdsim import cli
from pdsim.output import usd_pack
from pdsim.output.usd_files import CacheError, world_points

FRAMES = 3


def _default_cache(folder: Path, *extra: str) -> Path:
    """The default scene (the shipped cantilever) run for FRAMES frames into ``folder``/shot.usdc by the CLI."""
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / "shot.usdc"
    code = cli.main(["run", "--frames", str(FRAMES), "--out", str(out), "--device", "cpu", "--quiet", *extra])
    assert code == 0
    return out


def _blender_python() -> str | None:
    """An interpreter with bpy: $PDSIM_BLENDER_PYTHON (Blender in a venv of its own), or this one; None when none."""
    exe = os.environ.get("PDSIM_BLENDER_PYTHON")
    if exe and os.access(exe, os.X_OK):
        probe = subprocess.run([exe, "-c", "import bpy"], check=False, capture_output=True, timeout=120)
        if probe.returncode == 0:
            return exe
    return sys.executable if importlib.util.find_spec("bpy") is not None else None


BLENDER_IMPORT = textwrap.dedent(
    """
    import json, sys
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=sys.argv[1], import_guide=True) == {"FINISHED"}  # the points are guides
    scene = bpy.context.scene
    counts = {}
    for frame in range(scene.frame_start, scene.frame_end + 1):
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        for ob in scene.objects:
            if ob.type == "POINTCLOUD":
                data = ob.evaluated_get(depsgraph).data
                xf = ob.evaluated_get(depsgraph).matrix_world
                z = sum((xf @ p.co).z for p in data.points) / max(len(data.points), 1)
                counts.setdefault(ob.name, []).append([len(data.points), z])
    print("RESULT " + json.dumps({"range": [scene.frame_start, scene.frame_end], "points": counts}))
    """
)


def test_default_cache_travels_alone(tmp_path):
    """One file, copied alone: every frame and every body's points through pxr, `pdsim preview` renders it, and
    Blender imports every frame (when a bpy interpreter is available)."""
    from pxr import Usd, UsdGeom

    out = _default_cache(tmp_path / "a")
    assert not (tmp_path / "a" / "shot.frames").exists()
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["shot.usdc"]
    alone = tmp_path / "b" / "shot.usdc"
    alone.parent.mkdir()
    shutil.copy(out, alone)
    shutil.rmtree(tmp_path / "a")

    stage = Usd.Stage.Open(str(alone))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, FRAMES)
    bodies = [p for p in stage.Traverse() if p.IsA(UsdGeom.Points)]
    assert bodies
    for prim in bodies:
        n = len(UsdGeom.Points(prim).GetWidthsAttr().Get())
        frames = [world_points(prim, Usd.TimeCode(t)) for t in range(FRAMES + 1)]
        assert all(x.shape == (n, 3) and np.isfinite(x).all() for x in frames), prim.GetPath()
        assert np.abs(frames[-1] - frames[0]).max() > 1.0e-6  # the cantilever moves: samples, not one held value
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) and prim.GetName().endswith("_surface"):
            assert all(len(world_points(prim, Usd.TimeCode(t))) for t in range(FRAMES + 1))

    image = tmp_path / "b" / "preview.png"
    assert cli.main(["preview", str(alone), "--out", str(image), "--frames", str(FRAMES), "--size", "64x48"]) == 0
    assert image.stat().st_size > 0

    exe = _blender_python()
    if exe is None:
        pytest.skip("no interpreter with bpy (set PDSIM_BLENDER_PYTHON)")
    script = tmp_path / "blender_import.py"
    script.write_text(BLENDER_IMPORT)
    proc = subprocess.run([exe, str(script), str(alone)], check=False, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    result = json.loads(next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))[7:])
    assert result["range"] == [0, FRAMES]
    assert result["points"], result
    first = stage.GetPrimAtPath(bodies[0].GetPath())
    for series in result["points"].values():
        assert len(series) == FRAMES + 1 and all(count > 0 for count, _ in series)
    # Blender places the points where pxr does at every frame (mean height of the body [m], through the transforms)
    series = result["points"][first.GetName()]
    heights = [world_points(first, Usd.TimeCode(t))[:, 2].mean() for t in range(FRAMES + 1)]
    np.testing.assert_allclose([z for _, z in series], heights, atol=1.0e-5)
    assert abs(heights[-1] - heights[0]) > 1.0e-3  # animated: a held first frame would fail


def test_clip_cache_without_its_folder_is_refused(tmp_path, capsys):
    """`--layout clips` keeps the folder; `pdsim pack` makes one file that plays every attribute as the clip cache at
    every frame; the top-level layer copied alone makes `pdsim preview` exit non-zero naming the folder to copy."""
    from pxr import Usd, UsdGeom

    out = _default_cache(tmp_path / "a", "--layout", "clips")
    run_dirs = list((tmp_path / "a" / "shot.frames").iterdir())
    assert len(run_dirs) == 1 and run_dirs[0].is_dir()

    packed = tmp_path / "packed.usdc"
    assert cli.main(["pack", str(out), str(packed)]) == 0
    assert out.is_file() and run_dirs[0].is_dir()  # packing into another file leaves the clip cache
    clips, one = Usd.Stage.Open(str(out)), Usd.Stage.Open(str(packed))
    compared = 0
    for prim in clips.TraverseAll():
        other = one.GetPrimAtPath(prim.GetPath())
        assert other, prim.GetPath()
        for attr in prim.GetAttributes():
            for t in range(FRAMES + 1):
                a = _as_comparable(attr.Get(Usd.TimeCode(t)))
                b = _as_comparable(other.GetAttribute(attr.GetName()).Get(Usd.TimeCode(t)))
                assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, (attr.GetPath(), t)
                compared += 1
    assert compared > 100

    alone = tmp_path / "b" / "shot.usdc"
    alone.parent.mkdir()
    shutil.copy(out, alone)
    capsys.readouterr()
    code = cli.main(["preview", str(alone), "--out", str(tmp_path / "b" / "x.png"), "--size", "64x48"])
    err = capsys.readouterr().err.strip()
    assert code != 0
    assert not (tmp_path / "b" / "x.png").exists()
    assert len(err.splitlines()) == 1 and "shot.frames/" + run_dirs[0].name in err and "copy" in err, err

    # `pdsim pack CACHE` packs in place and removes the folder (and the temporary file of a killed packing)
    (tmp_path / "a" / ".shot.usdc.pack-1.tmp.usdc").write_bytes(b"partial")
    assert cli.main(["pack", str(out)]) == 0
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["shot.usdc"]
    stage = Usd.Stage.Open(str(out))
    assert stage.GetRootLayer().customLayerData["pdsim"]["layout"] == "packed"
    body = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Points))
    assert len(world_points(body, FRAMES)) > 0


def test_pack_refuses_a_full_disk_and_keeps_the_earlier_cache(tmp_path, monkeypatch):
    """With too little free space the run's packing fails with one line naming the sizes; the earlier cache at the
    same path is byte for byte as it was, the run's frames stay playable in the partial clip cache, and no temporary
    file is left."""
    out = tmp_path / "grips.usdc"
    _pd_bar(frames=1, ground=False).run(out, device="cpu", progress=False)
    before = out.read_bytes()

    monkeypatch.setattr(usd_pack, "_free_bytes", lambda folder: 1000)
    with pytest.raises(CacheError) as ei:
        _pd_bar(frames=2, ground=False).run(out, device="cpu", progress=False)
    message = str(ei.value)
    assert len(message.splitlines()) == 1 and "MB needed" in message and "0.0 MB free" in message, message
    assert out.read_bytes() == before
    partial = tmp_path / "grips.partial.usdc"
    assert partial.is_file()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    monkeypatch.undo()
    assert usd_pack.pack_cache(partial, out) == out  # packed later, as the message says
    assert out.read_bytes() != before and _end(out) == 2


def _end(path) -> float:
    from pxr import Sdf

    return Sdf.Layer.OpenAsAnonymous(str(path)).endTimeCode


def test_exact_placement_far_from_the_origin(tmp_path):
    """The bar at x = 1e6 m: the cache's last-frame points (world space through the double transform, read with pxr)
    equal the bar's at the origin shifted by 1e6 m within 1e-4 m (float32 world positions there are rounded to
    6 cm steps). The surface mesh keeps the same precision relative to its own rest centre (its vertex count is not
    compared: the surface extraction is not translation-invariant)."""
    from pxr import Usd

    shift = np.array([1.0e6, 0.0, 0.0])
    near, far = tmp_path / "near.usdc", tmp_path / "far.usdc"
    _pd_bar(frames=2, ground=False).run(near, device="cpu", progress=False)
    _pd_bar(tuple(shift), frames=2, ground=False).run(far, device="cpu", progress=False)
    a, b = Usd.Stage.Open(str(near)), Usd.Stage.Open(str(far))
    t = Usd.TimeCode(2)
    x0 = world_points(a.GetPrimAtPath("/World/bar"), t)
    x1 = world_points(b.GetPrimAtPath("/World/bar"), t)
    assert x0.shape == x1.shape == (288, 3)
    error = np.abs(x1 - (x0 + shift)).max()
    assert error < 1.0e-4, error
    assert np.abs(x0 - x0[0]).max() > 1.0e-3  # distinct points: the test would see 6 cm rounding
    surface = b.GetPrimAtPath("/World/bar_surface")
    local = np.asarray(surface.GetAttribute("points").Get(t), dtype=np.float64)
    translate = np.asarray(surface.GetAttribute("xformOp:translate").Get(t), dtype=np.float64)
    assert abs(translate[0] - 1.0e6) < 1.0 and np.abs(local).max() < 1.0  # small float32 offsets from a double origin
    assert np.allclose(world_points(surface, t).mean(axis=0), x1.mean(axis=0), atol=0.02)


def test_pack_errors_are_one_line(tmp_path, capsys):
    """`pdsim pack` on a missing file, a file that is not USD and a cache that is already one file: exit status 1 and
    one line naming the file and what is wrong; nothing is written."""
    from pdsim.output.usd import UsdCache

    packed = tmp_path / "packed.usdc"
    with UsdCache(packed, fps=24.0, pack=True) as cache:
        handle = cache.add_points("p", widths=np.full(4, 0.1), origin=(1.0e6, 0.0, 0.0))
        for f in range(3):
            cache.write_points(handle, f, np.full((4, 3), 1.0e6 + 0.001 * f))
            cache.end_frame(f)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["packed.usdc"]
    garbage = tmp_path / "garbage.usdc"
    garbage.write_text("not usd")
    cases = {
        tmp_path / "none.usdc": "no cache at",
        garbage: "is not a USD layer",
        packed: "already one self-contained file",
    }
    for path, message in cases.items():
        capsys.readouterr()
        assert cli.main(["pack", str(path)]) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and message in err and path.name in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["garbage.usdc", "packed.usdc"]
