"""Mesh intake: the seven public test meshes of ../shared/meshes (open, several parts, non-manifold edges, thin
features, CAD edges) load without hand repair, fitted to 30 cm, fill and drop onto the ground with render surfaces;
UV-seam-split vertices weld, quads triangulate, a flat sheet is refused, and load_mesh places an asset in metres."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import trimesh

import pdsim
from pdsim.mesh_repair import is_closed
from pdsim.run import advance_frame

MESHES = Path(__file__).resolve().parents[1].parent / "shared" / "meshes"
NAMES = ["teapot", "suzanne", "beetle", "cheburashka", "fandisk", "homer", "rocker-arm"]
SIZE = 0.3  # fitted largest extent [m]
ACROSS = 16  # preview spacing: SIZE / ACROSS
DROP = 0.10  # height of the bottom above the ground [m]
FPS, FRAMES = 48, 12
G = 9.81
SOFT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def _need_meshes():
    if not MESHES.is_dir():
        pytest.skip(f"the shared test meshes are not beside the project ({MESHES} is absent)")


@pytest.mark.parametrize("name", NAMES)
def test_shared_mesh_loads_fills_and_drops(name):
    """``load_mesh(NAME.obj, fit_size=0.3, position=(0, 0, 0.1))``: the shape is closed, 0.3 m across (1e-9) with its
    bottom 0.1 m above the ground; at spacing h = 0.3 m / 16 the particle count equals volume / h^3 within 15 % (the
    lattice's error at thin features); the render surface of the intact body is closed and has at least as many
    vertices as the repaired mesh and as the input (its distinct positions); over 12 frames at 48 fps the centre of
    mass falls g t^2 / 2 (1e-3 relative) until the ground is within reach (t < sqrt(2 x 0.1 m / g) less one frame),
    and afterwards stays above the ground."""
    _need_meshes()
    shape = pdsim.load_mesh(MESHES / f"{name}.obj", fit_size=SIZE, position=(0.0, 0.0, DROP))
    assert is_closed(shape.faces.astype(np.int64), len(shape.vertices))
    assert float(shape.extent.max()) == pytest.approx(SIZE, rel=1e-9)
    assert float(shape.bounds[0, 2]) == pytest.approx(DROP, abs=1e-12)
    h = SIZE / ACROSS
    scene = pdsim.Scene(fps=FPS, frames=FRAMES, name="drop")
    body = scene.add_peridynamic_body(shape, SOFT, spacing=h)
    scene.add_ground_plane(height=0.0, friction=0.5)
    count_ratio = body.particle_count * h**3 / shape.volume
    assert abs(count_ratio - 1.0) < 0.15, count_ratio
    solver = scene.build_solver(device="cpu")
    frame_dt = 1.0 / FPS
    substeps = max(1, math.ceil(frame_dt / min(scene.time_step_safety * solver.stable_time_step(), frame_dt)))
    z0 = None
    contact = math.sqrt(2.0 * DROP / G) - frame_dt
    for frame in range(FRAMES + 1):
        if frame:
            advance_frame([solver], frame_dt / substeps, substeps)
        points, surface = solver.views()
        z = float(points.positions[:, 2].mean())
        if frame == 0:
            z0 = z
            surf = trimesh.Trimesh(surface.points, surface.faces, process=False)
            assert surf.is_watertight and surf.is_winding_consistent
            assert len(surface.points) >= len(shape.vertices)
            raw = trimesh.load(MESHES / f"{name}.obj", force="mesh", process=False)
            raw.merge_vertices(merge_tex=True, merge_norm=True)
            assert len(surface.points) >= len(raw.vertices)  # the input's detail: at least its distinct vertices
            print(
                f"\n{name}: {body.particle_count} particles, N h^3 / V = {count_ratio:.3f}, render surface "
                f"{len(surface.points)} vertices (mesh {len(shape.vertices)}), {shape.repairs or 'no repair'}"
            )
        t = frame * frame_dt
        if t < contact:
            assert z0 - z == pytest.approx(0.5 * G * t * t, rel=1e-3, abs=1e-9), (frame, z0 - z)
        assert float(points.positions[:, 2].min()) > 0.0


def _obj_with_uv_seam(mesh: trimesh.Trimesh) -> str:
    """OBJ text of ``mesh`` whose faces on the y > 0 side use texture coordinate 2 and the others 1: every vertex on
    the seam (used by both sides) is written as two vertices by OBJ readers that split by texture coordinate."""
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in mesh.vertices] + ["vt 0 0", "vt 1 1"]
    side = np.where(mesh.triangles_center[:, 1] > 0.0, 2, 1)
    lines += [f"f {a + 1}/{s} {b + 1}/{s} {c + 1}/{s}" for (a, b, c), s in zip(mesh.faces, side, strict=True)]
    return "\n".join(lines) + "\n"


def test_uv_seam_split_vertices_weld(tmp_path):
    """An icosphere (642 vertices) written with a UV seam (trimesh's OBJ reader splits the seam's vertices, and
    merging them by position and texture coordinate leaves it open) loads: the seam's vertices are welded, the shape
    has the icosphere's 642 vertices and its volume (1e-12 relative)."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.15)
    path = tmp_path / "seam.obj"
    path.write_text(_obj_with_uv_seam(sphere))
    raw = trimesh.load(path, force="mesh", process=True)
    raw.merge_vertices()  # by position and texture coordinate: the seam stays open
    assert len(raw.vertices) > len(sphere.vertices) and not raw.is_watertight
    shape = pdsim.load_mesh(path)
    assert len(shape.vertices) == len(sphere.vertices)
    assert shape.volume == pytest.approx(sphere.volume, rel=1e-12)
    assert f"{len(raw.vertices) - len(sphere.vertices)} coincident vertices welded" in shape.repairs


def test_obj_with_quads(tmp_path):
    """A cube written as 6 quads loads as 12 triangles with volume 1 m^3 (1e-12) and '6 polygons triangulated'."""
    v = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    quads = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a} {b} {c} {d}\n" for a, b, c, d in quads)
    path = tmp_path / "cube.obj"
    path.write_text(text)
    shape = pdsim.load_mesh(path)
    assert shape.faces.shape == (12, 3)
    assert shape.volume == pytest.approx(1.0, rel=1e-12)
    assert "6 polygons triangulated" in shape.repairs


def test_placement(tmp_path):
    """A Y-up box of 2 x 4 x 1 file units (x, y up, z) loaded with up_axis='Y', rotation=(0, 0, 90) degrees,
    fit_size=0.3 m and position=(1000, 5, 0.2) m: extents (0.075, 0.15, 0.3) m (1e-12), the bounding box's bottom
    centre at the position (1e-9 m, 1 km from the origin); the same rotation as a matrix gives the same vertices;
    scale=0.01 instead of fit_size gives extents (0.01, 0.02, 0.04) m."""
    box = trimesh.creation.box(extents=(2.0, 4.0, 1.0))
    box.apply_translation((3.0, 7.0, -2.0))
    path = tmp_path / "crate.obj"
    box.export(path)
    shape = pdsim.load_mesh(path, up_axis="Y", rotation=(0.0, 0.0, 90.0), fit_size=0.3, position=(1000.0, 5.0, 0.2))
    np.testing.assert_allclose(shape.extent, [0.075, 0.15, 0.3], rtol=1e-12)
    lo, hi = shape.bounds
    np.testing.assert_allclose([*(0.5 * (lo + hi))[:2], lo[2]], [1000.0, 5.0, 0.2], rtol=0.0, atol=1e-9)
    matrix = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    same = pdsim.load_mesh(path, up_axis="Y", rotation=matrix, fit_size=0.3, position=(1000.0, 5.0, 0.2))
    np.testing.assert_allclose(same.vertices, shape.vertices, rtol=0.0, atol=1e-9)
    scaled = pdsim.load_mesh(path, up_axis="Y", rotation=(0.0, 0.0, 90.0), scale=0.01)
    np.testing.assert_allclose(scaled.extent, [0.01, 0.02, 0.04], rtol=1e-12)


def test_repair_far_from_the_origin():
    """An open box (two triangles of a side missing) capped at the origin and 1 km away: the same volume (1e-9
    relative) and the same vertices up to the shift (1e-9 m)."""
    box = trimesh.creation.box(extents=(0.3, 0.2, 0.1))
    near = pdsim.shape_from_arrays(box.vertices, box.faces[:-2], name="near")
    far = pdsim.shape_from_arrays(box.vertices + 1000.0, box.faces[:-2], name="far")
    assert near.volume == pytest.approx(0.006, rel=1e-9) and far.volume == pytest.approx(0.006, rel=1e-9)
    np.testing.assert_allclose(far.vertices - 1000.0, near.vertices, rtol=0.0, atol=1e-9)


def test_glb_of_overlapping_parts(tmp_path):
    """A GLB scene of two 0.2 m cubes overlapping by half along x (two closed parts) loads as their union: volume
    0.2 x 0.2 x 0.3 m^3 (1e-6 relative; GLB stores float32), one closed surface, '2 pieces united'."""
    a = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    b = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    b.apply_translation((0.1, 0.0, 0.0))
    path = tmp_path / "parts.glb"
    trimesh.Scene([a, b]).export(path)
    shape = pdsim.load_mesh(path)
    assert shape.volume == pytest.approx(0.2 * 0.2 * 0.3, rel=1e-6)
    assert is_closed(shape.faces.astype(np.int64), len(shape.vertices))
    assert "2 pieces united" in shape.repairs
