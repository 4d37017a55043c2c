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
    """The shells' signed volumes add up to the box's (relative 1e-9) after each of the three steps."""
    centre = np.array([1000.0, -500.0, 3.0])
    size = (0.4, 0.2, 0.12)
    shape = pdsim.box(size, center=tuple(centre))
    rest = _lattice_in(shape)
    surfaces = FragmentSurfaces(shape, rest, H, "b", clean_tiles=True)
    for labels, damage in _steps(rest, centre):
        assert surfaces.update_topology(labels, damage)
        shell_of = surfaces.vertex_fragment[surfaces.faces[:, 0]]
        volume = sum(
            _volume(surfaces.rest_vertices, surfaces.faces[shell_of == s], centre) for s in range(shell_of.max() + 1)
        )
        assert abs(volume - np.prod(size)) < 1e-9 * np.prod(size), volume
