"""The drawn surface's sliver pass works on the neighbourhoods of its candidates (pdsim/fragment_surfaces/drawn.py):
its rounds of flips, vertex moves and merges, each on the triangles around its candidates' corners in their own
vertex numbering, give the same surface bit for bit as the same rounds over the whole surface."""

import numpy as np
from scipy.spatial import ConvexHull

import pdsim.fragment_surfaces.drawn as drawn
from pdsim.fragment_surfaces import shells_closed, triangle_angles


def _sphere(offset):
    """A closed, outward-oriented triangulation of 400 random points on a unit sphere (a convex hull: many
    slivers), 1 km from the origin; every face a crack face of shell 0, all of one patch."""
    rng = np.random.default_rng(5)
    p = rng.normal(size=(400, 3))
    p /= np.linalg.norm(p, axis=1)[:, None]
    tri = ConvexHull(p).simplices.astype(np.int64)
    n = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    flip = np.einsum("ij,ij->i", n, p[tri].mean(axis=1)) < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    f = len(tri)
    return p + offset, tri, np.zeros(f, dtype=np.int64), np.zeros(f, dtype=np.int64), np.ones(f, dtype=np.int32)


def test_local_rounds_match_whole_surface_rounds(monkeypatch):
    x, tri, shell, patch, crack = _sphere(np.array([1000.0, -1000.0, 500.0]))
    parent = np.arange(len(tri))
    first_added = 200  # the second half may merge into a neighbour
    spacing = 0.3
    assert (triangle_angles(x, tri).min(axis=1) < 5.0).sum() >= 10
    seen = []
    inner = drawn._compact

    def spy(t):
        seen.append(len(t))
        return inner(t)

    monkeypatch.setattr(drawn, "_compact", spy)
    x_local = x.copy()
    faces, par = drawn._unsliver(x_local, tri, parent, shell, patch, crack, first_added, spacing)
    assert seen and max(seen) < len(tri)  # the rounds worked on parts of the surface
    assert shells_closed(faces, np.zeros(len(faces), dtype=np.int64), len(x)).all()
    before = (triangle_angles(x, tri).min(axis=1) < 5.0).sum()
    assert (triangle_angles(x_local, faces).min(axis=1) < 5.0).sum() < before
    assert len(faces) < len(tri) - 100  # added vertices merged

    monkeypatch.setattr(drawn, "_around", lambda t, flag, n: np.arange(len(t)))
    seen.clear()
    x_whole = x.copy()
    faces_w, par_w = drawn._unsliver(x_whole, tri, parent, shell, patch, crack, first_added, spacing)
    assert max(seen) == len(tri)
    np.testing.assert_array_equal(x_local, x_whole)
    np.testing.assert_array_equal(faces, faces_w)
    np.testing.assert_array_equal(par, par_w)
