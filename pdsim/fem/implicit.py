"""The implicit integrator of the tetrahedral FEM solver (pdsim/fem/solver.py): linearly implicit backward Euler with
the corotated stiffness (kernels/fem/solver.py), one CG solve per step (pdsim/fem/cg.py), at any step size;
:meth:`SolverFem.stable_time_step` then reports ``implicit_step_ratio`` (default 10) times the explicit limit as the
step the scene should use. The linear measure uses the constant stiffness, the Green measure has no implicit
integrator here (ParameterError). Constrained components (boundary conditions, per axis) carry the condition's mid-step
velocity; the CG works on the free components.

    ((1 + dt c) M + dt^2 K_R) v_{n+1} = M v_n + dt (f(u_n) + f_ext + M g),   u_{n+1} = u_n + dt v_{n+1}
"""

from __future__ import annotations

import warp as wp

from ..kernels.fem import solver as ks
from ..kernels.launch import by_name
from .operators import FemOperators


class BackwardEuler:
    """The backward-Euler step of a solver (the :class:`FemOperators` of a :class:`SolverFem`) for one topology of its
    mesh (the solver builds a new one with its vertex data), with the operator mass cached per step size."""

    def __init__(self, solver: FemOperators):
        self.solver = solver
        self._op_mass = None
        self._op_mass_dt = None

    def operator_mass(self, dt: float):
        """(1 + dt c) m per vertex [kg] (the mass term of the backward-Euler operator; dt [s], c [1/s]), cached per
        dt and topology."""
        s = self.solver
        if self._op_mass is None or self._op_mass_dt != dt:
            om = s.lumped_mass_host * (1.0 + dt * s.vertex_damping_host)
            self._op_mass = wp.array(om.astype(s.np_dtype), dtype=s.dtype, device=s.device)
            self._op_mass_dt = dt
        return self._op_mass

    def step(self, dt: float):
        """Backward Euler: kicks, conditions at the mid-step, forces at u_n with the loads at t + dt, the CG solve
        for v_{n+1} (constrained components at the condition's velocity), u += dt v, colliders at t + dt."""
        s = self.solver
        d, kin, t, cg = s.device, s.kin, s.time, s.cg
        kin.apply_kicks(t, dt)
        if kin.condition_count:
            kin.evaluate_conditions(t + 0.5 * dt)
        s.element_forces(dt)
        s.loads_into_force(t + dt)
        s.add_element_forces()
        ks.implicit_rhs(
            forces=s.force,
            mass=s.lumped_mass,
            velocities=kin.v,
            **by_name(kin, "point_condition", "active_kind", "cond_axes", "active_velocity", "point_kind"),
            gravity=s.gravity,
            dt=s.dtype(dt),
            rhs=cg.rhs,
            guess=cg.x,
            constrained=cg.constrained,
            dtype=s.dtype,
            device=d,
        )
        report = s.cg_solve(self.operator_mass(dt), 1.0, dt * dt)
        s.cg_reports = [report]
        wp.copy(kin.v, cg.x)
        ks.advance_displacements(displacements=kin.u, velocities=kin.v, dt=s.dtype(dt), dtype=s.dtype, device=d)
        s.apply_colliders(t + dt, dt)


__all__ = ["BackwardEuler"]
