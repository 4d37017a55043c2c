"""Vertex kernels of the tetrahedral FEM solver: force gathers (one fused with the shared velocity-Verlet kick), the
implicit backward-Euler right-hand side and update, and the quasi-static residual; the conjugate-gradient kernels are
in kernels/fem/cg.py.

Element kernels (kernels/fem/elements.py) write one vector per element corner ("slot" 4 e + a); the vertex kernels
gather them over a CSR incidence list (``vertex_offsets``, ``vertex_slots``, each vertex's slots in element order):
one thread per vertex, no atomics. The explicit step on the CPU skips the corners: its element pass adds them onto the
vertices itself, one thread walking the elements in order, which is the same sum in the same order (bit for bit).

State: displacements u [m], velocities v [m/s], accelerations a [m/s^2] of the shared kinematics
(kernels/integration.py, pdsim/kinematics.py); the force array starts each evaluation holding the loads [N]
(``apply_loads``), and the gathers add the element forces onto it.

Explicit step (velocity Verlet, kernels/integration.py's ``kick_drift``, then):
    (element forces at the new displacements)
    gather_kick:  f = loads + sum of corner forces ; a = f / m + g - c v ; v <- v + dt/2 a   (free axes; kick_point)
    (on the CPU: the element pass adds the corner forces onto the loads, then kernels/integration.py's ``kick``)

Implicit step (linearly implicit backward Euler with the corotated stiffness, rotations frozen at u_n):
    ((1 + dt c) M + dt^2 K_R) v_{n+1} = M v_n + dt (f(u_n) + f_ext + M g),   u_{n+1} = u_n + dt v_{n+1}
solved by the conjugate-gradient kernels of kernels/fem/cg.py.

Constraints are per component: ``constrained[i]`` holds a bit mask (bit d set when axis d of vertex i is held by a
boundary condition, 7 for a whole vertex).
"""

import functools

import warp as wp

from ..integration import POINT_FREE, integration_kernels
from ..launch import launch
from .elements import fem_types


@functools.cache
def constraint_funcs(dtype):
    """Warp functions on the per-vertex constraint bit masks: axis_bits, free_components, filter_block,
    condition_bits (a dict)."""
    vec3, mat33, _ = fem_types(dtype)

    @wp.func
    def axis_bits(axes: wp.vec3):
        """Bit mask of the constrained axes of a condition (1 per constrained component of ``axes``)."""
        bits = int(0)
        for d in range(3):
            if axes[d] > 0.5:
                bits = bits | (1 << d)
        return bits

    @wp.func
    def free_components(x: vec3, bits: int):
        """x with its constrained components zeroed."""
        out = x
        for d in range(3):
            if ((bits >> d) & 1) != 0:
                out[d] = dtype(0.0)
        return out

    @wp.func
    def filter_block(d: mat33, bits: int):
        """The inverse of the 3x3 block ``d`` restricted to the free components (zero rows and columns on the
        constrained ones); the identity's inverse on the free part when the block is not positive definite."""
        b = d
        for k in range(3):
            if ((bits >> k) & 1) != 0:
                for j in range(3):
                    b[k, j] = dtype(0.0)
                    b[j, k] = dtype(0.0)
                b[k, k] = dtype(1.0)
        p = wp.identity(3, dtype)
        if wp.determinant(b) > dtype(0.0):
            p = wp.inverse(b)
        for k in range(3):
            if ((bits >> k) & 1) != 0:
                for j in range(3):
                    p[k, j] = dtype(0.0)
                    p[j, k] = dtype(0.0)
        return p

    @wp.func
    def condition_bits(c: int, active_kind: wp.array(dtype=wp.int32), cond_axes: wp.array(dtype=wp.vec3)):
        """(kind this step, bit mask of the constrained axes) of a vertex under condition ``c`` (-1: none):
        (POINT_FREE, 0) without a condition or with an inactive one."""
        kind = POINT_FREE
        bits = int(0)
        if c >= 0:
            kind = active_kind[c]
            if kind != POINT_FREE:
                bits = axis_bits(cond_axes[c])
        return kind, bits

    return {
        "axis_bits": axis_bits,
        "free_components": free_components,
        "filter_block": filter_block,
        "condition_bits": condition_bits,
    }


@functools.cache
def vertex_kernels(dtype):
    """Kernels over vertices shared by the integrators and the static solve (a dict):

    - gather_forces: f_i = sum of the corner vectors of vertex i (overwrites).
    - gather_add: f_i += sum of the corner vectors of vertex i (onto the loads already in f).
    - gather_kick: gather_add, then the shared second half kick (``kick_point``): a = f / m + g - c v,
      v += dt/2 a on the free axes (dt = 0: accelerations only).
    - advance_displacements: u += dt v (backward Euler; constrained components carry their prescribed velocity).
    - constraint_bits: the bit mask of each vertex's active condition (0 when free) and its kind this step.
    - residual_forces: r_i = f_i + m_i g [N] on the free components (static equilibrium residual).
    - apply_increment: u += du.
    """
    vec3, _, _ = fem_types(dtype)
    ik = integration_kernels(dtype)
    kick_point = ik.kick_point
    cf = constraint_funcs(dtype)
    condition_bits = cf["condition_bits"]
    free_components = cf["free_components"]

    @wp.func
    def gather_corners(
        f: vec3,
        i: int,
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
    ):
        """f plus the corner vectors of vertex i [N], added in the order of its CSR incidence list."""
        acc = f
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            acc += corner_forces[vertex_slots[q]]
        return acc

    def gather_kernel(add: bool):
        """gather_add (``add``: onto the loads already in f) or gather_forces (overwrites)."""

        @wp.kernel(module="unique")
        def gather(
            vertex_offsets: wp.array(dtype=wp.int32),
            vertex_slots: wp.array(dtype=wp.int32),
            corner_forces: wp.array(dtype=vec3),
            forces: wp.array(dtype=vec3),
        ):
            i = wp.tid()
            if wp.static(add):
                forces[i] = gather_corners(forces[i], i, vertex_offsets, vertex_slots, corner_forces)
            else:
                forces[i] = gather_corners(vec3(dtype(0.0)), i, vertex_offsets, vertex_slots, corner_forces)

        return gather

    @wp.kernel(module="unique")
    def gather_kick(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        inv_mass: wp.array(dtype=dtype),
        gravity: vec3,
        damping: wp.array(dtype=dtype),
        dt: dtype,
        point_condition: wp.array(dtype=wp.int32),
        point_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        forces: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
    ):
        """f_i = loads + sum of corner forces [N]; then kick_point (kernels/integration.py). The gather and the kick are
        fused into one launch, so this repeats the kick_point call of kernels/integration.py's ``kick``."""
        i = wp.tid()
        f = gather_corners(forces[i], i, vertex_offsets, vertex_slots, corner_forces)
        forces[i] = f
        kick_point(
            i,
            f,
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
    def advance_displacements(displacements: wp.array(dtype=vec3), velocities: wp.array(dtype=vec3), dt: dtype):
        i = wp.tid()
        displacements[i] = displacements[i] + dt * velocities[i]

    @wp.kernel(module="unique")
    def constraint_bits(
        point_condition: wp.array(dtype=wp.int32),
        active_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        point_kind: wp.array(dtype=wp.int32),
        constrained: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        kind, bits = condition_bits(point_condition[i], active_kind, cond_axes)
        point_kind[i] = kind
        constrained[i] = bits

    @wp.kernel(module="unique")
    def residual_forces(
        forces: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        gravity: vec3,
        constrained: wp.array(dtype=wp.int32),
        residual: wp.array(dtype=vec3),
    ):
        i = wp.tid()
        residual[i] = free_components(forces[i] + mass[i] * gravity, constrained[i])

    @wp.kernel(module="unique")
    def apply_increment(displacements: wp.array(dtype=vec3), du: wp.array(dtype=vec3)):
        i = wp.tid()
        displacements[i] = displacements[i] + du[i]

    return {
        "gather_forces": gather_kernel(False),
        "gather_add": gather_kernel(True),
        "gather_kick": gather_kick,
        "advance_displacements": advance_displacements,
        "constraint_bits": constraint_bits,
        "residual_forces": residual_forces,
        "apply_increment": apply_increment,
    }


@functools.cache
def implicit_rhs_kernel(dtype):
    """Kernel over vertices: the backward-Euler right-hand side b = m v + dt (f + m g) [N s] (f: internal forces plus
    loads), the initial guess of the new velocity (the old one on free components, the condition's velocity at the
    mid-step on constrained ones: zero for a fixed condition), the constraint bit mask and the kind of each vertex."""
    vec3, _, _ = fem_types(dtype)
    ik = integration_kernels(dtype)
    constrained_velocity = ik.constrained_velocity
    condition_bits = constraint_funcs(dtype)["condition_bits"]

    @wp.kernel(module="unique")
    def implicit_rhs(
        forces: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        velocities: wp.array(dtype=vec3),
        point_condition: wp.array(dtype=wp.int32),
        active_kind: wp.array(dtype=wp.int32),
        cond_axes: wp.array(dtype=wp.vec3),
        active_velocity: wp.array(dtype=wp.vec3),
        gravity: vec3,
        dt: dtype,
        rhs: wp.array(dtype=vec3),
        guess: wp.array(dtype=vec3),
        constrained: wp.array(dtype=wp.int32),
        point_kind: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        m = mass[i]
        v = velocities[i]
        rhs[i] = m * v + dt * (forces[i] + m * gravity)
        c = point_condition[i]
        kind, bits = condition_bits(c, active_kind, cond_axes)
        if kind != POINT_FREE:
            v = constrained_velocity(v, cond_axes[c], active_velocity[c])
        guess[i] = v
        constrained[i] = bits
        point_kind[i] = kind

    return implicit_rhs


# -- launches ----------------------------------------------------------------------------------------------------------
# One function per kernel, its arguments given by the kernel's parameter names (kernels/launch.py); ``dtype`` is the
# solver's scalar type (wp.float32 or wp.float64), one thread per vertex.


def gather_forces(*, dtype, device, **arguments):
    """forces[i] = sum of the corner vectors of vertex i [N] (overwrites; vertex_kernels' gather_forces)."""
    launch(vertex_kernels(dtype)["gather_forces"], arguments["forces"].shape[0], device=device, **arguments)


def gather_add(*, dtype, device, **arguments):
    """forces[i] += sum of the corner vectors of vertex i [N] (onto the loads already in ``forces``; vertex_kernels'
    gather_add)."""
    launch(vertex_kernels(dtype)["gather_add"], arguments["forces"].shape[0], device=device, **arguments)


def gather_kick(*, dtype, device, **arguments):
    """gather_add, then the second half kick: a = f / m + g - c v [m/s^2], v += dt/2 a on the free axes (dt [s]; 0:
    the accelerations only; vertex_kernels' gather_kick)."""
    launch(vertex_kernels(dtype)["gather_kick"], arguments["forces"].shape[0], device=device, **arguments)


def advance_displacements(*, dtype, device, **arguments):
    """u += dt v [m] (dt [s]; vertex_kernels' advance_displacements)."""
    launch(
        vertex_kernels(dtype)["advance_displacements"], arguments["displacements"].shape[0], device=device, **arguments
    )


def constraint_bits(*, dtype, device, **arguments):
    """The bit mask of each vertex's active condition into ``constrained`` (0 when free) and its kind into
    ``point_kind`` (vertex_kernels' constraint_bits)."""
    launch(vertex_kernels(dtype)["constraint_bits"], arguments["constrained"].shape[0], device=device, **arguments)


def residual_forces(*, dtype, device, **arguments):
    """residual_i = f_i + m_i g [N] on the free components (the static equilibrium residual; vertex_kernels'
    residual_forces)."""
    launch(vertex_kernels(dtype)["residual_forces"], arguments["residual"].shape[0], device=device, **arguments)


def apply_increment(*, dtype, device, **arguments):
    """u += du [m] (vertex_kernels' apply_increment)."""
    launch(vertex_kernels(dtype)["apply_increment"], arguments["displacements"].shape[0], device=device, **arguments)


def implicit_rhs(*, dtype, device, **arguments):
    """The backward-Euler right-hand side b = m v + dt (f + m g) [N s] into ``rhs``, the initial guess of the new
    velocity [m/s] into ``guess``, the constraint bit masks and the vertex kinds (implicit_rhs_kernel)."""
    launch(implicit_rhs_kernel(dtype), arguments["rhs"].shape[0], device=device, **arguments)
