"""CI smoke test of the gallery: every scene of scenes/ (a script defining build_scene; scenes/lattice_paper.py is the
lattice cases' library) runs at its preview resolution (its ``PREVIEW`` keyword arguments of build_scene) for two
frames into a cache that passes pxr.UsdValidation (pdsim.output.usd_files.usd_problems) and reads back with finite
points on every frame.

tools/make_gallery.py runs the same scenes for all their preview frames and renders docs/gallery.md.
"""

from __future__ import annotations

import importlib.util
import os
import sys

import numpy as np
import pytest

SCENES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scenes")
LIBRARIES = {"lattice_paper"}
FRAMES = 2


def _scene_names() -> list[str]:
    names = []
    for f in sorted(os.listdir(SCENES)):
        name, ext = os.path.splitext(f)
        if ext == ".py" and name not in LIBRARIES and not name.startswith("_"):
            with open(os.path.join(SCENES, f), encoding="utf-8") as fh:
                if "build_scene" in fh.read():
                    names.append(name)
    return names


def _load(name: str):
    if SCENES not in sys.path:
        sys.path.insert(0, SCENES)  # as when a scene runs on its own: lattice scenes import lattice_paper
    spec = importlib.util.spec_from_file_location(f"gallery_scene_{name}", os.path.join(SCENES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_gallery_holds_the_issue_scenes():
    """The scenes the gallery promises are there (at least ten), and each declares its preview settings."""
    names = _scene_names()
    for required in (
        "four_walls",
        "ductile_bar",
        "glass_pane",
        "plank_grain",
        "metal_dent_tear",
        "drop_shatter",
        "fem_slab_crack",
        "fem_plastic_bar",
        "mixed_methods",
        "lattice_3d_tear",
    ):
        assert required in names
    assert len(names) >= 10
    assert "lattice_paper" not in names


@pytest.mark.parametrize("name", _scene_names())
def test_scene_runs_at_preview_resolution(name, tmp_path):
    """build_scene(**PREVIEW) runs FRAMES frames on the CPU; the cache validates (no UsdValidation error), holds the
    time codes 0..FRAMES with their simulated times, and every Points / Mesh prim has finite points at each of them;
    the scene's docstring says what it shows and how to run it."""
    from pxr import Usd, UsdGeom

    from pdsim.output.usd_files import usd_problems

    module = _load(name)
    assert isinstance(getattr(module, "PREVIEW", None), dict), f"scenes/{name}.py defines no PREVIEW dict"
    doc = module.__doc__ or ""
    assert len(doc.split()) > 15 and "Run:" in doc, f"scenes/{name}.py: docstring lacks what it shows or Run:"
    scene = module.build_scene(**module.PREVIEW)
    out = tmp_path / f"{name}.usdc"
    report = scene.run(out, frames=FRAMES, device="cpu", progress=False, checkpoint_interval_s=None)
    assert report.frames_written == FRAMES + 1

    assert usd_problems(out) == []
    stage = Usd.Stage.Open(str(out))
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == FRAMES
    geometry = [p for p in stage.Traverse() if p.IsA(UsdGeom.Points) or p.IsA(UsdGeom.Mesh)]
    assert geometry, "the cache holds no Points or Mesh prim"
    for prim in geometry:
        attr = UsdGeom.PointBased(prim).GetPointsAttr()
        for frame in range(FRAMES + 1):
            points = np.asarray(attr.Get(frame))
            assert points.ndim == 2 and len(points) > 0, (prim.GetPath(), frame)
            assert np.all(np.isfinite(points)), (prim.GetPath(), frame)
    times = stage.GetPrimAtPath("/World").GetAttribute("pdsim:time")
    assert times.Get(0) == 0.0 and times.Get(FRAMES) == pytest.approx(FRAMES * scene.frame_time)
