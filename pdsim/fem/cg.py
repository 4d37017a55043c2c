"""Preconditioned conjugate gradient of the tetrahedral FEM solver (pdsim/fem/solver.py), built from the Warp kernels
of kernels/fem/cg.py: the implicit backward-Euler step (pdsim/fem/implicit.py) and the quasi-static Newton iterations
(pdsim/fem/static.py) solve (c_mass diag(m) + c_stiff K_R) x = b with it, K_R = sum_e R K_e R^T the stiffness with the
element rotations frozen (the identity for the linear measure).

The stiffness is applied either matrix-free (the element kernels with the frozen rotations, every iteration) or as an
assembled matrix of 3x3 blocks in CSR order, filled once per solve from the element stiffness blocks (the pattern is
computed once per topology); the preconditioner is the inverse of each vertex's 3x3 diagonal block. Constraints are per
component (a bit mask per vertex in :attr:`FemCg.constrained`): the CG works on the free components, constrained
components of the unknown keep their initial value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from ..kernels.fem import cg as kc
from ..kernels.fem import elements as ke
from ..kernels.launch import by_name
from .model import FemModel

CG_CHUNK = 256  # vertices per partial sum of the CG reductions


@dataclass
class CgReport:
    """Outcome of one CG solve: iterations, final relative residual |r| / |b|, and whether it reached the tolerance."""

    iterations: int
    relative_residual: float
    converged: bool


class FemCg:
    """The CG of one topology of the solver's mesh: its work arrays, the assembled-stiffness pattern (built on the first
    assembled solve) and the iteration. The solver builds a new one whenever fracture changes the topology.

    Args:
        model: the element data (Dm^-1, volumes, Lame parameters, Warp types, device).
        rotation: the element rotations (Warp mat33 [m]), updated in place by the solver's force evaluations.
        rotated: whether K_R uses the rotations (the corotated measure) or the identity.
        tets_h: element corners int64 [m, 4] (the assembled pattern); tets: the same as a Warp vec4i array.
        vertex_offsets, vertex_slots: the CSR list of the element corners of each vertex (Warp int32).
        vertex_count: the number of vertices.

    Arrays (Warp, one entry per vertex): ``rhs`` (the right-hand side b, filled by the caller), ``x`` (the initial
    guess, kept on the constrained components, and the result), ``constrained`` (bit mask of the constrained axes,
    filled by the caller).
    """

    def __init__(
        self,
        model: FemModel,
        rotation,
        rotated: bool,
        tets_h: np.ndarray,
        tets,
        vertex_offsets,
        vertex_slots,
        vertex_count: int,
    ):
        self.model = model
        self.device = dev = model.device
        self.dtype = dtype = model.dtype
        vec3, mat33, _ = ke.fem_types(dtype)
        self.mat33 = mat33
        self.rotation = rotation
        self.rotated = rotated
        self.tets_h = tets_h
        self.tets = tets
        self.incidence = {"vertex_offsets": vertex_offsets, "vertex_slots": vertex_slots}  # keyed by kernel names
        n = self.vertex_count = vertex_count
        self.chunk = CG_CHUNK
        chunks = self.chunks = max(1, math.ceil(n / CG_CHUNK))
        self.rhs = wp.zeros(n, dtype=vec3, device=dev)
        self.x = wp.zeros(n, dtype=vec3, device=dev)
        self.r = wp.zeros(n, dtype=vec3, device=dev)
        self.z = wp.zeros(n, dtype=vec3, device=dev)
        self.p = wp.zeros(n, dtype=vec3, device=dev)
        self.q = wp.zeros(n, dtype=vec3, device=dev)
        self.precond = wp.zeros(n, dtype=mat33, device=dev)
        self.constrained = wp.zeros(n, dtype=wp.int32, device=dev)  # bit mask of the constrained axes
        self.partial = wp.zeros(chunks, dtype=dtype, device=dev)
        self.partial2 = wp.zeros(chunks, dtype=wp.types.vector(2, dtype), device=dev)
        self.partial3 = wp.zeros(chunks, dtype=vec3, device=dev)
        self.scalars = wp.zeros(8, dtype=dtype, device=dev)  # kernels/fem/cg.py's CG_* slots
        self.corner_product = wp.zeros(4 * model.element_count, dtype=vec3, device=dev)  # matrix-free K_R p
        self._bsr = None  # assembled stiffness pattern, built lazily

    def apply_stiffness(self, u, out_corner):
        """Corner products (K_R u) per element corner into ``out_corner`` (the matrix-free operator)."""
        m = self.model
        ke.element_stiffness_product(
            u=u,
            tets=self.tets,
            **m.element_arrays,
            rotation=self.rotation,
            corner_out=out_corner,
            dtype=self.dtype,
            rotated=self.rotated,
            device=self.device,
        )

    def solve(
        self, op_mass, c_mass: float, c_stiff: float, *, tolerance: float, max_iterations: int, assembled: bool
    ) -> CgReport:
        """Solves (c_mass diag(op_mass) + c_stiff K_R) x = rhs on the free components (``constrained`` bit masks) by
        block-Jacobi preconditioned CG to the relative residual ``tolerance`` or ``max_iterations``, the stiffness
        ``assembled`` or matrix-free; ``x`` holds the initial guess (kept on the constrained components) and the
        result."""
        mdl = self.model
        dtype = self.dtype
        d, ch, chunks = self.device, self.chunk, self.chunks
        tol = tolerance
        max_it = int(max_iterations)
        c_mass, c_stiff = dtype(c_mass), dtype(c_stiff)
        # the arguments every operator and preconditioner launch shares (named like the kernels' parameters)
        operator = {
            "mass": op_mass,
            "c_mass": c_mass,
            "c_stiff": c_stiff,
            "constrained": self.constrained,
            "dtype": dtype,
            "device": d,
        }
        if assembled:
            bsr = self.assemble_stiffness()
            kc.bsr_block_jacobi(diagonal=bsr["diagonal"], values=bsr["values"], precond=self.precond, **operator)

            def apply_operator(p):
                """q = A p into ``q`` and the chunks' p . q into ``partial``."""
                kc.bsr_operator_gather(
                    row_offsets=bsr["row_offsets"],
                    columns=bsr["columns"],
                    values=bsr["values"],
                    p=p,
                    chunk=ch,
                    q_out=self.q,
                    partial=self.partial,
                    **operator,
                )

        else:
            kc.block_jacobi(
                **mdl.element_arrays,
                rotation=self.rotation,
                precond=self.precond,
                rotated=self.rotated,
                **self.incidence,
                **operator,
            )

            def apply_operator(p):
                """q = A p into ``q`` (the corner products first) and the chunks' p . q into ``partial``."""
                self.apply_stiffness(p, self.corner_product)
                kc.operator_gather(
                    corner_products=self.corner_product,
                    p=p,
                    chunk=ch,
                    q_out=self.q,
                    partial=self.partial,
                    **self.incidence,
                    **operator,
                )

        # q = A x0 (constrained components zeroed), r = b - q, z = P r, p = z
        apply_operator(self.x)
        kc.residual_init(
            b=self.rhs,
            ax=self.q,
            chunk=ch,
            dtype=dtype,
            device=d,
            **by_name(self, "constrained", "precond", "r", "z", "p", "partial3"),
        )
        kc.reduce_init(partial3=self.partial3, scalars=self.scalars, dtype=dtype, device=d)
        s = self.scalars.numpy()
        bb = float(s[kc.CG_BB])
        if bb == 0.0:
            return CgReport(0, 0.0, True)
        target = tol * tol * bb
        it = 0
        rr = float(s[kc.CG_RR])
        while rr > target and it < max_it:
            apply_operator(self.p)
            kc.reduce_alpha(partial=self.partial, scalars=self.scalars, dtype=dtype, device=d)
            kc.update_xr(
                chunk=ch,
                dtype=dtype,
                device=d,
                **by_name(self, "p", "q", "precond", "scalars", "x", "r", "z", "partial2"),
            )
            kc.reduce_beta(partial2=self.partial2, scalars=self.scalars, dtype=dtype, device=d)
            kc.update_p(z=self.z, scalars=self.scalars, chunk=ch, p=self.p, chunks=chunks, dtype=dtype, device=d)
            it += 1
            rr = float(self.scalars.numpy()[kc.CG_RR])
        rel = math.sqrt(max(rr, 0.0) / bb)
        return CgReport(it, rel, rr <= target)

    def assemble_stiffness(self) -> dict:
        """The assembled K_R as 3x3 blocks in CSR order (pattern cached per topology; values filled per call from the
        element blocks by a gather over the precomputed contribution lists)."""
        d, mdl = self.device, self.model
        if self._bsr is None:
            n, m = self.vertex_count, mdl.element_count
            tets = self.tets_h
            rows = np.repeat(tets, 4, axis=1).ravel()  # (e, a, b) in 16 e + 4 a + b order
            cols = np.tile(tets, (1, 4)).ravel()
            key = rows * n + cols
            uniq, block_of = np.unique(key, return_inverse=True)
            block_of = block_of.ravel()
            row_of_block = uniq // n
            row_offsets = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(np.bincount(row_of_block, minlength=n), out=row_offsets[1:])
            order = np.argsort(block_of, kind="stable")
            contrib_offsets = np.zeros(len(uniq) + 1, dtype=np.int64)
            np.cumsum(np.bincount(block_of, minlength=len(uniq)), out=contrib_offsets[1:])
            diagonal = np.searchsorted(uniq, np.arange(n) * n + np.arange(n))

            def i32(a):
                return wp.array(np.asarray(a, dtype=np.int32), dtype=wp.int32, device=d)

            self._bsr = {
                "row_offsets": i32(row_offsets),
                "columns": i32(uniq % n),
                "diagonal": i32(diagonal),
                "contrib_offsets": i32(contrib_offsets),
                "contrib_ids": i32(order),
                "values": wp.zeros(len(uniq), dtype=self.mat33, device=d),
                "element_blocks": wp.zeros(16 * m, dtype=self.mat33, device=d),
            }
        bsr = self._bsr
        ke.element_stiffness_blocks(
            **mdl.element_arrays,
            rotation=self.rotation,
            blocks=bsr["element_blocks"],
            dtype=self.dtype,
            rotated=self.rotated,
            device=d,
        )
        kc.assemble_blocks(
            contrib_offsets=bsr["contrib_offsets"],
            contrib_ids=bsr["contrib_ids"],
            element_blocks=bsr["element_blocks"],
            values=bsr["values"],
            dtype=self.dtype,
            device=d,
        )
        return bsr


__all__ = ["CG_CHUNK", "CgReport", "FemCg"]
