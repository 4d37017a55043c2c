"""Tetrahedral FEM: bodies, meshing, the explicit/implicit/static solver and fracture by vertex splitting."""

from .body import FemBody, FemPlasticity
from .cg import CgReport
from .mesh import TetMesh, box_tet_mesh, tet_mesh_from_arrays, tetrahedralize, write_tet_mesh
from .mesh_files import load_tet_mesh
from .solver import SolverFem
from .static import StaticSolveReport

__all__ = [
    "CgReport",
    "FemBody",
    "FemPlasticity",
    "SolverFem",
    "StaticSolveReport",
    "TetMesh",
    "box_tet_mesh",
    "load_tet_mesh",
    "tet_mesh_from_arrays",
    "tetrahedralize",
    "write_tet_mesh",
]
