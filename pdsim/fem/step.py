"""Time stepping of the tetrahedral FEM solver (:class:`pdsim.fem.solver.SolverFem`): the stable steps, the element
forces, loads and gathers (the operators that pdsim/fem/operators.py documents for the implicit step and the static
solve), the explicit velocity-Verlet step and the colliders, and the calls into the implicit step
(pdsim/fem/implicit.py) and the quasi-static solve (pdsim/fem/static.py).
"""

from __future__ import annotations

import math

import numpy as np

from ..checks import check_range
from ..contact import material_contact_values
from ..errors import ParameterError
from ..kernels.fem import elements as ke
from ..kernels.fem import solver as ks
from ..kernels.launch import by_name
from .cg import CgReport
from .static import StaticSolveReport, solve_static


class FemStep:
    """The stepping of :class:`pdsim.fem.solver.SolverFem` (a mixin over the solver's state: kinematics, element
    arrays, model; ``_implicit`` is the solver's :class:`pdsim.fem.implicit.BackwardEuler`)."""

    # -- time step ------------------------------------------------------------------------------------------------
    def explicit_time_step(self) -> float:
        """Stable explicit step 0.5 h_min / c_p [s] (see the module docstring)."""
        return self.model.explicit_dt

    def stable_time_step(self) -> float:
        """The step the scene should use [s]: the explicit limit, or ``implicit_step_ratio`` times it (implicit)."""
        if self.integrator == "implicit":
            return min(b.implicit_step_ratio for b in self.bodies) * self.model.explicit_dt
        return self.model.explicit_dt

    # -- the operators of the implicit step and the static solve (pdsim/fem/operators.py) ---------------------------
    def element_forces(self, dt: float, displacements=None, scatter: bool = False, store_rotation: bool = True) -> None:
        """Corner forces [N] of every element at ``displacements`` (Warp [m]; default: the current ones), with the
        plastic update of step dt [s]; fracture's over-strength count starts from zero. ``scatter`` (CPU only): added
        onto ``force`` per vertex in element order instead of written per corner (the same sums, in the same order,
        as the per-vertex gathers over the incidence list, whose slots run in element order). Without
        ``store_rotation`` (the explicit step, whose forces read the quaternions only) the rotation matrices are
        formed from the quaternions when next read (``_rotation``)."""
        m = self.model
        self._rotation_stale = self._rotated and not store_rotation
        if self.fracture:
            self._over_count.zero_()
        ke.element_forces(
            displacements=self.kin.u if displacements is None else displacements,
            tets=self._tets,
            **m.element_arrays,
            plastic_params=m.plastic_params,
            plastic_strain=self._plastic_strain,
            dt=self.dtype(dt),
            strength=self._strength,
            principal=self._principal,
            over_count=self._over_count,
            rotation_q=self._rotation_q,
            rotation=self._rotation_matrix,
            corner_forces=self._corner,
            forces=self.force,
            dtype=self.dtype,
            measure=self._measure_id,
            plastic=self.plastic,
            fracture=self.fracture,
            scatter=scatter,
            store_rotation=store_rotation,
            device=self.device,
        )

    def loads_into_force(self, t: float) -> None:
        """``force`` <- the loads [N] at time ``t`` [s] (zero without loads); the gathers add the element forces."""
        self.force.zero_()
        self.kin.add_loads(self.force, t)

    def add_element_forces(self) -> None:
        """``force`` += the element corner forces gathered per vertex [N]."""
        ks.gather_add(
            **self._incidence,
            corner_forces=self._corner,
            forces=self.force,
            dtype=self.dtype,
            device=self.device,
        )

    def _gather_kick(self, dt: float) -> None:
        """``force`` += the element corner forces [N], then the second half kick of step ``dt`` [s] (0: the
        accelerations a = f / m + g - c v only)."""
        kin = self.kin
        ks.gather_kick(
            **self._incidence,
            corner_forces=self._corner,
            inv_mass=self.inv_mass,
            gravity=self.gravity,
            dt=self.dtype(dt),
            **by_name(kin, "damping", "point_condition", "point_kind", "cond_axes"),
            forces=self.force,
            velocities=kin.v,
            accelerations=kin.a,
            dtype=self.dtype,
            device=self.device,
        )

    def reset_over_count(self) -> None:
        """Zeroes fracture's over-strength count (no-op without fracture): forces evaluated outside a step split
        nothing."""
        if self.fracture:
            self._over_count.zero_()

    def update_accelerations(self) -> None:
        """a = f / m + g - c v [m/s^2] at the current state, without a kick or a plastic update (after init, splits
        and state changes)."""
        self.element_forces(0.0)
        self.loads_into_force(self.time)
        self._gather_kick(0.0)
        self.reset_over_count()

    def apply_colliders(self, time: float, dt: float) -> None:
        """Ground plane, then the scene's colliders, on the free vertices (zero radius) at ``time`` [s], each vertex
        with its body's material friction (its restitution does not apply: the vertices meet them inelastically)."""
        kin = self.kin
        contact = self.point_contact_values(colliders=True)
        for c in self.colliders:
            c.apply(kin.rest, kin.u, kin.v, self._zero_radius, kin.point_kind, time, dt, mass=kin.mass, contact=contact)

    def point_contact_values(self, colliders: bool = False):
        """The vertices' own (restitution, friction), float64 [n] each: their body's material contact_restitution
        and contact_friction (NaN where it has none; pdsim/contact.py material_contact_values), for the contact
        between methods and surfaces; ``colliders``: the values for the ground and colliders, without restitution
        (the vertices meet them inelastically). Rebuilt when the vertices change (fracture splits); the same tuple
        otherwise."""
        body = self._vertex_body_h
        if getattr(self, "_vertex_contact_of", None) is not body:
            e, mu = (np.asarray(values)[body] for values in material_contact_values(self.bodies, per_body=True))
            self._vertex_contact_of = body
            self._vertex_contact_values = {False: (e, mu), True: (np.full(len(body), np.nan), mu)}
        return self._vertex_contact_values[bool(colliders)]

    # -- stepping ---------------------------------------------------------------------------------------------------
    def begin_step(self, dt: float) -> None:
        """Explicit: the shared kick-drift and the colliders (PointSolver). Implicit: the whole backward-Euler step
        (forces at the start of the step, CG solve, displacement update, colliders); forces added to ``force`` after
        it are not used."""
        self._dt = float(dt)
        if self.integrator == "implicit":
            self._force_time = self.time + dt
            self._implicit.step(dt)
        else:
            super().begin_step(dt)

    def compute_forces(self) -> None:
        """Explicit: element forces at the current displacements (plastic update of the step begun) plus the loads at
        the end of the step into ``force``. Implicit: nothing (``force`` holds the forces the step used)."""
        if self.integrator == "implicit":
            return
        self.loads_into_force(self._force_time)
        if self.device.is_cpu:
            self.element_forces(self._dt, scatter=True, store_rotation=False)
        else:
            self.element_forces(self._dt, store_rotation=False)
            self.add_element_forces()

    def end_step(self, dt: float) -> None:
        """Explicit: the shared second half kick. Both: time advances, then fracture splits over-stressed elements."""
        if self.integrator == "implicit":
            self.time += dt
            self.step_count += 1
        else:
            super().end_step(dt)
        if self.fracture:
            self._fracture_event()

    def step(self, dt: float):
        """Advances all bodies by one step of ``dt`` [s]. The explicit integrator refuses dt above its stable limit
        (ParameterError); use :meth:`simulate` for automatic substepping."""
        dt = check_range("dt", dt, 0.0, None)
        if self.integrator == "implicit":
            self.begin_step(dt)
            self.end_step(dt)
            return
        limit = self.model.explicit_dt
        if dt > limit * (1.0 + 1.0e-9):
            raise ParameterError(
                "dt", dt, f"(0, {limit:.6g}] s: the explicit stable limit 0.5 h_min / c_p (simulate() substeps)"
            )
        self.begin_step(dt)
        self.loads_into_force(self._force_time)
        if self.device.is_cpu:
            # the element forces added onto the loads by the element pass, then the shared kick
            self.element_forces(dt, scatter=True, store_rotation=False)
            self.kin.end_step(self.force, self.inv_mass, dt)
        else:
            # compute_forces and the kick fused: one gather-and-kick launch
            self.element_forces(dt, store_rotation=False)
            self._gather_kick(dt)
            self.kin.end_clock_step()
        self.time += dt
        self.step_count += 1
        if self.fracture:
            self._fracture_event()

    def graph_capture_blocker(self, dt: float) -> str | None:
        """Why a frame of steps of ``dt`` [s] cannot be replayed as a graph (docs/architecture.md, GPU path), or
        None: fracture splits elements on the host (a read of the over-strength count every step, then a new
        topology); the implicit integrator's conjugate-gradient solve tests its convergence on the host; a scene
        step above the explicit limit is split into a number of steps of the solver's own."""
        if self.fracture:
            return "FEM fracture (the over-strength count is read every step and splits rebuild the mesh on the host)"
        if self.integrator == "implicit":
            return "the implicit FEM integrator (its conjugate-gradient solve tests convergence on the host)"
        if dt > self.model.explicit_dt * (1.0 + 1.0e-9):
            return "an FEM body stepping alone above its explicit limit (simulate() splits each step)"
        return None

    def simulate(self, dt: float, steps: int):
        """Runs ``steps`` steps of ``dt`` [s]; the explicit integrator splits each into ceil(dt / dt_stable) equal
        substeps when dt exceeds its stable limit."""
        dt = check_range("dt", dt, 0.0, None)
        sub = 1
        if self.integrator == "explicit":
            sub = max(1, math.ceil(dt / self.model.explicit_dt - 1.0e-9))
        for _ in range(int(steps) * sub):
            self.step(dt / sub)

    # -- implicit and static solves (pdsim/fem/implicit.py, pdsim/fem/static.py, pdsim/fem/cg.py) ------------------
    def cg_solve(self, op_mass, c_mass: float, c_stiff: float, *, tolerance=None, max_iterations=None) -> CgReport:
        """Solves (c_mass diag(op_mass) + c_stiff K_R) x = rhs on the free components (op_mass [kg] per vertex, K_R
        [N/m]) with the CG of the current topology (``self.cg``: its ``constrained`` bit masks, ``x`` the initial
        guess and the result), to the solver's ``cg_tolerance`` and ``cg_max_iterations`` unless given, the stiffness
        as set by ``stiffness``."""
        return self.cg.solve(
            op_mass,
            c_mass,
            c_stiff,
            tolerance=self.cg_tolerance if tolerance is None else tolerance,
            max_iterations=self.cg_max_iterations if max_iterations is None else int(max_iterations),
            assembled=self.stiffness == "assembled",
        )

    # the keyword arguments repeat pdsim/fem/static.py's solve_static so that this public method documents them
    def solve_static(
        self,
        *,
        constrained=None,
        time: float | None = None,
        tolerance: float = 1.0e-6,
        max_newton_iterations: int = 30,
        cg_tolerance: float | None = None,
        cg_max_iterations: int = 20000,
    ) -> StaticSolveReport:
        """Quasi-static equilibrium f_int(u) + f_ext(t) + M g = 0 on the free components, by Newton iterations with
        the tangent K_R (rotations frozen per iteration; the constant K for the linear and the Green measure), each
        solved by CG. The loads are those of the bodies (body forces, tractions, pressures, forces) scaled by their
        curves at ``time``; the constrained components keep their current displacement. The plastic strain is not
        updated. Afterwards ``force`` holds the internal forces plus the loads at the solution (reaction_forces()).

        Args:
            constrained: bool mask [vertex_count] of vertices held in place on all axes; default: the boundary
                conditions active at ``time``, each on its own axes (a roller holds only its axes).
            time: the time [s] of the loads' curves and of the conditions' windows; default: the solver's time.
            tolerance: stop when |residual| <= tolerance * |f_ext + M g| over the free components (or * the first
                residual without external load), or when a Newton update is below max(tolerance, 1000 eps) times the
                displacement change so far (the float32 floor).
            max_newton_iterations: Newton iterations at most (the linear measure needs one).
            cg_tolerance: relative CG residual per Newton iteration (default: the solver's).
            cg_max_iterations: CG iterations per Newton iteration.
        """
        return solve_static(
            self,
            constrained=constrained,
            time=time,
            tolerance=tolerance,
            max_newton_iterations=max_newton_iterations,
            cg_tolerance=cg_tolerance,
            cg_max_iterations=cg_max_iterations,
        )


__all__ = ["FemStep"]
