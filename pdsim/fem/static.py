"""Quasi-static solve of the tetrahedral FEM solver (:meth:`SolverFem.solve_static`, pdsim/fem/solver.py): Newton
iterations with the CG of the implicit step (pdsim/fem/cg.py) on f_int(u) + f_ext(t) + M g = 0, with the same loads
(gravity, body forces, tractions, pressures, forces) and the per-axis boundary conditions.

The tangent is K_R with the rotations frozen per iteration (the constant K for the linear and the Green measure); the
linear measure needs one iteration. In float32 the residual stalls at round-off, so the iterations also stop when an
update is below max(tolerance, 1000 eps) times the displacement change so far.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from ..checks import check_range
from ..errors import ParameterError
from ..kernels.fem import solver as ks
from ..kernels.launch import by_name
from .operators import FemOperators


@dataclass
class StaticSolveReport:
    """Outcome of :meth:`SolverFem.solve_static`: Newton iterations, CG iterations in total, the final equilibrium
    residual |f_int + f_ext| over the free components [N] and relative to the external load."""

    newton_iterations: int
    cg_iterations: int
    residual: float
    relative_residual: float


def solve_static(
    solver: FemOperators,
    *,
    constrained=None,
    time: float | None = None,
    tolerance: float = 1.0e-6,
    max_newton_iterations: int = 30,
    cg_tolerance: float | None = None,
    cg_max_iterations: int = 20000,
) -> StaticSolveReport:
    """:meth:`SolverFem.solve_static` of ``solver`` (its :class:`FemOperators`; the arguments are documented
    there)."""
    s = solver
    n = s.point_count
    kin, cg = s.kin, s.cg
    t = s.time if time is None else float(time)
    tolerance = check_range("tolerance", tolerance, 0.0, None)
    d, dtype = s.device, s.dtype
    if constrained is None:
        if kin.condition_count:
            kin.evaluate_conditions(t)
        ks.constraint_bits(
            **by_name(kin, "point_condition", "active_kind", "cond_axes", "point_kind"),
            constrained=cg.constrained,
            dtype=dtype,
            device=d,
        )
        bits = cg.constrained.numpy()
    else:
        mask = np.asarray(constrained)
        if mask.shape != (n,) or mask.dtype != np.bool_:
            raise ParameterError("constrained", constrained, f"a bool mask of shape ({n},) or None")
        bits = np.where(mask, 7, 0).astype(np.int32)
        wp.copy(cg.constrained, wp.array(bits, dtype=wp.int32, device=d))
    free = ((bits[:, None] >> np.arange(3)) & 1) == 0  # [n, 3]
    s.loads_into_force(t)
    external = s.force.numpy().astype(np.float64) + s.lumped_mass_host[:, None] * s.gravity_host
    load = float(np.linalg.norm(external[free]))
    zero_mass = wp.zeros(n, dtype=s.dtype, device=d)
    reports = []
    u_start = kin.displacements()
    step_tol = max(tolerance, 1000.0 * float(np.finfo(s.np_dtype).eps))

    def residual_norm() -> float:
        s.element_forces(0.0)
        s.loads_into_force(t)
        s.add_element_forces()
        ks.residual_forces(
            forces=s.force,
            mass=s.lumped_mass,
            gravity=s.gravity,
            constrained=cg.constrained,
            residual=cg.rhs,
            dtype=dtype,
            device=d,
        )
        return float(np.linalg.norm(cg.rhs.numpy().astype(np.float64)))

    try:
        res = residual_norm()
        ref = load if load > 0.0 else max(res, 1.0e-300)
        for newton in range(int(max_newton_iterations)):
            if res <= tolerance * ref:
                break
            cg.x.zero_()
            reports.append(s.cg_solve(zero_mass, 0.0, 1.0, tolerance=cg_tolerance, max_iterations=cg_max_iterations))
            ks.apply_increment(displacements=kin.u, du=cg.x, dtype=dtype, device=d)
            du = float(np.linalg.norm(cg.x.numpy().astype(np.float64)))
            u = float(np.linalg.norm(kin.displacements() - u_start))
            res = residual_norm()
            if s.measure == "linear":
                break  # the linear problem is solved by one iteration (to the CG tolerance)
            if newton > 0 and du <= step_tol * u:
                break  # converged in the increment (float32 round-off bounds the residual)
    finally:
        s.reset_over_count()
    s.cg_reports = reports
    if s.integrator == "explicit":
        s.update_accelerations()
    return StaticSolveReport(
        newton_iterations=len(reports),
        cg_iterations=sum(r.iterations for r in reports),
        residual=res,
        relative_residual=res / ref if ref else 0.0,
    )


__all__ = ["StaticSolveReport", "solve_static"]
