"""The shared point state of every method with mass, integrated by kernels/integration.py.

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

import numpy as np
import warp as wp

from .errors import InstabilityError
from .kernels import integration as ki
from .kernels.launch import by_name


class PointKinematics:
    """Displacements, velocities and accelerations of ``point_count`` points, with their boundary conditions and
    loads.

    ``watchdog`` (a :class:`pdsim.watchdog.Watchdog`, set by it) is told of every step, kick and load evaluation so
    that it can account for the energy put in; None (default) costs nothing. ``ranges`` (set by a solver that splits
    its passes over CPU threads: the peridynamic solver's ``ParticleRanges.launch``) runs the kick and drift as range
    launches on those threads, every point computed as in one launch; None (default): one launch each.

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
    ranges = None  # None: kick and drift as one launch; else ranges(kernel, inputs) running them on a solver's threads

    def __init__(
        self, bodies, body_offsets, rest_world, origin, mass, force_to_newton, damping, gravity, device, dtype
    ):
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
        ki.end_clock_step(self.clock, self.device)
        self.clock_host[0] = self.clock_host[1]

    # -- stepping ------------------------------------------------------------------------------------------------------
    def begin_step(self, t: float, dt: float):
        """Velocity kicks due in [t, t + dt), the conditions' state at t + dt/2, then the first half kick and drift.
        The device clock advances to the step: clock[0] = t (already there unless the state was changed from the
        host), clock[1] = t + dt."""
        d = self.device
        self.apply_kicks(t, dt)  # first: it starts the step (the watchdog's check every few steps runs there)
        self.set_clock(t, 0)
        ki.begin_clock_step(self.clock, dt, d)
        self.clock_host[1] = self.clock_host[0] + float(dt)
        if self.condition_count:
            self._evaluate_conditions_at(0, 0.5 * dt)
        ki.kick_drift(
            self.k,
            self.point_count,
            displacements=self.u,
            velocities=self.v,
            accelerations=self.a,
            dt=dt,
            device=d,
            ranges=self.ranges,
            **by_name(self, "point_condition", "active_kind", "cond_axes", "active_velocity", "point_kind"),
        )
        if self.watchdog is not None:
            self.watchdog.after_drift(self)

    def apply_kicks(self, t: float, dt: float):
        """The velocity kicks due in [t, t + dt), each applied once. Every step of every integrator starts here (the
        watchdog takes the step's length from it)."""
        watchdog = self.watchdog
        if watchdog is not None:
            watchdog.step_start(self, dt)
        while self.next_kick < len(self.kicks) and self.kicks[self.next_kick][0] < t + dt:
            _, pts, dv = self.kicks[self.next_kick]
            if watchdog is not None:
                watchdog.kick(self, pts, dv)
            ki.add_velocity(self.k, pts, dv, self.v, self.device)
            self.next_kick += 1

    def evaluate_conditions(self, t: float):
        """Each boundary condition's state at time ``t`` [s] (active kind and velocity), on the device (``t`` is
        written to the clock's scratch slot unless the clock holds it)."""
        self._evaluate_conditions_at(self._clock_slot(t), 0.0)

    def _evaluate_conditions_at(self, slot: int, offset: float):
        """Each boundary condition's state at the device time clock[slot] + offset [s]."""
        ki.conditions_at(
            self.condition_count,
            curve_time=self.cond_curve_time,
            curve_data=self.cond_curve_value,
            slot=slot,
            offset=offset,
            device=self.device,
            **by_name(self, "cond_kind", "cond_start", "cond_release", "cond_velocity", "cond_curve", "clock"),
            **by_name(self, "active_kind", "active_velocity"),
        )

    def add_loads(self, force, t: float):
        """Adds every load, scaled by its curve at ``t`` [s], to ``force`` (the solver's force array). ``t`` is read
        from the device clock (the end of the step begun, or its start; another time is written to the scratch
        slot)."""
        if self.load_count:
            d = self.device
            slot = self._clock_slot(t)
            ki.curves_at(
                self.load_count,
                self.load_curve,
                self.load_curve_time,
                self.load_curve_value,
                self.clock,
                slot,
                self.load_scale,
                d,
            )
            ki.apply_loads(
                self.k,
                self.load_entry_count,
                self.load_point,
                self.load_index,
                self.load_force,
                self.load_scale,
                force,
                d,
            )
        if self.watchdog is not None:
            self.watchdog.loads_applied(self)

    def end_step(self, force, inv_mass, dt: float):
        """Second half kick: a = force * inv_mass + g - c v on the free axes; the device clock moves to the step's
        end."""
        ki.kick(
            self.k,
            self.point_count,
            force=force,
            inv_mass=inv_mass,
            dt=dt,
            velocities=self.v,
            accelerations=self.a,
            device=self.device,
            ranges=self.ranges,
            **by_name(self, "gravity", "damping", "point_condition", "point_kind", "cond_axes"),
        )
        self.end_clock_step()

    # -- outputs and checks --------------------------------------------------------------------------------------------
    def reactions(self, force, t: float) -> dict:
        """Force [N] each boundary condition exerts on its body at time ``t`` (from ``force``, the solver's internal
        force plus loads of the last evaluation): {(body name, condition name): float64 [3]}; zero when inactive."""
        if not self.condition_count:
            return {}
        self.evaluate_conditions(t)
        self._reaction.zero_()
        ki.condition_reactions(
            self.k,
            self.point_count,
            force=force,
            reaction=self._reaction,
            device=self.device,
            **by_name(self, "point_condition", "active_kind", "cond_axes", "force_to_newton", "mass", "gravity"),
        )
        r = self._reaction.numpy()
        return {name: r[i].astype(np.float64) for i, name in enumerate(self.condition_names)}

    def check(self, speed_limit: float, where: str, hint: str = ""):
        """Raises InstabilityError when a displacement or velocity is not finite or a speed exceeds ``speed_limit``
        [m/s]; the message says ``where`` and ends with ``hint``."""
        self._check.zero_()
        ki.max_speed_and_finite(self.k, self.point_count, self.u, self.v, self._check, self.device)
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
        wp.copy(self.u, wp.array(np.asarray(u, dtype=self.npf).reshape(-1, 3), dtype=self.k.vec3, device=self.device))

    def set_velocities(self, v):
        wp.copy(self.v, wp.array(np.asarray(v, dtype=self.npf).reshape(-1, 3), dtype=self.k.vec3, device=self.device))

    def kinetic_energy(self) -> float:
        v = self.velocities()
        return float(0.5 * np.dot(self.mass_host, np.einsum("ij,ij->i", v, v)))

    def linear_momentum(self) -> np.ndarray:
        return self.mass_host @ self.velocities()

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        x = self.positions() - np.asarray(origin, dtype=np.float64)
        return self.mass_host @ np.cross(x, self.velocities())


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


__all__ = ["PointKinematics", "scene_origin"]
