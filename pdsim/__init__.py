"""pdsim: fracture-animation simulator on NVIDIA Warp, writing USD animation caches.

Importing pdsim is light: Warp, pxr and trimesh load on first use.
"""

from __future__ import annotations

__version__ = "0.1.0"

from . import presets as presets  # named materials: pdsim.presets.glass(), ceramic, stone, plaster, steel, ...
from .bodies import BoundaryCondition, PointKind
from .colliders import BoxProjectile, GroundPlane, MeshCollider, MeshProjectile, SphereProjectile
from .errors import FeatureNotAvailableError, GeometryError, InstabilityError, ParameterError, PdsimError
from .fem import (
    FemBody,
    FemPlasticity,
    SolverFem,
    TetMesh,
    box_tet_mesh,
    load_tet_mesh,
    tet_mesh_from_arrays,
    tetrahedralize,
    write_tet_mesh,
)
from .geometry import SolidShape, box, cylinder, load_mesh, shape_from_arrays, sphere
from .lattice import (
    Lattice,
    LatticeBody,
    LatticeFracture,
    LatticeKind,
    LatticeNeighbourhood,
    LatticeRule,
    LatticeRuleCentroid,
    LatticeRuleDistanceWeighted,
    LatticeRuleMixedCoordinate,
    LatticeType,
    SolverLattice,
)
from .loads import TimeCurve
from .materials import Anisotropy, Material
from .peridynamics import PeridynamicBody, RigidHandoff, SolverPeridynamics
from .regions import BoxRegion, HalfSpace, SphereRegion
from .rigid import BoxShape, RigidBody, SphereShape
from .scene import RunReport, Scene
from .solver import Solver, SolverContext

__all__ = [
    "Anisotropy",
    "BoundaryCondition",
    "BoxProjectile",
    "BoxRegion",
    "BoxShape",
    "FeatureNotAvailableError",
    "FemBody",
    "FemPlasticity",
    "GeometryError",
    "GroundPlane",
    "HalfSpace",
    "InstabilityError",
    "Lattice",
    "LatticeBody",
    "LatticeFracture",
    "LatticeKind",
    "LatticeNeighbourhood",
    "LatticeRule",
    "LatticeRuleCentroid",
    "LatticeRuleDistanceWeighted",
    "LatticeRuleMixedCoordinate",
    "LatticeType",
    "Material",
    "MeshCollider",
    "MeshProjectile",
    "ParameterError",
    "PdsimError",
    "PeridynamicBody",
    "PointKind",
    "RigidBody",
    "RigidHandoff",
    "RunReport",
    "Scene",
    "SolidShape",
    "Solver",
    "SolverContext",
    "SolverFem",
    "SolverLattice",
    "SolverPeridynamics",
    "SphereProjectile",
    "SphereRegion",
    "SphereShape",
    "TetMesh",
    "TimeCurve",
    "__version__",
    "box",
    "box_tet_mesh",
    "cylinder",
    "load_mesh",
    "load_tet_mesh",
    "shape_from_arrays",
    "sphere",
    "tet_mesh_from_arrays",
    "tetrahedralize",
    "write_tet_mesh",
]
