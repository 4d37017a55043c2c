"""Tests for pdsim.output: USD animation caches (metadata, time samples, crash safety, validation)."""

from __future__ import annotations

import numpy as np
import pytest

from pdsim.output import UsdCache, validate_usd

N = 50


def _positions(frame: int, n: int = N) -> np.ndarray:
    rng = np.random.default_rng(frame)
    return rng.random((n, 3), dtype=np.float32) + np.float32(frame)


def _tetra():
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int64)
    return points, faces


def _write_cache(path, *, frames: int = 4, fps: float = 24.0, **kwargs) -> None:
    widths = np.full(N, 0.1, np.float32)
    with UsdCache(path, fps=fps, **kwargs) as cache:
        pts = cache.add_points(
            "particles", widths=widths, primvars={"damage": "float", "fragment_id": "int", "stress_dir": "vector3f"}
        )
        for f in range(frames):
            x = _positions(f)
            cache.write_points(
                pts,
                f,
                x,
                velocities=np.full((N, 3), f, np.float32),
                primvars={
                    "damage": np.full(N, f / 10, np.float32),
                    "fragment_id": np.arange(N) + f,
                    "stress_dir": np.tile(np.array([f, 0.0, 1.0]), (N, 1)),
                },
            )
            cache.end_frame(f)
        assert cache.frames_written == frames


def _open(path):
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    return stage


def test_stage_metadata(tmp_path):
    """Stage metadata: time codes per second = frames per second = fps, start/end frames, up axis, units and
    default prim."""
    from pxr import UsdGeom

    path = tmp_path / "cache.usdc"
    _write_cache(path, frames=3, fps=30.0, start_frame=0, up_axis="Y", meters_per_unit=0.01)
    stage = _open(path)
    assert stage.GetTimeCodesPerSecond() == 30.0
    assert stage.GetFramesPerSecond() == 30.0
    assert stage.GetStartTimeCode() == 0
    assert stage.GetEndTimeCode() == 2
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert stage.GetDefaultPrim().IsA(UsdGeom.Xform)
    # The file really is binary crate (the temporary file kept the extension, so Export chose the format).
    assert path.read_bytes()[:8] == b"PXR-USDC"
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"


@pytest.mark.parametrize("suffix", [".usda", ".usd"])
def test_other_formats(tmp_path, suffix):
    """.usda is written as text and .usd as crate; both read back with the frames."""
    path = tmp_path / f"cache{suffix}"
    _write_cache(path, frames=2)
    head = path.read_bytes()[:8]
    assert head.startswith(b"#usda") if suffix == ".usda" else head == b"PXR-USDC"
    stage = _open(path)
    assert stage.GetPrimAtPath("/World/particles").GetAttribute("points").GetTimeSamples() == [0.0, 1.0]


def test_points_samples_and_primvars(tmp_path):
    """One time sample per frame on points, velocities, primvars and extent; widths are a default value only."""
    from pxr import UsdGeom

    path = tmp_path / "cache.usdc"
    _write_cache(path, frames=4)
    stage = _open(path)
    pts = UsdGeom.Points(stage.GetPrimAtPath("/World/particles"))
    assert pts
    frames = [0.0, 1.0, 2.0, 3.0]
    assert pts.GetPointsAttr().GetTimeSamples() == frames
    assert pts.GetVelocitiesAttr().GetTimeSamples() == frames
    assert pts.GetExtentAttr().GetTimeSamples() == frames
    assert pts.GetWidthsAttr().GetNumTimeSamples() == 0
    np.testing.assert_allclose(np.asarray(pts.GetWidthsAttr().Get()), 0.1, rtol=1e-6)
    assert pts.GetWidthsInterpolation() == UsdGeom.Tokens.vertex
    np.testing.assert_array_equal(np.asarray(pts.GetPointsAttr().Get(2)), _positions(2))
    np.testing.assert_array_equal(np.asarray(pts.GetVelocitiesAttr().Get(3)), 3.0)

    x = _positions(1)
    extent = np.asarray(pts.GetExtentAttr().Get(1))
    np.testing.assert_allclose(extent, [x.min(0) - 0.05, x.max(0) + 0.05], rtol=1e-6)

    api = UsdGeom.PrimvarsAPI(pts)
    damage = api.GetPrimvar("damage")
    assert damage.GetInterpolation() == UsdGeom.Tokens.vertex
    assert damage.GetTypeName() == "float[]"
    np.testing.assert_allclose(np.asarray(damage.Get(2)), 0.2, rtol=1e-6)
    frag = api.GetPrimvar("fragment_id")
    assert frag.GetTypeName() == "int[]"
    np.testing.assert_array_equal(np.asarray(frag.Get(3)), np.arange(N) + 3)
    sdir = api.GetPrimvar("stress_dir")
    assert sdir.GetTypeName() == "vector3f[]"
    np.testing.assert_array_equal(np.asarray(sdir.Get(1))[0], [1.0, 0.0, 1.0])
    assert sdir.GetAttr().GetTimeSamples() == frames


def test_mesh_topology_samples_only_where_given(tmp_path):
    """Mesh points and extent are sampled every frame, topology only at the frames where faces were passed."""
    from pxr import UsdGeom

    path = tmp_path / "mesh.usdc"
    points, faces = _tetra()
    with UsdCache(path, fps=24.0, save_interval_s=0) as cache:
        mesh = cache.add_mesh("fragments 0")  # sanitized to fragments_0
        for f in range(5):
            if f == 0:
                cache.write_mesh(mesh, f, points, faces)
            elif f == 3:  # topology change: a second tetrahedron appears
                pts2 = np.concatenate([points, points + 2.0])
                cache.write_mesh(mesh, f, pts2, np.concatenate([faces, faces + 4]))
            elif f > 3:
                cache.write_mesh(mesh, f, np.concatenate([points, points + 2.0]) + f)
            else:
                cache.write_mesh(mesh, f, points + f)
            cache.end_frame(f)

    stage = _open(path)
    m = UsdGeom.Mesh(stage.GetPrimAtPath("/World/fragments_0"))
    assert m
    assert m.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    assert m.GetPointsAttr().GetTimeSamples() == [0, 1, 2, 3, 4]
    assert m.GetExtentAttr().GetTimeSamples() == [0, 1, 2, 3, 4]
    assert m.GetFaceVertexIndicesAttr().GetTimeSamples() == [0, 3]
    assert m.GetFaceVertexCountsAttr().GetTimeSamples() == [0, 3]
    assert list(m.GetFaceVertexCountsAttr().Get(2)) == [3] * 4  # held from frame 0
    assert list(m.GetFaceVertexCountsAttr().Get(4)) == [3] * 8
    np.testing.assert_array_equal(np.asarray(m.GetFaceVertexIndicesAttr().Get(1)), faces.reshape(-1))
    np.testing.assert_allclose(np.asarray(m.GetExtentAttr().Get(2)), [[2, 2, 2], [3, 3, 3]])
    assert validate_usd(path) == []


def test_validate_written_cache_is_clean(tmp_path):
    """A cache written by UsdCache passes every registered UsdValidation validator."""
    path = tmp_path / "cache.usdc"
    _write_cache(path, frames=3)
    assert validate_usd(path) == []


def test_validate_reports_broken_stage(tmp_path):
    """validate_usd reports errors: missing stage metadata and an attribute whose type contradicts its schema."""
    path = tmp_path / "broken.usda"
    path.write_text(
        '#usda 1.0\ndef Xform "World"\n{\n    def Points "p"\n    {\n        int[] points = [1, 2, 3]\n    }\n}\n'
    )
    errors = validate_usd(path)
    text = "\n".join(errors)
    assert "AttributeTypeMismatch" in text
    assert "MissingDefaultPrim" in text
    assert "MissingUpAxisMetadata" in text
    assert "MissingMetersPerUnitMetadata" in text


def test_exception_inside_with_keeps_finished_frames(tmp_path):
    """An exception after 3 finished frames leaves a readable cache of frames 0, 1, 2; the unfinished frame 3 is
    dropped even though it was partly written."""
    path = tmp_path / "crash.usdc"
    widths = np.full(N, 0.1, np.float32)
    with pytest.raises(RuntimeError, match="solver blew up"), UsdCache(path, fps=24.0, save_interval_s=3600.0) as cache:
        pts = cache.add_points("particles", widths=widths, primvars={"damage": "float"})
        for f in range(10):
            cache.write_points(pts, f, _positions(f), primvars={"damage": np.zeros(N)})
            if f == 3:
                raise RuntimeError("solver blew up")
            cache.end_frame(f)
    assert cache.frames_written == 3
    stage = _open(path)
    assert stage.GetEndTimeCode() == 2
    prim = stage.GetPrimAtPath("/World/particles")
    assert prim.GetAttribute("points").GetTimeSamples() == [0.0, 1.0, 2.0]
    assert prim.GetAttribute("primvars:damage").GetTimeSamples() == [0.0, 1.0, 2.0]
    cache.close()  # idempotent
    assert validate_usd(path) == []


def test_keyboard_interrupt_saves(tmp_path):
    """KeyboardInterrupt (Ctrl-C) inside the with block still saves the finished frames and is re-raised."""
    path = tmp_path / "ctrlc.usdc"
    with pytest.raises(KeyboardInterrupt), UsdCache(path, fps=24.0, save_interval_s=3600.0) as cache:
        pts = cache.add_points("particles", widths=np.ones(N), primvars={})
        cache.write_points(pts, 0, _positions(0))
        cache.end_frame(0)
        raise KeyboardInterrupt
    stage = _open(path)
    assert stage.GetPrimAtPath("/World/particles").GetAttribute("points").GetTimeSamples() == [0.0]


def test_file_complete_after_every_end_frame(tmp_path):
    """With save_interval_s=0 the file at path holds every finished frame right after each end_frame."""
    from pxr import Sdf

    path = tmp_path / "live.usdc"
    cache = UsdCache(path, fps=24.0, start_frame=10, save_interval_s=0)
    pts = cache.add_points("particles", widths=np.ones(N), primvars={"damage": "float"})
    assert not path.exists()  # nothing on disk before the first finished frame
    for i, f in enumerate(range(10, 15)):
        cache.write_points(pts, f, _positions(f), primvars={"damage": np.full(N, i)})
        cache.end_frame(f)
        # Read the file fresh (not from the layer registry) to see what is on disk.
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
        assert layer.startTimeCode == 10
        assert layer.endTimeCode == f
        assert layer.ListTimeSamplesForPath("/World/particles.points") == list(range(10, f + 1))
        assert cache.frames_written == i + 1
    cache.close()
    cache.close()
    assert not list(tmp_path.glob(".*tmp*"))


def test_save_throttled_by_interval(tmp_path):
    """With a long save interval nothing reaches the disk until close()."""
    path = tmp_path / "slow.usdc"
    cache = UsdCache(path, fps=24.0, save_interval_s=3600.0)
    pts = cache.add_points("particles", widths=np.ones(N), primvars={})
    for f in range(3):
        cache.write_points(pts, f, _positions(f))
        cache.end_frame(f)
    assert not path.exists()
    cache.close()
    assert _open(path).GetEndTimeCode() == 2


def test_bad_shapes_raise(tmp_path):
    """Wrong shapes, non-finite values, undeclared primvars and finished frames raise ValueError with a clear
    message."""
    cache = UsdCache(tmp_path / "bad.usdc", fps=24.0)
    pts = cache.add_points("particles", widths=np.ones(N), primvars={"damage": "float", "fragment_id": "int"})
    good = _positions(0)
    with pytest.raises(ValueError, match=r"positions has shape \[50, 2\]; expected \[point_count, 3\] = \[50, 3\]"):
        cache.write_points(pts, 0, good[:, :2])
    with pytest.raises(ValueError, match=r"positions has shape \[49, 3\]"):
        cache.write_points(pts, 0, good[:-1])
    with pytest.raises(ValueError, match=r"velocities has shape \[50\]"):
        cache.write_points(pts, 0, good, velocities=np.zeros(N))
    bad = good.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions .*non-finite"):
        cache.write_points(pts, 0, bad)
    with pytest.raises(ValueError, match=r"primvar 'damage' has shape \[50, 1\]; expected \[point_count\] = \[50\]"):
        cache.write_points(pts, 0, good, primvars={"damage": np.zeros((N, 1))})
    with pytest.raises(ValueError, match="primvar 'fragment_id' must hold integers"):
        cache.write_points(pts, 0, good, primvars={"fragment_id": np.zeros(N)})
    with pytest.raises(ValueError, match="not declared"):
        cache.write_points(pts, 0, good, primvars={"plastic_strain": np.zeros(N)})
    with pytest.raises(ValueError, match=r"widths has shape \[2, 2\]"):
        cache.add_points("p2", widths=np.ones((2, 2)), primvars={})
    with pytest.raises(ValueError, match="kind"):
        cache.add_points("p3", widths=np.ones(2), primvars={"x": "double"})
    with pytest.raises(ValueError, match="already used"):
        cache.add_points("particles", widths=np.ones(2), primvars={})

    mesh = cache.add_mesh("surface")
    points, faces = _tetra()
    with pytest.raises(ValueError, match="first call must pass faces"):
        cache.write_mesh(mesh, 0, points)
    with pytest.raises(ValueError, match=r"faces has shape \[4, 4\]; expected \[triangle_count, 3\]"):
        cache.write_mesh(mesh, 0, points, np.zeros((4, 4), int))
    with pytest.raises(ValueError, match="outside"):
        cache.write_mesh(mesh, 0, points, faces + 1)
    cache.write_mesh(mesh, 0, points, faces)
    with pytest.raises(ValueError, match="pass faces when the vertex count changes"):
        cache.write_mesh(mesh, 1, points[:3])

    cache.write_points(pts, 0, good)
    cache.end_frame(0)
    with pytest.raises(ValueError, match="not after the last finished frame"):
        cache.write_points(pts, 0, good)
    with pytest.raises(ValueError, match="not after the last finished frame"):
        cache.end_frame(0)
    cache.close()
    with pytest.raises(RuntimeError, match="closed"):
        cache.write_points(pts, 1, good)


def test_constructor_rejects_bad_parameters(tmp_path):
    """Bad fps, up axis, units, interval or extension raise ValueError."""
    with pytest.raises(ValueError, match="fps"):
        UsdCache(tmp_path / "a.usdc", fps=0.0)
    with pytest.raises(ValueError, match="up_axis"):
        UsdCache(tmp_path / "a.usdc", fps=24.0, up_axis="X")
    with pytest.raises(ValueError, match="meters_per_unit"):
        UsdCache(tmp_path / "a.usdc", fps=24.0, meters_per_unit=-1.0)
    with pytest.raises(ValueError, match="save_interval_s"):
        UsdCache(tmp_path / "a.usdc", fps=24.0, save_interval_s=-1.0)
    with pytest.raises(ValueError, match="must end in"):
        UsdCache(tmp_path / "a.abc", fps=24.0)


def test_import_is_light():
    """Importing pdsim.output does not import pxr (checked in a fresh interpreter)."""
    import subprocess
    import sys
    from pathlib import Path

    code = "import sys, pdsim.output; assert 'pxr' not in sys.modules, 'pxr imported'"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).resolve().parents[1])
