"""Shared kinematics of every method with mass: velocity-Verlet integration on displacements, boundary conditions,
loads with time curves, reaction forces and the finite/speed watchdog.

State per point: displacement u from the rest position [m], velocity v [m/s], acceleration a [m/s^2]. Positions are
never integrated in world coordinates: a point's position is X + u with X its rest position in the solver's local
frame, so float32 resolves a displacement to about 1e-7 of its own size wherever the body sits in the world, and
deformation is computed from displacement differences (see kernels/peridynamics/step.py and kernels/fem/).

One step of length dt, with a_n the acceleration of the previous force evaluation:

    evaluate_conditions:  each boundary condition's state at the mid-step time t + dt/2 (active or not, velocity)
    kick_drift:           v <- v + dt/2 a_n ; u <- u + dt v          (constrained axes: v prescribed, fixed: v = 0)
    (colliders and contact move u and v; internal forces at the new displacements; apply_loads adds f_ext(t + dt))
    kick:                 a = f / m + g - c v ; v <- v + dt/2 a       (free axes only)

``f / m`` is the force per unit mass: force density over density for peridynamics (f [N/m^3], inv_mass = 1 / rho),
nodal force over lumped mass for the FEM (f [N], inv_mass = 1 / m).

Boundary conditions: each constrained point names one condition (``point_condition``, -1 for none). A condition has
a kind (fixed or prescribed velocity), the axes it constrains (1 per constrained component; the others move freely,
e.g. a roller grip), a velocity [m/s] scaled by a time curve, and a window [start, release) outside which its points
are free. The kind in force this step is written per point (``point_kind``) for the colliders and contact, which act
on free points only.

Time curves are piecewise-linear tables (time [s], value), constant beyond their ends: a constant is one entry, a
ramp two. ``curve_span[c] = (first, count)`` locates curve c in the concatenated tables.

Kernels are built per scalar type (float32 for peridynamics, float32 or float64 for the FEM) by
``integration_kernels(dtype)``; the condition and curve tables are always float32.
"""

import functools

import warp as wp

from .launch import launch, launch_inputs, range_inputs

POINT_FREE = wp.constant(0)
POINT_FIXED = wp.constant(1)
POINT_PRESCRIBED = wp.constant(2)
PARTICLE_FREE = POINT_FREE  # name used by the collider and contact kernels


@wp.func
def curve_value(span: wp.vec2i, times: wp.array(dtype=float), values: wp.array(dtype=float), t: float):
    """Value of a piecewise-linear time curve at t [s], held constant before its first and after its last entry."""
    first = span[0]
    count = span[1]
    if count <= 1 or t <= times[first]:
        return values[first]
    last = first + count - 1
    if t >= times[last]:
        return values[last]
    k = first
    while times[k + 1] < t:
        k += 1
    t0 = times[k]
    t1 = times[k + 1]
    w = (t - t0) / (t1 - t0)
    return values[k] + w * (values[k + 1] - values[k])


@wp.kernel
def evaluate_conditions(
    cond_kind: wp.array(dtype=wp.int32),
    cond_start: wp.array(dtype=float),
    cond_release: wp.array(dtype=float),
    cond_velocity: wp.array(dtype=wp.vec3),
    cond_curve: wp.array(dtype=wp.vec2i),
    curve_time: wp.array(dtype=float),
    curve_data: wp.array(dtype=float),
    clock: wp.array(dtype=wp.float64),
    slot: int,
    offset: wp.float64,
    active_kind: wp.array(dtype=wp.int32),
    active_velocity: wp.array(dtype=wp.vec3),
):
    """State of boundary condition c at time t = clock[slot] + offset [s] (the device clock of pdsim/kinematics.py,
    so that no launch argument changes between steps): its kind inside [start, release), free outside; its velocity
    scaled by its time curve (zero for a fixed condition)."""
    c = wp.tid()
    t = wp.float32(clock[slot] + offset)
    kind = cond_kind[c]
    if t < cond_start[c] or t >= cond_release[c]:
        kind = POINT_FREE
    active_kind[c] = kind
    v = wp.vec3(0.0)
    if kind == POINT_PRESCRIBED:
        v = cond_velocity[c] * curve_value(cond_curve[c], curve_time, curve_data, t)
    active_velocity[c] = v


@wp.kernel
def evaluate_curves(
    span: wp.array(dtype=wp.vec2i),
    curve_time: wp.array(dtype=float),
    curve_data: wp.array(dtype=float),
    clock: wp.array(dtype=wp.float64),
    slot: int,
    value: wp.array(dtype=float),
):
    """value[c] = curve c at time t = clock[slot] [s] (the load scales of a step)."""
    c = wp.tid()
    value[c] = curve_value(span[c], curve_time, curve_data, wp.float32(clock[slot]))


@wp.kernel
def clock_begin_step(clock: wp.array(dtype=wp.float64), dt: wp.float64):
    """The device clock of a step of dt [s]: clock[1] (the time at the end of the step) <- clock[0] + dt."""
    clock[1] = clock[0] + dt


@wp.kernel
def clock_end_step(clock: wp.array(dtype=wp.float64)):
    """The step is done: clock[0] (the time at the start of the next step) <- clock[1]."""
    clock[0] = clock[1]


@functools.cache
def integration_kernels(dtype=wp.float32):
    """Integration kernels for scalar ``dtype`` (wp.float32 or wp.float64), returned as a namespace."""
    vec3 = wp.vec3d if dtype == wp.float64 else wp.vec3

    @wp.func
    def constrained_velocity(v: vec3, axes: wp.vec3, prescribed: wp.vec3):
        """v with its constrained components replaced by the prescribed ones."""
        out = v
        for d in range(3):
            if axes[d] > 0.5:
                out[d] = dtype(prescribed[d])
        return out

    @wp.func
    def free_part(a: vec3, axes: wp.vec3):
        """a with its constrained components zeroed."""
        out = a
        for d in range(3):
            if axes[d] > 0.5:
                out[d] = dtype(0.0)
        return out

    @wp.kernel(module="unique")
    def kick_drift(
        first: int,
        displacements: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
        point_condition: wp.array(dtype=wp.int32),
        active_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        active_velocity: wp.array(dtype=wp.vec3),
        dt: dtype,
        point_kind: wp.array(dtype=wp.int32),
    ):
        """First half kick and drift of point i = first + tid. A fixed point keeps its displacement on the constrained
        axes (zero velocity there); a prescribed one moves at the condition's mid-step velocity; free axes follow the
        half kick."""
        i = first + wp.tid()
        v = velocities[i] + (dtype(0.5) * dt) * accelerations[i]
        kind = POINT_FREE
        c = point_condition[i]
        if c >= 0:
            kind = active_kind[c]
            if kind != POINT_FREE:
                v = constrained_velocity(v, cond_axes[c], active_velocity[c])
        point_kind[i] = kind
        velocities[i] = v
        displacements[i] = displacements[i] + dt * v

    @wp.func
    def kick_point(
        i: int,
        f: vec3,
        inv_mass: dtype,
        gravity: vec3,
        damping: dtype,
        dt: dtype,
        point_condition: wp.array(dtype=wp.int32),
        point_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
    ):
        """a = f / m + g - c v; second half kick on the free axes (the fused step of kick, shared with the FEM's
        gather-and-kick)."""
        v = velocities[i]
        a = f * inv_mass + gravity - damping * v
        accelerations[i] = a
        dv = (dtype(0.5) * dt) * a
        if point_kind[i] != POINT_FREE:
            dv = free_part(dv, cond_axes[point_condition[i]])
        velocities[i] = v + dv

    @wp.kernel(module="unique")
    def kick(
        first: int,
        force: wp.array(dtype=vec3),
        inv_mass: wp.array(dtype=dtype),
        gravity: vec3,
        damping: wp.array(dtype=dtype),
        dt: dtype,
        point_condition: wp.array(dtype=wp.int32),
        point_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
    ):
        """Second half kick of point i = first + tid from the force of this step (see kick_point)."""
        i = first + wp.tid()
        kick_point(
            i,
            force[i],
            inv_mass[i],
            gravity,
            damping[i],
            dt,
            point_condition,
            point_kind,
            cond_axes,
            velocities,
            accelerations,
        )

    @wp.kernel(module="unique")
    def apply_loads(
        load_point: wp.array(dtype=wp.int32),
        load_index: wp.array(dtype=wp.int32),
        load_force: wp.array(dtype=wp.vec3),
        load_scale: wp.array(dtype=float),
        force: wp.array(dtype=vec3),
    ):
        """force[p] += scale(load) * F for each (point, load) entry; F is already in the solver's force unit
        (force density for peridynamics, newtons for the FEM)."""
        q = wp.tid()
        f = load_force[q] * load_scale[load_index[q]]
        wp.atomic_add(force, load_point[q], vec3(dtype(f[0]), dtype(f[1]), dtype(f[2])))

    @wp.kernel(module="unique")
    def add_velocity(points: wp.array(dtype=wp.int32), dv: wp.vec3, velocities: wp.array(dtype=vec3)):
        """A velocity kick: v += dv on the listed points."""
        q = wp.tid()
        i = points[q]
        velocities[i] = velocities[i] + vec3(dtype(dv[0]), dtype(dv[1]), dtype(dv[2]))

    # Every kernel that honours the boundary conditions takes the per-point condition arrays (point_condition,
    # active_kind, cond_axes) as parameters in the same order: the repeated lines are those parameter lists.
    @wp.kernel(module="unique")
    def condition_reactions(
        point_condition: wp.array(dtype=wp.int32),
        active_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        force: wp.array(dtype=vec3),
        force_to_newton: wp.array(dtype=dtype),
        mass: wp.array(dtype=dtype),
        gravity: vec3,
        reaction: wp.array(dtype=wp.vec3d),
    ):
        """Force [N] each active condition exerts on the body: on its constrained axes, minus the sum over its points
        of the internal force, the loads and the weight (the support's share of equilibrium; the inertia of a
        point whose prescribed velocity changes is neglected)."""
        i = wp.tid()
        c = point_condition[i]
        if c < 0:
            return
        if active_kind[c] == POINT_FREE:
            return
        s = -(force[i] * force_to_newton[i] + mass[i] * gravity)
        axes = cond_axes[c]
        r = wp.vec3d(
            wp.float64(s[0]) * wp.float64(axes[0]),
            wp.float64(s[1]) * wp.float64(axes[1]),
            wp.float64(s[2]) * wp.float64(axes[2]),
        )
        wp.atomic_add(reaction, c, r)

    @wp.kernel(module="unique")
    def max_speed_and_finite(
        displacements: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        result: wp.array(dtype=float),
    ):
        """result[0] = max |v| over points [m/s]; result[1] = 1 when any displacement or velocity is not finite."""
        i = wp.tid()
        s = float(wp.length(velocities[i]))
        x = float(wp.length(displacements[i]))
        if wp.isnan(s) or wp.isinf(s) or wp.isnan(x) or wp.isinf(x):
            result[1] = 1.0
        else:
            wp.atomic_max(result, 0, s)

    class IntegrationKernels:
        pass

    ns = IntegrationKernels()
    ns.dtype = dtype
    ns.vec3 = vec3
    ns.kick_drift = kick_drift
    ns.kick_point = kick_point
    ns.kick = kick
    ns.apply_loads = apply_loads
    ns.add_velocity = add_velocity
    ns.condition_reactions = condition_reactions
    ns.max_speed_and_finite = max_speed_and_finite
    ns.constrained_velocity = constrained_velocity
    ns.free_part = free_part
    return ns


# -- launches (pdsim/kinematics.py) -----------------------------------------------------------------------------------
# ``k`` is the namespace of integration_kernels for the state's scalar type; ``count`` the launch's thread count.
# ``ranges``: None (one launch over the points 0 .. count - 1) or a ``ranges(kernel, inputs)`` that runs a range kernel
# (first parameter: the first point of the launch) over every point, split into ranges launched at once (the
# peridynamic solver's ParticleRanges.launch); each point's arithmetic is the same either way.


def begin_clock_step(clock, dt: float, device):
    """The device clock of a step of ``dt`` [s] (clock_begin_step)."""
    launch_inputs(clock_begin_step, 1, [clock, wp.float64(dt)], device)


def end_clock_step(clock, device):
    """The step is done on the device clock (clock_end_step)."""
    launch_inputs(clock_end_step, 1, [clock], device)


def conditions_at(count: int, *, slot: int, offset: float, device, **arguments):
    """The state of ``count`` boundary conditions at the device time clock[slot] + offset [s] (evaluate_conditions)."""
    launch(evaluate_conditions, count, device=device, slot=int(slot), offset=wp.float64(offset), **arguments)


def curves_at(count: int, span, curve_time, curve_data, clock, slot: int, value, device):
    """value[c] = curve c at the device time clock[slot] [s] for ``count`` curves (evaluate_curves)."""
    launch_inputs(evaluate_curves, count, [span, curve_time, curve_data, clock, slot, value], device)


def _points_launch(kernel, count: int, ranges, device, arguments: dict) -> None:
    """``kernel`` (a range kernel) over the points 0 .. count - 1: one launch, or through ``ranges``."""
    if ranges is None:
        launch(kernel, count, device=device, first=0, **arguments)
    else:
        ranges(kernel, range_inputs(kernel, arguments))


def kick_drift(k, count: int, *, dt: float, device, ranges=None, **arguments):
    """First half kick and drift of ``count`` points over ``dt`` [s] (``k.kick_drift``)."""
    _points_launch(k.kick_drift, count, ranges, device, dict(arguments, dt=k.dtype(dt)))


def kick(k, count: int, *, dt: float, device, ranges=None, **arguments):
    """Second half kick of ``count`` points over ``dt`` [s] (``k.kick``)."""
    _points_launch(k.kick, count, ranges, device, dict(arguments, dt=k.dtype(dt)))


def apply_loads(k, count: int, load_point, load_index, load_force, load_scale, force, device):
    """Adds ``count`` scaled (point, load) entries to ``force`` (``k.apply_loads``)."""
    launch_inputs(k.apply_loads, count, [load_point, load_index, load_force, load_scale, force], device)


def add_velocity(k, points, dv, velocities, device):
    """A velocity kick: v += ``dv`` [m/s] (3 numbers) on ``points`` (``k.add_velocity``)."""
    wp.launch(k.add_velocity, dim=points.shape[0], inputs=[points, wp.vec3(*dv), velocities], device=device)


def condition_reactions(k, count: int, *, device, **arguments):
    """Adds each active condition's force on its body [N] over ``count`` points into ``reaction``
    (``k.condition_reactions``)."""
    launch(k.condition_reactions, count, device=device, **arguments)


def max_speed_and_finite(k, count: int, displacements, velocities, result, device):
    """result[0] = max |v| [m/s], result[1] = 1 when a value is not finite, over ``count`` points
    (``k.max_speed_and_finite``)."""
    wp.launch(k.max_speed_and_finite, dim=count, inputs=[displacements, velocities, result], device=device)
