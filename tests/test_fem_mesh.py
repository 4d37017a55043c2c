"""Tetrahedral meshes for the FEM solid: meshing with fTetWild, loading ready meshes (meshio, USD TetMesh), orientation
fixed on load, and bad input (open surfaces, degenerate, inverted and non-manifold elements, nu >= 0.5)."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, FemPlasticity
from pdsim.fem.fracture import closed_surface_defects
from pdsim.fem.mesh import (
    box_tet_mesh,
    signed_volumes,
    tet_mesh_from_arrays,
    tetrahedralize,
    write_tet_mesh,
)
from pdsim.fem.mesh_files import load_tet_mesh

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)


def _need_pytetwild():
    """Skips without pytetwild (found by spec: its package import needs pyvista, which pdsim does not)."""
    import importlib.util

    if importlib.util.find_spec("pytetwild") is None:
        pytest.skip("pytetwild is not installed")


def _unit_tet():
    return np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]])


def test_tetrahedralize_box_fills_the_volume_with_positive_quality_elements():
    """fTetWild fills a closed box: the tetrahedra's volumes sum to the box volume within the mesher's envelope
    (epsilon x bounding-box diagonal x surface area), every element is positively oriented after loading, the quality
    is bounded away from zero, and the boundary is a closed surface."""
    _need_pytetwild()
    size = np.array([0.4, 0.2, 0.1])
    eps = 1.0e-3
    mesh = tetrahedralize(pdsim.box(size), edge_length=0.05, epsilon=eps)
    exact = float(np.prod(size))
    area = 2.0 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2])
    assert abs(mesh.volume - exact) <= eps * np.linalg.norm(size) * area
    assert signed_volumes(mesh.vertices, mesh.tets).min() > 0.0
    assert mesh.quality.min() > 0.05
    assert closed_surface_defects(mesh.boundary_faces()) == 0


def test_structured_box_mesh_is_conforming_and_exact():
    """The structured (Kuhn) box mesh tiles the box exactly: volume equal to the box's to round-off (1e-12 relative),
    every element positive, boundary closed with 2 x 2 triangles per boundary cell face."""
    mesh = box_tet_mesh((1.0, 0.5, 0.25), (4, 2, 1))
    assert mesh.element_count == 6 * 8
    assert abs(mesh.volume - 0.125) <= 1.0e-12 * 0.125
    assert mesh.volumes.min() > 0.0
    faces = mesh.boundary_faces()
    assert len(faces) == 2 * 2 * (4 * 2 + 2 * 1 + 4 * 1)
    assert closed_surface_defects(faces) == 0


@pytest.mark.parametrize("suffix", [".msh", ".vtk", ".vtu"])
def test_meshio_round_trip_fixes_orientation(tmp_path, suffix):
    """A mesh written with the opposite winding (all elements negative) loads positively oriented with the same
    vertices and the same total volume (1e-12 relative)."""
    pytest.importorskip("meshio")
    mesh = box_tet_mesh((0.3, 0.2, 0.1), (3, 2, 1), jitter=0.2)
    flipped = mesh.tets[:, [0, 1, 3, 2]]
    path = tmp_path / f"flipped{suffix}"
    write_tet_mesh(type(mesh)(vertices=mesh.vertices, tets=flipped), path)
    loaded = load_tet_mesh(path)
    assert loaded.element_count == mesh.element_count
    assert loaded.volumes.min() > 0.0
    assert abs(loaded.volume - mesh.volume) <= 1.0e-12 * mesh.volume
    np.testing.assert_allclose(loaded.vertices, mesh.vertices, rtol=0, atol=1e-12)


def test_usd_tetmesh_is_loaded_in_world_space(tmp_path):
    """A UsdGeom.TetMesh under a translated Xform loads with its points moved by the translation [m]."""
    from pxr import Gf, Usd, UsdGeom, Vt

    mesh = box_tet_mesh((0.2, 0.2, 0.2), (2, 2, 2))
    path = str(tmp_path / "tets.usda")
    stage = Usd.Stage.CreateNew(path)
    xf = UsdGeom.Xform.Define(stage, "/World")
    xf.AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    tm = UsdGeom.TetMesh.Define(stage, "/World/body")
    tm.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(mesh.vertices.astype(np.float32)))
    tm.CreateTetVertexIndicesAttr(Vt.Vec4iArray.FromNumpy(mesh.tets.astype(np.int32)))
    stage.Save()
    loaded = load_tet_mesh(path)
    assert loaded.element_count == mesh.element_count
    np.testing.assert_allclose(loaded.vertices, mesh.vertices + np.array([1.0, 2.0, 3.0]), atol=1e-6)


def test_flat_surface_is_rejected(tmp_path):
    """A flat open sheet (a square of two triangles) encloses no volume: building the shape (from arrays or from a
    file) raises GeometryError."""
    import trimesh

    vertices = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]]
    faces = [[0, 1, 2], [0, 2, 3]]
    with pytest.raises(pdsim.GeometryError, match="encloses no volume"):
        pdsim.shape_from_arrays(vertices, faces)
    path = tmp_path / "open.obj"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    with pytest.raises(pdsim.GeometryError, match="encloses no volume"):
        FemBody(pdsim.load_mesh(path), MAT)


def test_zero_volume_and_repeated_vertex_elements_are_rejected():
    """A flat element (four coplanar corners) and an element with a repeated vertex have zero volume: GeometryError
    naming the element."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    with pytest.raises(pdsim.GeometryError, match="element 0 is degenerate"):
        tet_mesh_from_arrays(v, [[0, 1, 2, 3]])
    v2, _ = _unit_tet()
    with pytest.raises(pdsim.GeometryError, match="repeated vertex"):
        tet_mesh_from_arrays(v2, [[0, 1, 2, 2]])


def test_inverted_element_is_rejected_but_mixed_winding_is_fixed():
    """Two elements on the same side of their shared face overlap (one is inverted, folded over the other):
    GeometryError. The same two corner sets on opposite sides, written with mixed winding, load with both volumes
    positive."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0.2, 0.2, 1.0], [0.3, 0.3, 0.5], [0.2, 0.2, -1.0]])
    with pytest.raises(pdsim.GeometryError, match="inverted"):
        tet_mesh_from_arrays(v, [[0, 1, 2, 3], [0, 2, 1, 4]])
    mesh = tet_mesh_from_arrays(v, [[0, 1, 2, 3], [0, 1, 2, 5]])  # second one negative as written
    assert mesh.volumes.min() > 0.0
    assert mesh.vertex_count == 5  # the unused vertex 4 is dropped


def test_bad_indices_and_nonmanifold_faces_are_rejected():
    """Out-of-range indices and a face shared by three elements raise GeometryError."""
    v, _ = _unit_tet()
    with pytest.raises(pdsim.GeometryError, match="indices"):
        tet_mesh_from_arrays(v, [[0, 1, 2, 4]])
    v3 = np.vstack([v, [[0.3, 0.3, -1.0], [0.5, 0.5, 0.8]]])
    with pytest.raises(pdsim.GeometryError, match=r"not manifold|inverted"):
        tet_mesh_from_arrays(v3, [[0, 1, 2, 3], [0, 2, 1, 4], [0, 1, 2, 5]])


def test_bad_material_and_body_parameters_raise_parameter_errors():
    """nu >= 0.5 (incompressible: lambda infinite) and other out-of-range parameters raise ParameterError naming the
    field and the allowed range."""
    with pytest.raises(pdsim.ParameterError, match="poisson_ratio"):
        pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.5)
    with pytest.raises(pdsim.ParameterError, match="poisson_ratio"):
        pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.7)
    mesh = box_tet_mesh((1, 1, 1), (1, 1, 1))
    with pytest.raises(pdsim.ParameterError, match="measure"):
        FemBody(mesh, MAT, measure="cauchy")
    with pytest.raises(pdsim.ParameterError, match="measure"):
        FemBody(mesh, MAT, measure="green", integrator="implicit")
    with pytest.raises(pdsim.ParameterError, match="tensile_strength"):
        FemBody(mesh, MAT, tensile_strength=-1.0)
    with pytest.raises(pdsim.ParameterError, match="yield_strain"):
        FemPlasticity(yield_strain=0.0, creep=1.0, max_strain=0.1)
    with pytest.raises(pdsim.ParameterError, match="edge_length"):
        tetrahedralize(pdsim.box((1, 1, 1)), edge_length=-0.1)  # checked before the mesher is loaded


def test_mesh_cache_makes_meshing_reproducible(tmp_path):
    """fTetWild's output varies from run to run; with a cache folder the second call returns the first call's mesh
    exactly (same vertices to the last bit, same elements)."""
    _need_pytetwild()
    pytest.importorskip("meshio")
    shape = pdsim.box((0.3, 0.2, 0.1))
    a = tetrahedralize(shape, edge_length=0.05, cache_dir=tmp_path)
    b = tetrahedralize(shape, edge_length=0.05, cache_dir=tmp_path)
    assert len(list(tmp_path.glob("*.vtu"))) == 1
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.tets, b.tets)


def test_stable_order_is_numpys_stable_argsort():
    """pdsim.fem.mesh.stable_order gives numpy's stable argsort exactly (equal keys in index order): on keys with many
    repeats (the vertex of each element corner, the triple of each face), on an empty array, and on keys too large
    for the unique-key form (the stable sort itself)."""
    from pdsim.fem.mesh import stable_order

    rng = np.random.default_rng(7)
    for keys in (
        rng.integers(0, 50, 10_000),
        rng.integers(0, 2**40, 5_000),
        np.zeros(0, dtype=np.int64),
        np.array([2**62, 3, 2**62, 0], dtype=np.int64),
    ):
        assert np.array_equal(stable_order(keys), np.argsort(keys, kind="stable"))
