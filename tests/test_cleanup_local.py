"""The sliver clean-up works on the neighbourhoods of its candidates (pdsim/fragment_surfaces/cleanup.py): a round
over the triangles within two rings of the flagged ones decides as a round over the whole complex, leaves the rest
untouched, and the closedness check sees only the edges near the round's vertices."""

import numpy as np

import pdsim.fragment_surfaces.cleanup as cleanup
from pdsim.fragment_surfaces import shells_closed, triangle_angles

OCTA = np.array([[0, 1, 2], [1, 3, 2], [3, 4, 2], [4, 0, 2], [1, 0, 5], [3, 1, 5], [4, 3, 5], [0, 4, 5]])
UNIT = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=np.float64)


def _complex(offset):
    """Two shells far apart (1 km from the origin): shell 0 an octahedron whose face (0, 1, 2) is a fan around a
    vertex 1e-3 from vertex 0 (a needle), shell 1 a clean octahedron 10 m away."""
    x0 = UNIT + offset
    needle = (UNIT[0] + 1e-3 * (UNIT[1] + UNIT[2] - 2 * UNIT[0]) + offset)[None]
    x1 = UNIT + offset + np.array([10.0, 0.0, 0.0])
    points = np.concatenate([x0, needle, x1])
    tri = np.concatenate([OCTA[1:], [[6, 0, 1], [6, 1, 2], [6, 2, 0]], OCTA + 7])
    shell = np.repeat([0, 1], [10, 8]).astype(np.int64)
    patch = np.concatenate([np.arange(7), [7, 7, 7], np.arange(8) + 8]).astype(np.int64)
    return points, tri, shell, patch


def test_local_rounds_match_whole_complex_rounds(monkeypatch):
    """The clean-up removes the needle (shell 0 becomes the closed octahedron, no angle under 5 degrees), leaves
    shell 1 as it was, works only on shell 0's triangles, and gives the same triangles as rounds over the whole
    complex (``_neighbourhood`` widened to everything)."""
    points, tri, shell, patch = _complex(np.array([1000.0, -1000.0, 500.0]))
    seen = []
    round_ = cleanup._collapse_round

    def spy(p, t, *args, **kw):
        seen.append(len(t))
        return round_(p, t, *args, **kw)

    monkeypatch.setattr(cleanup, "_collapse_round", spy)
    out = cleanup.clean_complex(points.copy(), tri, shell, patch, 1.0)
    assert max(seen) == 10  # shell 0 only
    t, s, _ = out
    assert shells_closed(t, s, len(points)).all()
    assert 6 not in t and len(t) == 16
    assert triangle_angles(points, t).min() > 5.0
    np.testing.assert_array_equal(t[s == 1], tri[shell == 1])

    monkeypatch.setattr(cleanup, "_neighbourhood", lambda tri, flag, n: (np.arange(len(tri)), np.ones(n, dtype=bool)))
    seen.clear()
    whole = cleanup.clean_complex(points.copy(), tri, shell, patch, 1.0)
    assert max(seen) == 18
    for a, b in zip(out, whole):
        np.testing.assert_array_equal(a, b)


def test_closed_near_sees_holes_by_active_vertices():
    """The incremental closedness check: True on the intact complex, False when a triangle at an active vertex of a
    listed shell is missing, True when the hole is in a shell not listed or away from the active vertices."""
    points, tri, shell, _ = _complex(np.zeros(3))
    tri, shell = tri[tri[:, 0] != 6], shell[tri[:, 0] != 6]  # drop the fan: shell 0 is open at (0, 1, 2)
    tri = np.concatenate([[[0, 1, 2]], tri])
    shell = np.concatenate([[0], shell])
    n = len(points)
    active = np.zeros(n, dtype=bool)
    active[[0, 7]] = True
    both = np.array([0, 1])
    assert shells_closed(tri, shell, n).all()
    assert cleanup._closed_near(tri, shell, active, both, n)
    holed = np.ones(len(tri), dtype=bool)
    holed[0] = False  # the face (0, 1, 2) of shell 0: vertex 0 is active
    assert not cleanup._closed_near(tri[holed], shell[holed], active, both, n)
    assert cleanup._closed_near(tri[holed], shell[holed], active, np.array([1]), n)
    far = np.ones(len(tri), dtype=bool)
    far[np.flatnonzero((shell == 1) & ~np.isin(tri, [7]).any(axis=1))[0]] = False  # no active vertex
    assert not shells_closed(tri[far], shell[far], n).all()
    assert cleanup._closed_near(tri[far], shell[far], active, both, n)
