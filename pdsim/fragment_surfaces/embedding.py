"""How the fragment surfaces move with the particles (step 8 of the method in :mod:`pdsim.fragment_surfaces`).

Each shell vertex follows the particles of its own region only: ``x_v = T_F(X_v) + sum_k phi_vk r_k``. Here ``T_F``
is the region's best-fit rigid motion (:func:`rigid_fit`: Kabsch, from its particles' rest and current positions;
the minimal rotation for collinear regions, a translation for single particles), and ``r_k`` is the k-th neighbour
particle's deviation from ``T_F``. The ``phi_vk`` are moving-least-squares shape functions
(:class:`ShellEmbedding`: linear basis, weights ``exp(-(d / 1.25 h)^2)`` over the 20 nearest particles of the same
region): a partition of unity, exact for affine fields up to a 1e-3 ridge. They are computed at each topology change
as a sparse matrix [vertex_count, particle_count], so a frame is a rigid fit per shell and one sparse product.
Rigidly moving regions move their shells exactly rigidly, an affine deformation is reproduced to about 1e-3 h, and
vertices next to clamped particles stay put.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

__all__ = ["ShellEmbedding", "rigid_fit"]

NEIGHBOR_COUNT = 20  # particles per vertex in the moving-least-squares interpolation
MLS_WIDTH = 1.25  # Gaussian width of the MLS weights [spacings]
_MLS_RIDGE = 1.0e-3  # ridge on the linear MLS terms (in units of h^2 times the weight sum): keeps A invertible


class ShellEmbedding:
    """Rest points embedded in the particles of their own shell by MLS shape functions.

    Args:
        rest_positions: particle rest positions [m], float64 [particle_count, 3].
        particle_shell: shell of each particle, int [particle_count] (-1: in no shell).
        shape_vertices: the input surface's vertices [m] [v, 3] (with the particles, they size the lift below).
        spacing: particle spacing h [m].

    A fourth coordinate, the shell index times a lift far beyond the body's size, keeps every k-d tree query inside
    the queried point's own shell.
    """

    def __init__(self, rest_positions: np.ndarray, particle_shell: np.ndarray, shape_vertices, spacing: float):
        self.rest_positions = rest_positions
        self.particle_shell = particle_shell
        self.spacing = spacing
        self.particles = np.flatnonzero(particle_shell >= 0)
        span = float(np.ptp(np.concatenate([rest_positions, shape_vertices]), axis=0).max())
        self.lift = 10.0 * (span + spacing)
        pts = np.concatenate(
            [rest_positions[self.particles], (particle_shell[self.particles] * self.lift)[:, None]], axis=1
        )
        self.tree = cKDTree(pts)

    def shape_functions(self, rest_points: np.ndarray, shell: np.ndarray):
        """MLS shape functions of rest points [m] [q, 3] of shells ``shell`` [q] over the NEIGHBOR_COUNT nearest
        particles of their own shell: sparse [q, particle_count]."""
        h = self.spacing
        tree, particles = self.tree, self.particles
        part_shell = self.particle_shell
        vtx = np.concatenate([rest_points, (shell * self.lift)[:, None]], axis=1)
        k = min(NEIGHBOR_COUNT, particles.shape[0])
        dist, idx = tree.query(vtx, k=k, workers=-1)
        dist, idx = dist.reshape(len(vtx), k), idx.reshape(len(vtx), k)
        idx = particles[idx]
        valid = part_shell[idx] == shell[:, None]
        # Gaussian weights exp(-(d / (MLS_WIDTH h))^2), scaled by exp((d_min / (MLS_WIDTH h))^2) against underflow
        # (MLS shape functions do not change when all weights are scaled alike).
        d_min = np.min(np.where(valid, dist, np.inf), axis=1)
        w = np.where(valid, np.exp(-(dist**2 - d_min[:, None] ** 2) / (MLS_WIDTH * h) ** 2), 0.0)
        p = np.concatenate(
            [np.ones((len(vtx), k, 1)), (self.rest_positions[idx] - rest_points[:, None, :]) / h], axis=2
        )
        moment = np.einsum("vk,vki,vkj->vij", w, p, p)
        moment[:, 1:, 1:] += (_MLS_RIDGE * w.sum(axis=1))[:, None, None] * np.eye(3)
        rhs = np.zeros((len(vtx), 4, 1))
        rhs[:, 0, 0] = 1.0
        y = np.linalg.solve(moment, rhs)[..., 0]
        phi = w * np.einsum("vki,vi->vk", p, y)
        rows = np.repeat(np.arange(len(vtx)), k)
        out = csr_matrix((phi.ravel(), (rows, idx.ravel())), shape=(len(vtx), self.rest_positions.shape[0]))
        out.sum_duplicates()
        return out


def rigid_fit(rest: np.ndarray, current: np.ndarray, group: np.ndarray, group_count: int):
    """Best-fit rigid motion per group (Kabsch), vectorised over groups.

    Args:
        rest: rest positions [m], shape [n, 3]; current: current positions [m], shape [n, 3].
        group: group index per point in 0..group_count-1, int shape [n].

    Returns:
        (rest centroids [m] [g, 3], current centroids [m] [g, 3], rotations [g, 3, 3]). Groups whose points are
        collinear get the minimal rotation taking the rest axis to the current axis; single points the identity.
    """
    count = np.bincount(group, minlength=group_count).astype(np.float64)
    inv = 1.0 / np.maximum(count, 1.0)
    rest_c = np.stack([np.bincount(group, rest[:, a], group_count) for a in range(3)], axis=1) * inv[:, None]
    cur_c = np.stack([np.bincount(group, current[:, a], group_count) for a in range(3)], axis=1) * inv[:, None]
    y = current - cur_c[group]
    x = rest - rest_c[group]
    prod = (y[:, :, None] * x[:, None, :]).reshape(-1, 9)
    cov = np.stack([np.bincount(group, prod[:, j], group_count) for j in range(9)], axis=1).reshape(-1, 3, 3)
    u, s, vt = np.linalg.svd(cov)
    det = np.sign(np.linalg.det(u @ vt))
    det[det == 0] = 1.0
    rot = u @ (np.concatenate([np.ones((len(det), 2)), det[:, None]], axis=1)[:, :, None] * vt)
    # Degenerate groups. Collinear: minimal rotation from the rest axis vt[0] to the current axis u[:, 0].
    scale = np.maximum(s[:, 0], 1e-300)
    collinear = (s[:, 1] <= 1e-6 * scale) & (s[:, 0] > 0.0)
    if collinear.any():
        a = vt[collinear, 0]
        b = u[collinear, :, 0]
        axis = np.cross(a, b)
        sin = np.linalg.norm(axis, axis=1)
        cos = np.einsum("ij,ij->i", a, b)
        k = axis / np.maximum(sin, 1e-300)[:, None]
        kx = np.zeros((len(k), 3, 3))
        kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
        kx = kx - kx.transpose(0, 2, 1)
        eye = np.broadcast_to(np.eye(3), kx.shape)
        rot_c = eye + sin[:, None, None] * kx + (1.0 - cos)[:, None, None] * (kx @ kx)
        aligned = sin < 1e-12
        rot_c[aligned & (cos > 0.0)] = np.eye(3)
        flipped = aligned & (cos <= 0.0)  # turned end for end: half turn about an axis perpendicular to a
        if flipped.any():
            af = a[flipped]
            helper = np.eye(3)[np.argmin(np.abs(af), axis=1)]
            perp = np.cross(af, helper)
            perp /= np.linalg.norm(perp, axis=1)[:, None]
            rot_c[flipped] = 2.0 * perp[:, :, None] * perp[:, None, :] - np.eye(3)
        rot[collinear] = rot_c
    rot[s[:, 0] <= 0.0] = np.eye(3)
    return rest_c, cur_c, rot
