"""Position-based particle lattice (shared/seeds/pbd_lattice.txt): lattices, neighbourhoods, rules, bodies and the
solver. The paper's cases live in scenes/lattice_paper.py and its figures in tools/lattice_plots.py."""

from .body import (
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
from .solver import SolverLattice

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
