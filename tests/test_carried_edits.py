"""Render-surface rebuilds that carry the last sliver clean-up's edits (pdsim/fragment_surfaces/edits.py): where
the complex is unchanged the rebuild takes the clean-up's result, and cleans only the rest. The shells equal those
of cleaning the whole complex again on a box (bit for bit), stay closed and partition the solid on a faceted sphere
(as many slivers as the whole clean-up leaves), and the clean-up starts from a fraction of the flagged triangles.
A resumed run rebuilds as the uninterrupted one (the record is in the checkpoint): tests/test_resume_cache.py."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from test_surface_reuse import H, _lattice_in, _steps

import pdsim
import pdsim.fragment_surfaces.booleans as booleans
from pdsim.fragment_surfaces import FragmentSurfaces, shells_closed, triangle_angles
from pdsim.fragment_surfaces.cleanup import SHORT_EDGE, SLIVER_ANGLE, _needs_work
from pdsim.fragment_surfaces.edits import apply_edits, complex_record
from pdsim.geometry import SolidShape

SHELL_ARRAYS = ("rest_vertices", "faces", "face_fragment", "face_crack", "fragment_ids", "vertex_fragment")


@pytest.fixture
def flagged(monkeypatch):
    """Triangles flagged (a side under 0.3 h or an angle under 5 degrees) at the start of each clean-up."""
    counts = []
    inner = booleans.clean_complex

    def spy(points, tri, shell, patch, spacing, **kw):
        counts.append(int(_needs_work(points, tri, spacing, SHORT_EDGE, SLIVER_ANGLE).sum()))
        return inner(points, tri, shell, patch, spacing, **kw)

    monkeypatch.setattr(booleans, "clean_complex", spy)
    return counts


def _rebuild_both(shape, rest, steps, flagged):
    """Yields (carrying, not carrying, flagged at the start of each one's clean-up) after each step's rebuild; chips
    drawn as their cells (they then take part in the clean-up, and the shells partition the solid)."""
    on = FragmentSurfaces(shape, rest, H, "b", carry_edits=True, chip_shape="cell")
    off = FragmentSurfaces(shape, rest, H, "b", carry_edits=False, chip_shape="cell")
    for labels, damage in steps:
        assert on.update_topology(labels, damage)
        assert off.update_topology(labels, damage)
        assert not on.clean_failed and not off.clean_failed
        yield on, off, flagged[-2], flagged[-1]


def test_carried_edits_give_the_whole_clean_up_of_a_box(flagged):
    """A box 1 km from the origin: two halves, the lower half split, eight chips. After each rebuild every array of
    the shells equals, bit for bit, that of cleaning the whole complex again; the chips' rebuild (the halves' clips
    reused) starts its clean-up from under half the flagged triangles."""
    centre = np.array([1000.0, -500.0, 3.0])
    shape = pdsim.box((0.4, 0.2, 0.12), center=tuple(centre))
    rest = _lattice_in(shape)
    counts = []
    for on, off, n_on, n_off in _rebuild_both(shape, rest, _steps(rest, centre), flagged):
        for name in SHELL_ARRAYS:
            a, b = getattr(on, name), getattr(off, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        counts.append((n_on, n_off))
    assert counts[0][0] == counts[0][1]  # the first rebuild has nothing to carry
    assert counts[2][0] < 0.5 * counts[2][1], counts


def _volume(points, faces, centre):
    """Signed volume [m^3] enclosed by triangles ``faces`` of ``points`` [m] (relative to ``centre``)."""
    t = points[faces] - centre
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def _sphere():
    """An icosphere (radius 0.15 m, 1,280 facets) 1 km from the origin, its lattice points and three steps: halves, a
    split, six chips. Returns (shape, rest positions, steps, centre)."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.15)
    centre = np.array([1000.0, 20.0, -300.0])
    shape = SolidShape(vertices=mesh.vertices + centre, faces=mesh.faces, name="sphere")
    rest = _lattice_in(shape)
    r = rest - centre
    halves = (r[:, 0] > 0.0).astype(np.int64)
    split = halves + 2 * ((r[:, 0] <= 0.0) & (r[:, 1] > 0.0))
    damage = np.zeros(len(rest))
    corner = np.flatnonzero((r[:, 0] < -0.05) & (r[:, 1] < -0.03))
    damage[corner[::5][:6]] = 1.0
    return shape, rest, [(halves, None), (split, None), (split, damage)], centre


def test_carried_edits_on_a_faceted_sphere(flagged):
    """The sphere of :func:`_sphere` broken in three rebuilds: with carried edits every shell is closed, the shells'
    volumes add up to the input's (1e-9 relative), no more triangles have an angle under 5 degrees than after
    cleaning the whole complex, and the chips' rebuild starts its clean-up from under half the flagged triangles."""
    shape, rest, steps, centre = _sphere()
    whole = _volume(shape.vertices, shape.faces, centre)
    counts = []
    for on, off, n_on, n_off in _rebuild_both(shape, rest, steps, flagged):
        assert shells_closed(on.faces, on._face_shell, len(on.rest_vertices)).all()
        assert sum(_volume(on.rest_vertices, f, centre) for f in np.split(on.faces, on._face_ranges[1:-1])) == (
            pytest.approx(whole, rel=1e-9)
        )
        slivers = [int((triangle_angles(s.rest_vertices, s.faces).min(axis=1) < SLIVER_ANGLE).sum()) for s in (on, off)]
        assert slivers[0] <= slivers[1], slivers
        counts.append((n_on, n_off))
    assert counts[2][0] < 0.5 * counts[2][1], counts


def test_a_record_applied_to_its_own_raw_complex_gives_its_clean_up():
    """The same raw complex, bit for bit: the record's cleaned complex itself; a complex with one vertex moved
    off every match: nothing applied (the record's edits there are not carried)."""
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    tri = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    shell, patch = np.zeros(4, dtype=np.int64), np.arange(4)
    clean = (points + 0.0, tri[[1, 0, 3, 2]], shell, patch[[1, 0, 3, 2]])
    clean[0][3] += 0.1  # a moved vertex: every triangle around it is an edit
    record = complex_record((points, tri, shell, patch), clean, np.array([1, 0, 3, 2]))
    out = apply_edits(record, points, tri, shell, patch, 1.0)
    assert out[6] == -1 and np.array_equal(out[0], clean[0]) and np.array_equal(out[1], clean[1])
    moved = points.copy()
    moved[0] += 1e-6
    out = apply_edits(record, moved, tri, shell, patch, 1.0)
    assert out[6] == 0 and np.array_equal(out[1], tri) and np.array_equal(out[0], moved)


def test_the_checkpoint_carries_the_record():
    """Surfaces made anew from a checkpoint of the sphere's after two rebuilds rebuild the chips as the original
    does, bit for bit; made anew without it they clean the whole complex, which here gives other shells (so the
    checkpoint is what keeps a resumed run equal to the uninterrupted one)."""
    shape, rest, steps, _ = _sphere()
    first = FragmentSurfaces(shape, rest, H, "b")
    for labels, damage in steps[:2]:
        first.update_topology(labels, damage)
    resumed, fresh = FragmentSurfaces(shape, rest, H, "b"), FragmentSurfaces(shape, rest, H, "b")
    resumed.restore(first.checkpoint())
    for s in (first, resumed, fresh):
        assert s.update_topology(*steps[2])
    for name in SHELL_ARRAYS:
        a, b = getattr(first, name), getattr(resumed, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert first.faces.shape != fresh.faces.shape or not np.array_equal(first.faces, fresh.faces)
