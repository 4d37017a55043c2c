"""Vertex kernels of the tetrahedral FEM solver: force gathers, explicit and implicit integration, boundary conditions,
the ground-plane collider, and a preconditioned conjugate-gradient solver built from Warp kernels.

Element kernels (kernels/fem/elements.py) write one vector per element corner ("slot" 4 e + a); the vertex kernels
gather them over a CSR incidence list (``vertex_offsets``, ``vertex_slots``): one thread per vertex, no atomics, so the
CPU and the GPU sum in the same order.

Explicit step (velocity Verlet, as kernels/integration.py; a_n from the previous force evaluation):
    kick_drift:   v <- v + dt/2 a_n ; x <- x + dt v       (boundary conditions, then the ground plane)
    (element forces at the new positions)
    gather_kick:  a = f / m + g - c v ; v <- v + dt/2 a    (free vertices)

Implicit step (linearly implicit backward Euler with the corotated stiffness, rotations frozen at x_n):
    ((1 + dt c) M + (dt^2 + dt beta) K_R) v_{n+1} = M v_n + dt (f(x_n) + M g),   x_{n+1} = x_n + dt v_{n+1}
solved by block-Jacobi preconditioned CG, the stiffness applied either matrix-free (the element kernels with the
frozen rotations, every iteration) or as an assembled matrix of 3x3 blocks in CSR order, filled once per solve by a
gather of the element blocks (faster on the CPU: docs/benchmarks.md). Constrained vertices (fixed or prescribed
velocity) are filtered: their unknowns keep the prescribed value and their residual is zero.

Vertex kinds: 0 free, 1 fixed (held at its rest position), 2 prescribed velocity (as kernels/integration.py).
The ground plane follows kernels/integration.py's collider (projection onto the plane, approaching normal velocity
removed, Coulomb friction on the tangential velocity) with zero radius: vertices lie on the body's surface.

Reductions (dot products) are chunked: thread c sums a contiguous range of vertices into ``partial[c]`` and a single
thread adds the partial sums, so the result does not depend on thread scheduling.
"""

import functools

import warp as wp

from .elements import fem_funcs, fem_types

VERTEX_FREE = wp.constant(0)
VERTEX_FIXED = wp.constant(1)
VERTEX_PRESCRIBED = wp.constant(2)

# cg_scalars slots
CG_RZ = 0  # r . z
CG_PQ = 1  # p . A p
CG_ALPHA = 2
CG_BETA = 3
CG_RR = 4  # r . r
CG_BB = 5  # b . b (filtered right-hand side)
CG_SCALAR_COUNT = 8


@functools.cache
def explicit_kernels(dtype):
    """(kick_drift, gather_kick) kernels of the explicit velocity-Verlet step for scalar ``dtype``."""
    vec3, _, _ = fem_types(dtype)

    @wp.kernel(module="unique")
    def kick_drift(
        positions: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
        rest_positions: wp.array(dtype=vec3),
        kind: wp.array(dtype=wp.int32),
        prescribed_velocity: wp.array(dtype=vec3),
        dt: dtype,
    ):
        """First half kick and drift; fixed vertices stay at rest, prescribed ones move at their velocity."""
        i = wp.tid()
        c = kind[i]
        if c == VERTEX_FIXED:
            positions[i] = rest_positions[i]
            velocities[i] = vec3(dtype(0.0))
        elif c == VERTEX_PRESCRIBED:
            v = prescribed_velocity[i]
            velocities[i] = v
            positions[i] = positions[i] + dt * v
        else:
            v = velocities[i] + (dtype(0.5) * dt) * accelerations[i]
            velocities[i] = v
            positions[i] = positions[i] + dt * v

    @wp.kernel(module="unique")
    def gather_kick(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        inv_mass: wp.array(dtype=dtype),
        kind: wp.array(dtype=wp.int32),
        gravity: vec3,
        damping: wp.array(dtype=dtype),
        dt: dtype,
        velocities: wp.array(dtype=vec3),
        accelerations: wp.array(dtype=vec3),
        forces: wp.array(dtype=vec3),
    ):
        """f_i = sum of corner forces [N]; a = f / m + g - c v [m/s^2]; second half kick for free vertices."""
        i = wp.tid()
        f = vec3(dtype(0.0))
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
        forces[i] = f
        v = velocities[i]
        a = f * inv_mass[i] + gravity - damping[i] * v
        accelerations[i] = a
        if kind[i] == VERTEX_FREE:
            velocities[i] = v + (dtype(0.5) * dt) * a

    return kick_drift, gather_kick


@functools.cache
def vertex_kernels(dtype):
    """Kernels shared by the integrators: gather_forces, advance_positions, collide_ground_plane, max_speed_and_finite,
    residual_forces, apply_displacement (a dict)."""
    vec3, _, _ = fem_types(dtype)

    @wp.kernel(module="unique")
    def gather_forces(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        forces: wp.array(dtype=vec3),
    ):
        """f_i = sum of the corner vectors of vertex i."""
        i = wp.tid()
        f = vec3(dtype(0.0))
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
        forces[i] = f

    @wp.kernel(module="unique")
    def advance_positions(
        positions: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        rest_positions: wp.array(dtype=vec3),
        kind: wp.array(dtype=wp.int32),
        dt: dtype,
    ):
        """x <- x + dt v (backward Euler position update); fixed vertices at rest with zero velocity."""
        i = wp.tid()
        if kind[i] == VERTEX_FIXED:
            positions[i] = rest_positions[i]
            velocities[i] = vec3(dtype(0.0))
        else:
            positions[i] = positions[i] + dt * velocities[i]

    @wp.kernel(module="unique")
    def collide_ground_plane(
        positions: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        kind: wp.array(dtype=wp.int32),
        normal: vec3,
        offset: dtype,
        friction: dtype,
    ):
        """Keeps free vertices above the plane n . x = offset (kernels/integration.py's rule with zero radius)."""
        i = wp.tid()
        if kind[i] != VERTEX_FREE:
            return
        x = positions[i]
        depth = offset - wp.dot(normal, x)
        if depth > dtype(0.0):
            positions[i] = x + depth * normal
            v = velocities[i]
            vn = wp.dot(v, normal)
            if vn < dtype(0.0):
                vt = v - vn * normal
                vt_len = wp.length(vt)
                scale = dtype(0.0)
                if vt_len > dtype(0.0):
                    scale = wp.max(dtype(0.0), dtype(1.0) - friction * (-vn) / vt_len)
                velocities[i] = vt * scale

    @wp.kernel(module="unique")
    def max_speed_and_finite(
        positions: wp.array(dtype=vec3),
        velocities: wp.array(dtype=vec3),
        result: wp.array(dtype=float),
    ):
        """result[0] = max |v| [m/s]; result[1] = 1 when any position or velocity is not finite."""
        i = wp.tid()
        s = float(wp.length(velocities[i]))
        xl = float(wp.length(positions[i]))
        if wp.isnan(s) or wp.isinf(s) or wp.isnan(xl) or wp.isinf(xl):
            result[1] = 1.0
        else:
            wp.atomic_max(result, 0, s)

    @wp.kernel(module="unique")
    def residual_forces(
        forces: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        gravity: vec3,
        constrained: wp.array(dtype=wp.int32),
        residual: wp.array(dtype=vec3),
    ):
        """r_i = f_i + m_i g [N] for unconstrained vertices, 0 for constrained ones (static equilibrium residual)."""
        i = wp.tid()
        if constrained[i] != 0:
            residual[i] = vec3(dtype(0.0))
        else:
            residual[i] = forces[i] + mass[i] * gravity

    @wp.kernel(module="unique")
    def apply_displacement(positions: wp.array(dtype=vec3), du: wp.array(dtype=vec3)):
        i = wp.tid()
        positions[i] = positions[i] + du[i]

    return {
        "gather_forces": gather_forces,
        "advance_positions": advance_positions,
        "collide_ground_plane": collide_ground_plane,
        "max_speed_and_finite": max_speed_and_finite,
        "residual_forces": residual_forces,
        "apply_displacement": apply_displacement,
    }


@functools.cache
def implicit_rhs_kernel(dtype):
    """Kernel over vertices: the backward-Euler right-hand side b = m v + dt (f + m g) [N s] and the initial guess of
    the new velocity (the old one; the prescribed one for constrained vertices)."""
    vec3, _, _ = fem_types(dtype)

    @wp.kernel(module="unique")
    def implicit_rhs(
        vertex_offsets: wp.array(dtype=wp.int32),
        vertex_slots: wp.array(dtype=wp.int32),
        corner_forces: wp.array(dtype=vec3),
        mass: wp.array(dtype=dtype),
        velocities: wp.array(dtype=vec3),
        kind: wp.array(dtype=wp.int32),
        prescribed_velocity: wp.array(dtype=vec3),
        gravity: vec3,
        dt: dtype,
        forces: wp.array(dtype=vec3),
        rhs: wp.array(dtype=vec3),
        guess: wp.array(dtype=vec3),
        constrained: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        f = vec3(dtype(0.0))
        for q in range(vertex_offsets[i], vertex_offsets[i + 1]):
            f += corner_forces[vertex_slots[q]]
        forces[i] = f
        m = mass[i]
        c = kind[i]
        rhs[i] = m * velocities[i] + dt * (f + m * gravity)
        if c == VERTEX_FIXED:
            guess[i] = vec3(dtype(0.0))
            constrained[i] = 1
        elif c == VERTEX_PRESCRIBED:
            guess[i] = prescribed_velocity[i]
            constrained[i] = 1
        else:
            guess[i] = velocities[i]
            constrained[i] = 0

    return implicit_rhs


@functools.cache
def cg_kernels(dtype, rotated: bool):
    """Kernels of the preconditioned CG for A = c_mass M + c_stiff K_R (K_R = sum_e R K_e R^T, R frozen; identity when
    not ``rotated``), as a dict:

    - block_jacobi (vertices): P_i = inverse of the 3x3 diagonal block c_mass m_i I + c_stiff sum R K_aa R^T
      (zero for constrained vertices).
    - operator_gather (chunks): q_i = c_mass m_i p_i + c_stiff sum of corner products, 0 when constrained;
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
        if constrained[i] != 0:
            precond[i] = mat33(dtype(0.0))
            return
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
        if wp.determinant(d) > dtype(0.0):
            precond[i] = wp.inverse(d)
        else:
            precond[i] = wp.identity(3, dtype)

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
            if constrained[i] != 0:
                q_out[i] = vec3(dtype(0.0))
            else:
                k = vec3(dtype(0.0))
                for s in range(vertex_offsets[i], vertex_offsets[i + 1]):
                    k += corner_products[vertex_slots[s]]
                q = (c_mass * mass[i]) * p[i] + c_stiff * k
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
            ri = vec3(dtype(0.0))
            if constrained[i] == 0:
                ri = b[i] - ax[i]
                bb += wp.dot(b[i], b[i])
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
    - bsr_operator_gather (chunks): q_i = c_mass m_i p_i + c_stiff sum_k values[k] p[columns[k]] over row i, 0 for
      constrained rows; partial[c] = sum p . q over the chunk.
    - bsr_block_jacobi (vertices): P_i = inverse of c_mass m_i I + c_stiff values[diagonal block of row i].
    """
    vec3, mat33, _ = fem_types(dtype)

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
            if constrained[i] != 0:
                q_out[i] = vec3(dtype(0.0))
            else:
                k = vec3(dtype(0.0))
                for s in range(row_offsets[i], row_offsets[i + 1]):
                    k += values[s] * p[columns[s]]
                q = (c_mass * mass[i]) * p[i] + c_stiff * k
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
        if constrained[i] != 0:
            precond[i] = mat33(dtype(0.0))
            return
        d = (c_mass * mass[i]) * wp.identity(3, dtype) + c_stiff * values[diagonal[i]]
        if wp.determinant(d) > dtype(0.0):
            precond[i] = wp.inverse(d)
        else:
            precond[i] = wp.identity(3, dtype)

    return {
        "assemble_blocks": assemble_blocks,
        "bsr_operator_gather": bsr_operator_gather,
        "bsr_block_jacobi": bsr_block_jacobi,
    }
