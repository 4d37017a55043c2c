"""Kernels of the preconditioned conjugate-gradient solver of the tetrahedral FEM (pdsim/fem/cg.py): the implicit
backward-Euler step and the quasi-static Newton iterations solve (c_mass M + c_stiff K_R) x = b with it.

The solver is block-Jacobi preconditioned CG, the stiffness applied either matrix-free (the element kernels with the
frozen rotations, every iteration: kernels/fem/elements.py's ``element_stiffness_product_kernel``) or as an assembled
matrix of 3x3 blocks in CSR order, filled once per solve by a gather of the element blocks (faster on the CPU:
docs/benchmarks.md).

Constraints are per component (the bit masks of kernels/fem/solver.py): the CG works on the free components only,
constrained components of the unknown keep their initial (prescribed) value, their residual, search direction and
preconditioner rows are zero.

Reductions (dot products) are chunked: thread c sums a contiguous range of vertices into ``partial[c]`` and a single
thread adds the partial sums, so the result does not depend on thread scheduling.
"""

import functools

import warp as wp

from ..launch import launch
from .elements import fem_funcs, fem_types
from .solver import constraint_funcs

# cg_scalars slots
CG_RZ = 0  # r . z
CG_PQ = 1  # p . A p
CG_ALPHA = 2
CG_BETA = 3
CG_RR = 4  # r . r
CG_BB = 5  # b . b (filtered right-hand side)
CG_SCALAR_COUNT = 8


@functools.cache
def cg_funcs(dtype):
    """Warp functions shared by the CG kernels (a dict): operator_value."""
    vec3, _, _ = fem_types(dtype)
    free_components = constraint_funcs(dtype)["free_components"]

    @wp.func
    def operator_value(m: dtype, p: vec3, k: vec3, c_mass: dtype, c_stiff: dtype, bits: int):
        """(A p)_i = c_mass m_i p_i + c_stiff (K p)_i with its constrained components zeroed (m [kg], k = (K p)_i)."""
        return free_components((c_mass * m) * p + c_stiff * k, bits)

    return {"operator_value": operator_value}


@functools.cache
def block_jacobi_kernel(dtype, rotated: bool):
    """Kernel over vertices (matrix-free variant): P_i = inverse of the 3x3 diagonal block
    c_mass m_i I + c_stiff sum R K_aa R^T (R frozen; identity when not ``rotated``) restricted to the free components
    (zero rows and columns on constrained ones)."""
    _, mat33, _ = fem_types(dtype)
    fn = fem_funcs(dtype)
    shape_gradient = fn["shape_gradient"]
    stiffness_block = fn["stiffness_block"]
    filter_block = constraint_funcs(dtype)["filter_block"]

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

    return block_jacobi


@functools.cache
def cg_kernels(dtype):
    """Kernels of the preconditioned CG for A = c_mass M + c_stiff K_R (K_R = sum_e R K_e R^T, R frozen) on the free
    components (``constrained`` bit masks), as a dict (the matrix-free preconditioner is block_jacobi_kernel):

    - operator_gather (chunks): q_i = c_mass m_i p_i + c_stiff sum of corner products, constrained components zeroed;
      partial[c] = sum p . q over the chunk.
    - residual_init (chunks): r = b - A x (filtered), z = P r, p = z; partials of r . z, r . r and b . b.
    - update_xr (chunks): x += alpha p, r -= alpha q, z = P r; partials of r . z and r . r.
    - update_p (chunks): p = z + beta p.
    - reduce_alpha / reduce_init / reduce_beta (one thread): sum the partials and set the scalars.
    """
    vec3, mat33, _ = fem_types(dtype)
    vec2 = wp.types.vector(2, dtype)
    free_components = constraint_funcs(dtype)["free_components"]
    operator_value = cg_funcs(dtype)["operator_value"]

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
            q = operator_value(mass[i], p[i], k, c_mass, c_stiff, constrained[i])
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
    filter_block = constraint_funcs(dtype)["filter_block"]
    operator_value = cg_funcs(dtype)["operator_value"]

    # the CSR gather of kernels/fem/solver.py's gather_corners, on 3x3 blocks (a wp.func there is typed for vectors)
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

    # Warp kernels cannot take a function argument, so bsr_operator_gather repeats the chunk loop of cg_kernels'
    # operator_gather with the block-row product in place of the corner gather.
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
            q = operator_value(mass[i], p[i], k, c_mass, c_stiff, constrained[i])
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


# -- launches ----------------------------------------------------------------------------------------------------------
# One function per kernel, its arguments given by the kernel's parameter names (kernels/launch.py); ``dtype`` is the
# solver's scalar type (wp.float32 or wp.float64). The chunked kernels run one thread per chunk of ``chunk`` vertices
# (``chunks`` threads: the length of their partial-sum array), the reductions one thread.


def block_jacobi(*, dtype, rotated: bool, device, **arguments):
    """The matrix-free block-Jacobi preconditioner P_i of every vertex into ``precond`` (block_jacobi_kernel)."""
    launch(block_jacobi_kernel(dtype, rotated), arguments["precond"].shape[0], device=device, **arguments)


def operator_gather(*, dtype, device, **arguments):
    """q = A p [N] from the matrix-free corner products (constrained components zeroed) and the chunks' p . q
    (cg_kernels' operator_gather)."""
    launch(cg_kernels(dtype)["operator_gather"], arguments["partial"].shape[0], device=device, **arguments)


def residual_init(*, dtype, device, **arguments):
    """r = b - A x, z = P r, p = z (free components) and the chunks' r . z, r . r and b . b (cg_kernels'
    residual_init)."""
    launch(cg_kernels(dtype)["residual_init"], arguments["partial3"].shape[0], device=device, **arguments)


def reduce_init(*, dtype, device, **arguments):
    """Sums the chunks' r . z, r . r and b . b into ``scalars`` (CG_RZ, CG_RR, CG_BB; cg_kernels' reduce_init)."""
    launch(cg_kernels(dtype)["reduce_init"], 1, device=device, **arguments)


def reduce_alpha(*, dtype, device, **arguments):
    """Sums the chunks' p . q into ``scalars[CG_PQ]`` and sets alpha = r . z / p . q (cg_kernels' reduce_alpha)."""
    launch(cg_kernels(dtype)["reduce_alpha"], 1, device=device, **arguments)


def update_xr(*, dtype, device, **arguments):
    """x += alpha p, r -= alpha q, z = P r and the chunks' r . z and r . r (cg_kernels' update_xr)."""
    launch(cg_kernels(dtype)["update_xr"], arguments["partial2"].shape[0], device=device, **arguments)


def reduce_beta(*, dtype, device, **arguments):
    """Sums the chunks' r . z and r . r and sets beta = new r . z / old r . z (cg_kernels' reduce_beta)."""
    launch(cg_kernels(dtype)["reduce_beta"], 1, device=device, **arguments)


def update_p(*, chunks: int, dtype, device, **arguments):
    """p = z + beta p over ``chunks`` chunks of ``chunk`` vertices (cg_kernels' update_p)."""
    launch(cg_kernels(dtype)["update_p"], chunks, device=device, **arguments)


def assemble_blocks(*, dtype, device, **arguments):
    """The assembled stiffness blocks [N/m] into ``values`` (a gather of the element blocks; assembled_kernels'
    assemble_blocks)."""
    launch(assembled_kernels(dtype)["assemble_blocks"], arguments["values"].shape[0], device=device, **arguments)


def bsr_operator_gather(*, dtype, device, **arguments):
    """q = A p [N] with the assembled stiffness (constrained components zeroed) and the chunks' p . q
    (assembled_kernels' bsr_operator_gather)."""
    launch(assembled_kernels(dtype)["bsr_operator_gather"], arguments["partial"].shape[0], device=device, **arguments)


def bsr_block_jacobi(*, dtype, device, **arguments):
    """The block-Jacobi preconditioner P_i of every vertex from the assembled diagonal blocks into ``precond``
    (assembled_kernels' bsr_block_jacobi)."""
    launch(assembled_kernels(dtype)["bsr_block_jacobi"], arguments["precond"].shape[0], device=device, **arguments)
