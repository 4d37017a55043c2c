"""State-based peridynamics (the peridynamics supplement of the project specification): bodies, the model built from
them, the explicit solver and the renderable fragment surfaces."""

from .body import SURFACE_CORRECTIONS, PeridynamicBody
from .handoff import RigidHandoff
from .model import PeridynamicModel, PeridynamicState, build_model
from .solver import SolverPeridynamics

__all__ = [
    "SURFACE_CORRECTIONS",
    "PeridynamicBody",
    "PeridynamicModel",
    "PeridynamicState",
    "RigidHandoff",
    "SolverPeridynamics",
    "build_model",
]
