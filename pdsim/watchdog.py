"""The divergence watchdog of the solvers with mass: :class:`Watchdog` accounts on the device for the energy put into
a solver's points and checks the state every few steps (kernels/watchdog.py holds its reductions)."""

from __future__ import annotations

import math
import time

import numpy as np
import warp as wp

from .checkpoint import RunInterrupted
from .device import device_of, wait_for
from .errors import InstabilityError
from .kernels import watchdog as kw
from .kernels.launch import by_name
from .kernels.watchdog import (
    WATCH_BAD,
    WATCH_FIRST_BAD,
    WATCH_GRAVITY,
    WATCH_HELD_KE,
    WATCH_KE,
    WATCH_POINT_KE,
    WATCH_RESET,
    WATCH_SLOTS,
    WATCH_STRAIN_MAX,
    WATCH_STRAIN_MIN,
    WATCH_VMAX,
)

STRAIN_EVERY = 8  # the strain pass (a pass over the bonds or elements) runs every 8th check and at frame ends

ENERGY_FACTOR = 2.0
"""The fast energy check (every few steps) trips when E(t) > E(0) + W(t) + (ENERGY_FACTOR - 1) (|E(0)| + W(t) +
|U_g(t)|) + floor, E = kinetic + gravitational energy, U_g the gravity potential relative to the rest configuration
(see :class:`Watchdog`)."""

TOTAL_TOLERANCE = {"automatic": 0.25, "larger": 0.5}
"""The frame-end check trips when kinetic + strain + contact + gravitational energy exceeds
E(0) + W + tolerance (|E(0)| + W + |U_g|) + floor, the tolerance 25 % at or below the automatic step and 50 % above it.
Velocity Verlet conserves a shadow energy, not the energy measured at the step ends, which sits a few percent above
E(0) at the automatic step, more at larger steps, and stays there (docs/stability.md); a divergence that grows slowly,
just past the stable step, passes the tolerance within a few frames."""

STRAIN_LIMITS = {"bond stretch": (-0.9, 19.0), "volume ratio": (0.1, 20.0)}
"""Strain blow-up: the stretch of every live peridynamic bond (|eta| / |xi| - 1) and the volume ratio J of every
tetrahedron must stay inside these ranges [-]: no two bonded particles closer than 10 % of their rest distance (they
passed through each other: the body collapsed), no bond or element beyond 20x. A 30 % compression is J = 0.7, bonds
at about -0.3 to -0.1."""


class Watchdog:
    """Catches a diverging explicit integration on the device, every few steps, in a way fracture cannot fool.

    Attached to a PointSolver (``Watchdog(solver, ...)`` sets ``solver.watchdog`` and ``solver.kin.watchdog``), it
    accounts every step, on the device and without a host read, for the energy put into the solver's points, as
    upper bounds of the net input (positive parts only):

    - loads: F(t + dt) . v dt per loaded point (v the mid-step velocity);
    - prescribed-velocity boundary conditions: the reaction R = -(f + m g) on the held axes times the condition's
      velocity, times dt;
    - velocity kicks: the kinetic energy they add, 1/2 m (|v + dv|^2 - |v|^2);
    - moving colliders (projectiles): sum m |dv| over what the colliders (and contact) changed in the step, times the
      largest speed of a collider surface (``surface_speed``);
    - contact with a body of another method (pdsim.contact.MethodContact): the positive part of the contact force's
      work on the points, max(F . v dt, 0) per contact and step, added into the colliders' slot by the contact kernel;
    - boundary conditions that start moving points: the positive increments of the kinetic energy of the held axes.

    :meth:`check` (the solvers' ``check_state``; the scene calls it every ``check_interval`` steps and at frame ends)
    reduces the state in one launch and reads 16 numbers: it raises InstabilityError when

    - a displacement or velocity is not finite;
    - a point speed exceeds ``speed_limit`` [m/s];
    - the energy E = kinetic + gravity potential U_g (relative to the rest configuration) exceeds
      E(0) + W + (ENERGY_FACTOR - 1) (|E(0)| + W + |U_g|) + ``energy_floor``: a stable run cannot have more than it
      started with plus the work put in (strain, contact and plastic work are left out of E: they are never negative),
      while a run past its stable step gains energy exponentially; fracture caps the speeds a divergence reaches
      (particles fly apart once their bonds break) but not the energy it makes;
    - a strain leaves STRAIN_LIMITS (peridynamic bond stretch, tetrahedron volume ratio): particles that passed through
      each other or a blown-up mesh;
    - at frame ends (``full_check``), the total energy (kinetic + strain + contact + gravitational) exceeds
      E(0) + W + ``total_tolerance`` (|E(0)| + W + |U_g|) + ``energy_floor`` (TOTAL_TOLERANCE): a slow divergence,
      just past the stable step, that the fast bound lets grow.

    The message names the time, step, body, the fastest (or first non-finite) point and, through ``explain``
    (callable (solver, point index, position [m] or None, what) -> str, from the scene), the likely cause.

    Args:
        solver: a PointSolver (``kin``, ``force``).
        energy_floor: round-off tolerance [J] added to the energy bounds (the scene: 1/2 M (1e-6 c_p)^2; the bounds
            otherwise scale with the energy the run moves about).
        surface_speed: callable (t, dt) -> the largest collider surface speed [m/s] over the step ending at t, or
            None when no collider moves.
        explain: the cause callable, or None ("the time step").
        energy: False turns the energy check off (the implicit FEM integrator: unconditionally stable, and its
            accelerations are not the explicit ones the accounting reads).
        total_tolerance: of the frame-end check (TOTAL_TOLERANCE: the scene gives 0.25 at or below the automatic
            step, 0.5 above it).
    """

    def __init__(
        self,
        solver,
        *,
        energy_floor: float = 0.0,
        surface_speed=None,
        explain=None,
        energy: bool = True,
        total_tolerance: float = TOTAL_TOLERANCE["larger"],
    ):
        kin = solver.kin
        self.solver = solver
        self.device = kin.device
        self.energy_floor = float(energy_floor)
        self.surface_speed = surface_speed
        self.explain = explain
        self.energy = bool(energy)
        self.total_tolerance = float(total_tolerance)
        self.acc = wp.zeros(WATCH_SLOTS, dtype=wp.float64, device=self.device)
        self._reset = wp.array(WATCH_RESET, dtype=wp.float64, device=self.device)
        self._no_alive = wp.zeros(1, dtype=wp.uint8, device=self.device)
        self.kin = None
        self._held_cache = None
        self.bind(kin)
        solver.watchdog = self
        self.frame = None  # the frame being simulated (the scene sets it; used in messages)
        self._step_dt = None  # length of the step in progress [s] (between step_start and loads_applied)
        self._pending = None  # (dt, kinematics, force array) of the last step whose support work is not yet counted
        self._time = float(getattr(solver, "time", 0.0))
        self.checks = 0
        self.seconds = 0.0  # wall time of the checks [s] (pdsim/profile.py's "checks")
        self.full_check = True  # the next check includes the strain pass (the scene sets it for frame ends)
        self.last = {}
        # checks inside the step loop (the scene sets these): every ``interval`` steps the solver's check_state runs
        # with ``speed_limit`` at the start of a step; ``stop`` (a pdsim.checkpoint.StopRequest) is polled there too,
        # at step boundaries of the scene (every ``stride`` solver steps) after the frame's first step
        self.interval = None
        self.speed_limit = None
        self.stop = None
        self.stride = 1
        self.frame_start_step = 0
        self._done = 0  # steps completed since the last check
        # a frame replayed as a graph (pdsim/capture.py) checks and polls ``stop`` at its end only
        self.frame_checks_only = False
        # the largest collider surface speed of each step of the frame, on the device (``begin_frame`` writes it;
        # the last entry is a scratch slot for steps outside a frame program)
        self._speed_times: dict = {}
        self._speeds = wp.zeros(1, dtype=wp.float64, device=self.device)
        values = self._reduce()
        self.initial_energy = values["kinetic"] + values["gravity"]  # E(0) [J]
        self.held_kinetic = values["held_kinetic"]  # kinetic energy of the held axes at the last check [J]
        self.held_work = 0.0  # positive increments of it [J]

    # -- binding ----------------------------------------------------------------------------------------------------
    def bind(self, kin) -> None:
        """Follows ``kin``: a solver that rebuilds its kinematics (FEM fracture renumbers the vertices) is re-bound at
        its next step (PointSolver.begin_step) or check. The last step's support work is still counted on the
        kinematics and force array it ran on."""
        if self.kin is not None and self.kin is not kin and self.kin.watchdog is self:
            self.kin.watchdog = None
        self.kin = kin
        kin.watchdog = self
        self._before = wp.zeros_like(kin.v) if self.surface_speed is not None else None

    def _held_points(self, kin):
        """The points of ``kin`` held by a prescribed-velocity condition (int32 Warp array, None when none),
        cached per kinematics."""
        cached = self._held_cache
        if cached is not None and cached[0] is kin:
            return cached[1]
        held = np.zeros(0, dtype=np.int32)
        if kin.condition_count:
            kinds = kin.cond_kind.numpy()
            prescribed = np.flatnonzero(kinds == 2)  # PointKind.PRESCRIBED
            held = np.flatnonzero(np.isin(kin.point_condition_host, prescribed)).astype(np.int32)
        array = wp.array(held, dtype=wp.int32, device=self.device) if len(held) else None
        self._held_cache = (kin, array)
        return array

    # -- hooks (PointKinematics calls them) ---------------------------------------------------------------------------
    def step_start(self, kin, dt: float) -> None:
        """A step of ``dt`` [s] begins: every ``interval`` steps the solver's check_state runs (the state is the end of
        the previous step), a stop request is honoured (pdsim.checkpoint.RunInterrupted), and the support work of the
        previous step is counted (its forces are final)."""
        if kin is not self.kin:
            self.bind(kin)
        in_frame = not self.frame_checks_only
        if in_frame and self.interval is not None and self._done >= self.interval and self.speed_limit is not None:
            self.solver.check_state(self.speed_limit)  # resets _done
        if in_frame and self.stop is not None and self.stop.requested:
            done = int(getattr(self.solver, "step_count", 0)) - self.frame_start_step
            if done > 0 and done % self.stride == 0:
                exc = RunInterrupted(self.stop.signal)
                exc.in_frame = done // self.stride  # scene steps of the frame done
                raise exc
        self._done += 1
        self._flush_support_work()
        self._step_dt = float(dt)

    def kick(self, kin, points, dv) -> None:
        kw.kick_work(
            kw.watchdog_kernels(kin.dtype),
            points=points,
            dv=dv,
            velocities=kin.v,
            mass=kin.mass,
            acc=self.acc,
            device=self.device,
        )

    def after_drift(self, kin) -> None:
        if self._before is not None and self._before.shape == kin.v.shape:
            wp.copy(self._before, kin.v)

    def loads_applied(self, kin) -> None:
        """The step's loads are in the force array (velocities at mid-step): load work, collider work."""
        dt = self._step_dt
        if dt is None:  # a force evaluation outside a step (initial accelerations, a state change)
            return
        self._step_dt = None
        self._time += dt
        n = kin.point_count
        k = kw.watchdog_kernels(kin.dtype)
        if kin.load_count:
            kw.load_work(
                k,
                velocities=kin.v,
                dt=dt,
                count=kin.load_entry_count,
                acc=self.acc,
                device=self.device,
                **by_name(kin, "load_point", "load_index", "load_force", "load_scale", "force_to_newton"),
            )
        if self._before is not None and self._before.shape == kin.v.shape and n:
            slot = self._speed_slot(self._time, dt)
            kw.impulse_work(
                k,
                velocities=kin.v,
                before=self._before,
                mass=kin.mass,
                surface_speeds=self._speeds,
                slot=slot,
                count=n,
                acc=self.acc,
                device=self.device,
            )
        # the support work of this step is counted once its forces are final (next step, or the check), on the
        # kinematics and force array of this step (a fracture may rebuild both at the end of the step)
        self._pending = (dt, kin, getattr(self.solver, "force", None))

    # -- frames (pdsim/capture.py) ---------------------------------------------------------------------------
    def begin_frame(self, dt: float, steps: int) -> None:
        """Writes the collider surface speed of each of the next ``steps`` steps of ``dt`` [s] to the device (one
        copy), so that the steps read it from a table instead of a launch argument."""
        if self.surface_speed is None:
            return
        times, t = [], self._time
        for _ in range(int(steps)):
            t += dt
            times.append(t)
        speeds = np.array([float(self.surface_speed(x, dt)) for x in times] + [0.0], dtype=np.float64)
        if self._speeds.shape[0] != speeds.shape[0]:
            self._speeds = wp.zeros(speeds.shape[0], dtype=wp.float64, device=self.device)
        self._speeds.assign(speeds)
        self._speed_times = {(x, float(dt)): k for k, x in enumerate(times)}

    def _speed_slot(self, time: float, dt: float) -> int:
        """The slot of ``_speeds`` holding the surface speed of the step of ``dt`` ending at ``time`` (from
        :meth:`begin_frame`), or the scratch slot written now (a step outside a frame program; never under
        capture)."""
        slot = self._speed_times.get((time, float(dt)))
        if slot is not None:
            return slot
        if self.device.is_capturing:
            raise RuntimeError(
                f"the watchdog's collider speed of the step ending at t={time!r} s is not in the frame's table "
                "(Watchdog.begin_frame) during a graph capture"
            )
        slot = self._speeds.shape[0] - 1
        speed = float(self.surface_speed(time, dt)) if self.surface_speed is not None else 0.0
        wp.copy(self._speeds, wp.array([speed], dtype=wp.float64, device="cpu"), dest_offset=slot, count=1)
        return slot

    def after_replay(self, dt: float, steps: int) -> None:
        """The host bookkeeping of ``steps`` steps of ``dt`` [s] that a graph replayed (what step_start and
        loads_applied do on the host each step)."""
        for _ in range(int(steps)):
            self._time += dt
        self._done += int(steps)
        self._step_dt = None
        self._pending = (dt, self.kin, getattr(self.solver, "force", None))

    def _flush_support_work(self) -> None:
        pending, self._pending = self._pending, None
        if pending is None:
            return
        dt, kin, force = pending
        held = self._held_points(kin)
        if dt <= 0.0 or held is None or force is None or force.shape[0] != kin.point_count:
            return
        kw.support_work(
            kw.watchdog_kernels(kin.dtype),
            points=held,
            force=force,
            dt=dt,
            count=int(held.shape[0]),
            acc=self.acc,
            device=self.device,
            **by_name(kin, "force_to_newton", "mass", "gravity"),
            **by_name(kin, "point_condition", "active_kind", "cond_axes", "active_velocity"),
        )

    # -- the check ---------------------------------------------------------------------------------------------------
    def _launch_strain(self) -> str | None:
        """Launches the strain range of the solver's method into the accumulator; returns its name (STRAIN_LIMITS)."""
        solver = self.solver
        model = getattr(solver, "model", None)
        state = getattr(solver, "state", None)
        if getattr(state, "bond_ne", None) is not None and getattr(model, "bond_geom", None) is not None:
            # peridynamics: the live bonds' stretch, from the bond cache of the last force pass (the current state)
            alive = getattr(state, "bond_alive", None)
            kw.bond_stretch_range(
                bond_ne=state.bond_ne,
                bond_geom=model.bond_geom,
                bond_alive=alive if alive is not None else self._no_alive,  # a placeholder, not read
                use_alive=int(alive is not None),
                count=int(model.bond_count),
                acc=self.acc,
                device=self.device,
            )
            return "bond stretch"
        tets = getattr(solver, "_tets", None)
        if tets is not None and getattr(model, "dm_inv", None) is not None:  # FEM
            k = kw.watchdog_kernels(self.kin.dtype)
            kw.tet_strain_range(
                k,
                displacements=self.kin.u,
                tets=tets,
                dm_inv=model.dm_inv,
                count=int(tets.shape[0]),
                acc=self.acc,
                device=self.device,
            )
            return "volume ratio"
        return None

    def _reduce(self) -> dict:
        """One reduction of the state and one host read: the numbers of the check."""
        kin = self.kin
        wp.copy(self.acc, self._reset, dest_offset=4, src_offset=0, count=WATCH_SLOTS - 4)
        kw.state_sums(
            kw.watchdog_kernels(kin.dtype),
            displacements=kin.u,
            velocities=kin.v,
            count=kin.point_count,
            acc=self.acc,
            device=self.device,
            **by_name(kin, "mass", "point_condition", "point_kind", "cond_axes", "gravity"),
        )
        strain = None
        if self.full_check or self.checks % STRAIN_EVERY == 0:
            strain = self._launch_strain()
        a = self.acc.numpy()
        return {
            "work": float(a[:4].sum()),
            "work_parts": a[:4].copy(),
            "bad": int(a[WATCH_BAD]),
            "first_bad": int(a[WATCH_FIRST_BAD]) if a[WATCH_BAD] > 0 else -1,
            "vmax": float(a[WATCH_VMAX]),
            "kinetic": float(a[WATCH_KE]),
            "gravity": float(a[WATCH_GRAVITY]),
            "held_kinetic": float(a[WATCH_HELD_KE]),
            "point_kinetic": float(a[WATCH_POINT_KE]),
            "strain": strain,
            "strain_range": (float(a[WATCH_STRAIN_MIN]), float(a[WATCH_STRAIN_MAX])),
        }

    def check(self, speed_limit: float, where: str, hint: str = "") -> dict:
        """Raises InstabilityError (see the class) or returns the check's numbers: energy ``energy`` and its bound
        ``bound`` [J], work put in ``work`` [J], largest speed ``vmax`` [m/s], strain range. Its time (``seconds``)
        starts once the steps launched before it are done (on CUDA the check's host read would wait for them: that
        wait is the steps' time, not the check's)."""
        wait_for([device_of(self.solver)])
        t0 = time.perf_counter()
        try:
            return self._check(speed_limit, where, hint)
        finally:
            self.seconds += time.perf_counter() - t0

    def _check(self, speed_limit: float, where: str, hint: str) -> dict:
        solver = self.solver
        if solver.kin is not self.kin:
            self.bind(solver.kin)
        self._flush_support_work()
        full = self.full_check
        r = self._reduce()
        self.checks += 1
        self.full_check = False
        self._done = 0
        rise = r["held_kinetic"] - self.held_kinetic
        if rise > 0.0:
            self.held_work += rise
        self.held_kinetic = r["held_kinetic"]
        work = r["work"] + self.held_work
        energy = r["kinetic"] + r["gravity"]
        e0 = self.initial_energy
        budget = abs(e0) + work + abs(r["gravity"])  # the energy the run has moved about [J]
        bound = e0 + work + (ENERGY_FACTOR - 1.0) * budget + self.energy_floor
        r.update(energy=energy, bound=bound, work=work, budget=budget)
        self.last = r
        what = None
        if r["bad"]:
            what = f"non-finite displacements or velocities ({r['bad']} points)"
        elif r["vmax"] > speed_limit:
            what = f"a point speed of {r['vmax']:.3g} m/s (limit {speed_limit:.3g} m/s)"
        elif self.energy and energy > bound:
            what = (
                f"its kinetic plus gravitational energy reached {energy:.3g} J, far more than the {e0:.3g} J it "
                f"started with + {work:.3g} J put in by loads, boundary conditions, kicks, moving colliders and "
                f"contact (+ {ENERGY_FACTOR - 1.0:.0%} of the {budget:.3g} J moved about, gravity's included): "
                "a stable run cannot gain energy"
            )
        elif r["strain"] is not None:
            lo, hi = STRAIN_LIMITS[r["strain"]]
            smin, smax = r["strain_range"]
            if smin < lo or smax > hi:
                value = smin if smin < lo else smax
                what = (
                    f"a {r['strain']} of {value:.3g} (allowed {lo:g} to {hi:g}): particles passed through each other "
                    "or elements collapsed"
                )
        if what is None and self.energy and full:
            what = self._total_energy_check(r, energy, work)
        if what is None:
            return r
        raise self._error(what, r, where, hint)

    def _total_energy_check(self, r: dict, energy: float, work: float) -> str | None:
        """The frame-end energy check: E = kinetic + strain + contact + gravitational energy against E(0) + W +
        total_tolerance (|E(0)| + W + |U_g|) + energy_floor (the strain and contact energies are read from the
        solver: a pass over the bonds or elements, and one of contact, once a frame). Records ``total`` and
        ``total_bound`` in the check's numbers; returns the failure's description or None."""
        solver = self.solver
        strain = float(solver.strain_energy()) if hasattr(solver, "strain_energy") else 0.0
        contact = float(solver.contact_energy()) if hasattr(solver, "contact_energy") else 0.0
        total = energy + strain + contact
        e0 = self.initial_energy
        bound = e0 + work + self.total_tolerance * r["budget"] + self.energy_floor
        r.update(total=total, total_bound=bound, strain_energy=strain, contact_energy=contact)
        if total <= bound and math.isfinite(total):
            return None
        return (
            f"its total energy reached {total:.3g} J (kinetic + gravitational {energy:.3g} J, strain {strain:.3g} J, "
            f"contact {contact:.3g} J), more than the {e0:.3g} J it started with + {work:.3g} J put in by loads, "
            f"boundary conditions, kicks, moving colliders and contact (+ {self.total_tolerance:.0%} of the "
            f"{r['budget']:.3g} J "
            "moved about, gravity's included): a stable run cannot gain energy"
        )

    def _error(self, what: str, r: dict, where: str, hint: str):
        kin = self.kin
        index, position = self._worst_point(r)
        body = ""
        if index is not None and len(kin.bodies):
            b = int(np.searchsorted(kin.body_offsets, index, side="right") - 1)
            b = min(max(b, 0), len(kin.bodies) - 1)
            body = f" in body '{kin.bodies[b].name}'"
        at = ""
        if position is not None:
            speed = float(np.linalg.norm(kin.v.numpy()[index]))
            at = f" (fastest point {speed:.3g} m/s at ({position[0]:.4g}, {position[1]:.4g}, {position[2]:.4g}) m)"
        elif index is not None:
            at = f" (first at point {index})"
        frame = f" in frame {self.frame}" if self.frame is not None else ""
        cause = ""
        if self.explain is not None:
            cause = self.explain(self.solver, index, position, what)
        elif hint:
            cause = hint
        message = f"the simulation diverged{frame} {where}{body}: {what}{at}"
        if cause:
            message += f"; likely cause: {cause}"
        return InstabilityError(message)

    def _worst_point(self, r: dict):
        """(index, world position [m] or None) of the first non-finite point or else of the fastest one (one host
        read of u and v, only when the check fails)."""
        kin = self.kin
        if kin.point_count == 0:
            return None, None
        if r["bad"]:
            return int(r["first_bad"]), None
        v = kin.v.numpy().astype(np.float64)
        i = int(np.argmax(np.einsum("ij,ij->i", v, v)))
        return i, kin.rest_world[i] + kin.u.numpy()[i].astype(np.float64)

    # -- checkpoints ---------------------------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        """The accounting to carry over a checkpoint (work slots and baselines)."""
        self._flush_support_work()
        return {
            "work": self.acc.numpy()[:4].copy(),
            "initial_energy": self.initial_energy,
            "held_kinetic": self.held_kinetic,
            "held_work": self.held_work,
            "time": self._time,
        }

    def restore(self, state: dict) -> None:
        work = np.asarray(state["work"], dtype=np.float64)
        wp.copy(self.acc, wp.array(work, dtype=wp.float64, device=self.device), count=4)
        self.initial_energy = float(state["initial_energy"])
        self.held_kinetic = float(state["held_kinetic"])
        self.held_work = float(state["held_work"])
        self._time = float(state["time"])
        self._pending = None
        self._step_dt = None


__all__ = ["ENERGY_FACTOR", "STRAIN_LIMITS", "TOTAL_TOLERANCE", "Watchdog"]
