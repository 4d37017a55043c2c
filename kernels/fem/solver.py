"""Vertex kernels of the tetrahedral FEM solver: force gathers (one fused with the shared velocity-Verlet kick), the
implicit backward-Euler right-hand side and update, the quasi-static residual, and a preconditioned conjugate-gradient
solver built from Warp kernels.

Element kernels (kernels/fem/elements.py) write one vector per element corner ("slot" 4 e + a); the vertex kernels
gather them over a CSR incidence list (``vertex_offsets``, ``vertex_slots``): one thread per vertex, no atomics, so the
CPU and the GPU sum in the same order.

State: displacements u [m], velocities v [m/s], accelerations a [m/s^2] of the shared kinematics
(kernels/integration.py, pdsim/kinematics.py); the force array starts each evaluation holding the loads [N]
(``apply_loads``), and the gathers add the element forces onto it.

Explicit step (velocity Verlet, kernels/integration.py's ``kick_drift``, then):
    (element forces at the new displacements)
    gather_kick:  f = loads + sum of corner forces ; a = f / m + g - c v ; v <- v + dt/2 a   (free axes; kick_point)

Implicit step (linearly implicit backward Euler with the corotated stiffness, rotations frozen at u_n):
    ((1 + dt c) M + dt^2 K_R) v_{n+1} = M v_n + dt (f(u_n) + f_ext + M g),   u_{n+1} = u_n + dt v_{n+1}
solved by block-Jacobi preconditioned CG, the stiffness applied either matrix-free (the element kernels with the
frozen rotations, every iteration) or as an assembled matrix of 3x3 blocks in CSR order, filled once per solve by a
gather of the element blocks (faster on the CPU: docs/benchmarks.md).

Constraints are per component: ``constrained[i]`` holds a bit mask (bit d set when axis d of vertex i is held by a
boundary condition, 7 for a whole vertex). The CG works on the free components only: constrained components of the
unknown keep their initial (prescribed) value, their residual, search direction and preconditioner rows are zero.

Reductions (dot products) are chunked: thread c sums a contiguous range of vertices into ``partial[c]`` and a single
thread adds the partial sums, so the result does not depend on thread scheduling.
"""

import functools

import warp as wp

from ..integration import POINT_FREE, integration_kernels
from .elements import fem_funcs, fem_types

# cg_scalars slots
CG_RZ = 0  # r . z
CG_PQ = 1  # p . A p
CG_ALPHA = 2
CG_BETA = 3
CG_RR = 4  # r . r
CG_BB = 5  # b . b (filtered right-hand side)
CG_SCALAR_COUNT = 8


@functools.cache
def constraint_funcs(dtype):
    """Warp functions on the per-vertex constraint bit masks: axis_bits, free_components, filter_block (a dict)."""
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

    return {"axis_bits": axis_bits, "free_components": free_components, "filter_block": filter_block}


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
    axis_bits = cf["axis_bits"]
    free_components = cf["free_components"]

    @wp.kernel(module="unique")
    def gather_forces(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        forces: wp.array(dtype=vec3),
    ):
        i = wp.tid()
        f = vec3(dtype(0.0))
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
        forces[i] = f

    @wp.kernel(module="unique")
    def gather_add(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        forces: wp.array(dtype=vec3),
    ):
        i = wp.tid()
        f = forces[i]
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
        forces[i] = f

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
        """f_i = loads + sum of corner forces [N]; then kick_point (kernels/integration.py)."""
        i = wp.tid()
        f = forces[i]
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
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
        kind = POINT_FREE
        bits = int(0)
        c = point_condition[i]
        if c >= 0:
            kind = active_kind[c]
            if kind != POINT_FREE:
                bits = axis_bits(cond_axes[c])
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
        "gather_forces": gather_forces,
        "gather_add": gather_add,
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
    axis_bits = constraint_funcs(dtype)["axis_bits"]

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
        kind = POINT_FREE
        bits = int(0)
        c = point_condition[i]
        if c >= 0:
            kind = active_kind[c]
            if kind != POINT_FREE:
                bits = axis_bits(cond_axes[c])
                v = constrained_velocity(v, cond_axes[c], active_velocity[c])
        guess[i] = v
        constrained[i] = bits
        point_kind[i] = kind

    return implicit_rhs


@functools.cache
def cg_kernels(dtype, rotated: bool):
    """Kernels of the preconditioned CG for A = c_mass M + c_stiff K_R (K_R = sum_e R K_e R^T, R frozen; identity when
    not ``rotated``) on the free components (``constrained`` bit masks), as a dict:

    - block_jacobi (vertices): P_i = inverse of the 3x3 diagonal block c_mass m_i I + c_stiff sum R K_aa R^T
      restricted to the free components (zero rows and columns on constrained ones).
    - operator_gather (chunks): q_i = c_mass m_i p_i + c_stiff sum of corner products, constrained components zeroed;
      partial[c] = sum p . q over the chunk.
    - residual_init (chunks): r = b - A x (filtered), z = P r, p = z; partials of r . z, r . r and b . b.
    - update_xr (chunks): x += alpha p, r -= alpha q, z = P r; partials of r . z and r . r.
    - update_p (chunks): p = z + beta p.
    - reduce_alpha / reduce_init / reduce_beta (one thread): sum the partials and set the scalars.
    """
    vec3, mat33, _ = fem_types(dtype)
    vec2 = wp.types.vector(2, dtype)
    fn = fem_funcs(dtype)
    shape_gradient = fn["shape_gradient"]
    stiffness_block = fn["stiffness_block"]
    cf = constraint_funcs(dtype)
    free_components = cf["free_components"]
    filter_block = cf["filter_block"]

    @wp.kernel(module="unique")
    def block_jacobi(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        dm_inv: wp.array(dtype=mat33),
        volume: wp.array(dtype=dtype),
        lame: wp.array(dtype=wp.types.vector(2, dtype)),
        rotation: wp.array(dtype=mat33),
        mass: wp.array(dtype=dtype),
        c_mass: dtype,
        c_stiff: dtype,
        constrained: wp.array(dtype=wp.int32),
        precond: wp.array(dtype=mat33),
    ):
        i = wp.tid()
        d = (c_mass * mass[i]) * wp.identity(3, dtype)
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            s = vertex_slots[q]
            e = s // 4
            g = shape_gradient(dm_inv[e], s - 4 * e)
            k = stiffness_block(g, g, volume[e], lame[e][0], lame[e][1])
            if wp.static(rotated):
                r = rotation[e]
                k = r * k * wp.transpose(r)
            d += c_stiff * k
        precond[i] = filter_block(d, constrained[i])

    @wp.kernel(module="unique")
    def operator_gather(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_products: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        c_mass: dtype,
        c_stiff: dtype,
        constrained: wp.array(dtype=wp.int32),
        p: wp.array(dtype=vec3),
        chunk: int,
        q_out: wp.array(dtype=vec3),
        partial: wp.array(dtype=dtype),
    ):
        c = wp.tid()
        n = p.shape[0]
        acc = dtype(0.0)
        for i in range(c * chunk, wp.min(n, (c + 1) * chunk)):
            k = vec3(dtype(0.0))
            for s in range(vertex_offsets[i], vertex_offsets[i + 1]):
                k += corner_products[vertex_slots[s]]
            q = free_components((c_mass * mass[i]) * p[i] + c_stiff * k, constrained[i])
            q_out[i] = q
            acc += wp.dot(p[i], q)
        partial[c] = acc

    @wp.kernel(module="unique")
    def residual_init(
        b: wp.array(dtype=vec3),
        ax: wp.array(dtype=vec3),
        constrained: wp.array(dtype=wp.int32),
        precond: wp.array(dtype=mat33),
        chunk: int,
        r: wp.array(dtype=vec3),
        z: wp.array(dtype=vec3),
        p: wp.array(dtype=vec3),
        partial3: wp.array(dtype=vec3),
    ):
        c = wp.tid()
        n = b.shape[0]
        rz = dtype(0.0)
        rr = dtype(0.0)
        bb = dtype(0.0)
        for i in range(c * chunk, wp.min(n, (c + 1) * chunk)):
            bits = constrained[i]
            bi = free_components(b[i], bits)
            ri = free_components(b[i] - ax[i], bits)
            bb += wp.dot(bi, bi)
            zi = precond[i] * ri
            r[i] = ri
            z[i] = zi
            p[i] = zi
            rz += wp.dot(ri, zi)
            rr += wp.dot(ri, ri)
        partial3[c] = vec3(rz, rr, bb)

    @wp.kernel(module="unique")
    def reduce_init(partial3: wp.array(dtype=vec3), scalars: wp.array(dtype=dtype)):
        s = vec3(dtype(0.0))
        for c in range(partial3.shape[0]):
            s += partial3[c]
        scalars[CG_RZ] = s[0]
        scalars[CG_RR] = s[1]
        scalars[CG_BB] = s[2]

    @wp.kernel(module="unique")
    def reduce_alpha(partial: wp.array(dtype=dtype), scalars: wp.array(dtype=dtype)):
        s = dtype(0.0)
        for c in range(partial.shape[0]):
            s += partial[c]
        scalars[CG_PQ] = s
        alpha = dtype(0.0)
        if s > dtype(0.0):
            alpha = scalars[CG_RZ] / s
        scalars[CG_ALPHA] = alpha

    @wp.kernel(module="unique")
    def update_xr(
        p: wp.array(dtype=vec3),
        q: wp.array(dtype=vec3),
        precond: wp.array(dtype=mat33),
        scalars: wp.array(dtype=dtype),
        chunk: int,
        x: wp.array(dtype=vec3),
        r: wp.array(dtype=vec3),
        z: wp.array(dtype=vec3),
        partial2: wp.array(dtype=vec2),
    ):
        c = wp.tid()
        n = p.shape[0]
        alpha = scalars[CG_ALPHA]
        rz = dtype(0.0)
        rr = dtype(0.0)
        for i in range(c * chunk, wp.min(n, (c + 1) * chunk)):
            x[i] = x[i] + alpha * p[i]
            ri = r[i] - alpha * q[i]
            zi = precond[i] * ri
            r[i] = ri
            z[i] = zi
            rz += wp.dot(ri, zi)
            rr += wp.dot(ri, ri)
        partial2[c] = vec2(rz, rr)

    @wp.kernel(module="unique")
    def reduce_beta(partial2: wp.array(dtype=vec2), scalars: wp.array(dtype=dtype)):
        rz = dtype(0.0)
        rr = dtype(0.0)
        for c in range(partial2.shape[0]):
            rz += partial2[c][0]
            rr += partial2[c][1]
        beta = dtype(0.0)
        if scalars[CG_RZ] > dtype(0.0):
            beta = rz / scalars[CG_RZ]
        scalars[CG_BETA] = beta
        scalars[CG_RZ] = rz
        scalars[CG_RR] = rr

    @wp.kernel(module="unique")
    def update_p(
        z: wp.array(dtype=vec3),
        scalars: wp.array(dtype=dtype),
        chunk: int,
        p: wp.array(dtype=vec3),
    ):
        c = wp.tid()
        n = p.shape[0]
        beta = scalars[CG_BETA]
        for i in range(c * chunk, wp.min(n, (c + 1) * chunk)):
            p[i] = z[i] + beta * p[i]

    return {
        "block_jacobi": block_jacobi,
        "operator_gather": operator_gather,
        "residual_init": residual_init,
        "reduce_init": reduce_init,
        "reduce_alpha": reduce_alpha,
        "update_xr": update_xr,
        "reduce_beta": reduce_beta,
        "update_p": update_p,
    }


@functools.cache
def assembled_kernels(dtype):
    """Kernels of the assembled (block-sparse, 3x3 blocks in CSR order) variant of the CG operator, as a dict:

    - assemble_blocks (blocks): values[k] = sum of the element blocks R K_ab R^T that land on block k (a gather over a
      CSR list of contributions: no atomics).
    - bsr_operator_gather (chunks): q_i = c_mass m_i p_i + c_stiff sum_k values[k] p[columns[k]] over row i, constrained
      components zeroed; partial[c] = sum p . q over the chunk.
    - bsr_block_jacobi (vertices): P_i = inverse of c_mass m_i I + c_stiff values[diagonal block of row i]
      restricted to the free components.
    """
    vec3, mat33, _ = fem_types(dtype)
    cf = constraint_funcs(dtype)
    free_components = cf["free_components"]
    filter_block = cf["filter_block"]

    @wp.kernel(module="unique")
    def assemble_blocks(
        contrib_offsets: wp.array(dtype=wp.int32),
        contrib_ids: wp.array(dtype=wp.int32),
        element_blocks: wp.array(dtype=mat33),
        values: wp.array(dtype=mat33),
    ):
        k = wp.tid()
        acc = mat33(dtype(0.0))
        for c in range(contrib_offsets[k], contrib_offsets[k + 1]):
            acc += element_blocks[contrib_ids[c]]
        values[k] = acc

    @wp.kernel(module="unique")
    def bsr_operator_gather(
        row_offsets: wp.array(dtype=wp.int32),
        columns: wp.array(dtype=wp.int32),
        values: wp.array(dtype=mat33),
        mass: wp.array(dtype=dtype),
        c_mass: dtype,
        c_stiff: dtype,
        constrained: wp.array(dtype=wp.int32),
        p: wp.array(dtype=vec3),
        chunk: int,
        q_out: wp.array(dtype=vec3),
        partial: wp.array(dtype=dtype),
    ):
        c = wp.tid()
        n = p.shape[0]
        acc = dtype(0.0)
        for i in range(c * chunk, wp.min(n, (c + 1) * chunk)):
            k = vec3(dtype(0.0))
            for s in range(row_offsets[i], row_offsets[i + 1]):
                k += values[s] * p[columns[s]]
            q = free_components((c_mass * mass[i]) * p[i] + c_stiff * k, constrained[i])
            q_out[i] = q
            acc += wp.dot(p[i], q)
        partial[c] = acc

    @wp.kernel(module="unique")
    def bsr_block_jacobi(
        diagonal: wp.array(dtype=wp.int32),
        values: wp.array(dtype=mat33),
        mass: wp.array(dtype=dtype),
        c_mass: dtype,
        c_stiff: dtype,
        constrained: wp.array(dtype=wp.int32),
        precond: wp.array(dtype=mat33),
    ):
        i = wp.tid()
        d = (c_mass * mass[i]) * wp.identity(3, dtype) + c_stiff * values[diagonal[i]]
        precond[i] = filter_block(d, constrained[i])

    return {
        "assemble_blocks": assemble_blocks,
        "bsr_operator_gather": bsr_operator_gather,
        "bsr_block_jacobi": bsr_block_jacobi,
    }
