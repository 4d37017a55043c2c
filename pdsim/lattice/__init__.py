"""Position-based particle lattice (dell'Erba 2018): lattices and neighbourhoods (geometry.py), rules and fracture
(rules.py), bodies (body.py) and the solver (solver.py). The paper's cases live in scenes/lattice_paper.py and its
figures in tools/lattice_plots.py."""

from .body import LatticeBody, LatticeKind
from .geometry import Lattice, LatticeNeighbourhood, LatticeType
from .rules import (
    LatticeFracture,
    LatticeRule,
    LatticeRuleCentroid,
    LatticeRuleDistanceWeighted,
    LatticeRuleMixedCoordinate,
)
from .solver import SolverLattice

# The lattice package's public names; pdsim/__init__.py repeats them within its own alphabetical __all__ (the package's
# top-level namespace), so each list is complete where it is read.
__all__ = [
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
    "SolverLattice",
]
