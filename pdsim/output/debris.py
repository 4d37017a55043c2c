"""Debris: the fragments of a body too small to draw as meshes, as instances for a point instancer.

The writer (pdsim/output/writer.py, ``ViewWriter(debris_particles=N)``) takes every fragment of fewer than N points out
of the body's surface mesh and writes it as one instance of ``/World/<body>_debris`` (a ``UsdGeom.PointInstancer``):
its centroid, mean velocity, the rotation that carries its rest shape onto its current one (a least-squares fit) and
its size. Everything here is vectorised numpy over points and fragments.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .views import MeshView, PointsView


@dataclass
class Debris:
    """The small fragments of one body at one frame, one row each, in increasing fragment id.

    ids: fragment ids, int64 [m]. positions: centroids of their points [m], float64 [m, 3]. velocities: mean point
    velocities [m/s], float64 [m, 3]. orientations: unit quaternions (x, y, z, w) of the rotation from the rest pose,
    float64 [m, 4]. sizes: diameters [m], float64 [m]: twice the largest distance of a point from the centroid plus
    the point width. particles: point counts, int64 [m]."""

    ids: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    orientations: np.ndarray
    sizes: np.ndarray
    particles: np.ndarray


def _quaternions(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (x, y, z, w), float64 [m, 4], of rotation matrices ``r`` [m, 3, 3] (Shepperd's method: the
    largest of the four squared components is computed first, so the result is accurate for any angle), w >= 0."""
    m = len(r)
    t = np.stack(
        [
            1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2],
            1.0 - r[:, 0, 0] + r[:, 1, 1] - r[:, 2, 2],
            1.0 - r[:, 0, 0] - r[:, 1, 1] + r[:, 2, 2],
            1.0 + r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2],
        ],
        axis=1,
    )  # 4 x the squares of x, y, z, w
    pick = np.argmax(t, axis=1)
    s = np.sqrt(np.maximum(t[np.arange(m), pick], 1e-300))  # 2 |component|
    q = np.zeros((m, 4))
    a, b, c = r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]  # 4 w (x, y, z)
    d, e, f = r[:, 0, 1] + r[:, 1, 0], r[:, 0, 2] + r[:, 2, 0], r[:, 1, 2] + r[:, 2, 1]  # 4 (xy, xz, yz)
    rows = [
        np.stack([s / 2, d / (2 * s), e / (2 * s), a / (2 * s)], axis=1),
        np.stack([d / (2 * s), s / 2, f / (2 * s), b / (2 * s)], axis=1),
        np.stack([e / (2 * s), f / (2 * s), s / 2, c / (2 * s)], axis=1),
        np.stack([a / (2 * s), b / (2 * s), c / (2 * s), s / 2], axis=1),
    ]
    for k in range(4):  # four cases, each vectorised over the fragments
        q[pick == k] = rows[k][pick == k]
    q[q[:, 3] < 0] *= -1.0
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def fit_rotations(rest: np.ndarray, current: np.ndarray, group: np.ndarray, count: int) -> np.ndarray:
    """Per group, the rotation matrix R (float64 [count, 3, 3]) minimising sum |R (rest - rest centroid) -
    (current - current centroid)|^2 over its points (Kabsch: SVD of the cross-covariance, reflections excluded).
    ``group``: the group of each point, int [n] in [0, count). A group of one point, or of points on one line, gets
    a rotation that is exact for them (the identity when they do not move)."""
    n_of = np.bincount(group, minlength=count).astype(np.float64)
    n_of = np.maximum(n_of, 1.0)
    c0 = np.stack([np.bincount(group, rest[:, k], minlength=count) for k in range(3)], axis=1) / n_of[:, None]
    c1 = np.stack([np.bincount(group, current[:, k], minlength=count) for k in range(3)], axis=1) / n_of[:, None]
    p = rest - c0[group]
    q = current - c1[group]
    h = np.zeros((count, 3, 3))
    for i in range(3):
        for j in range(3):
            h[:, i, j] = np.bincount(group, p[:, i] * q[:, j], minlength=count)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("mji,mkj->mik", vt, u)))
    d[d == 0] = 1.0
    fix = np.ones((count, 3))
    fix[:, 2] = d
    return np.einsum("mji,mj,mkj->mik", vt, fix, u)  # V diag(1, 1, d) U^T


def small_fragments(view: PointsView, min_points: int) -> Debris | None:
    """The fragments of ``view`` (its ``fragment`` attribute) with fewer than ``min_points`` points, or None when it
    has no fragment attribute. Rest positions are ``positions - displacement`` (without a ``displacement``
    attribute the orientations are the identity)."""
    frag = view.attributes.get("fragment")
    if frag is None:
        return None
    frag = np.asarray(frag, dtype=np.int64)
    ids, inverse, counts = np.unique(frag, return_inverse=True, return_counts=True)
    small = counts < int(min_points)
    keep = small[inverse]
    group = np.cumsum(small)[inverse[keep]] - 1  # the row of each debris point's fragment
    m = int(small.sum())
    x = np.asarray(view.positions, dtype=np.float64)[keep]
    v = np.asarray(view.velocities, dtype=np.float64)[keep]
    widths = np.broadcast_to(np.asarray(view.widths, dtype=np.float64), (len(frag),))[keep]
    n_of = counts[small].astype(np.float64)
    centre = np.stack([np.bincount(group, x[:, k], minlength=m) for k in range(3)], axis=1) / n_of[:, None]
    velocity = np.stack([np.bincount(group, v[:, k], minlength=m) for k in range(3)], axis=1) / n_of[:, None]
    reach = np.linalg.norm(x - centre[group], axis=1) + 0.5 * widths
    size = np.zeros(m)
    np.maximum.at(size, group, 2.0 * reach)
    displacement = view.attributes.get("displacement")
    if displacement is None:
        orientation = np.tile([0.0, 0.0, 0.0, 1.0], (m, 1))
    else:
        rest = x - np.asarray(displacement, dtype=np.float64)[keep]
        orientation = _quaternions(fit_rotations(rest, x, group, m)) if m else np.zeros((0, 4))
    return Debris(ids[small], centre, velocity, orientation, size, counts[small].astype(np.int64))


def without_fragments(view: MeshView, ids: np.ndarray) -> MeshView:
    """``view`` without the faces of the fragments ``ids`` (its ``fragment`` face attribute); the vertices stay. Its
    topology version becomes (the view's version, the ids), which changes exactly when the faces written change."""
    face_fragment = np.asarray(view.face_attributes["fragment"])
    keep = ~np.isin(face_fragment, ids)
    return MeshView(
        view.name,
        view.points,
        view.velocities,
        (view.topology_version, tuple(int(i) for i in ids)),
        np.asarray(view.faces).reshape(-1, 3)[keep],
        {k: np.asarray(a)[keep] for k, a in view.face_attributes.items()},
        view.vertex_attributes,
    )


def chunk_prototype() -> tuple[np.ndarray, np.ndarray]:
    """The debris prototype: an icosahedron of unit diameter (vertices at 0.5 from its centre, float64 [12, 3]) and
    its 20 triangles (int [20, 3], counter-clockwise seen from outside); an instance's scale is its size [m]."""
    g = (1.0 + 5.0**0.5) / 2.0
    v = np.array(
        [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
         [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]],
        dtype=np.float64,
    )  # fmt: skip
    v *= 0.5 / np.linalg.norm(v[0])
    f = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6],
         [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
         [8, 6, 7], [9, 8, 1]],
        dtype=np.int64,
    )  # fmt: skip
    return v, f


__all__ = ["Debris", "chunk_prototype", "fit_rotations", "small_fragments", "without_fragments"]
