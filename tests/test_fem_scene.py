"""The FEM solid on the method-neutral core: output views of boundary surfaces (closed, topology version changing
only when fracture changes it, crack and fragment face attributes), the embedded render mesh, the ground-plane
collider in the local frame, and the settings the FEM refuses (FeatureNotAvailableError)."""

import itertools
import math
import pathlib

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, FemPlasticity, SolverFem
from pdsim.fem.fracture import closed_surface_defects
from pdsim.fem.mesh import box_tet_mesh, tet_mesh_from_arrays
from pdsim.output.views import MeshView, PointsView
from pdsim.solver import SolverContext, solver_for

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
ROOT = pathlib.Path(__file__).resolve().parents[1]


def _notched_bar():
    m0 = box_tet_mesh((1.0, 0.1, 0.1), (20, 2, 2), center=(0.5, 0.0, 0.0))
    c = m0.vertices[m0.tets].mean(axis=1)
    notch = (np.abs(c[:, 0] - 0.3) < 0.025) & (c[:, 2] > 0.0)
    return tet_mesh_from_arrays(m0.vertices, m0.tets[~notch], name="bar")


def _views_by_name(solver):
    return {v.name: v for v in solver.views()}


@pytest.mark.parametrize("crack_surfaces", ["elements", "smooth"])
def test_fracturing_body_views_closed_surfaces_with_topology_versions_only_on_change(crack_surfaces):
    """A notched bar pulled apart (implicit, 10 frames of 0.1 s): each frame's views hold a PointsView "bar" of the
    input vertices (a fixed count: world positions, displacement and fragment attributes) and a MeshView
    "bar_surface" whose topology version changes on some frames but not all (only when fracture changed the faces;
    unchanged versions come with identical faces); every frame's surface is closed (each directed edge has one
    opposite edge), the faces created by fracture carry crack = 1 (none at frame 0, some at the end) and the two
    pieces at the end have distinct fragment ids on faces and vertices. The PointsView carries the reactions of both
    boundary conditions, and the solver's contact mesh (for contact with particle methods) is a closed surface with
    the solver's topology version: with crack_surfaces="elements" the very surface drawn (the boundary faces of the
    elements; "smooth" draws the input surface with fitted crack surfaces, tests/test_fem_crack_surfaces.py)."""
    body = FemBody(
        _notched_bar(), MAT, tensile_strength=2.0e4, integrator="implicit", damping=5.0, crack_surfaces=crack_surfaces
    )
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1e-6, 1, 1)))
    body.set_velocity(pdsim.BoxRegion(lo=(1.0 - 1e-6, -1, -1), hi=(2, 1, 1)), (0.1, 0.0, 0.0))
    assert solver_for(body) is SolverFem
    solver = SolverFem([body], SolverContext(origin=np.array([0.5, 0.0, 0.0])))
    steps = math.ceil(0.1 / solver.stable_time_step())
    frames = []
    for frame in range(11):
        if frame:
            solver.simulate(0.1 / steps, steps)
        views = _views_by_name(solver)
        assert set(views) == {"bar", "bar_surface"}
        points, surface = views["bar"], views["bar_surface"]
        assert isinstance(points, PointsView) and isinstance(surface, MeshView)
        # the input vertices, in their order, on every frame (the crack copies show in the surface only)
        n = body.vertex_count
        assert points.positions.shape == (n, 3) == points.attributes["displacement"].shape
        np.testing.assert_array_equal(solver.rest_positions[:n], body.mesh.vertices)
        np.testing.assert_allclose(points.positions, body.mesh.vertices + points.attributes["displacement"])
        assert surface.faces.max() < len(surface.points)
        assert closed_surface_defects(surface.faces) == 0
        assert set(points.reactions) == {"fix_0", "velocity_1"}
        ids, tris, version = solver.contact_mesh()  # the elements' boundary, for contact between methods
        assert version == solver.topology_version and closed_surface_defects(tris.numpy().reshape(-1, 3)) == 0
        if crack_surfaces == "elements":  # the same closed surface
            assert tris.shape[0] == 3 * len(surface.faces) and ids.shape[0] == len(surface.points)
        frames.append((surface.topology_version, surface.faces.copy(), surface.face_attributes, points.attributes))
    versions = [f[0] for f in frames]
    assert versions[0] == 0 and 1 < len(set(versions)) < len(versions)
    for (v0, f0, _, _), (v1, f1, _, _) in itertools.pairwise(frames):
        if v0 == v1:
            np.testing.assert_array_equal(f0, f1)
    assert frames[0][2]["crack"].sum() == 0 and frames[-1][2]["crack"].sum() > 0
    assert len(np.unique(frames[-1][2]["fragment"])) >= 2
    assert len(np.unique(frames[-1][3]["fragment"])) >= 2


def test_scene_run_writes_the_fem_views(tmp_path):
    """End to end through Scene.run and the view writer: the fracturing notched bar gives a UsdGeom.Points "bar" with
    the same point count on every frame and a UsdGeom.Mesh "bar_surface" with points on every frame and its topology
    (face indices, fragment and crack primvars) only on frame 0 and the frames where fracture changed it; the stage
    passes pxr.UsdValidation."""
    from pxr import Usd, UsdGeom

    from pdsim.output.usd_files import usd_problems

    scene = pdsim.Scene(fps=10, frames=6, gravity=(0.0, 0.0, 0.0), name="pull")
    body = FemBody(_notched_bar(), MAT, tensile_strength=2.0e4, integrator="implicit", damping=5.0)
    body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(1e-6, 1, 1)))
    body.set_velocity(pdsim.BoxRegion(lo=(1.0 - 1e-6, -1, -1), hi=(2, 1, 1)), (0.2, 0.0, 0.0))
    scene.add_body(body)
    out = tmp_path / "pull.usdc"
    report = scene.run(out, progress=False, device="cpu")
    assert report.frames_written == 7
    stage = Usd.Stage.Open(str(out))
    points = UsdGeom.Points(stage.GetPrimAtPath("/World/bar"))
    assert {len(points.GetPointsAttr().Get(float(t))) for t in range(7)} == {body.vertex_count}
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/bar_surface"))
    assert mesh.GetPointsAttr().GetTimeSamples() == [float(f) for f in range(7)]
    topo = mesh.GetFaceVertexIndicesAttr().GetTimeSamples()
    assert topo[0] == 0.0 and 1 < len(topo) < 7
    for t in topo:
        faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(t)).reshape(-1, 3)
        assert closed_surface_defects(faces) == 0 and faces.max() < len(mesh.GetPointsAttr().Get(t))
    assert usd_problems(out) == []


def test_render_mesh_follows_the_tetrahedra():
    """A sphere surface embedded in a box of tetrahedra as a render mesh: at rest the embedding reproduces the input
    vertices (1e-5 m), and after the body falls freely for 0.2 s every render vertex has moved by
    g t^2 / 2 = 0.196 m (1e-3 m) and moves at g t = 1.96 m/s (1e-3 m/s): the barycentric weights follow the
    tetrahedra. Its topology version never changes."""
    shape = pdsim.sphere(0.15, subdivisions=2, center=(0.0, 0.0, 1.0), name="ball")
    mesh = box_tet_mesh((0.4, 0.4, 0.4), (4, 4, 4), center=(0.0, 0.0, 1.0), name="ball")
    solver = SolverFem([FemBody(mesh, MAT, render_mesh=shape)], gravity=(0.0, 0.0, -9.81))
    assert "render_mesh" in solver.features
    p0 = _views_by_name(solver)["ball_render"]
    np.testing.assert_allclose(p0.points, shape.vertices, atol=1e-5)
    dt = solver.stable_time_step()
    steps = math.ceil(0.2 / dt)
    solver.simulate(0.2 / steps, steps)
    p2 = _views_by_name(solver)["ball_render"]
    np.testing.assert_allclose(p0.points[:, 2] - p2.points[:, 2], 0.5 * 9.81 * 0.2**2, atol=1e-3)
    np.testing.assert_allclose(p2.velocities[:, 2], -9.81 * 0.2, atol=1e-3)
    np.testing.assert_array_equal(p2.faces, np.asarray(shape.faces))
    assert p0.topology_version == p2.topology_version == 0


def test_block_dropped_on_ground_plane_comes_to_rest_on_it():
    """A block dropped from 5 cm onto the ground plane (friction 0.5, damping 2 /s) ends at rest on it: no vertex
    below the plane (the collider projects vertices back, 1e-6 m) and the lowest vertices within 2 mm of it (the
    block's own weight compresses it by about 1e-4 m). Built by the Scene: the solver's local frame is centred on the
    block and the solver binds the plane to that origin."""
    scene = pdsim.Scene(fps=20, frames=20, name="drop")
    mesh = box_tet_mesh((0.2, 0.2, 0.1), (2, 2, 1), center=(0.0, 0.0, 0.1))
    scene.add_body(FemBody(mesh, MAT, damping=2.0, name="block"))
    scene.add_ground_plane(height=0.0, friction=0.5)
    solver = scene.build_solver(device="cpu")
    assert isinstance(solver, SolverFem) and "ground_plane" in solver.features
    np.testing.assert_allclose(solver.kin.origin, [0.0, 0.0, 0.1])
    dt = 0.7 * solver.stable_time_step()
    solver.simulate(dt, int(1.0 / dt))
    z = solver.positions()[:, 2]
    assert z.min() >= -1e-6
    assert z.min() <= 2e-3
    assert np.abs(solver.velocities()).max() < 0.05


def test_plastic_body_views_carry_plastic_strain():
    """A yielding body's PointsView carries a per-vertex plastic_strain attribute (>= 0, float); an elastic one
    does not."""
    mesh = box_tet_mesh((0.2, 0.1, 0.1), (2, 1, 1))
    plastic = FemBody(mesh, MAT, plasticity=FemPlasticity(yield_strain=0.001, creep=100.0, max_strain=0.5))
    solver = SolverFem([plastic])
    solver.set_positions(mesh.vertices * np.array([1.05, 1.0, 1.0]))
    solver.step(solver.stable_time_step())
    ep = _views_by_name(solver)["box"].attributes["plastic_strain"]
    assert ep.shape == (mesh.vertex_count,) and ep.min() >= 0.0 and ep.max() > 0.0
    assert "plastic_strain" not in _views_by_name(SolverFem([FemBody(mesh, MAT)]))["box"].attributes


@pytest.mark.parametrize(
    ("material", "field", "instead"),
    [
        (pdsim.Material(1000.0, 1.0e6, 0.3, yield_stress=1.0e4), "yield_stress", "FemPlasticity"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, critical_stretch=0.01), "critical_stretch", "tensile_strength"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, fracture_energy=10.0), "fracture_energy", "tensile_strength"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, anisotropy=pdsim.Anisotropy()), "anisotropy", "isotropic"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, hardening_modulus=1.0e5), "hardening_modulus", "FemPlasticity"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, compressive_bonus=1.0), "compressive_bonus", "tensile_strength"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, retardation_time=1.0e-5), "retardation_time", r"FemBody\(\.\.\., damping"),
        (pdsim.Material(1000.0, 1.0e6, 0.3, rigid_handoff=True), "rigid_handoff", "rigid_handoff=False"),
    ],
)
def test_peridynamic_material_fields_are_refused(material, field, instead):
    """Material fields the FEM does not read (peridynamic plasticity, fracture, anisotropy, internal damping and the
    rigid hand-off) raise FeatureNotAvailableError naming the body, the field and the FEM setting to use instead."""
    body = FemBody(box_tet_mesh((0.2, 0.1, 0.1), (2, 1, 1)), material, name="slab")
    with pytest.raises(pdsim.FeatureNotAvailableError, match=rf"'slab'.*{field}.*{instead}"):
        SolverFem([body])


def test_float64_with_a_collider_is_refused():
    """Colliders are float32 kernels: a float64 FEM solver with a ground plane raises FeatureNotAvailableError naming
    the body, the setting and the remedy."""
    body = FemBody(box_tet_mesh((0.2, 0.1, 0.1), (2, 1, 1)), MAT, name="slab")
    with pytest.raises(pdsim.FeatureNotAvailableError, match=r"'slab'.*float64.*use precision='float32'"):
        SolverFem([body], precision="float64", ground=pdsim.GroundPlane())


def test_context_and_shortcuts_are_exclusive():
    """A solver is built from a SolverContext or from the device/gravity/ground/colliders shortcuts, not both
    (ParameterError naming the shortcut)."""
    body = FemBody(box_tet_mesh((0.2, 0.1, 0.1), (2, 1, 1)), MAT)
    with pytest.raises(pdsim.ParameterError, match=r"gravity=.*SolverContext"):
        SolverFem([body], SolverContext(), gravity=(0.0, 0.0, -9.81))


def _two_fem_blocks():
    scene = pdsim.Scene(gravity=(0.0, 0.0, 0.0))
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
    for i, x in enumerate((30.0, 30.2)):
        scene.add_body(FemBody(box_tet_mesh((0.1, 0.1, 0.1), (2, 2, 2), center=(x, -4.0, 2.0)), material, name=f"b{i}"))
    return scene


def test_contact_between_fem_surfaces_is_on_unless_switched_off():
    """Two FEM bodies get contact between their surfaces (pdsim.contact.MethodContact with surfaces on), asked for
    or automatic, without a warning; with contact off there is none (tests/test_fem_contact.py tests the physics)."""
    import warnings

    from pdsim.run import method_contact

    for enabled in (True, None):
        scene = _two_fem_blocks()
        if enabled:
            scene.enable_contact(True)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            solvers = scene.build_solvers(device="cpu")
        coupling = method_contact(scene, solvers)
        assert coupling is not None and coupling.surfaces
    scene = _two_fem_blocks()
    scene.enable_contact(False)
    assert method_contact(scene, scene.build_solvers(device="cpu")) is None
