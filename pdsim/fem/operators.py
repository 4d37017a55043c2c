"""The operator interface of the tetrahedral FEM solver that its implicit step (pdsim/fem/implicit.py) and its
quasi-static solve (pdsim/fem/static.py) use: :class:`pdsim.fem.solver.SolverFem` provides it, and those modules see
the solver only through it (they never import pdsim/fem/solver.py, which imports them).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .cg import CgReport, FemCg


class FemOperators(Protocol):
    """What the implicit step and the static solve read and call on the solver.

    State: ``kin`` (the shared :class:`pdsim.kinematics.PointKinematics` on the vertices: displacements [m],
    velocities [m/s], boundary conditions), ``force`` (Warp vec3 per vertex: the nodal forces [N] of the last
    evaluation), ``cg`` (the :class:`FemCg` of the current topology: its ``rhs``, ``x`` and ``constrained`` arrays),
    ``lumped_mass`` (Warp, lumped mass per vertex [kg]), ``lumped_mass_host`` (the same, float64 numpy [kg]),
    ``vertex_damping_host`` (mass-proportional damping c per vertex [1/s], float64 numpy), ``gravity`` (Warp vec3
    [m/s^2]) and ``gravity_host`` (float64 numpy [m/s^2]), ``dtype`` / ``np_dtype`` (the scalar type, Warp and numpy),
    ``device``, ``time`` [s], ``point_count``, ``measure``, ``integrator``, ``cg_reports`` (of the last solve).
    """

    kin: object
    force: object
    cg: FemCg
    lumped_mass: object
    lumped_mass_host: np.ndarray
    vertex_damping_host: np.ndarray
    gravity: object
    gravity_host: np.ndarray
    dtype: object
    np_dtype: object
    device: object
    time: float
    point_count: int
    measure: str
    integrator: str
    cg_reports: list

    def element_forces(self, dt: float, displacements=None) -> None:
        """Corner forces [N] of every element at ``displacements`` (Warp [m]; default: the current ones), with the
        plastic update of a step of ``dt`` [s] (0: none); fracture's over-strength count starts from zero."""

    def loads_into_force(self, t: float) -> None:
        """``force`` <- the loads [N] at time ``t`` [s] (zero without loads)."""

    def add_element_forces(self) -> None:
        """``force`` += the element corner forces gathered per vertex [N]."""

    def update_accelerations(self) -> None:
        """a = f / m + g - c v [m/s^2] at the current state (explicit integrator), no kick, no plastic update."""

    def apply_colliders(self, time: float, dt: float) -> None:
        """The ground plane, then the scene's colliders, on the free vertices at ``time`` [s] for a step of ``dt``
        [s]."""

    def reset_over_count(self) -> None:
        """Zeroes fracture's over-strength count (no-op without fracture): forces evaluated outside a step split
        nothing."""

    def cg_solve(self, op_mass, c_mass: float, c_stiff: float, *, tolerance=None, max_iterations=None) -> CgReport:
        """Solves (c_mass diag(op_mass) + c_stiff K_R) x = ``cg.rhs`` on the free components (``cg.constrained``),
        ``cg.x`` the initial guess and the result; op_mass [kg] per vertex (Warp), K_R [N/m]; tolerance: relative
        residual (default: the solver's ``cg_tolerance``), max_iterations (default: ``cg_max_iterations``)."""


__all__ = ["FemOperators"]
