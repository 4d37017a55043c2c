"""Watchdog kernels: grid-stride reductions of the point state, the strain and the energy put in, for
pdsim/watchdog.py.

Every kernel folds into one float64 accumulator ``acc`` of WATCH_SLOTS slots: thread ``tid`` of ``threads`` folds the
items tid, tid + threads, ... and adds to each slot once, so a GPU sees few atomics on one address whatever the item
count. The work slots (energy put in [J]: loads, supports, kicks, colliders and contact) accumulate over the run; the
state slots are reset to WATCH_RESET before each check. The kernels of the point state are built per scalar type by
``watchdog_kernels(dtype)``, like kernels/integration.py's.
"""

import functools

import numpy as np
import warp as wp

from .integration import POINT_FREE, POINT_PRESCRIBED
from .launch import launch

WATCH_LOADS, WATCH_SUPPORTS, WATCH_KICKS, WATCH_COLLIDERS = 0, 1, 2, 3  # work put in [J] (accumulated over the run)
WATCH_BAD, WATCH_VMAX, WATCH_KE, WATCH_GRAVITY, WATCH_HELD_KE, WATCH_POINT_KE = 4, 5, 6, 7, 8, 9  # state of a check
WATCH_STRAIN_MIN, WATCH_STRAIN_MAX, WATCH_FIRST_BAD = 10, 11, 12
WATCH_SLOTS = 16
WATCH_RESET = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0e300, -1.0e300, 1.0e300, 0.0, 0.0, 0.0])  # slots 4..15
WATCH_THREADS = 4096  # grid-stride threads of the reductions


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
def watchdog_kernels(dtype=wp.float32):
    """Watchdog kernels for the point state of scalar ``dtype`` (wp.float32 or wp.float64), returned as a namespace."""
    vec3 = wp.vec3d if dtype == wp.float64 else wp.vec3
    mat33 = wp.mat33d if dtype == wp.float64 else wp.mat33

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

    class WatchdogKernels:
        pass

    ns = WatchdogKernels()
    ns.watch_state = watch_state
    ns.watch_support_work = watch_support_work
    ns.watch_load_work = watch_load_work
    ns.watch_kick_work = watch_kick_work
    ns.watch_impulse_work = watch_impulse_work
    ns.watch_tet_strain = watch_tet_strain
    return ns


# -- launches (pdsim/watchdog.py) -------------------------------------------------------------------------------------
# Each takes the kernel's arguments as keywords named like its parameters (kernels/launch.py), among them the item
# ``count`` and the accumulator ``acc``, and launches min(count, WATCH_THREADS) grid-stride threads.


def _grid_stride(kernel, count: int, device, **arguments):
    """Launches ``kernel`` on min(count, WATCH_THREADS) threads striding over ``count`` items (its ``count`` and
    ``threads`` arguments); nothing when there are no items."""
    threads = min(count, WATCH_THREADS)
    if threads:
        launch(kernel, threads, device=device, count=count, threads=threads, **arguments)


def bond_stretch_range(*, count: int, device, **arguments):
    """Live bonds' stretch range into acc[10], acc[11] (watch_bond_stretch); nothing when there are no bonds."""
    _grid_stride(watch_bond_stretch, count, device, **arguments)


def tet_strain_range(k, *, count: int, device, **arguments):
    """Tetrahedra's volume-ratio range into acc[10], acc[11] (``k.watch_tet_strain``, ``k`` from watchdog_kernels);
    nothing when there are no tetrahedra."""
    _grid_stride(k.watch_tet_strain, count, device, **arguments)


def state_sums(k, *, count: int, device, **arguments):
    """The state slots of a check (``k.watch_state``); nothing when there are no points."""
    _grid_stride(k.watch_state, count, device, **arguments)


def support_work(k, *, dt: float, count: int, device, **arguments):
    """Work of the prescribed-velocity conditions over a step of ``dt`` [s] into acc[1] (``k.watch_support_work``)."""
    _grid_stride(k.watch_support_work, count, device, dt=wp.float64(dt), **arguments)


def load_work(k, *, dt: float, count: int, device, **arguments):
    """Work of the loads over a step of ``dt`` [s] into acc[0] (``k.watch_load_work``)."""
    _grid_stride(k.watch_load_work, count, device, dt=wp.float64(dt), **arguments)


def kick_work(k, *, points, dv, device, **arguments):
    """Kinetic energy the velocity kick ``dv`` [m/s] (3 numbers) on ``points`` adds, into acc[2]
    (``k.watch_kick_work``, launched before the kick); nothing when there are no points."""
    _grid_stride(k.watch_kick_work, int(points.shape[0]), device, points=points, dv=wp.vec3(*dv), **arguments)


def impulse_work(k, *, count: int, device, **arguments):
    """Bound of the moving colliders' work since ``before`` was taken, into acc[3] (``k.watch_impulse_work``)."""
    _grid_stride(k.watch_impulse_work, count, device, **arguments)
