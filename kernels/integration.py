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


@wp.kernel
def watch_scalar_range(values: wp.array(dtype=float), count: int, threads: int, acc: wp.array(dtype=wp.float64)):
    """Smallest and largest of ``values`` (e.g. the peridynamic dilatation [-]) into acc[10], acc[11]; a non-finite
    value counts as -1e300 (the smallest)."""
    tid = wp.tid()
    lo = wp.float64(1.0e300)
    hi = wp.float64(-1.0e300)
    i = tid
    while i < count:
        x = wp.float64(values[i])
        if wp.isnan(x) or wp.isinf(x):
            x = wp.float64(-1.0e300)
        lo = wp.min(lo, x)
        hi = wp.max(hi, x)
        i += threads
    wp.atomic_min(acc, 10, lo)
    wp.atomic_max(acc, 11, hi)


@wp.kernel
def watch_bond_stretch(
    bond_ne: wp.array(dtype=wp.vec4),
    bond_geom: wp.array(dtype=wp.vec4),
    bond_alive: wp.array(dtype=wp.uint8),
    use_alive: int,
    count: int,
    threads: int,
    acc: wp.array(dtype=wp.float64),
):
    """Smallest and largest stretch e / L [-] of the live peridynamic bonds into acc[10], acc[11], from the bond cache
    of the last force pass (``bond_ne`` = (deformed direction, extension e [m]), ``bond_geom`` = (xi / L, L [m]));
    ``bond_alive`` is read when ``use_alive`` is 1; a non-finite stretch counts as -1e300. A stretch near -1 means two
    bonded particles met: the body collapsed or particles passed through each other."""
    tid = wp.tid()
    lo = float(1.0e30)
    hi = float(-1.0e30)
    bad = int(0)
    q = tid
    while q < count:
        live = int(1)
        if use_alive == 1:
            if bond_alive[q] == wp.uint8(0):
                live = 0
        if live == 1:
            s = bond_ne[q][3] / bond_geom[q][3]
            if wp.isnan(s) or wp.isinf(s):
                bad = 1
            else:
                lo = wp.min(lo, s)
                hi = wp.max(hi, s)
        q += threads
    if bad == 1:
        wp.atomic_min(acc, 10, wp.float64(-1.0e300))
    if hi >= lo:
        wp.atomic_min(acc, 10, wp.float64(lo))
        wp.atomic_max(acc, 11, wp.float64(hi))


@functools.cache
def integration_kernels(dtype=wp.float32):
    """Integration kernels for scalar ``dtype`` (wp.float32 or wp.float64), returned as a namespace."""
    vec3 = wp.vec3d if dtype == wp.float64 else wp.vec3
    mat33 = wp.mat33d if dtype == wp.float64 else wp.mat33

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
        """First half kick and drift. A fixed point keeps its displacement on the constrained axes (zero velocity
        there); a prescribed one moves at the condition's mid-step velocity; free axes follow the half kick."""
        i = wp.tid()
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
        """Second half kick from the force of this step (see kick_point)."""
        i = wp.tid()
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

    # -- the watchdog (pdsim/kinematics.py, Watchdog) -----------------------------------------------------------------
    # Grid-stride reductions into one float64 accumulator ``acc`` (slots: pdsim/kinematics.py, WATCH_*): thread ``tid``
    # of ``threads`` folds the items tid, tid + threads, ... and adds to each slot once, so a GPU sees few atomics on
    # one address whatever the point count. The work slots (energy put in) accumulate over the run; the state slots
    # are reset before each check.

    @wp.kernel(module="unique")
    def watch_state(
        displacements: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        point_condition: wp.array(dtype=wp.int32),
        point_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        gravity: vec3,
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """Over the points: how many have a non-finite displacement or velocity and the smallest such index; the
        largest speed |v| [m/s]; the kinetic energy sum 1/2 m |v|^2 [J] and the largest point's [J]; the gravity
        potential -sum m g . u [J] relative to the rest configuration; the kinetic energy of the components held by a
        boundary condition in force [J] (point masses ``mass`` [kg])."""
        tid = wp.tid()
        bad = wp.float64(0.0)
        first = wp.float64(1.0e300)
        vmax = wp.float64(0.0)
        ke = wp.float64(0.0)
        pke = wp.float64(0.0)
        ug = wp.float64(0.0)
        kec = wp.float64(0.0)
        i = tid
        while i < count:
            u = displacements[i]
            v = velocities[i]
            finite = int(1)
            for d in range(3):
                ud = wp.float64(u[d])
                vd = wp.float64(v[d])
                if wp.isnan(ud) or wp.isinf(ud) or wp.isnan(vd) or wp.isinf(vd):
                    finite = 0
            if finite == 1:
                m = wp.float64(mass[i])
                v0 = wp.float64(v[0])
                v1 = wp.float64(v[1])
                v2 = wp.float64(v[2])
                vv = v0 * v0 + v1 * v1 + v2 * v2
                vmax = wp.max(vmax, wp.sqrt(vv))
                e = wp.float64(0.5) * m * vv
                ke += e
                pke = wp.max(pke, e)
                gu = wp.float64(gravity[0]) * wp.float64(u[0]) + wp.float64(gravity[1]) * wp.float64(u[1])
                gu = gu + wp.float64(gravity[2]) * wp.float64(u[2])
                ug -= m * gu
                if point_kind[i] != POINT_FREE:
                    axes = cond_axes[point_condition[i]]
                    held = wp.float64(0.0)
                    if axes[0] > 0.5:
                        held += v0 * v0
                    if axes[1] > 0.5:
                        held += v1 * v1
                    if axes[2] > 0.5:
                        held += v2 * v2
                    kec += wp.float64(0.5) * m * held
            else:
                bad += wp.float64(1.0)
                first = wp.min(first, wp.float64(i))
            i += threads
        if bad > wp.float64(0.0):
            wp.atomic_add(acc, 4, bad)
            wp.atomic_min(acc, 12, first)
        wp.atomic_max(acc, 5, vmax)
        wp.atomic_add(acc, 6, ke)
        wp.atomic_add(acc, 7, ug)
        wp.atomic_add(acc, 8, kec)
        wp.atomic_max(acc, 9, pke)

    @wp.kernel(module="unique")
    def watch_support_work(
        points: wp.array(dtype=wp.int32),
        force: wp.array(dtype=vec3),
        force_to_newton: wp.array(dtype=dtype),
        mass: wp.array(dtype=dtype),
        gravity: vec3,
        point_condition: wp.array(dtype=wp.int32),
        active_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        active_velocity: wp.array(dtype=wp.vec3),
        dt: wp.float64,
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """Work [J] the prescribed-velocity conditions put in over a step of ``dt`` [s]: the reaction
        R = -(f + m g) on each held axis (f the point's force in newtons: internal, contact and loads) times the
        condition's velocity, per point, summed where positive (a bound of the net input) into acc[1]."""
        tid = wp.tid()
        w = wp.float64(0.0)
        q = tid
        while q < count:
            i = points[q]
            c = point_condition[i]
            if active_kind[c] == POINT_PRESCRIBED:
                f = force[i] * force_to_newton[i] + mass[i] * gravity
                axes = cond_axes[c]
                vp = active_velocity[c]
                p = wp.float64(0.0)
                for d in range(3):
                    if axes[d] > 0.5:
                        p -= wp.float64(f[d]) * wp.float64(vp[d])
                if p > wp.float64(0.0):
                    w += p * dt
            q += threads
        wp.atomic_add(acc, 1, w)

    @wp.kernel(module="unique")
    def watch_load_work(
        load_point: wp.array(dtype=wp.int32),
        load_index: wp.array(dtype=wp.int32),
        load_force: wp.array(dtype=wp.vec3),
        load_scale: wp.array(dtype=float),
        force_to_newton: wp.array(dtype=dtype),
        velocities: wp.array(dtype=vec3),
        dt: wp.float64,
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """Work [J] of the loads over a step of ``dt`` [s]: F . v per (point, load) entry (F in newtons: the entry's
        force in the solver's unit times ``force_to_newton``), summed where positive into acc[0]."""
        tid = wp.tid()
        w = wp.float64(0.0)
        q = tid
        while q < count:
            i = load_point[q]
            f = load_force[q] * (load_scale[load_index[q]] * float(force_to_newton[i]))
            v = velocities[i]
            p = wp.float64(f[0]) * wp.float64(v[0]) + wp.float64(f[1]) * wp.float64(v[1])
            p = p + wp.float64(f[2]) * wp.float64(v[2])
            if p > wp.float64(0.0):
                w += p * dt
            q += threads
        wp.atomic_add(acc, 0, w)

    @wp.kernel(module="unique")
    def watch_kick_work(
        points: wp.array(dtype=wp.int32),
        dv: wp.vec3,
        velocities: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """Kinetic energy a velocity kick ``dv`` [m/s] adds [J]: 1/2 m (|v + dv|^2 - |v|^2) per point, where positive,
        into acc[2] (launched before the kick)."""
        tid = wp.tid()
        w = wp.float64(0.0)
        q = tid
        while q < count:
            i = points[q]
            v = velocities[i]
            e = wp.float64(0.0)
            for d in range(3):
                a = wp.float64(v[d])
                b = a + wp.float64(dv[d])
                e += b * b - a * a
            e = wp.float64(0.5) * wp.float64(mass[i]) * e
            if e > wp.float64(0.0):
                w += e
            q += threads
        wp.atomic_add(acc, 2, w)

    @wp.kernel(module="unique")
    def watch_impulse_work(
        velocities: wp.array(dtype=vec3),
        before: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        surface_speeds: wp.array(dtype=wp.float64),
        slot: int,
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """A bound of the work [J] moving colliders did on the points since ``before`` was copied from the velocities:
        sum m |v - v_before| times the largest speed of a collider surface [m/s] (``surface_speeds[slot]``, a table
        of the frame's steps written before the frame), into acc[3]."""
        tid = wp.tid()
        surface_speed = surface_speeds[slot]
        w = wp.float64(0.0)
        i = tid
        while i < count:
            d = velocities[i] - before[i]
            w += wp.float64(mass[i]) * wp.float64(wp.length(d)) * surface_speed
            i += threads
        wp.atomic_add(acc, 3, w)

    @wp.kernel(module="unique")
    def watch_tet_strain(
        displacements: wp.array(dtype=vec3),
        tets: wp.array(dtype=wp.vec4i),
        dm_inv: wp.array(dtype=mat33),
        count: int,
        threads: int,
        acc: wp.array(dtype=wp.float64),
    ):
        """Smallest and largest volume ratio J = det(I + Du Dm^-1) of the tetrahedra [-] into acc[10], acc[11]
        (non-finite J counts as -1e300, so it shows as the smallest)."""
        tid = wp.tid()
        lo = wp.float64(1.0e300)
        hi = wp.float64(-1.0e300)
        e = tid
        while e < count:
            t = tets[e]
            u0 = displacements[t[0]]
            u1 = displacements[t[1]]
            u2 = displacements[t[2]]
            u3 = displacements[t[3]]
            du = mat33(u1[0] - u0[0], u2[0] - u0[0], u3[0] - u0[0],
                       u1[1] - u0[1], u2[1] - u0[1], u3[1] - u0[1],
                       u1[2] - u0[2], u2[2] - u0[2], u3[2] - u0[2])  # fmt: skip
            f = wp.identity(n=3, dtype=dtype) + du * dm_inv[e]
            j = wp.float64(wp.determinant(f))
            if wp.isnan(j) or wp.isinf(j):
                j = wp.float64(-1.0e300)
            lo = wp.min(lo, j)
            hi = wp.max(hi, j)
            e += threads
        wp.atomic_min(acc, 10, lo)
        wp.atomic_max(acc, 11, hi)

    class IntegrationKernels:
        pass

    ns = IntegrationKernels()
    ns.vec3 = vec3
    ns.mat33 = mat33
    ns.kick_drift = kick_drift
    ns.kick_point = kick_point
    ns.kick = kick
    ns.apply_loads = apply_loads
    ns.add_velocity = add_velocity
    ns.condition_reactions = condition_reactions
    ns.max_speed_and_finite = max_speed_and_finite
    ns.watch_state = watch_state
    ns.watch_support_work = watch_support_work
    ns.watch_load_work = watch_load_work
    ns.watch_kick_work = watch_kick_work
    ns.watch_impulse_work = watch_impulse_work
    ns.watch_tet_strain = watch_tet_strain
    ns.constrained_velocity = constrained_velocity
    ns.free_part = free_part
    return ns
