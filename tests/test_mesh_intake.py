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
    lattice's error at thin features); the render surface of the intact body is closed and keeps at least the
    repaired mesh's vertices; over 12 frames at 48 fps the centre of mass falls g t^2 / 2 (1e-3 relative) until the
    ground is within reach (t < sqrt(2 x 0.1 m / g) less one frame), and afterwards stays above the ground."""
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
            print(f"\n{name}: {body.particle_count} particles, N h^3 / V = {count_ratio:.3f}, render surface "
                  f"{len(surface.points)} vertices (mesh {len(shape.vertices)}), {shape.repairs or 'no repair'}")
        t = frame * frame_dt
        if t < contact:
            assert z0 - z == pytest.approx(0.5 * G * t * t, rel=1e-3, abs=1e-9), (frame, z0 - z)
        assert float(points.positions[:, 2].min()) > 0.0
