"""Element data of the tetrahedral FEM solver (pdsim/fem/solver.py): the FEM bodies of a scene concatenated into one
mesh (elements never join two bodies), with what never changes over a simulation: the element geometry, the materials
per element, the explicit stable step, the input surfaces and the render-mesh embeddings.

Precision: element strains come from displacement differences, G = [u1-u0, u2-u0, u3-u0] Dm^-1 with Dm^-1 computed
on the host in float64 from rest differences (kernels/fem/elements.py), so a float32 solver gives the same answer
wherever the scene sits in the world.

Fracture (pdsim/fem/fracture.py) splits vertices but never elements: element ids, and with them every per-element
array here, keep their meaning after a split. The vertex arrays built here (rest positions, corners, vertex bodies,
boundary conditions) are those of the input meshes; the solver renumbers its own copies when fracture splits vertices.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from ..kernels.fem import elements as ke
from .body import FemBody, mass_scaled_heights
from .mesh import TET_EDGES, boundary_faces, element_heights

EXPLICIT_STEP_FACTOR = 0.5  # dt_stable = 0.5 h_min / c_p (see pdsim/fem/solver.py's module docstring)


class RenderEmbedding(NamedTuple):
    """A body's render mesh embedded in its tetrahedra: body index, element per point (global ids, Warp int32),
    barycentric weights (Warp vec4), faces int32 [f, 3], float64 world rest positions of the points [p, 3], and the
    output buffers of the embedded displacements and velocities (Warp vec3 [p], written by views())."""

    body: int
    elements: object
    weights: object
    faces: np.ndarray
    rest_points: np.ndarray
    out_u: object
    out_v: object


def _embed(rest: np.ndarray, tets: np.ndarray, points: np.ndarray, *, candidates: int = 16):
    """Barycentric embedding of ``points`` [p, 3] in a tet mesh: (element [p], weights [p, 4]); each point takes, among
    the ``candidates`` elements with the nearest centroids, the one it is deepest inside (largest smallest weight);
    points slightly outside the mesh (fTetWild's envelope) get slightly negative weights (linear extrapolation)."""
    cent = rest[tets].mean(axis=1)
    k = min(candidates, len(tets))
    _, idx = cKDTree(cent).query(points, k=k)
    idx = idx.reshape(len(points), k)
    x = rest[tets[idx]]  # [p, k, 4, 3]
    dm = np.stack([x[..., 1, :] - x[..., 0, :], x[..., 2, :] - x[..., 0, :], x[..., 3, :] - x[..., 0, :]], axis=-1)
    lam = np.linalg.solve(dm, (points[:, None, :] - x[..., 0, :])[..., None])[..., 0]  # [p, k, 3]
    w = np.concatenate([1.0 - lam.sum(axis=-1, keepdims=True), lam], axis=-1)
    best = np.argmax(w.min(axis=-1), axis=1)
    rows = np.arange(len(points))
    return idx[rows, best], w[rows, best]


def _mean_edge_length(vertices: np.ndarray, tets: np.ndarray) -> float:
    """Mean length of the distinct edges of a tet mesh [m]."""
    e = np.sort(np.asarray(tets, dtype=np.int64)[:, TET_EDGES].reshape(-1, 2), axis=1)
    e = np.unique(e, axis=0)
    return float(np.linalg.norm(vertices[e[:, 1]] - vertices[e[:, 0]], axis=1).mean())


class FemModel:
    """The element data of the FEM bodies of a scene, built once by the solver and never modified.

    Args:
        bodies: the FEM bodies, concatenated in this order.
        origin: the solver's local frame [m] (world = origin + local), float64 [3].
        dtype, np_dtype: the solver's Warp and numpy scalar types.
        device: the Warp device of the arrays.

    The body and material settings take their kernel names here, and only here: ``FemBody.tensile_strength`` ->
    ``strength``, ``Material.lame_lambda`` and ``Material.shear_modulus`` -> ``lame`` = (lambda, mu),
    ``FemPlasticity`` (yield_strain, creep, max_strain) -> ``plastic_params``, ``FemBody.fracture_energy`` ->
    ``fracture_energy_h``.

    ``dtype``, ``np_dtype`` and ``device`` are those given. Host arrays (float64 unless noted):
    ``element_offsets`` [bodies + 1] and ``element_body`` [m] (int64), ``volume_h`` [m^3], ``density_h``
    [kg/m^3] (with the mass scaling), ``centroids_h`` (local frame, fracture's crack planes), ``strength_h``
    (tensile strength per element [Pa], inf on bodies without fracture, None when no body fractures; the solver retires
    split elements in its own copy),
    ``fracture_energy_h`` (G_c per element [J/m^2], None when no body fractures),
    ``surface_face_ids`` (the boundary faces 4 e + k of the input meshes: every other boundary face is a crack face),
    ``widths`` (half the mean edge length of each body [m], the PointsView widths), ``element_dt_h`` (each element's
    own stable step 0.5 h / c_p [s], times the square root of its mass-scaling factor), ``explicit_dt`` (their
    smallest [s]), ``unscaled_dt`` (0.5 h_min / c_p [s], the step without mass scaling); per body, ``body_mass``
    (rho V [kg]), ``added_mass`` (the mass scaling's [kg]) and ``scaled_elements`` (how many elements it scaled);
    Warp arrays ``dm_inv``, ``volume``, ``lame`` ((lambda, mu) per element [Pa]; the three also as the dict
    ``element_arrays``, keyed by the kernels' parameter names) and ``plastic_params`` ((yield strain, creep, max strain)
    per element; None without plasticity); ``render``: a :class:`RenderEmbedding` per body with a render mesh.

    Input vertex data (the solver's initial topology): ``rest`` (world rest positions [m]), ``rest_local64`` (local
    rest positions, float64: the stable step and the lumped masses), ``rest_local`` (the local rest positions as the
    solver stores them, float32-rounded in a float32 solver, differenced in float64: the element geometry), ``tets``
    (int64 [m, 4]), ``vertex_body``, ``point_condition`` (body-local boundary condition per vertex, int32).
    """

    def __init__(self, bodies: list[FemBody], origin: np.ndarray, dtype, np_dtype, device):
        self.dtype, self.np_dtype, self.device = dtype, np_dtype, device
        vec3, mat33, vec4 = ke.fem_types(dtype)
        vec2 = wp.types.vector(2, dtype)
        v_counts = [b.vertex_count for b in bodies]
        e_counts = [b.element_count for b in bodies]
        v_off = np.concatenate([[0], np.cumsum(v_counts)]).astype(np.int64)
        self.element_offsets = np.concatenate([[0], np.cumsum(e_counts)]).astype(np.int64)
        rest = np.concatenate([b.mesh.vertices for b in bodies]).astype(np.float64)
        tets = np.concatenate([b.mesh.tets.astype(np.int64) + v_off[i] for i, b in enumerate(bodies)])
        self.element_body = np.repeat(np.arange(len(bodies)), e_counts)
        mats = [b.material for b in bodies]

        def per_element(values):
            return np.asarray(values, dtype=np.float64)[self.element_body]

        # the element geometry (Dm^-1, volumes, crack planes) is that of the local rest positions exactly as the
        # solver stores them (kin.rest: float32-rounded in a float32 solver), differenced in float64: the same digits
        # wherever the scene sits in the world, so a translated scene computes and decides (crack planes) bit for bit
        # the same; the stable step and the lumped masses use the float64 local rest positions
        self.rest_local64 = rest - origin
        local = self.rest_local64
        if np_dtype == np.float32:
            local = local.astype(np.float32).astype(np.float64)
        self.rest_local = local
        x = local[tets]
        dm = np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=-1)  # columns
        self.volume_h = np.linalg.det(dm) / 6.0
        dm_inv = np.linalg.inv(dm)
        lam = per_element([m.lame_lambda for m in mats])
        mu = per_element([m.shear_modulus for m in mats])
        cp = per_element([m.p_wave_speed for m in mats])
        heights = element_heights(self.rest_local64, tets)
        # selective mass scaling (FemBody.mass_scaling): the density of each body's smallest elements is raised so
        # that their step is that of an element of the body's floor height; the step grows as sqrt(density)
        scaled_heights = np.concatenate(
            [
                mass_scaled_heights(heights[lo:hi], b.mass_scaling)
                for b, lo, hi in zip(bodies, self.element_offsets[:-1], self.element_offsets[1:])
            ]
        )
        factors = (scaled_heights / heights) ** 2  # pdsim.fem.body.mass_scaling_factors, per body
        material_density = per_element([m.density for m in mats])
        self.density_h = material_density * factors
        self.element_dt_h = EXPLICIT_STEP_FACTOR * scaled_heights / cp
        self.explicit_dt = float(np.min(self.element_dt_h))
        self.unscaled_dt = float(np.min(EXPLICIT_STEP_FACTOR * heights / cp))
        added = (factors - 1.0) * material_density * np.abs(self.volume_h)
        self.added_mass = np.bincount(self.element_body, weights=added, minlength=len(bodies))
        self.body_mass = np.bincount(
            self.element_body, weights=material_density * np.abs(self.volume_h), minlength=len(bodies)
        )
        self.scaled_elements = np.bincount(self.element_body, weights=factors > 1.0, minlength=len(bodies))
        self.centroids_h = x.mean(axis=1)  # local frame (fracture's crack planes)
        self.plastic = any(b.plasticity is not None for b in bodies)
        self.fracture = any(b.tensile_strength is not None for b in bodies)
        dev, f = device, np_dtype
        self.element_count = len(tets)
        self.dm_inv = wp.array(dm_inv.astype(f), dtype=mat33, device=dev)
        self.volume = wp.array(self.volume_h.astype(f), dtype=dtype, device=dev)
        self.lame = wp.array(np.stack([lam, mu], axis=1).astype(f), dtype=vec2, device=dev)
        # the element material arrays under the element kernels' parameter names (kernels/fem/elements.py)
        self.element_arrays = {"dm_inv": self.dm_inv, "volume": self.volume, "lame": self.lame}
        self.plastic_params = None
        if self.plastic:
            inf = np.inf
            pp = np.array(
                [
                    (b.plasticity.yield_strain, b.plasticity.creep, b.plasticity.max_strain)
                    if b.plasticity is not None
                    else (inf, 0.0, inf)
                    for b in bodies
                ],
                dtype=np.float64,
            )[self.element_body]
            self.plastic_params = wp.array(pp.astype(f), dtype=vec3, device=dev)
        self.strength_h = self.fracture_energy_h = None
        if self.fracture:
            self.strength_h = per_element(
                [np.inf if b.tensile_strength is None else b.tensile_strength for b in bodies]
            )
            self.fracture_energy_h = per_element([b.fracture_energy for b in bodies])
        # faces of the input surfaces (4 e + k): every other boundary face is a crack face
        self.surface_face_ids = boundary_faces(tets, return_face_ids=True)[1]
        self.widths = [0.5 * _mean_edge_length(b.mesh.vertices, b.mesh.tets) for b in bodies]

        # render meshes: barycentric embedding in the body's own elements (global element ids)
        self.render: list[RenderEmbedding] = []
        for i, b in enumerate(bodies):
            if b.render_mesh is None:
                continue
            lo, hi = self.element_offsets[i], self.element_offsets[i + 1]
            elem, w = _embed(rest, tets[lo:hi], np.asarray(b.render_mesh.vertices, dtype=np.float64))
            elem = elem + lo
            rest_points = np.einsum("pa,paj->pj", w, rest[tets[elem]])  # float64 world rest of the embedded points
            self.render.append(
                RenderEmbedding(
                    i,
                    wp.array(elem.astype(np.int32), dtype=wp.int32, device=dev),
                    wp.array(w.astype(f), dtype=vec4, device=dev),
                    np.asarray(b.render_mesh.faces, dtype=np.int32),
                    rest_points,
                    wp.zeros(len(w), dtype=vec3, device=dev),
                    wp.zeros(len(w), dtype=vec3, device=dev),
                )
            )

        # input vertex data (the solver renumbers its copies when fracture splits vertices)
        self.rest = rest
        self.tets = tets
        self.vertex_body = np.repeat(np.arange(len(bodies)), v_counts)
        self.point_condition = np.concatenate([b.point_condition for b in bodies]).astype(np.int32)  # body-local


__all__ = ["EXPLICIT_STEP_FACTOR", "FemModel", "RenderEmbedding"]
