"""Loading ready tetrahedral meshes in any supported format, USD TetMesh included. Apart from pdsim/fem/mesh.py
(meshing, element data, meshio files) so that the FEM solver, which reads no USD, never imports pxr."""

from __future__ import annotations

import os

from ..errors import GeometryError
from ..output.usd_files import read_tet_mesh
from .mesh import DEFAULT_MIN_QUALITY, TET_MESH_SUFFIXES, TetMesh, read_meshio_tets, tet_mesh_from_arrays


def load_tet_mesh(
    path: str | os.PathLike,
    *,
    scale: float = 1.0,
    translate=(0.0, 0.0, 0.0),
    name: str | None = None,
    prim_path: str | None = None,
    min_quality: float = DEFAULT_MIN_QUALITY,
) -> TetMesh:
    """Loads a ready tetrahedral mesh: Gmsh .msh, VTK .vtk/.vtu, Medit .mesh, Abaqus .inp, ... through meshio, or a
    ``UsdGeom.TetMesh`` from .usd/.usda/.usdc (the first one, or the prim at ``prim_path``; its points are taken in
    world space). Only the tetrahedra of the file are used. Checked as :func:`tet_mesh_from_arrays`.

    Args:
        path: mesh file.
        scale: uniform scale [-], > 0, applied before ``translate`` [m].
        name: label; defaults to the file's stem.
        prim_path: USD only: the TetMesh prim to load.
        min_quality: smallest allowed element quality.
    """
    path = os.fspath(path)
    label = name or os.path.splitext(os.path.basename(path))[0]
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in TET_MESH_SUFFIXES:
        raise GeometryError(
            f"{path}: unknown tetrahedral mesh type '{suffix}'; supported: {', '.join(TET_MESH_SUFFIXES)}"
        )
    if not os.path.isfile(path):
        raise GeometryError(f"{path}: no such file")
    if suffix in (".usd", ".usda", ".usdc"):
        v, t = read_tet_mesh(path, prim_path)
    else:
        v, t = read_meshio_tets(path)
    mesh = tet_mesh_from_arrays(v, t, name=label, min_quality=min_quality)
    return mesh.transformed(scale=scale, translate=translate)
