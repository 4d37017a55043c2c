"""The shared point state of every method with mass, and the launches of kernels/integration.py.

:class:`PointKinematics` holds what every point-based solver integrates the same way: displacements from the rest
configuration, velocities, accelerations, the kinematic kind of each point this step, the boundary-condition and
time-curve tables of all the solver's bodies, and the loads resolved onto points. A solver owns one, gives it the
per-point inverse mass in its own force unit and calls

    begin_step(t, dt)            conditions at t + dt/2, kick-drift (u and v at t + dt)
    (colliders, contact, internal forces into ``force``)
    add_loads(force, t + dt)     loads scaled by their curves at t + dt
    end_step(force, dt)          second half kick

Rest positions are stored relative to the scene's origin (``origin``, float64 [3]), so the float32 arrays resolve
the same deformation wherever the scene sits in the world; world positions are ``origin + rest + u``, formed in
float64 only on the host for output.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import InstabilityError


class PointKinematics:
    """Displacements, velocities and accelerations of ``point_count`` points, with their boundary conditions and
    loads.

    ``watchdog`` (a :class:`Watchdog`, set by it) is told of every step, kick and load evaluation so that it can
    account for the energy put in; None (default) costs nothing.

    Args:
        bodies: the solver's PointBody instances, in the order of their points.
        body_offsets: first point of each body, int [body_count + 1].
        rest_world: rest positions [m] in world coordinates, float64 [n, 3].
        origin: the scene's origin [m], float64 [3] (the local frame's origin).
        mass: point masses [kg], float64 [n].
        force_to_newton: what turns the solver's force unit into newtons per point (the particle volume for a force
            density, 1 for nodal forces), float64 [n].
        damping: mass-proportional damping [1/s] per point, float64 [n].
        gravity: scene gravity [m/s^2], 3 numbers.
        device: Warp device.
        dtype: wp.float32 or wp.float64 (the solver's state precision).
    """

    watchdog = None  # the Watchdog accounting this state's energy, if any (Watchdog.bind sets it)

    def __init__(
        self, bodies, body_offsets, rest_world, origin, mass, force_to_newton, damping, gravity, device, dtype
    ):
        import warp as wp

        from .kernels import integration as ki

        self.device = wp.get_device(device)
        self.dtype = dtype
        self.k = ki.integration_kernels(dtype)
        vec3 = self.k.vec3
        npf = np.float64 if dtype == wp.float64 else np.float32
        self.npf = npf
        n = int(body_offsets[-1])
        self.point_count = n
        self.bodies = list(bodies)
        self.body_offsets = np.asarray(body_offsets, dtype=np.int64)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.rest_world = np.asarray(rest_world, dtype=np.float64)
        self.rest_local_host = self.rest_world - self.origin
        self.mass_host = np.asarray(mass, dtype=np.float64)
        self.force_to_newton_host = np.asarray(force_to_newton, dtype=np.float64)
        d = self.device

        def v3(a):
            return wp.array(np.asarray(a, dtype=npf).reshape(-1, 3), dtype=vec3, device=d)

        def sc(a):
            return wp.array(np.asarray(a, dtype=npf), dtype=dtype, device=d)

        self.rest = v3(self.rest_local_host)
        init_v = np.concatenate([b.initial_velocity for b in bodies]) if bodies else np.zeros((0, 3))
        self.u = wp.zeros(n, dtype=vec3, device=d)
        self.v = v3(init_v)
        self.a = wp.zeros(n, dtype=vec3, device=d)
        self.mass = sc(self.mass_host)
        self.force_to_newton = sc(self.force_to_newton_host)
        self.damping = sc(damping)
        self.gravity_host = np.asarray(gravity, dtype=np.float64)
        self.gravity = vec3(*[float(g) for g in self.gravity_host])
        self.point_kind = wp.zeros(n, dtype=wp.int32, device=d)
        self._check = wp.zeros(2, dtype=float, device=d)
        # The device clock [s]: [0] the time at the start of the step, [1] the time at its end (the loads' time),
        # [2] a scratch time for evaluations outside the step loop. Kernels read it, so no launch argument changes
        # from step to step and a frame's steps can be replayed as a CUDA graph; ``clock_host`` mirrors it on the
        # host (advanced by the same float64 additions, never read back).
        self.clock = wp.zeros(3, dtype=wp.float64, device=d)
        self.clock_host = [0.0, 0.0, 0.0]
        self._build_conditions()
        self._build_loads()
        self.time = 0.0

    # -- tables --------------------------------------------------------------------------------------------------------
    def _build_conditions(self):
        import warp as wp

        d = self.device
        conds, point_cond, names = [], [], []
        for b in self.bodies:
            pc = b.point_condition.astype(np.int64)
            point_cond.append(np.where(pc >= 0, pc + len(conds), -1))
            conds += b.conditions
            names += [(b.name, c.name) for c in b.conditions]
        self.condition_names = names
        self.condition_count = len(conds)
        pc = np.concatenate(point_cond) if point_cond else np.zeros(0)
        self.point_condition_host = pc.astype(np.int32)
        self.point_condition = wp.array(self.point_condition_host, dtype=wp.int32, device=d)
        m = max(len(conds), 1)
        kind = np.zeros(m, dtype=np.int32)
        axes = np.zeros((m, 3), dtype=np.float32)
        vel = np.zeros((m, 3), dtype=np.float32)
        start = np.zeros(m, dtype=np.float32)
        release = np.full(m, np.finfo(np.float32).max, dtype=np.float32)
        for i, c in enumerate(conds):
            kind[i] = int(c.kind)
            axes[i] = c.axes
            vel[i] = c.velocity
            start[i] = c.start
            release[i] = min(c.release, float(np.finfo(np.float32).max))
        spans, times, values = _curve_tables([c.curve for c in conds])
        self.cond_kind = wp.array(kind, dtype=wp.int32, device=d)
        self.cond_axes = wp.array(axes, dtype=wp.vec3, device=d)
        self.cond_velocity = wp.array(vel, dtype=wp.vec3, device=d)
        self.cond_start = wp.array(start, dtype=float, device=d)
        self.cond_release = wp.array(release, dtype=float, device=d)
        self.cond_curve = wp.array(spans, dtype=wp.vec2i, device=d)
        self.cond_curve_time = wp.array(times, dtype=float, device=d)
        self.cond_curve_value = wp.array(values, dtype=float, device=d)
        self.active_kind = wp.zeros(m, dtype=wp.int32, device=d)
        self.active_velocity = wp.zeros(m, dtype=wp.vec3, device=d)
        self._reaction = wp.zeros(m, dtype=wp.vec3d, device=d)

    def _build_loads(self):
        import warp as wp

        d = self.device
        points, forces, index, curves = [], [], [], []
        for b, lo in zip(self.bodies, self.body_offsets[:-1]):
            hi = lo + b.point_count
            for pts, f, curve in b.resolved_loads(self.rest_world[lo:hi], self.mass_host[lo:hi]):
                gp = pts + lo
                points.append(gp)
                forces.append(f / self.force_to_newton_host[gp, None])  # newtons -> the solver's force unit
                index.append(np.full(len(pts), len(curves)))
                curves.append(curve)
        self.load_count = len(curves)
        self.load_entry_count = int(sum(len(p) for p in points))
        if self.load_count:
            self.load_point = wp.array(np.concatenate(points).astype(np.int32), dtype=wp.int32, device=d)
            self.load_force = wp.array(np.concatenate(forces).astype(np.float32), dtype=wp.vec3, device=d)
            self.load_index = wp.array(np.concatenate(index).astype(np.int32), dtype=wp.int32, device=d)
            spans, times, values = _curve_tables(curves)
            self.load_curve = wp.array(spans, dtype=wp.vec2i, device=d)
            self.load_curve_time = wp.array(times, dtype=float, device=d)
            self.load_curve_value = wp.array(values, dtype=float, device=d)
            self.load_scale = wp.zeros(self.load_count, dtype=float, device=d)
        self.kicks = []  # (time, points, dv), sorted by time
        for b, lo in zip(self.bodies, self.body_offsets[:-1]):
            for kick in b.kicks:
                pts = wp.array((b.kick_points(kick) + lo).astype(np.int32), dtype=wp.int32, device=d)
                self.kicks.append((kick.time, pts, kick.velocity))
        self.kicks.sort(key=lambda k: k[0])
        self.next_kick = 0  # index of the first kick not yet applied

    @property
    def features(self) -> set[str]:
        """Live kinematic features: boundary_conditions, loads, velocity_kicks, gravity, damping."""
        out = set()
        if self.condition_count:
            out.add("boundary_conditions")
        if self.load_count:
            out.add("loads")
        if self.kicks:
            out.add("velocity_kicks")
        if np.any(self.gravity_host != 0.0):
            out.add("gravity")
        if np.any(self.damping.numpy() != 0.0):
            out.add("damping")
        return out

    # -- the device clock ------------------------------------------------------------------------------------------
    def set_clock(self, t: float, slot: int = 0) -> None:
        """Writes time ``t`` [s] into ``clock[slot]`` from the host (a restore, a rebuilt state, an evaluation at an
        arbitrary time). Never inside a graph capture: a captured copy would replay the same time every frame."""
        import warp as wp

        t = float(t)
        if self.clock_host[slot] == t:
            return
        if self.device.is_capturing:
            raise RuntimeError(
                f"the device clock was set from the host to t={t!r} s during a graph capture (it holds "
                f"{self.clock_host[slot]!r} s): a step outside PointKinematics.begin_step/end_step changed the time"
            )
        wp.copy(self.clock, wp.array([t], dtype=wp.float64, device="cpu"), dest_offset=slot, count=1)
        self.clock_host[slot] = t

    def _clock_slot(self, t: float) -> int:
        """The clock slot holding time ``t`` [s] (the step's start or end), or the scratch slot set to it."""
        t = float(t)
        for slot in (1, 0):
            if self.clock_host[slot] == t:
                return slot
        self.set_clock(t, 2)
        return 2

    def end_clock_step(self) -> None:
        """The step begun by :meth:`begin_step` is done: the clock's start time becomes its end time (on the device
        and in the host mirror). kick-drift integrators that do not call :meth:`end_step` call this."""
        import warp as wp

        from .kernels import integration as ki

        wp.launch(ki.clock_end_step, dim=1, inputs=[self.clock], device=self.device)
        self.clock_host[0] = self.clock_host[1]

    # -- stepping ------------------------------------------------------------------------------------------------------
    def begin_step(self, t: float, dt: float):
        """Velocity kicks due in [t, t + dt), the conditions' state at t + dt/2, then the first half kick and drift.
        The device clock advances to the step: clock[0] = t (already there unless the state was changed from the
        host), clock[1] = t + dt."""
        import warp as wp

        from .kernels import integration as ki

        d = self.device
        self.apply_kicks(t, dt)  # first: it starts the step (the watchdog's check every few steps runs there)
        self.set_clock(t, 0)
        wp.launch(ki.clock_begin_step, dim=1, inputs=[self.clock, wp.float64(dt)], device=d)
        self.clock_host[1] = self.clock_host[0] + float(dt)
        if self.condition_count:
            self._evaluate_conditions_at(0, 0.5 * dt)
        wp.launch(
            self.k.kick_drift,
            dim=self.point_count,
            inputs=[
                self.u,
                self.v,
                self.a,
                self.point_condition,
                self.active_kind,
                self.cond_axes,
                self.active_velocity,
                self.dtype(dt),
                self.point_kind,
            ],
            device=d,
        )
        if self.watchdog is not None:
            self.watchdog.after_drift(self)

    def apply_kicks(self, t: float, dt: float):
        """The velocity kicks due in [t, t + dt), each applied once. Every step of every integrator starts here (the
        watchdog takes the step's length from it)."""
        import warp as wp

        watchdog = self.watchdog
        if watchdog is not None:
            watchdog.step_start(self, dt)
        while self.next_kick < len(self.kicks) and self.kicks[self.next_kick][0] < t + dt:
            _, pts, dv = self.kicks[self.next_kick]
            if watchdog is not None:
                watchdog.kick(self, pts, dv)
            wp.launch(self.k.add_velocity, dim=pts.shape[0], inputs=[pts, wp.vec3(*dv), self.v], device=self.device)
            self.next_kick += 1

    def evaluate_conditions(self, t: float):
        """Each boundary condition's state at time ``t`` [s] (active kind and velocity), on the device (``t`` is
        written to the clock's scratch slot unless the clock holds it)."""
        self._evaluate_conditions_at(self._clock_slot(t), 0.0)

    def _evaluate_conditions_at(self, slot: int, offset: float):
        """Each boundary condition's state at the device time clock[slot] + offset [s]."""
        import warp as wp

        from .kernels import integration as ki

        wp.launch(
            ki.evaluate_conditions,
            dim=self.condition_count,
            inputs=[
                self.cond_kind,
                self.cond_start,
                self.cond_release,
                self.cond_velocity,
                self.cond_curve,
                self.cond_curve_time,
                self.cond_curve_value,
                self.clock,
                int(slot),
                wp.float64(offset),
                self.active_kind,
                self.active_velocity,
            ],
            device=self.device,
        )

    def add_loads(self, force, t: float):
        """Adds every load, scaled by its curve at ``t`` [s], to ``force`` (the solver's force array). ``t`` is read
        from the device clock (the end of the step begun, or its start; another time is written to the scratch
        slot)."""
        import warp as wp

        from .kernels import integration as ki

        if self.load_count:
            d = self.device
            wp.launch(
                ki.evaluate_curves,
                dim=self.load_count,
                inputs=[
                    self.load_curve,
                    self.load_curve_time,
                    self.load_curve_value,
                    self.clock,
                    self._clock_slot(t),
                    self.load_scale,
                ],
                device=d,
            )
            wp.launch(
                self.k.apply_loads,
                dim=self.load_entry_count,
                inputs=[self.load_point, self.load_index, self.load_force, self.load_scale, force],
                device=d,
            )
        if self.watchdog is not None:
            self.watchdog.loads_applied(self)

    def end_step(self, force, inv_mass, dt: float):
        """Second half kick: a = force * inv_mass + g - c v on the free axes; the device clock moves to the step's
        end."""
        import warp as wp

        wp.launch(
            self.k.kick,
            dim=self.point_count,
            inputs=[
                force,
                inv_mass,
                self.gravity,
                self.damping,
                self.dtype(dt),
                self.point_condition,
                self.point_kind,
                self.cond_axes,
                self.v,
                self.a,
            ],
            device=self.device,
        )
        self.end_clock_step()

    # -- outputs and checks --------------------------------------------------------------------------------------------
    def reactions(self, force, t: float) -> dict:
        """Force [N] each boundary condition exerts on its body at time ``t`` (from ``force``, the solver's internal
        force plus loads of the last evaluation): {(body name, condition name): float64 [3]}; zero when inactive."""
        import warp as wp

        if not self.condition_count:
            return {}
        self.evaluate_conditions(t)
        self._reaction.zero_()
        wp.launch(
            self.k.condition_reactions,
            dim=self.point_count,
            inputs=[
                self.point_condition,
                self.active_kind,
                self.cond_axes,
                force,
                self.force_to_newton,
                self.mass,
                self.gravity,
                self._reaction,
            ],
            device=self.device,
        )
        r = self._reaction.numpy()
        return {name: r[i].astype(np.float64) for i, name in enumerate(self.condition_names)}

    def check(self, speed_limit: float, where: str, hint: str = ""):
        """Raises InstabilityError when a displacement or velocity is not finite or a speed exceeds ``speed_limit``
        [m/s]; the message says ``where`` and ends with ``hint``."""
        import warp as wp

        self._check.zero_()
        wp.launch(
            self.k.max_speed_and_finite, dim=self.point_count, inputs=[self.u, self.v, self._check], device=self.device
        )
        vmax, bad = (float(x) for x in self._check.numpy())
        if bad > 0 or vmax > speed_limit:
            what = "non-finite displacements or velocities" if bad > 0 else f"a point speed of {vmax:.3g} m/s"
            raise InstabilityError(f"the simulation diverged {where}: {what}" + (f"; {hint}" if hint else ""))

    def displacements(self) -> np.ndarray:
        """u [m], float64 [n, 3]."""
        return self.u.numpy().astype(np.float64)

    def positions(self) -> np.ndarray:
        """World positions origin + X + u [m], float64 [n, 3]."""
        return self.rest_world + self.u.numpy().astype(np.float64)

    def local_positions(self) -> np.ndarray:
        """Positions in the local frame X + u [m], float64 [n, 3]."""
        return self.rest_local_host + self.u.numpy().astype(np.float64)

    def velocities(self) -> np.ndarray:
        """v [m/s], float64 [n, 3]."""
        return self.v.numpy().astype(np.float64)

    def set_displacements(self, u):
        import warp as wp

        wp.copy(self.u, wp.array(np.asarray(u, dtype=self.npf).reshape(-1, 3), dtype=self.k.vec3, device=self.device))

    def set_velocities(self, v):
        import warp as wp

        wp.copy(self.v, wp.array(np.asarray(v, dtype=self.npf).reshape(-1, 3), dtype=self.k.vec3, device=self.device))

    def kinetic_energy(self) -> float:
        v = self.velocities()
        return float(0.5 * np.dot(self.mass_host, np.einsum("ij,ij->i", v, v)))

    def linear_momentum(self) -> np.ndarray:
        return self.mass_host @ self.velocities()

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        x = self.positions() - np.asarray(origin, dtype=np.float64)
        return self.mass_host @ np.cross(x, self.velocities())


WATCH_LOADS, WATCH_SUPPORTS, WATCH_KICKS, WATCH_COLLIDERS = 0, 1, 2, 3  # work put in [J] (accumulated over the run)
WATCH_BAD, WATCH_VMAX, WATCH_KE, WATCH_GRAVITY, WATCH_HELD_KE, WATCH_POINT_KE = 4, 5, 6, 7, 8, 9  # state of a check
WATCH_STRAIN_MIN, WATCH_STRAIN_MAX, WATCH_FIRST_BAD = 10, 11, 12
WATCH_SLOTS = 16
_WATCH_RESET = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0e300, -1.0e300, 1.0e300, 0.0, 0.0, 0.0])  # slots 4..15
_WATCH_THREADS = 4096  # grid-stride threads of the reductions
STRAIN_EVERY = 8  # the strain pass (a pass over the bonds or elements) runs every 8th check and at frame ends

ENERGY_FACTOR = 2.0
"""The fast energy check (every few steps) trips when E(t) > E(0) + W(t) + (ENERGY_FACTOR - 1) (|E(0)| + W(t) +
|U_g(t)|) + floor, E = kinetic + gravitational energy, U_g the gravity potential relative to the rest configuration
(see :class:`Watchdog`)."""

TOTAL_TOLERANCE = {"automatic": 0.25, "larger": 0.5}
"""The frame-end check trips when kinetic + strain + contact + gravitational energy exceeds
E(0) + W + tolerance (|E(0)| + W + |U_g|) + floor, the tolerance 25 % at or below the automatic step and 50 % above it.
Velocity Verlet conserves a shadow energy, not the energy measured at the step ends: measured on a block whose
velocities are white noise (the worst case, its highest modes excited), the measured energy sits 2-3 % above E(0) at
the automatic step, 6-10 % at 1.5x and 15-20 % at 2x, and stays there; a divergence that grows slowly, just past the
stable step, passes the tolerance within a few frames."""

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
        import warp as wp

        kin = solver.kin
        self.solver = solver
        self.device = kin.device
        self.energy_floor = float(energy_floor)
        self.surface_speed = surface_speed
        self.explain = explain
        self.energy = bool(energy)
        self.total_tolerance = float(total_tolerance)
        self.acc = wp.zeros(WATCH_SLOTS, dtype=wp.float64, device=self.device)
        self._reset = wp.array(_WATCH_RESET, dtype=wp.float64, device=self.device)
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
        # a frame replayed as a graph (pdsim/frame_graph.py) checks and polls ``stop`` at its end only
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
        import warp as wp

        if self.kin is not None and self.kin is not kin and self.kin.watchdog is self:
            self.kin.watchdog = None
        self.kin = kin
        kin.watchdog = self
        self._before = wp.zeros_like(kin.v) if self.surface_speed is not None else None

    def _held_points(self, kin):
        """The points of ``kin`` held by a prescribed-velocity condition (int32 Warp array, None when none),
        cached per kinematics."""
        import warp as wp

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
                from .checkpoint import RunInterrupted

                exc = RunInterrupted(self.stop.signal)
                exc.in_frame = done // self.stride  # scene steps of the frame done
                raise exc
        self._done += 1
        self._flush_support_work()
        self._step_dt = float(dt)

    def kick(self, kin, points, dv) -> None:
        import warp as wp

        n = int(points.shape[0])
        threads = min(n, _WATCH_THREADS)
        if threads:
            wp.launch(
                kin.k.watch_kick_work,
                dim=threads,
                inputs=[points, wp.vec3(*dv), kin.v, kin.mass, n, threads, self.acc],
                device=self.device,
            )

    def after_drift(self, kin) -> None:
        import warp as wp

        if self._before is not None and self._before.shape == kin.v.shape:
            wp.copy(self._before, kin.v)

    def loads_applied(self, kin) -> None:
        """The step's loads are in the force array (velocities at mid-step): load work, collider work."""
        import warp as wp

        dt = self._step_dt
        if dt is None:  # a force evaluation outside a step (initial accelerations, a state change)
            return
        self._step_dt = None
        self._time += dt
        n = kin.point_count
        if kin.load_count:
            m = kin.load_entry_count
            threads = min(m, _WATCH_THREADS)
            wp.launch(
                kin.k.watch_load_work,
                dim=threads,
                inputs=[
                    kin.load_point,
                    kin.load_index,
                    kin.load_force,
                    kin.load_scale,
                    kin.force_to_newton,
                    kin.v,
                    wp.float64(dt),
                    m,
                    threads,
                    self.acc,
                ],
                device=self.device,
            )
        if self._before is not None and self._before.shape == kin.v.shape and n:
            threads = min(n, _WATCH_THREADS)
            wp.launch(
                kin.k.watch_impulse_work,
                dim=threads,
                inputs=[
                    kin.v,
                    self._before,
                    kin.mass,
                    self._speeds,
                    self._speed_slot(self._time, dt),
                    n,
                    threads,
                    self.acc,
                ],
                device=self.device,
            )
        # the support work of this step is counted once its forces are final (next step, or the check), on the
        # kinematics and force array of this step (a fracture may rebuild both at the end of the step)
        self._pending = (dt, kin, getattr(self.solver, "force", None))

    # -- frames (pdsim/frame_graph.py) ---------------------------------------------------------------------------
    def begin_frame(self, dt: float, steps: int) -> None:
        """Writes the collider surface speed of each of the next ``steps`` steps of ``dt`` [s] to the device (one
        copy), so that the steps read it from a table instead of a launch argument."""
        import warp as wp

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
        import warp as wp

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
        import warp as wp

        pending, self._pending = self._pending, None
        if pending is None:
            return
        dt, kin, force = pending
        held = self._held_points(kin)
        if dt <= 0.0 or held is None or force is None or force.shape[0] != kin.point_count:
            return
        m = int(held.shape[0])
        threads = min(m, _WATCH_THREADS)
        wp.launch(
            kin.k.watch_support_work,
            dim=threads,
            inputs=[
                held,
                force,
                kin.force_to_newton,
                kin.mass,
                kin.gravity,
                kin.point_condition,
                kin.active_kind,
                kin.cond_axes,
                kin.active_velocity,
                wp.float64(dt),
                m,
                threads,
                self.acc,
            ],
            device=self.device,
        )

    # -- the check ---------------------------------------------------------------------------------------------------
    def _launch_strain(self) -> str | None:
        """Launches the strain range of the solver's method into the accumulator; returns its name (STRAIN_LIMITS)."""
        import warp as wp

        from .kernels import integration as ki

        solver = self.solver
        model = getattr(solver, "model", None)
        state = getattr(solver, "state", None)
        if getattr(state, "bond_ne", None) is not None and getattr(model, "bond_geom", None) is not None:
            # peridynamics: the live bonds' stretch, from the bond cache of the last force pass (the current state)
            n = int(model.bond_count)
            threads = min(n, _WATCH_THREADS)
            alive = getattr(state, "bond_alive", None)
            if threads:
                wp.launch(
                    ki.watch_bond_stretch,
                    dim=threads,
                    inputs=[
                        state.bond_ne,
                        model.bond_geom,
                        alive if alive is not None else self._no_alive,  # a placeholder, not read
                        int(alive is not None),
                        n,
                        threads,
                        self.acc,
                    ],
                    device=self.device,
                )
            return "bond stretch"
        tets = getattr(solver, "_tets", None)
        if tets is not None and getattr(model, "dm_inv", None) is not None:  # FEM
            m = int(tets.shape[0])
            threads = min(m, _WATCH_THREADS)
            if threads:
                wp.launch(
                    self.kin.k.watch_tet_strain,
                    dim=threads,
                    inputs=[self.kin.u, tets, model.dm_inv, m, threads, self.acc],
                    device=self.device,
                )
            return "volume ratio"
        return None

    def _reduce(self) -> dict:
        """One reduction of the state and one host read: the numbers of the check."""
        import warp as wp

        kin = self.kin
        wp.copy(self.acc, self._reset, dest_offset=4, src_offset=0, count=WATCH_SLOTS - 4)
        n = kin.point_count
        threads = min(n, _WATCH_THREADS)
        if threads:
            wp.launch(
                kin.k.watch_state,
                dim=threads,
                inputs=[
                    kin.u,
                    kin.v,
                    kin.mass,
                    kin.point_condition,
                    kin.point_kind,
                    kin.cond_axes,
                    kin.gravity,
                    n,
                    threads,
                    self.acc,
                ],
                device=self.device,
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
        ``bound`` [J], work put in ``work`` [J], largest speed ``vmax`` [m/s], strain range."""
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
        from .errors import InstabilityError

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
        import warp as wp

        work = np.asarray(state["work"], dtype=np.float64)
        wp.copy(self.acc, wp.array(work, dtype=wp.float64, device=self.device), count=4)
        self.initial_energy = float(state["initial_energy"])
        self.held_kinetic = float(state["held_kinetic"])
        self.held_work = float(state["held_work"])
        self._time = float(state["time"])
        self._pending = None
        self._step_dt = None


def _curve_tables(curves):
    """Concatenated (spans int32 [c, 2], times float32, values float32) of TimeCurves; one dummy entry when empty."""
    if not curves:
        return np.zeros((1, 2), dtype=np.int32), np.zeros(1, dtype=np.float32), np.ones(1, dtype=np.float32)
    spans, first = [], 0
    for c in curves:
        spans.append((first, len(c.times)))
        first += len(c.times)
    times = np.concatenate([c.times for c in curves]).astype(np.float32)
    values = np.concatenate([c.values for c in curves]).astype(np.float32)
    return np.asarray(spans, dtype=np.int32), times, values


def scene_origin(bounds) -> np.ndarray:
    """The local frame's origin [m] for world-space bounding boxes ``bounds`` (pairs of float64 [3] lo, hi): the
    centre of their union, so that every body's rest positions are as small as the scene's own extent."""
    lo = np.min([b[0] for b in bounds], axis=0)
    hi = np.max([b[1] for b in bounds], axis=0)
    return 0.5 * (lo + hi)


__all__ = [
    "ENERGY_FACTOR",
    "STRAIN_LIMITS",
    "TOTAL_TOLERANCE",
    "PointKinematics",
    "Watchdog",
    "scene_origin",
]
