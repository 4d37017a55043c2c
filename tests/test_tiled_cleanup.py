"""The sliver clean-up tile by tile (pdsim/fragment_surfaces/tiles.py). A tile's result depends on its own raw
triangles only: surfaces rebuilt with the tiles' results kept from earlier rebuilds equal, bit for bit, surfaces
made anew at the last step (so no record crosses rebuilds or checkpoints); the shells stay closed and partition the
solid; a rebuild that changes a corner of the body cleans a fraction of the tiles."""

from __future__ import annotations

import numpy as np
from test_surface_reuse import H, _lattice_in, _steps

import pdsim
from pdsim.fragment_surfaces import FragmentSurfaces, shells_closed

SHELL_ARRAYS = ("rest_vertices", "faces", "face_fragment", "face_crack", "fragment_ids", "vertex_fragment")


def _volume(points, faces, centre):
    """Signed volume [m^3] enclosed by triangles ``faces`` of ``points`` [m] (relative to ``centre``)."""
    t = points[faces] - centre
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


def test_tiles_kept_across_rebuilds_equal_surfaces_made_anew():
    """A box 1 km from the origin broken in three steps (halves, a split, eight chips): after each step, the shells
    of the surfaces that kept their tiles' results equal those of new surfaces built at that step alone, bit for
    bit; every shell is closed; the chips' rebuild cleans under half of the tiles with work."""
    centre = np.array([1000.0, -500.0, 3.0])
    size = (0.4, 0.2, 0.12)
    shape = pdsim.box(size, center=tuple(centre))
    rest = _lattice_in(shape)
    kept = FragmentSurfaces(shape, rest, H, "b", clean_tiles=True)
    fractions = []
    for labels, damage in _steps(rest, centre):
        assert kept.update_topology(labels, damage)
        tiles = kept._tiles
        fractions.append(tiles.cleaned_tiles / max(tiles.tiles, 1))
        anew = FragmentSurfaces(shape, rest, H, "b", clean_tiles=True)
        assert anew.update_topology(labels, damage)
        assert not kept.clean_failed and not anew.clean_failed
        for name in SHELL_ARRAYS:
            a, b = getattr(kept, name), getattr(anew, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        shell_of = kept.vertex_fragment[kept.faces[:, 0]]
        assert shells_closed(kept.faces, shell_of, len(kept.rest_vertices)).all()
    assert fractions[0] == 1.0
    assert fractions[2] < 0.5, fractions


def test_tiled_shells_partition_the_box():
    """The shells' signed volumes add up to the box's (relative 1e-9) after each of the three steps (chips drawn as
    their cells, which partition the solid with the fragments)."""
    centre = np.array([1000.0, -500.0, 3.0])
    size = (0.4, 0.2, 0.12)
    shape = pdsim.box(size, center=tuple(centre))
    rest = _lattice_in(shape)
    surfaces = FragmentSurfaces(shape, rest, H, "b", clean_tiles=True, chip_shape="cell")
    for labels, damage in _steps(rest, centre):
        assert surfaces.update_topology(labels, damage)
        shell_of = surfaces.vertex_fragment[surfaces.faces[:, 0]]
        volume = sum(
            _volume(surfaces.rest_vertices, surfaces.faces[shell_of == s], centre) for s in range(shell_of.max() + 1)
        )
        assert abs(volume - np.prod(size)) < 1e-9 * np.prod(size), volume


def test_a_tile_whose_raw_triangles_changed_is_cleaned_again():
    """The raw complex of a broken box (captured at its last rebuild: eight chips), cleaned tile by tile; then the
    same complex with one crack vertex of a triangle that needs work moved by 0.05 h: the clean-up that kept the
    first call's tiles gives, bit for bit, what a new one gives on the moved complex, and that differs from the first
    result (a kept tile is reused only when its raw content is the same)."""
    from pdsim.fragment_surfaces.cleanup import SHORT_EDGE, SLIVER_ANGLE, _needs_work
    from pdsim.fragment_surfaces.tiles import TiledCleanup

    centre = np.array([1000.0, -500.0, 3.0])
    shape = pdsim.box((0.4, 0.2, 0.12), center=tuple(centre))
    rest = _lattice_in(shape)
    surfaces = FragmentSurfaces(shape, rest, H, "b", clean_tiles=True)
    calls = []
    inner = surfaces._tiles.clean

    def keep(*args):
        calls.append(tuple(np.array(a, copy=True) for a in args))
        return inner(*args)

    surfaces._tiles.clean = keep
    for labels, damage in _steps(rest, centre):
        assert surfaces.update_topology(labels, damage)
    points, tri, shell, patch, plane_of_patch = calls[-1]
    crack = plane_of_patch[patch] < 0
    on_outer = np.zeros(len(points), dtype=bool)
    on_outer[tri[~crack].ravel()] = True
    flagged = _needs_work(points, tri, H, SHORT_EDGE, SLIVER_ANGLE)  # in a tile with work
    candidates = np.setdiff1d(tri[crack & flagged].ravel(), np.flatnonzero(on_outer))
    moved = points.copy()
    moved[candidates[len(candidates) // 2]] += 0.05 * H * np.array([0.6, 0.0, 0.8])

    kept = TiledCleanup(surfaces._surface, H)
    first = kept.clean(points, tri, shell, patch, plane_of_patch)
    again = kept.clean(moved, tri, shell, patch, plane_of_patch)
    fresh = TiledCleanup(surfaces._surface, H).clean(moved, tri, shell, patch, plane_of_patch)
    for a, b in zip(again, fresh):
        assert a.dtype == b.dtype and np.array_equal(a, b)
    assert not all(np.array_equal(a, b) for a, b in zip(first, fresh))
