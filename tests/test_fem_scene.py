"""The FEM solid in the shared scene layer: USD output of boundary surfaces (closed, topology time-sampled only when it
changes), the embedded render mesh, the ground-plane collider."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody
from pdsim.fem.fracture import closed_surface_defects
from pdsim.fem.mesh import box_tet_mesh, tet_mesh_from_arrays
from pdsim.output import validate_usd

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def _need_pytetwild():
    """Skips without pytetwild (found by spec: its package import needs pyvista, which pdsim does not)."""
    import importlib.util

    if importlib.util.find_spec("pytetwild") is None:
        pytest.skip("pytetwild is not installed")


def _notched_bar():
    m0 = box_tet_mesh((1.0, 0.1, 0.1), (20, 2, 2), center=(0.5, 0.0, 0.0))
    c = m0.vertices[m0.tets].mean(axis=1)
    notch = (np.abs(c[:, 0] - 0.3) < 0.025) & (c[:, 2] > 0.0)
    return tet_mesh_from_arrays(m0.vertices, m0.tets[~notch], name="bar")


def test_fracturing_body_writes_closed_surfaces_with_topology_samples_only_on_change(tmp_path):
    """A notched bar pulled apart in a Scene: the cache holds one UsdGeom.Mesh for the body with points on every frame
    and faceVertexIndices only on frame 0 and on frames where fracture changed the topology (fewer than the frames);
    the surface of every frame is closed (each directed edge has one opposite edge); the stage passes
    pxr.UsdValidation."""
    from pxr import Usd, UsdGeom

    scene = pdsim.Scene(fps=10, frames=10, gravity=(0.0, 0.0, 0.0), name="pull")
    body = FemBody(_notched_bar(), MAT, tensile_strength=2.0e4, integrator="implicit", damping=5.0)
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1e-6, 1, 1)))
    body.set_velocity(pdsim.BoxRegion(lo=(1.0 - 1e-6, -1, -1), hi=(2, 1, 1)), (0.1, 0.0, 0.0))
    scene.add_body(body)
    out = tmp_path / "pull.usdc"
    report = scene.run(out, progress=False, device="cpu")
    assert report.frames_written == 11 and report.bond_count == body.element_count
    stage = Usd.Stage.Open(str(out))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/bar"))
    point_times = mesh.GetPointsAttr().GetTimeSamples()
    topo_times = mesh.GetFaceVertexIndicesAttr().GetTimeSamples()
    assert point_times == [float(f) for f in range(11)]
    assert topo_times[0] == 0.0 and 1 < len(topo_times) < len(point_times)
    for t in point_times:
        faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(t)).reshape(-1, 3)
        points = np.asarray(mesh.GetPointsAttr().Get(t))
        assert faces.max() < len(points)
        assert closed_surface_defects(faces) == 0
    assert validate_usd(out) == []


def test_render_mesh_follows_the_tetrahedra(tmp_path):
    """A sphere meshed by fTetWild with its input surface embedded as a render mesh: at rest the embedding reproduces
    the input vertices (1e-5 m, float32), and after the body falls freely for 0.2 s every render vertex has moved by
    g t^2 / 2 = 0.196 m (1e-3 m): the barycentric weights follow the tetrahedra."""
    _need_pytetwild()
    from pxr import Usd, UsdGeom

    shape = pdsim.sphere(0.2, subdivisions=2, name="ball")
    scene = pdsim.Scene(fps=10, frames=2, name="fall")
    scene.add_body(FemBody(shape, MAT, edge_length=0.08, render_mesh=True))
    out = tmp_path / "fall.usdc"
    scene.run(out, progress=False, device="cpu")
    stage = Usd.Stage.Open(str(out))
    render = UsdGeom.Mesh(stage.GetPrimAtPath("/World/ball_render"))
    p0 = np.asarray(render.GetPointsAttr().Get(0.0), dtype=np.float64)
    p2 = np.asarray(render.GetPointsAttr().Get(2.0), dtype=np.float64)
    np.testing.assert_allclose(p0, shape.vertices, atol=1e-5)
    drop = p0[:, 2] - p2[:, 2]
    np.testing.assert_allclose(drop, 0.5 * 9.81 * 0.2**2, atol=1e-3)
    assert render.GetFaceVertexIndicesAttr().GetTimeSamples() == [0.0]
    assert validate_usd(out) == []


def test_block_dropped_on_ground_plane_comes_to_rest_on_it(tmp_path):
    """A block dropped from 5 cm onto the ground plane (friction 0.5, damping 2 /s) ends at rest on it: no vertex
    below the plane (the collider projects vertices back, 1e-6 m) and the lowest vertices within 2 mm of it (the
    block's own weight compresses it by about 1e-4 m)."""
    scene = pdsim.Scene(fps=20, frames=20, name="drop")
    mesh = box_tet_mesh((0.2, 0.2, 0.1), (2, 2, 1), center=(0.0, 0.0, 0.1))
    scene.add_body(FemBody(mesh, MAT, damping=2.0, name="block"))
    scene.add_ground_plane(height=0.0, friction=0.5)
    solver = scene.build_solver(device="cpu")
    dt = 0.7 * solver.stable_time_step()
    solver.simulate(dt, int(1.0 / dt))
    z = solver.positions()[:, 2]
    assert z.min() >= -1e-6
    assert z.min() <= 2e-3
    assert np.abs(solver.velocities()).max() < 0.05
