"""Render-surface rebuilds that reuse the clips of unchanged regions (the shells equal those of clipping every
region again, bit for bit; a breaking scene's cache: tests/test_surface_thread.py), and clips against a tile's cut
of the input mesh, whose size is the fragment's neighbourhood's, not the whole mesh's."""

from __future__ import annotations

import manifold3d
import numpy as np
import pytest
import trimesh

import pdsim
from pdsim.fragment_surfaces import FragmentSurfaces
from pdsim.fragment_surfaces.booleans import InputCuts, _manifold, refine_surface

H = 0.02  # spacing [m]
H_SPHERE = 0.01  # spacing of the sphere tests [m]: the sphere is 30 spacings across


def _lattice_in(shape, h=H):
    """Lattice points of spacing h inside ``shape`` (trimesh's inside test), float64 [n, 3]."""
    lo, hi = shape.bounds
    axes = [np.arange(lo[a] + 0.5 * h, hi[a], h) for a in range(3)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    return g[trimesh.Trimesh(shape.vertices, shape.faces).contains(g)]


def _steps(rest, centre):
    """Fragment labels and damage of three rebuilds: two halves; the lower half split; eight chips in the upper
    half (far from the second crack, so the lower half's clips are reused)."""
    rest = rest - centre
    halves = (rest[:, 0] > 0.0).astype(np.int64)
    split = halves + 2 * ((rest[:, 0] <= 0.0) & (rest[:, 1] > 0.0))
    damage = np.zeros(len(rest))
    upper = np.flatnonzero(rest[:, 0] > 0.1)
    damage[upper[:: max(len(upper) // 8, 1)][:8]] = 1.0
    return [(halves, None), (split, None), (split, damage)]


@pytest.mark.parametrize("chip_shape", ["cube", "cell"])
def test_reused_clips_give_the_shells_of_clipping_every_region_again(chip_shape):
    """Three rebuilds of a box's shells with reuse on and off: every array of the shells (rest vertices, faces,
    fragment and crack per face) is equal bit for bit after each, and reuse skipped booleans (the unchanged
    regions' clips came from the rebuild before). The last rebuild's eight chips take a boolean each when drawn as
    their cells, none as cubes."""
    centre = np.array([1000.0, -500.0, 3.0])  # far from the origin
    shape = pdsim.box((0.4, 0.2, 0.12), center=tuple(centre))
    rest = _lattice_in(shape)
    on = FragmentSurfaces(shape, rest, H, "b", reuse=True, chip_shape=chip_shape)
    off = FragmentSurfaces(shape, rest, H, "b", reuse=False, chip_shape=chip_shape)
    made_on, made_off = [], []
    for labels, damage in _steps(rest, centre):
        assert on.update_topology(labels, damage) and off.update_topology(labels, damage)
        for name in ("rest_vertices", "faces", "face_fragment", "face_crack", "fragment_ids", "vertex_fragment"):
            a, b = getattr(on, name), getattr(off, name)
            assert a.dtype == b.dtype and np.array_equal(a, b), name
        made_on.append(on.clips_made)
        made_off.append(off.clips_made)
    assert made_off == [2, 3, 3 + (8 if chip_shape == "cell" else 0)]  # every region clipped
    assert sum(made_on) < sum(made_off)  # regions unchanged since the last rebuild took their clips


@pytest.fixture(scope="module")
def fine_sphere():
    """An icosphere of 20,480 triangles (radius 0.15 m) and its cuts at spacing H_SPHERE."""
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=0.15)
    return InputCuts(refine_surface(mesh.vertices, mesh.faces, H_SPHERE), "sphere", H_SPHERE)


def test_a_small_region_is_clipped_against_a_cut_of_the_mesh_near_it(fine_sphere):
    """A chip (a cube of one spacing) on the surface of a 20k-triangle sphere is clipped against a cut holding a few
    percent of the mesh's triangles, with the very volume and area of the clip against the whole mesh (1e-12
    relative); a region too large for a tile is clipped against the whole mesh."""
    cuts = fine_sphere
    whole = cuts.solid.num_tri()
    assert whole == 20480
    for centre in ((0.15, 0.0, 0.0), (0.0, -0.106, 0.106), (-0.0866, 0.0866, -0.0866)):
        cube = trimesh.creation.box(extents=(H_SPHERE,) * 3)
        cube.apply_translation(centre)
        region = _manifold(cube.vertices, cube.faces)
        cut = cuts.for_box(cube.vertices.min(axis=0), cube.vertices.max(axis=0))
        assert cut is not cuts.solid and cut.num_tri() < 0.1 * whole  # the mesh near the chip (about 7 %)
        via_cut, via_whole = region ^ cut, region ^ cuts.solid
        assert via_whole.volume() > 0.0
        assert via_cut.volume() == pytest.approx(via_whole.volume(), rel=1e-12)
        assert via_cut.surface_area() == pytest.approx(via_whole.surface_area(), rel=1e-12)
        assert via_cut.status() == manifold3d.Error.NoError
    big = np.array([0.12, 0.12, 0.12])
    assert cuts.for_box(-big, big) is cuts.solid
