"""The side of a point against a closed surface in the contact between FEM surfaces (kernels/surface_contact.py
face_side): inside or outside, from the nearest face's normal or, where the nearest point is on an edge or a corner,
from a pseudo-normal. Checked against the generalised winding number (Warp's mesh query, independent of face_side)
on the surfaces a crack leaves: a piece of a jittered tetrahedral mesh cut along a wavy, noisy plane, whose boundary
is a staircase of element faces with corners where the faces fan unevenly. There an unweighted sum of the faces'
normals at a corner pointed away from the piece for some points (1 to 3 of 4,000 near each of these surfaces, up to
0.78 of the band from it), which the contact then took for vertices deep inside and pushed out: a cracked slab shed
single elements along its crack (tests/test_fem_fracture.py, the slab on its kept mesh)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from pdsim.fem.fracture import element_pieces, make_manifold
from pdsim.fem.mesh import boundary_faces, box_tet_mesh
from pdsim.kernels import surface_contact as ksf

CELLS = 6  # cells along each side of the unit box
BAND = 1.0 / CELLS  # the contact band: one edge of a cell
POINTS = 4000


@wp.kernel
def _probe(
    mesh: wp.uint64,
    m_x: wp.array(dtype=wp.vec3),
    m_faces: wp.array(dtype=wp.int32),
    m_label: wp.array(dtype=wp.int32),
    points: wp.array(dtype=wp.vec3),
    reach: float,
    side: wp.array(dtype=float),
    winding_sign: wp.array(dtype=float),
    faces: wp.array(dtype=wp.vec2i),
    distances: wp.array(dtype=wp.vec2),
):
    """Per point: the contact's side of the nearest face (0: none), the winding number's sign, and the nearest face
    and its distance found by nearest_foreign_face and by one search of the whole reach (foreign_face_within)."""
    t = wp.tid()
    x = points[t]
    side[t] = 0.0
    best, weights, dist = ksf.nearest_foreign_face(mesh, x, reach, m_x, m_faces, m_label, -1)
    whole, _, whole_dist = ksf.foreign_face_within(mesh, x, reach, m_x, m_faces, m_label, -1)
    faces[t] = wp.vec2i(best, whole)
    distances[t] = wp.vec2(dist, whole_dist)
    if best >= 0:
        _, sign = ksf.face_side(mesh, m_x, m_faces, m_label, best, weights, x, reach)
        side[t] = sign
    query = wp.mesh_query_point_sign_winding_number(mesh, x, 10.0 * reach)
    winding_sign[t] = query.sign


def _probe_points(vertices, faces, points) -> dict:
    """The kernel _probe over ``points`` against the closed surface (``vertices``, ``faces``), one piece: numpy
    arrays side, winding [n], faces [n, 2], distances [n, 2]."""
    m_x = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device="cpu")
    m_faces = wp.array(faces.ravel().astype(np.int32), dtype=wp.int32, device="cpu")
    mesh = wp.Mesh(points=m_x, indices=m_faces, support_winding_number=True)
    n = len(points)
    out = {
        "side": wp.zeros(n, dtype=float, device="cpu"),
        "winding": wp.zeros(n, dtype=float, device="cpu"),
        "faces": wp.zeros(n, dtype=wp.vec2i, device="cpu"),
        "distances": wp.zeros(n, dtype=wp.vec2, device="cpu"),
    }
    labels = wp.zeros(len(faces), dtype=wp.int32, device="cpu")
    points_wp = wp.array(points.astype(np.float32), dtype=wp.vec3, device="cpu")
    wp.launch(_probe, n, [mesh.id, m_x, m_faces, labels, points_wp, BAND, *out.values()], device="cpu")
    return {name: array.numpy() for name, array in out.items()}


def _cut_piece(seed: int):
    """The largest piece of a jittered box mesh below a wavy plane with per-element noise (a crack's staircase):
    (vertices, boundary faces)."""
    rng = np.random.default_rng(seed)
    box = box_tet_mesh((1.0, 1.0, 1.0), (CELLS, CELLS, CELLS), jitter=0.25, seed=seed)
    c = box.vertices[box.tets].mean(axis=1)
    below = c[:, 2] < 0.1 * np.sin(7.0 * c[:, 0] + seed) + 0.15 * c[:, 1] + rng.uniform(-0.08, 0.08, len(c))
    tets, parent = make_manifold(box.tets[below], len(box.vertices), np.unique(box.tets[below]))
    _, labels = element_pieces(tets)
    tets = tets[labels == np.argmax(np.bincount(labels))]
    return box.vertices[parent], boundary_faces(tets)


@pytest.mark.parametrize("seed", range(3))
def test_the_side_of_a_point_near_a_cracked_piece_matches_the_winding_number(seed):
    vertices, faces = _cut_piece(seed)
    rng = np.random.default_rng(100 + seed)
    on_surface = vertices[np.unique(faces)]
    points = on_surface[rng.integers(0, len(on_surface), POINTS)] + rng.normal(0.0, BAND / 2.5, (POINTS, 3))
    probe = _probe_points(vertices, faces, points)
    side, winding, distance = probe["side"], probe["winding"], probe["distances"][:, 0]
    # the points the contact judges: within the band of the surface, off it (on it the side does not matter)
    judged = (side != 0.0) & (distance > 1.0e-4) & (distance < BAND)
    assert judged.sum() > 0.9 * POINTS
    assert (winding[judged] != 0.0).all()
    wrong = judged & (side != winding)
    assert wrong.sum() == 0, f"{wrong.sum()} points on the wrong side, up to {distance[wrong].max():.3f} m deep"


def test_the_nearest_face_search_looks_near_first_and_finds_the_same_face():
    """nearest_foreign_face looks within a quarter of its reach first and within the whole reach only where that finds
    nothing as near: for points from on the surface to beyond the reach of a cracked piece (over a fifth of them
    farther than the quarter, some beyond the reach), it returns the same face at the same distance as one search of
    the whole reach."""
    vertices, faces = _cut_piece(0)
    rng = np.random.default_rng(7)
    on_surface = vertices[np.unique(faces)]
    points = on_surface[rng.integers(0, len(on_surface), POINTS)] + rng.normal(0.0, BAND / 2.0, (POINTS, 3))
    probe = _probe_points(vertices, faces, points)
    found, distance = probe["faces"], probe["distances"]
    hit = found[:, 1] >= 0
    far = hit & (distance[:, 1] > 0.25 * BAND)
    assert hit.sum() > 0.8 * POINTS and far.sum() > 0.2 * POINTS and (~hit).sum() > 0
    np.testing.assert_array_equal(found[:, 0], found[:, 1])
    np.testing.assert_array_equal(distance[hit, 0], distance[hit, 1])
