"""Bad input is rejected with pdsim.ParameterError / pdsim.GeometryError whose message names the field, the value and
the allowed range (or the problem); good input of every supported kind loads and samples correctly."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

import pdsim
from pdsim.sampling import fill_solid

SOFT = {"density": 1000.0, "youngs_modulus": 1.0e5, "poisson_ratio": 0.3}


def _material(**overrides):
    args = dict(SOFT)
    args.update(overrides)
    return pdsim.Material(**args)


def _closed_box(extents=(0.3, 0.2, 0.1), center=(0.0, 0.0, 0.0)):
    import trimesh

    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def _open_box():
    """A box with two of its twelve triangles removed: a hole, so no enclosed solid."""
    import trimesh

    m = _closed_box()
    return trimesh.Trimesh(vertices=m.vertices, faces=m.faces[:-2], process=False)


def _assert_error(excinfo, cls, *fragments):
    """The exception is ``cls`` (a PdsimError and ValueError) and its message contains every fragment."""
    exc = excinfo.value
    assert isinstance(exc, cls)
    assert isinstance(exc, pdsim.PdsimError)
    assert isinstance(exc, ValueError)
    msg = str(exc)
    assert "\n" not in msg
    for frag in fragments:
        assert frag in msg, f"{frag!r} not in {msg!r}"


def _tiny_scene(**kwargs) -> pdsim.Scene:
    scene = pdsim.Scene(fps=100.0, frames=2, **kwargs)
    scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)), _material(), spacing=0.05)
    return scene


# ----------------------------------------------------------------------------------------------------------- meshes


@pytest.mark.parametrize("suffix", [".obj", ".stl"])
def test_open_mesh_file_is_capped(tmp_path, suffix):
    """load_mesh of an open box (two triangles of one side missing) caps the hole: the box's exact volume (1e-6
    relative; STL stores float32), a closed surface, and the repair line says one hole was capped."""
    path = tmp_path / f"open{suffix}"
    _open_box().export(path)
    shape = pdsim.load_mesh(path)
    assert shape.volume == pytest.approx(0.3 * 0.2 * 0.1, rel=1e-6)
    assert "1 holes capped" in shape.repairs


def test_flat_sheet_encloses_no_volume():
    """shape_from_arrays of a flat open sheet (a square of two triangles) raises GeometryError naming the shape and
    saying it encloses no volume."""
    v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(v, [[0, 1, 2], [0, 2, 3]], name="sheet")
    _assert_error(ei, pdsim.GeometryError, "sheet", "encloses no volume")


@pytest.mark.parametrize(
    "text", ["# no geometry at all\n", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"], ids=["blank", "vertices_only"]
)
def test_empty_obj_file(tmp_path, text):
    """An OBJ file without faces (blank, or vertices only) raises GeometryError saying the mesh is empty."""
    path = tmp_path / "empty.obj"
    path.write_text(text)
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.load_mesh(path)
    _assert_error(ei, pdsim.GeometryError, str(path), "empty")


@pytest.mark.parametrize("vertices,faces", [([], []), (np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int32))])
def test_empty_arrays(vertices, faces):
    """shape_from_arrays with no vertices and no triangles raises GeometryError saying the mesh is empty."""
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(vertices, faces, name="nothing")
    _assert_error(ei, pdsim.GeometryError, "nothing", "empty")


def test_bad_arrays():
    """shape_from_arrays rejects out-of-range or fractional face indices, non-finite vertices and wrong shapes with
    GeometryError (not IndexError/ValueError from numpy or trimesh)."""
    m = _closed_box()
    bad_faces = m.faces.copy()
    bad_faces[0, 0] = len(m.vertices)
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(m.vertices, bad_faces, name="idx")
    _assert_error(ei, pdsim.GeometryError, "idx", "vertex indices", f"[0, {len(m.vertices)})")
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(m.vertices, m.faces - 1, name="neg")
    _assert_error(ei, pdsim.GeometryError, "neg", "vertex indices")
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(m.vertices, m.faces + 0.5, name="frac")
    _assert_error(ei, pdsim.GeometryError, "frac", "integer vertex indices")
    v = np.array(m.vertices)
    v[3, 1] = np.nan
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays(v, m.faces, name="nan")
    _assert_error(ei, pdsim.GeometryError, "nan", "non-finite")
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.shape_from_arrays([[0.0, 1.0]], [[0, 1, 2]], name="shape2")
    _assert_error(ei, pdsim.GeometryError, "shape2", "[n, 3]")
    # Float arrays holding whole numbers are fine (as before).
    assert pdsim.shape_from_arrays(m.vertices, m.faces.astype(np.float64)).volume == pytest.approx(0.006, rel=1e-12)


def test_unknown_file_type(tmp_path):
    """load_mesh('model.xyz') raises GeometryError naming the suffix and listing the supported types."""
    path = tmp_path / "model.xyz"
    path.write_text("0 0 0\n1 0 0\n")
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.load_mesh(path)
    _assert_error(ei, pdsim.GeometryError, "model.xyz", "'.xyz'", ".obj", ".stl", ".ply", ".glb")


def test_missing_file(tmp_path):
    """load_mesh of a file that does not exist raises GeometryError naming the path and 'no such file'."""
    path = tmp_path / "missing.obj"
    with pytest.raises(pdsim.GeometryError) as ei:
        pdsim.load_mesh(path)
    _assert_error(ei, pdsim.GeometryError, str(path), "no such file")


def test_load_mesh_bad_placement(tmp_path):
    """load_mesh rejects scale <= 0, fit_size <= 0, scale and fit_size together, a position that is not 3 finite
    numbers, a rotation that is neither 3 angles nor a rotation matrix and an up axis other than 'Y' or 'Z' with
    ParameterError naming the field."""
    path = tmp_path / "box.obj"
    _closed_box().export(path)
    for kwargs, fragments in [
        ({"scale": 0.0}, ("scale=0.0", "(0, inf)")),
        ({"fit_size": -1.0}, ("fit_size=-1.0", "(0, inf)")),
        ({"scale": 2.0, "fit_size": 0.3}, ("fit_size=0.3", "scale")),
        ({"position": (1.0, 2.0)}, ("position=(1.0, 2.0)", "3 finite numbers")),
        ({"position": (0.0, 0.0, float("nan"))}, ("position=", "3 finite numbers")),
        ({"rotation": (90.0, 0.0)}, ("rotation=", "Euler angles")),
        ({"rotation": 2.0 * np.eye(3)}, ("rotation=", "rotation matrix")),
        ({"up_axis": "X"}, ("up_axis='X'", "'Y' or 'Z'")),
    ]:
        with pytest.raises(pdsim.ParameterError) as ei:
            pdsim.load_mesh(path, **kwargs)
        _assert_error(ei, pdsim.ParameterError, *fragments)


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply", ".glb"])
def test_load_each_type_volume_and_fill(tmp_path, suffix, device):
    """A closed box written as OBJ/STL/PLY/GLB loads with its exact volume (1e-6 relative; STL/PLY/GLB store float32),
    its bounds and the file stem as name; a loaded 0.2 m cube filled at spacing 0.02 gives exactly 10^3 = 1000
    particles of volume 8e-6 m^3 each (also for the float32 formats, whose edge is 0.2 (1 + ~1e-8))."""
    box = _closed_box()
    path = tmp_path / f"part{suffix}"
    box.export(path)
    shape = pdsim.load_mesh(path)
    assert shape.name == "part"
    assert shape.volume == pytest.approx(0.3 * 0.2 * 0.1, rel=1e-6)
    np.testing.assert_allclose(shape.bounds, [[-0.15, -0.1, -0.05], [0.15, 0.1, 0.05]], atol=1e-7)
    assert shape.faces.shape == (12, 3)

    cube_path = tmp_path / f"cube{suffix}"
    _closed_box(extents=(0.2, 0.2, 0.2)).export(cube_path)
    cube = pdsim.load_mesh(cube_path)
    assert cube.volume == pytest.approx(0.008, rel=1e-6)
    positions, volumes = fill_solid(cube, 0.02, device=device)
    assert len(positions) == 1000
    np.testing.assert_allclose(volumes, 8.0e-6, rtol=1e-12)
    # a lattice h/2 inside the faces
    np.testing.assert_allclose(positions.min(axis=0), -0.09, atol=1e-6)
    np.testing.assert_allclose(positions.max(axis=0), 0.09, atol=1e-6)


def test_cube_body_particles(device):
    """PeridynamicBody on pdsim.box((0.2, 0.2, 0.2)) at spacing 0.02: exactly 1000 particles, each of volume 8e-6 m^3,
    total volume equal to the cube's 0.008 m^3."""
    body = pdsim.PeridynamicBody(pdsim.box((0.2, 0.2, 0.2)), _material(), spacing=0.02, device=device)
    assert body.particle_count == 1000
    np.testing.assert_allclose(body.volumes, 8.0e-6, rtol=1e-12)
    assert body.volumes.sum() == pytest.approx(0.008, rel=1e-9)


def test_sphere_fill_volume(device):
    """A sphere of radius r = 10 h (icosphere, 4 subdivisions) filled at spacing h by the exact inside test (winding
    number against the mesh): total particle volume within 5 % of 4/3 pi r^3. Measured: 4224 particles, i.e.
    4224 h^3 against 4188.79 h^3, +0.84 %. The inside test also agrees with the analytic ball test on every lattice
    point farther than 0.5 % of r from the sphere (the icosphere's facets lie within about 0.07 % of r)."""
    h = 0.01
    r = 10.0 * h
    shape = pdsim.sphere(r, center=(0.3, -0.2, 0.1))
    positions, volumes = fill_solid(shape, h, device=device)
    exact = 4.0 / 3.0 * math.pi * r**3
    assert abs(volumes.sum() / exact - 1.0) < 0.05
    assert len(positions) == 4224
    from pdsim.sampling import points_inside, simple_cubic_lattice

    candidates = simple_cubic_lattice(shape, h)
    inside = points_inside(shape, candidates, device=device)
    dist = np.linalg.norm(candidates - np.array([0.3, -0.2, 0.1]), axis=1)
    clear = np.abs(dist - r) > 0.005 * r  # away from the thin band between the facets and the true sphere
    assert clear.sum() > 0.9 * len(candidates)
    np.testing.assert_array_equal(inside[clear], dist[clear] < r)


# ---------------------------------------------------------------------------------------------------------- material


@pytest.mark.parametrize("nu", [0.5, -1.0, 0.7, -1.5])
def test_poisson_ratio_out_of_range(nu):
    """Poisson's ratio outside the open interval (-1, 0.5) raises ParameterError naming field, value and range."""
    with pytest.raises(pdsim.ParameterError) as ei:
        _material(poisson_ratio=nu)
    _assert_error(ei, pdsim.ParameterError, f"poisson_ratio={nu!r}", "(-1, 0.5)")
    assert ei.value.field == "poisson_ratio"
    assert ei.value.value == nu


def test_poisson_ratio_049_accepted():
    """Poisson's ratio 0.49 (nearly incompressible) is accepted and gives finite, positive moduli."""
    m = _material(poisson_ratio=0.49)
    assert m.poisson_ratio == 0.49
    assert m.bulk_modulus == pytest.approx(1.0e5 / (3.0 * 0.02))
    assert math.isfinite(m.p_wave_speed) and m.p_wave_speed > 0.0


@pytest.mark.parametrize(
    "field,value,allowed",
    [
        ("density", -1.0, "(0, inf)"),
        ("density", 0.0, "(0, inf)"),
        ("youngs_modulus", 0.0, "(0, inf)"),
        ("youngs_modulus", -2.0e6, "(0, inf)"),
        ("density", float("nan"), "finite"),
        ("youngs_modulus", float("nan"), "finite"),
        ("poisson_ratio", float("nan"), "finite"),
        ("youngs_modulus", float("inf"), "finite"),
        ("density", "heavy", "a real number"),
    ],
)
def test_material_bad_values(field, value, allowed):
    """Negative/zero density, zero/negative Young's modulus, NaN/inf and non-numbers raise ParameterError whose message
    names the field, the value and what is allowed."""
    with pytest.raises(pdsim.ParameterError) as ei:
        _material(**{field: value})
    _assert_error(ei, pdsim.ParameterError, f"{field}={value!r}", allowed)
    assert ei.value.field == field


# ----------------------------------------------------------------------------------------------------------- spacing


def test_spacing_larger_than_object(device):
    """A 0.1 m box at spacing 0.2 raises ParameterError naming spacing, 0.2 and the allowed (0, 0.1]."""
    with pytest.raises(pdsim.ParameterError) as ei:
        pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1), name="pebble"), _material(), spacing=0.2, device=device)
    _assert_error(ei, pdsim.ParameterError, "spacing=0.2", "(0, 0.1]", "pebble")


@pytest.mark.parametrize("spacing", [0.0, -0.05, float("nan")])
def test_spacing_not_positive(spacing, device):
    """Spacing <= 0 (or NaN) raises ParameterError naming spacing and its value."""
    with pytest.raises(pdsim.ParameterError) as ei:
        pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1)), _material(), spacing=spacing, device=device)
    _assert_error(ei, pdsim.ParameterError, f"spacing={spacing!r}")
    assert ei.value.field == "spacing"


# ------------------------------------------------------------------------------------------------------------ frames


@pytest.mark.parametrize("frames", [0, -3, 2.5, True])
def test_scene_frames_invalid(frames):
    """Scene(frames=0) (and negative, fractional, bool) raises ParameterError naming frames and 'an integer >= 1'."""
    with pytest.raises(pdsim.ParameterError) as ei:
        pdsim.Scene(frames=frames)
    _assert_error(ei, pdsim.ParameterError, f"frames={frames!r}", "an integer >= 1")


def test_run_frames_zero(tmp_path, device):
    """scene.run(frames=0) raises ParameterError naming frames before any file is written."""
    scene = _tiny_scene()
    out = tmp_path / "zero.usdc"
    with pytest.raises(pdsim.ParameterError) as ei:
        scene.run(out, frames=0, device=device, progress=False)
    _assert_error(ei, pdsim.ParameterError, "frames=0", "an integer >= 1")
    assert not out.exists()


def _pdsim_stderr_lines(stderr: str) -> list[str]:
    """stderr lines of the pdsim CLI, without the line that Warp's native library prints itself (unconditionally, from
    C++) when it finds no CUDA driver; pdsim cannot silence it."""
    return [ln for ln in stderr.splitlines() if ln.strip() and not ln.startswith("Warp CUDA warning:")]


SCENE_SCRIPT = """
import pdsim

def build_scene():
    scene = pdsim.Scene(fps=100.0, frames=2, name="tiny")
    body = scene.add_peridynamic_body(pdsim.box((0.3, 0.1, 0.1), center=(0.15, 0.0, 0.5)),
                                      pdsim.Material(density=1000.0, youngs_modulus=1.0e5, poisson_ratio=0.3),
                                      spacing=0.05, name="beam")
    body.fix(pdsim.BoxRegion(lo=(-1.0, -1.0, -1.0), hi=(0.05, 1.0, 2.0)))
    return scene
"""


def test_cli_frames_zero(tmp_path):
    """`pdsim run SCENE.py --frames 0`: non-zero exit, one line 'pdsim: error: frames=0 ...' on stderr, no traceback,
    no cache written."""
    script = tmp_path / "scene.py"
    script.write_text(SCENE_SCRIPT)
    out = tmp_path / "x.usdc"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pdsim.cli",
            "run",
            str(script),
            "--out",
            str(out),
            "--frames",
            "0",
            "--device",
            "cpu",
            "--quiet",
        ],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert proc.returncode != 0
    assert "Traceback" not in proc.stdout + proc.stderr
    lines = _pdsim_stderr_lines(proc.stderr)
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("pdsim: error:")
    assert "frames=0" in lines[0] and "an integer >= 1" in lines[0]
    assert not out.exists()


# ------------------------------------------------------------------------------------------- regions, axis, output


def test_fix_region_selects_nothing():
    """body.fix with a region that holds no particle raises ParameterError saying so and naming the body."""
    scene = _tiny_scene()
    body = scene.bodies[0]
    with pytest.raises(pdsim.ParameterError) as ei:
        body.fix(pdsim.BoxRegion(lo=(5.0, 5.0, 5.0), hi=(6.0, 6.0, 6.0)))
    _assert_error(ei, pdsim.ParameterError, "region=", "at least one particle", f"'{body.name}'")
    assert not body.constrained.any()


def test_bad_region_object():
    """body.fix with something that is not a region raises ParameterError naming the allowed kinds."""
    body = _tiny_scene().bodies[0]
    with pytest.raises(pdsim.ParameterError) as ei:
        body.fix("left end")
    _assert_error(ei, pdsim.ParameterError, "region='left end'", "BoxRegion")


@pytest.mark.parametrize("axis", ["X", "y", "", None])
def test_bad_up_axis(axis):
    """Scene(up_axis=...) other than 'Y' or 'Z' raises ParameterError naming up_axis, the value and 'Y' or 'Z'."""
    with pytest.raises(pdsim.ParameterError) as ei:
        pdsim.Scene(up_axis=axis)
    _assert_error(ei, pdsim.ParameterError, f"up_axis={axis!r}", "'Y' or 'Z'")


def test_bad_output_extension(tmp_path, device):
    """scene.run('cache.abc') raises ParameterError naming out and the allowed .usdc/.usda/.usd; nothing written."""
    scene = _tiny_scene()
    out = tmp_path / "cache.abc"
    with pytest.raises(pdsim.ParameterError) as ei:
        scene.run(out, device=device, progress=False)
    _assert_error(ei, pdsim.ParameterError, "cache.abc", ".usdc", ".usda", ".usd")
    assert os.listdir(tmp_path) == []


def test_output_folder_missing(tmp_path, device):
    """scene.run into a folder that does not exist raises ParameterError naming out (not a bare ValueError, which the
    CLI would print as a traceback)."""
    scene = _tiny_scene()
    out = tmp_path / "no_such_dir" / "cache.usdc"
    with pytest.raises(pdsim.ParameterError) as ei:
        scene.run(out, device=device, progress=False)
    _assert_error(ei, pdsim.ParameterError, "no_such_dir", "existing folder")


def test_inside_test_matches_trimesh_on_a_capsule():
    """The Warp winding-number inside test agrees with trimesh's ray test on 4,000 random points around a capsule
    (away from the surface by more than 1e-3 of its size, where both are well defined)."""
    import trimesh

    from pdsim.sampling import points_inside

    cap = trimesh.creation.capsule(height=8.0, radius=4.0)
    shape = pdsim.shape_from_arrays(cap.vertices, cap.faces)
    rng = np.random.default_rng(0)
    pts = rng.uniform(-9.0, 9.0, (4000, 3))
    far = np.abs(trimesh.proximity.signed_distance(cap, pts)) > 0.016
    assert np.array_equal(points_inside(shape, pts[far]), cap.contains(pts[far]))


# ------------------------------------------------------------------------------------------ encodings, meshing crash


def test_obj_with_latin1_comment_loads_without_charset_normalizer(tmp_path, monkeypatch):
    """A valid OBJ whose comment holds Latin-1 bytes (a degree sign, an accent) loads with its exact volume even when
    trimesh's optional charset detector (charset_normalizer) is not installed (it was refused with "No module named
    'charset_normalizer'")."""
    import trimesh

    monkeypatch.setitem(sys.modules, "charset_normalizer", None)  # as on an installation without it
    text = trimesh.exchange.obj.export_obj(_closed_box())
    path = tmp_path / "bracket.obj"
    path.write_bytes(b"# exported by Caf\xe9 CAD at 20\xb0C\n" + text.encode("ascii"))
    with pytest.raises(UnicodeDecodeError):
        path.read_bytes().decode("utf-8")
    shape = pdsim.load_mesh(path)
    assert shape.name == "bracket"
    assert shape.volume == pytest.approx(0.006, rel=1e-12)


def _need_pytetwild():
    import importlib.util

    if importlib.util.find_spec("pytetwild") is None:
        pytest.skip("pytetwild is not installed")


def test_mesher_crash_is_a_geometry_error_and_mesh_cache_still_works(tmp_path, monkeypatch):
    """fTetWild runs in a child process: a native crash there (forced with os.abort()) is a GeometryError naming the
    mesh, how the mesher ended and what to change, and writes no cache entry; the same call without the crash then
    meshes, fills the cache, and a second call returns the cached mesh exactly."""
    _need_pytetwild()
    from pdsim.fem import mesh as fem_mesh

    shape = pdsim.box((0.3, 0.2, 0.1), name="bracket")
    monkeypatch.setattr(fem_mesh, "_CHILD_TEST_HOOK", "import os; os.abort()")
    with pytest.raises(pdsim.GeometryError) as ei:
        fem_mesh.tetrahedralize(shape, edge_length=0.05, cache_dir=tmp_path)
    _assert_error(ei, pdsim.GeometryError, "bracket", "fTetWild crashed (SIGABRT)", "thicken the part", "edge_length")
    assert not list(tmp_path.glob("*.vtu"))
    monkeypatch.setattr(fem_mesh, "_CHILD_TEST_HOOK", "")
    a = fem_mesh.tetrahedralize(shape, edge_length=0.05, cache_dir=tmp_path)
    b = fem_mesh.tetrahedralize(shape, edge_length=0.05, cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.vtu"))) == 1
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.tets, b.tets)
    assert a.volume == pytest.approx(0.006, rel=1e-6)


def test_thin_parts_fail_cleanly_one_after_the_other():
    """Two thin closed boxes meshed in one process: 1 x 1 x 1e-5 m at the default edge length, then 1 x 1 x 1e-4 m at
    edge_length 0.05 m. In-process, fTetWild made no elements for the first and then segfaulted the interpreter (exit
    139) on the second; each now meshes in its own child process and both raise GeometryError naming the part."""
    _need_pytetwild()
    for size, edge in (((1.0, 1.0, 1.0e-5), None), ((1.0, 1.0, 1.0e-4), 0.05)):
        with pytest.raises(pdsim.GeometryError) as ei:
            pdsim.tetrahedralize(pdsim.box(size, name="foil"), edge_length=edge)
        _assert_error(ei, pdsim.GeometryError, "foil", "thicken the part")


# -------------------------------------------------------------------------------------------------------- pre-flight


def test_usd_identifier_matches_pxr():
    """pdsim.preflight.usd_identifier (no pxr import) gives Tf.MakeValidIdentifier's prim name for plain, spaced,
    punctuated, leading-digit, empty and non-ASCII names."""
    from pxr import Tf

    from pdsim.preflight import usd_identifier

    for name in ["beam", "body 1", "body_1", "1st", "a-b.c", "", "_x", "Zo\u00eb", "\u65e5\u672c", "ground"]:
        assert usd_identifier(name) == Tf.MakeValidIdentifier(name), name


def test_touching_bodies_pass_preflight(device):
    """Bodies that touch but do not interpenetrate pass: two peridynamic blocks face to face, an FEM block on top of
    one, a second FEM block resting on the ground with its bottom vertices exactly at the ground's height, and a
    sphere projectile touching the top face."""
    from pdsim.preflight import preflight

    scene = pdsim.Scene(fps=100.0, frames=2)
    mat = _material()
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2), center=(0.0, 0.0, 0.1)), mat, spacing=0.02, name="a")
    scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2), center=(0.2, 0.0, 0.1)), mat, spacing=0.02, name="b")
    scene.add_fem_body(pdsim.box_tet_mesh((0.2, 0.2, 0.2), (2, 2, 2), center=(0.0, 0.0, 0.3)), mat, name="c")
    scene.add_fem_body(pdsim.box_tet_mesh((0.2, 0.2, 0.2), (2, 2, 2), center=(0.5, 0.0, 0.1)), mat, name="d")
    scene.add_ground_plane(height=0.0)
    scene.add_collider(pdsim.SphereProjectile(0.05, center=(0.2, 0.0, 0.25), velocity=(0.0, 0.0, -1.0)))
    report = preflight(scene, device=device)
    assert report.points == 2 * 1000 + 2 * 27
    assert report.elements == 2 * 48


def test_preflight_estimates_bound_the_built_solver(device):
    """The pre-flight's counts match the built solver: particles exactly, bonds from above (interior count
    4/3 pi (m + 1/2)^3 - 1 per particle) within a factor 1.5 on a cube of 20^3 particles; its automatic step estimate
    is within 35 % of the solver's stable step and the substeps per frame follow from it."""
    from pdsim.preflight import preflight

    scene = pdsim.Scene(fps=100.0, frames=2)
    body = scene.add_peridynamic_body(pdsim.box((0.2, 0.2, 0.2)), _material(), spacing=0.01, name="cube")
    report = preflight(scene, device=device)
    solver = scene.build_solvers(device=device)[0]
    assert report.points == body.particle_count == solver.point_count
    assert solver.bond_count <= report.bonds <= 1.5 * solver.bond_count
    assert report.dt_estimate == pytest.approx(solver.stable_time_step(), rel=0.35)
    assert report.substeps == math.ceil(scene.frame_time / report.dt - 1e-9)
    assert report.host_bytes >= report.points * 400
    assert report.free_host_bytes is None or report.free_host_bytes > 0
    if device.startswith("cuda"):
        assert report.device_bytes > 0 and report.free_device_bytes > 0


def test_memory_check_fails_before_sampling_a_huge_lattice(monkeypatch):
    """A spacing whose particle sampling alone needs more host memory than is free fails at once with the numbers
    and the spacing that fits (free memory patched to 100 MB: a 1 m cube at 2 mm has 1.25e8 lattice points)."""
    import time

    from pdsim import memory

    monkeypatch.setattr(memory, "free_host_memory", lambda: 1.0e8)
    t0 = time.perf_counter()
    with pytest.raises(pdsim.ParameterError) as ei:
        pdsim.PeridynamicBody(pdsim.box((1.0, 1.0, 1.0), name="slab"), _material(), spacing=0.002)
    assert time.perf_counter() - t0 < 5.0
    _assert_error(ei, pdsim.ParameterError, "spacing=0.002", "100 MB of free host memory", "1.25e+08", "'slab'")


def test_spacing_equal_to_the_thinnest_extent_is_one_layer():
    """A box 1 cm thick filled at a 1 cm spacing, away from the origin: the vertices' round-off must not make the
    extent read smaller than the spacing. One layer of 30 x 30 particles; a spacing above the extent is refused."""
    from pdsim.sampling import fill_solid

    shape = pdsim.box((0.3, 0.01, 0.3), center=(3.0, -2.0, 0.6))
    positions, volumes = fill_solid(shape, 0.01)
    assert len(positions) == 900 and volumes.sum() == pytest.approx(0.3 * 0.01 * 0.3, rel=1e-9)
    with pytest.raises(pdsim.ParameterError, match=r"spacing=0.0101.*smallest extent"):
        fill_solid(shape, 0.0101)
