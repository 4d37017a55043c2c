"""Tests for pdsim.output: USD animation caches (metadata, time samples, crash safety, validation)."""

from __future__ import annotations

import numpy as np
import pytest

from pdsim.output.usd import UsdCache
from pdsim.output.usd_files import usd_problems

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
    assert not list(tmp_path.rglob(".*tmp*")), "temporary file left behind"


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
    assert usd_problems(path) == []


def test_validate_written_cache_is_clean(tmp_path):
    """A cache written by UsdCache passes every registered UsdValidation validator."""
    path = tmp_path / "cache.usdc"
    _write_cache(path, frames=3)
    assert usd_problems(path) == []


def test_validate_reports_broken_stage(tmp_path):
    """usd_problems reports errors: missing stage metadata and an attribute whose type contradicts its schema."""
    path = tmp_path / "broken.usda"
    path.write_text(
        '#usda 1.0\ndef Xform "World"\n{\n    def Points "p"\n    {\n        int[] points = [1, 2, 3]\n    }\n}\n'
    )
    errors = usd_problems(path)
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
    assert usd_problems(path) == []


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


def _fresh_stage(path):
    """The stage at ``path`` as it is on disk now (layers reloaded, not taken stale from the layer registry)."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    stage.Reload()
    return stage


def test_file_complete_after_every_end_frame(tmp_path):
    """With save_interval_s=0 (the default) the cache at path plays every finished frame right after each end_frame:
    the top-level layer names the frame layers written so far, each frame layer holds its own frame only."""
    from pxr import Sdf

    path = tmp_path / "live.usdc"
    cache = UsdCache(path, fps=24.0, start_frame=10)
    pts = cache.add_points("particles", widths=np.ones(N), primvars={"damage": "float"})
    assert not path.exists()  # nothing on disk before the first finished frame
    for i, f in enumerate(range(10, 15)):
        cache.write_points(pts, f, _positions(f), primvars={"damage": np.full(N, i)})
        cache.end_frame(f, time=0.5 * i)
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
        assert layer.startTimeCode == 10
        assert layer.endTimeCode == f
        frame_layer = Sdf.Layer.OpenAsAnonymous(str(cache.run_dir / f"frame.{f:06d}.usdc"))
        assert frame_layer.ListTimeSamplesForPath("/World/particles.points") == [f]
        stage = _fresh_stage(path)
        attr = stage.GetPrimAtPath("/World/particles").GetAttribute("points")
        assert attr.GetTimeSamples() == list(range(10, f + 1))
        np.testing.assert_array_equal(np.asarray(attr.Get(f)), _positions(f))
        assert stage.GetPrimAtPath("/World").GetAttribute("pdsim:time").Get(f) == 0.5 * i
        del stage
        assert cache.frames_written == i + 1
    cache.close()
    cache.close()
    assert not list(tmp_path.rglob(".*tmp*"))


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


# ------------------------------------------------------------------------------------------- streamed layout on disk


def test_layout_on_disk_and_clip_metadata(tmp_path):
    """The cache is a top-level layer plus ``<stem>.frames/<run>/``: one frame layer per finished frame (holding that
    frame's samples only), the manifest, and one topology clip set per mesh whose clips sit at the frames where its
    faces changed. The top-level layer holds no time samples of the clip attributes; its customLayerData names the
    run and the frames folder; cache_files lists every file; flatten_cache bakes it into one self-contained layer with
    the same samples."""
    from pxr import Sdf, Usd

    from pdsim.output.usd_files import cache_files, flatten_cache

    path = tmp_path / "layout.usdc"
    points, faces = _tetra()
    with UsdCache(path, fps=24.0, metadata={"frameTime": 0.01}) as cache:
        mesh = cache.add_mesh("shell", normals="vertex")
        for f in range(4):
            if f in (0, 2):
                cache.write_mesh(mesh, f, points + f, faces, normals=np.tile([0.0, 0.0, 1.0], (4, 1)))
            else:
                cache.write_mesh(mesh, f, points + f, normals=np.tile([0.0, 0.0, 1.0], (4, 1)))
            cache.end_frame(f, time=0.01 * f)
        run_dir = cache.run_dir
    assert run_dir.parent == tmp_path / "layout.frames"
    names = sorted(p.name for p in run_dir.iterdir())
    assert names == [
        "frame.000000.usdc",
        "frame.000001.usdc",
        "frame.000002.usdc",
        "frame.000003.usdc",
        "manifest.usdc",
        "topology_shell.000000.usdc",
        "topology_shell.000002.usdc",
        "topology_shell.manifest.usdc",
    ]
    top = Sdf.Layer.OpenAsAnonymous(str(path))
    assert top.ListTimeSamplesForPath("/World/shell.points") == []
    info = dict(top.customLayerData["pdsim"])
    assert info["run"] == run_dir.name and info["frames"] == f"./layout.frames/{run_dir.name}"
    assert info["frameTime"] == 0.01 and info["cacheFormat"] == 2
    clips = top.GetPrimAtPath("/World").GetInfo("clips")
    assert clips["default"]["templateAssetPath"] == f"./layout.frames/{run_dir.name}/frame.######.usdc"
    assert (clips["default"]["templateStartTime"], clips["default"]["templateEndTime"]) == (0.0, 3.0)
    assert list(clips["topology_shell"]["active"]) == [(0.0, 0.0), (2.0, 1.0)]
    frame1 = Sdf.Layer.OpenAsAnonymous(str(run_dir / "frame.000001.usdc"))
    assert frame1.ListTimeSamplesForPath("/World/shell.points") == [1.0]
    assert frame1.ListTimeSamplesForPath("/World/shell.faceVertexIndices") == []

    files = cache_files(path)
    assert files[0].name == "layout.usdc" and len(files) == 9
    stage = Usd.Stage.Open(str(path))
    m = stage.GetPrimAtPath("/World/shell")
    assert m.GetAttribute("faceVertexIndices").GetTimeSamples() == [0.0, 2.0]
    assert m.GetAttribute("points").GetTimeSamples() == [0.0, 1.0, 2.0, 3.0]
    flat = tmp_path / "flat.usdc"
    flatten_cache(path, flat)
    flat_layer = Sdf.Layer.OpenAsAnonymous(str(flat))
    assert flat_layer.ListTimeSamplesForPath("/World/shell.points") == [0.0, 1.0, 2.0, 3.0]
    np.testing.assert_array_equal(np.asarray(flat_layer.QueryTimeSample("/World/shell.points", 3.0)), points + 3)
    assert usd_problems(path) == [] and usd_problems(flat) == []


def test_memory_of_the_writer_does_not_hold_frames(tmp_path):
    """After a frame is finished, its samples are on disk and gone from memory: the writer keeps no pending frame and
    its top-level layer holds declarations only (its size does not grow with the frames)."""
    path = tmp_path / "mem.usdc"
    sizes = []
    with UsdCache(path, fps=24.0) as cache:
        pts = cache.add_points("particles", widths=np.ones(N), primvars={"damage": "float"})
        for f in range(30):
            cache.write_points(pts, f, _positions(f), velocities=np.zeros((N, 3)), primvars={"damage": np.zeros(N)})
            cache.end_frame(f)
            assert cache._pending == {}
            sizes.append(len(cache.stage.GetRootLayer().ExportToString()))
    assert sizes[-1] == sizes[0]


# ------------------------------------------------------------------------------------------------ normals and views


def _box_mesh():
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    return np.asarray(box.vertices), np.asarray(box.faces)


def _sphere_mesh():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    return np.asarray(sphere.vertices), np.asarray(sphere.faces)


def test_normals_crisp_box_smooth_sphere():
    """Normals: on a box every face corner gets its face's normal (edges of 90 degrees split the fans: crisp edges,
    and a box needs faceVarying normals); on an icosphere (dihedral angles about 12 degrees) the fans are whole vertex
    stars, vertex normals suffice and point radially (within 1 degree); a sharp_angle of 5 degrees makes the sphere
    faceted."""
    from pdsim.output.writer import _groups_are_per_vertex, _Shading, corner_normals, smoothing_groups

    v, f = _box_mesh()
    labels, count = smoothing_groups(v, f)
    assert not _groups_are_per_vertex(f, labels)
    n = corner_normals(v, f, labels, count).reshape(-1, 3, 3)
    face_n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    np.testing.assert_allclose(n, np.repeat(face_n[:, None], 3, axis=1), atol=1e-12)
    assert _Shading(v, f, 30.0, None).interpolation == "faceVarying"

    v, f = _sphere_mesh()
    shading = _Shading(v, f, 30.0, None)
    assert shading.interpolation == "vertex"
    vn = shading.normals(v)
    radial = v / np.linalg.norm(v, axis=1, keepdims=True)
    assert np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", vn, radial), -1, 1))).max() < 1.0
    assert _Shading(v, f, 5.0, None).interpolation == "faceVarying"


def test_normals_follow_deformation_with_fixed_fans():
    """The fans are fixed per topology: a box sheared so that two faces meet at 25 degrees keeps its crisp edge (the
    fan split at the topology change stays); the normals themselves follow the deformed faces."""
    from pdsim.output.writer import _Shading

    v, f = _box_mesh()
    shading = _Shading(v, f, 30.0, None)
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    n = shading.normals(v @ rot.T).reshape(-1, 3, 3)
    np.testing.assert_allclose(n, (shading.normals(v).reshape(-1, 3) @ rot.T).reshape(-1, 3, 3), atol=1e-12)


def test_writer_mesh_normals_velocities_subsets_and_colors(tmp_path):
    """A fracturing surface (crack and fragment face attributes) through the ViewWriter: faceVarying normals on every
    frame (one per face corner), velocities on every frame, the materialBind subsets "outer" and "crack" (indices
    written with the topology, family type nonOverlapping), and with color_attribute="damage" a per-vertex
    displayColor from the damage vertex attribute and a per-point one on the points."""
    from pxr import UsdGeom

    from pdsim.output.views import MeshView, PointsView
    from pdsim.output.writer import ViewWriter, color_ramp

    v, f = _box_mesh()
    path = tmp_path / "surface.usdc"
    with UsdCache(path, fps=24.0) as cache:
        writer = ViewWriter(cache, color_attribute="damage")
        for frame in range(4):
            if frame < 2:
                pts, faces, crack, version = v, f, np.zeros(len(f), int), 0
            else:  # split: a second box whose faces are crack faces
                pts, faces, version = np.r_[v, v + 3.0], np.r_[f, f + 8], 1
                crack = np.r_[np.zeros(len(f), int), np.ones(len(f), int)]
            damage = np.linspace(0.0, 1.0, len(pts))
            mesh = MeshView(
                "bar_surface",
                pts + frame,
                np.full_like(pts, 0.5),
                version,
                faces,
                {"fragment": (crack > 0).astype(int), "crack": crack},
                {"damage": damage},
            )
            x = np.zeros((3, 3)) + frame
            points = PointsView("bar", x, np.ones((3, 3)), np.full(3, 0.1), {"damage": np.array([0.0, 0.5, 1.0])})
            writer.write(frame, [points, mesh])
            cache.end_frame(frame)
    assert usd_problems(path) == []
    stage = _open(path)
    m = UsdGeom.Mesh(stage.GetPrimAtPath("/World/bar_surface"))
    assert m.GetNormalsInterpolation() == UsdGeom.Tokens.faceVarying
    for frame in range(4):
        nf = len(m.GetFaceVertexIndicesAttr().Get(frame))
        assert len(m.GetNormalsAttr().Get(frame)) == nf
        assert len(m.GetVelocitiesAttr().Get(frame)) == len(m.GetPointsAttr().Get(frame))
    assert m.GetFaceVertexIndicesAttr().GetTimeSamples() == [0.0, 2.0]
    subsets = {s.GetPrim().GetName(): s for s in UsdGeom.Subset.GetAllGeomSubsets(m)}
    assert set(subsets) == {"outer", "crack"}
    crack = subsets["crack"]
    assert crack.GetFamilyNameAttr().Get() == "materialBind"
    assert crack.GetElementTypeAttr().Get() == UsdGeom.Tokens.face
    assert crack.GetIndicesAttr().GetTimeSamples() == [0.0, 2.0]
    assert list(crack.GetIndicesAttr().Get(1)) == []
    assert list(crack.GetIndicesAttr().Get(3)) == list(range(12, 24))
    assert list(subsets["outer"].GetIndicesAttr().Get(3)) == list(range(12))
    assert UsdGeom.Subset.GetFamilyType(m, "materialBind") == UsdGeom.Tokens.nonOverlapping
    color = UsdGeom.PrimvarsAPI(m).GetPrimvar("displayColor")
    assert color.GetInterpolation() == UsdGeom.Tokens.vertex
    np.testing.assert_allclose(np.asarray(color.Get(3)), color_ramp(np.linspace(0, 1, 16), 0.0, 1.0), atol=1e-6)
    pcolor = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/bar")).GetPrimvar("displayColor")
    np.testing.assert_allclose(np.asarray(pcolor.Get(0))[[0, 2]], color_ramp([0.0, 1.0], 0.0, 1.0), atol=1e-6)


def test_fragments_as_prims_have_stable_names_and_visibility(tmp_path):
    """fragments_as_prims: /World/<surface> is an Xform and each fragment a Mesh fragment_<id> with its own closed
    vertex set; a fragment that appears at frame 2 is invisible before (visibility time samples) and its points start
    there (empty before); fragment ids keep their prim over the animation; a fragment that vanishes is hidden from then
    on."""
    from pxr import UsdGeom

    from pdsim.output.views import MeshView
    from pdsim.output.writer import ViewWriter

    v, f = _box_mesh()
    path = tmp_path / "frags.usdc"
    with UsdCache(path, fps=24.0) as cache:
        writer = ViewWriter(cache, fragments_as_prims=True)
        for frame in range(5):
            if frame < 2:
                pts, faces, frag, version = v, f, np.zeros(len(f), int), 0
            elif frame < 4:
                pts, faces, version = np.r_[v, v + 3.0], np.r_[f, f + 8], 1
                frag = np.r_[np.zeros(len(f), int), np.full(len(f), 7)]
            else:  # fragment 0 is gone (say it left the scene), 7 stays
                pts, faces, frag, version = v + 3.0, f, np.full(len(f), 7), 2
            crack = (frag > 0).astype(int)
            writer.write(frame, [MeshView("s", pts + frame, None, version, faces, {"fragment": frag, "crack": crack})])
            cache.end_frame(frame)
    assert usd_problems(path) == []
    stage = _open(path)
    assert stage.GetPrimAtPath("/World/s").IsA(UsdGeom.Xform)
    f0 = UsdGeom.Mesh(stage.GetPrimAtPath("/World/s/fragment_0"))
    f7 = UsdGeom.Mesh(stage.GetPrimAtPath("/World/s/fragment_7"))
    assert [f0.ComputeVisibility(t) for t in range(5)] == ["inherited"] * 4 + ["invisible"]
    assert [f7.ComputeVisibility(t) for t in range(5)] == ["invisible"] * 2 + ["inherited"] * 3
    np.testing.assert_allclose(np.asarray(f7.GetPointsAttr().Get(2)), v + 5.0, atol=1e-6)
    np.testing.assert_allclose(np.asarray(f7.GetPointsAttr().Get(4)), v + 7.0, atol=1e-6)
    assert len(f7.GetPointsAttr().Get(1)) == 0 and len(f7.GetFaceVertexIndicesAttr().Get(1)) == 0  # no geometry yet
    np.testing.assert_array_equal(np.asarray(f7.GetFaceVertexIndicesAttr().Get(3)).reshape(-1, 3), f)
    assert len(f7.GetNormalsAttr().Get(3)) == 3 * len(f)
    crack = UsdGeom.Subset(stage.GetPrimAtPath("/World/s/fragment_7/crack"))
    assert list(crack.GetIndicesAttr().Get(2)) == list(range(12))


def test_rigid_views_static_and_animated(tmp_path):
    """RigidViews: a static one (the ground, directly under /World) has its geometry and transform as default values
    (no time samples); a moving one under /World/colliders has its geometry once and xformOp:translate/orient
    sampled every frame; the points in world space are translation + rotate(orientation, body point)."""
    from pxr import Gf, UsdGeom

    from pdsim.output.views import RigidView
    from pdsim.output.writer import ViewWriter

    v, f = _box_mesh()
    path = tmp_path / "rigid.usdc"
    ground = RigidView(
        "ground", np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]]),
        np.zeros(3), np.array([0, 0, 0, 1.0]), static=True, group=None,
    )  # fmt: skip
    q90 = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])  # 90 degrees about z
    with UsdCache(path, fps=24.0) as cache:
        writer = ViewWriter(cache)
        for frame in range(3):
            box = RigidView("box", v, f, np.array([frame, 0.0, 1.0]), q90 if frame == 2 else np.array([0, 0, 0, 1.0]))
            writer.write(frame, [ground, box])
            cache.end_frame(frame)
    assert usd_problems(path) == []
    stage = _open(path)
    g = UsdGeom.Mesh(stage.GetPrimAtPath("/World/ground"))
    assert g.GetPointsAttr().GetNumTimeSamples() == 0 and len(g.GetPointsAttr().Get()) == 4
    assert g.GetPrim().GetAttribute("xformOp:translate").GetNumTimeSamples() == 0
    b = UsdGeom.Mesh(stage.GetPrimAtPath("/World/colliders/box"))
    assert b.GetPointsAttr().GetNumTimeSamples() == 0
    assert b.GetPrim().GetAttribute("xformOp:translate").GetTimeSamples() == [0.0, 1.0, 2.0]
    assert b.GetNormalsInterpolation() == UsdGeom.Tokens.faceVarying
    local = np.asarray(b.GetPointsAttr().Get(), dtype=np.float64)
    m = np.asarray(b.ComputeLocalToWorldTransform(2.0))
    world = local @ m[:3, :3] + m[3, :3]
    expected = v @ np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).T + [2.0, 0.0, 1.0]
    np.testing.assert_allclose(world, expected, atol=1e-6)
    assert isinstance(b.GetPrim().GetAttribute("xformOp:orient").Get(2), Gf.Quatf)


def test_failed_run_keeps_earlier_cache_unit(tmp_path):
    """UsdCache at a path that holds a cache: the new run writes <stem>.partial.usdc and replaces the cache only when
    it closes successfully; an exception leaves the earlier cache untouched (same frames, same data), the failed
    run's finished frames in the partial file, and a note on the exception naming both; a later successful run
    replaces the cache and removes the partial file and every frame folder no layer refers to."""
    path = tmp_path / "keep.usdc"
    _write_cache(path, frames=4)
    stage = _fresh_stage(path)
    before = np.asarray(stage.GetPrimAtPath("/World/particles").GetAttribute("points").Get(3))
    del stage
    with pytest.raises(RuntimeError, match="boom") as info, UsdCache(path, fps=24.0) as cache:
        pts = cache.add_points("particles", widths=np.ones(N))
        for f in range(2):
            cache.write_points(pts, f, _positions(f) + 100.0)
            cache.end_frame(f)
        assert cache.top_level_path == tmp_path / "keep.partial.usdc"
        raise RuntimeError("boom")
    assert any("keep.partial.usdc" in note for note in info.value.__notes__)
    stage = _fresh_stage(path)
    assert stage.GetEndTimeCode() == 3
    np.testing.assert_array_equal(stage.GetPrimAtPath("/World/particles").GetAttribute("points").Get(3), before)
    partial = _fresh_stage(tmp_path / "keep.partial.usdc")
    assert partial.GetEndTimeCode() == 1
    np.testing.assert_array_equal(
        partial.GetPrimAtPath("/World/particles").GetAttribute("points").Get(1), _positions(1) + 100.0
    )
    del stage, partial
    assert len(list((tmp_path / "keep.frames").iterdir())) == 2
    _write_cache(path, frames=2)
    assert not (tmp_path / "keep.partial.usdc").exists()
    assert len(list((tmp_path / "keep.frames").iterdir())) == 1
    assert _fresh_stage(path).GetEndTimeCode() == 1
    assert usd_problems(path) == []
