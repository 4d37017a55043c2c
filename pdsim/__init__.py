"""pdsim: fracture-animation simulator on NVIDIA Warp, writing USD animation caches.

Importing pdsim is light: Warp, pxr and trimesh load on first use.
"""

from __future__ import annotations

__version__ = "0.1.0"

from .errors import FeatureNotAvailableError, GeometryError, InstabilityError, ParameterError, PdsimError
from .geometry import SolidShape, box, cylinder, load_mesh, shape_from_arrays, sphere
from .contact import BoxProjectile, MeshCollider, MeshProjectile, SphereProjectile
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
)
from .lattice_solver import SolverLattice
from .materials import Anisotropy, Material
from .peridynamics import GroundPlane, PeridynamicBody, SolverPeridynamics
from .regions import BoxRegion, HalfSpace, SphereRegion
from .scene import RunReport, Scene

__all__ = [
    "Anisotropy",
    "BoxProjectile",
    "BoxRegion",
    "FeatureNotAvailableError",
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
    "RunReport",
    "Scene",
    "SolidShape",
    "SolverLattice",
    "SolverPeridynamics",
    "SphereProjectile",
    "SphereRegion",
    "__version__",
    "box",
    "cylinder",
    "load_mesh",
    "shape_from_arrays",
    "sphere",
]
