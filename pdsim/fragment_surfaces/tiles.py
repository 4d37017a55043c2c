"""The sliver clean-up by tiles of rest space (step 6 of the method in :mod:`pdsim.fragment_surfaces`), so that a
rebuild cleans only where the raw complex changed.

Rest space is cut into a fixed grid of cubic tiles of ``TILE`` spacings, anchored at a corner of the input surface
(so it moves with the body and never depends on the run's history). A vertex belongs to the tile holding it; a
triangle whose three vertices share a tile is inside that tile, the others cross a border. A tile's triangles are
cleaned (:func:`pdsim.fragment_surfaces.cleanup.clean_complex`) with every vertex that has a triangle outside the
tile held fixed, so the tile's cleaned triangles join the rest of the complex unchanged, and its result depends only
on its own triangles: their vertices' positions, their shells and patches (up to numbering), the input planes of
the patches, which vertices are fixed, and whether each shell has more than six vertices. The tiles are cleaned
together in one call whose groups are independent (``group``), and each tile's result is kept under a digest of
that content: a later rebuild takes the kept result of every tile whose content is the same bit for bit and cleans
only the others. The result is a function of the raw complex alone, whether or not a tile's result was kept, so
no record is carried across rebuilds or checkpoints.

Four passes, each on a part of the complex with the vertices of triangles outside the part held fixed (so the
work stays bounded, as a part's clean-up cannot spread beyond it): the tiles; the tiles shifted by half a tile
along every axis, on the triangles within two rings of the vertices the first pass held; the tiles shifted by a
quarter tile, on the triangles within two rings of the vertices both passes held (where a first-pass border crosses
a second-pass border); and, where slivers are left, all space as one tile on the triangles within two rings of
them. The first two passes hold the vertices of one-sided crack faces (:func:`_one_sided`); the last two let them
collapse but never move them (a move would change one shell's volume alone).
"""

from __future__ import annotations

import hashlib

import numpy as np

from .cleanup import SHORT_EDGE, SLIVER_ANGLE, _min_angles, _needs_work, _two_rings, clean_complex

__all__ = ["TILE", "TiledCleanup"]

TILE = 4.0  # tile edge [spacings]


def _plane_equations(surface) -> np.ndarray:
    """Unit normal and offset of each input plane, float64 [plane count, 4], from the (refined) input surface
    (vertices [m], triangles, plane id per triangle): the normalised sum of its triangles' area normals, and the mean
    offset of their centroids."""
    sv, sf, splane = surface
    count = int(splane.max()) + 1
    t = sv[sf]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    normal = np.stack([np.bincount(splane, n[:, a], count) for a in range(3)], axis=1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    offset = np.einsum("ij,ij->i", normal[splane], t.mean(axis=1))
    offset = np.bincount(splane, offset, count) / np.maximum(np.bincount(splane, minlength=count), 1)
    return np.concatenate([normal, offset[:, None]], axis=1)


def _canonical(points, tri, shell, patch, fixed, still, big_shell, plane_of_patch):
    """A tile's triangles in a numbering fixed by their content: (vertex ids [k] in canonical order, triangles
    [f, 3] over them, canonical shell [f], canonical patch [f], shell ids [s] and patch ids [p] in canonical order,
    digest). Vertices are ordered by position, each triangle starts at its smallest vertex, shells and patches are
    ordered by their smallest triangle, triangles by (shell, corners)."""
    verts, local = np.unique(tri, return_inverse=True)
    pos = points[verts]
    order = np.lexsort((pos[:, 2], pos[:, 1], pos[:, 0]))
    rank = np.empty(len(verts), dtype=np.int64)
    rank[order] = np.arange(len(verts))
    lt = rank[local.reshape(-1, 3)]
    first = np.argmin(lt, axis=1)[:, None]
    lt = np.take_along_axis(lt, (first + np.arange(3)) % 3, axis=1)
    n = len(verts)
    key3 = (lt[:, 0] * n + lt[:, 1]) * n + lt[:, 2]

    def relabel(ids):
        uniq, inv = np.unique(ids, return_inverse=True)
        smallest = np.full(len(uniq), np.iinfo(np.int64).max)
        np.minimum.at(smallest, inv, key3)
        by = np.argsort(smallest)
        new = np.empty(len(uniq), dtype=np.int64)
        new[by] = np.arange(len(uniq))
        return uniq[by], new[inv.reshape(-1)]

    shells, cs = relabel(shell)
    patches, cp = relabel(patch)
    tri_order = np.lexsort((key3, cs))
    lt, cs, cp = lt[tri_order], cs[tri_order], cp[tri_order]
    verts = verts[order]
    digest = hashlib.blake2b(digest_size=20)
    for part in (
        points[verts],
        lt,
        cs,
        cp,
        plane_of_patch[patches],
        big_shell[shells],
        fixed[verts],
        still[verts],
    ):
        digest.update(np.ascontiguousarray(part).tobytes())
        digest.update(b"|")
    return verts, lt, cs, cp, shells, patches, digest.digest()


def _one_sided(tri, crack, vertex_count) -> np.ndarray:
    """Bool [v]: vertices of crack triangles (``crack`` bool [f]) that no other triangle repeats in reverse (a crack
    face with one side only, e.g. on the input surface where the region beyond is outside the solid). Moving them
    would change one shell's volume with nothing on the other side to make up for it, so every pass holds them."""
    t = tri[crack]
    first = np.argmin(t, axis=1)[:, None]
    t = np.take_along_axis(t, (first + np.arange(3)) % 3, axis=1)
    n = np.int64(vertex_count)
    key = (t[:, 0] * n + t[:, 1]) * n + t[:, 2]
    rev = (t[:, 0] * n + t[:, 2]) * n + t[:, 1]
    sk = np.sort(key)
    paired = sk[np.minimum(np.searchsorted(sk, rev), max(len(sk) - 1, 0))] == rev if len(sk) else np.zeros(0, bool)
    out = np.zeros(vertex_count, dtype=bool)
    out[t[~paired].ravel()] = True
    return out


class TiledCleanup:
    """The tiled sliver clean-up of one body's shell complexes, keeping each tile's result for the next rebuild.

    Args:
        surface: the (refined) input surface (vertices [m], triangles, plane id per triangle).
        spacing: particle spacing h [m].
        tile: tile edge [spacings].
    """

    def __init__(self, surface, spacing: float, tile: float = TILE):
        self.surface = surface
        self.spacing = float(spacing)
        self.tile = float(tile) * self.spacing
        self.anchor = np.asarray(surface[0], dtype=np.float64).min(axis=0)
        self.plane_eq = _plane_equations(surface)
        self.kept: list[dict] = [{}, {}, {}, {}]  # per pass: digest -> (triangles, shells, patches, points) of the tile
        self.cleaned_tiles = 0  # tiles cleaned (not taken from an earlier rebuild) at the last call
        self.tiles = 0  # tiles with work at the last call

    def clean(self, points, tri, shell, patch, plane_of_patch):
        """The complex (points [m] [v, 3], tri [f, 3], shell [f], patch [f]; ``plane_of_patch`` [patch count]: input
        plane of each patch, -1 for crack patches) cleaned tile by tile. Returns (points, tri, shell, patch); points
        is a new array (vertex moves), vertex ids are kept (removed vertices are no longer used)."""
        points = np.array(points, dtype=np.float64)
        plane_of_patch = np.asarray(plane_of_patch, dtype=np.int64)
        n_v = len(points)
        sv = np.unique(shell.astype(np.int64)[:, None] * n_v + tri)
        big_shell = np.bincount(sv // n_v, minlength=int(shell.max()) + 1) > 6
        plane_eq = np.full((len(plane_of_patch), 4), np.nan)
        planar = plane_of_patch >= 0
        plane_eq[planar] = self.plane_eq[plane_of_patch[planar]]
        lonely = _one_sided(tri, plane_of_patch[patch] < 0, n_v)
        context = (big_shell, plane_of_patch, plane_eq)
        self.cleaned_tiles = self.tiles = 0
        kept = self.kept
        # the tiles, holding one-sided crack faces
        tri, shell, patch, held_a = self._pass(points, tri, shell, patch, 0.0, None, lonely, lonely, kept[0], context)
        # the shifted tiles, on the triangles within two rings of what the first pass held
        part = _two_rings(tri, np.flatnonzero(held_a & ~lonely), n_v)
        tri, shell, patch, held = self._pass(points, tri, shell, patch, 0.5, part, lonely, lonely, kept[1], context)
        # the tiles shifted by a quarter, within two rings of what both passes held
        part = _two_rings(tri, np.flatnonzero(held & held_a & ~lonely), n_v)
        free = np.zeros(n_v, dtype=bool)
        tri, shell, patch, _ = self._pass(points, tri, shell, patch, 0.25, part, free, lonely, kept[2], context)
        # one tile: within two rings of the slivers left
        sliver = _min_angles(points[tri]) < SLIVER_ANGLE
        if sliver.any():
            part = _two_rings(tri, tri[sliver].ravel(), n_v)
            tri, shell, patch, _ = self._pass(points, tri, shell, patch, None, part, free, lonely, kept[3], context)
        return points, tri, shell, patch

    def _pass(self, points, tri, shell, patch, shift, part, lonely, still, kept, context):
        """One pass over the tiles shifted by ``shift`` tiles (None: all space is one tile), on the triangles ``part``
        (bool [f]; None: all): (tri, shell, patch, held) after it, ``held`` bool [v] the vertices it held fixed (those
        with a triangle outside the tiles' parts, and ``lonely``); ``still``: vertices that vertex moves leave in
        place. ``points`` is changed in place."""
        n_v = len(points)
        if shift is None:
            tile_of = np.zeros(n_v, dtype=np.int64)
        else:
            cell = np.floor((points - self.anchor) / self.tile - shift).astype(np.int64)
            tile_of = np.unique(cell, axis=0, return_inverse=True)[1].reshape(-1)
        tt = tile_of[tri]
        inside = (tt[:, 0] == tt[:, 1]) & (tt[:, 1] == tt[:, 2])
        if part is not None:
            inside &= part
        held = lonely.copy()
        held[tri[~inside]] = True
        flag = _needs_work(points, tri, self.spacing, SHORT_EDGE, SLIVER_ANGLE)
        work = np.unique(tt[inside & flag, 0])
        self.tiles += len(work)
        in_work = np.zeros(int(tile_of.max()) + 1, dtype=bool)
        in_work[work] = True
        mine = inside & in_work[tt[:, 0]]
        rows = np.flatnonzero(mine)
        rows = rows[np.argsort(tt[rows, 0], kind="stable")]
        bounds = np.append(np.searchsorted(tt[rows, 0], work), len(rows))
        tiles, todo, new_kept = [], [], {}
        for k in range(len(work)):
            r = rows[bounds[k] : bounds[k + 1]]
            tiles.append(_canonical(points, tri[r], shell[r], patch[r], held, still, *context[:2]))
            if tiles[-1][-1] not in kept:
                todo.append(k)
        if todo:
            self._clean_tiles(points, [tiles[k] for k in todo], held, still, kept, context)
        self.cleaned_tiles += len(todo)
        parts_t, parts_s, parts_p = [tri[~mine]], [shell[~mine]], [patch[~mine]]
        for verts, _, _, _, shells, patches, key in tiles:
            lt, ls, lp, lpos = kept[key]
            new_kept[key] = kept[key]
            points[verts] = lpos
            parts_t.append(verts[lt])
            parts_s.append(shells[ls])
            parts_p.append(patches[lp])
        kept.clear()
        kept.update(new_kept)
        return np.concatenate(parts_t), np.concatenate(parts_s), np.concatenate(parts_p), held

    def _clean_tiles(self, points, tiles, fixed, still, kept, context):
        """Cleans the canonical tiles ``tiles`` together (independent groups) and keeps each one's result."""
        big_shell, plane_of_patch, plane_eq = context
        v_off = np.concatenate([[0], np.cumsum([len(t[0]) for t in tiles])])
        s_off = np.concatenate([[0], np.cumsum([len(t[4]) for t in tiles])])
        p_off = np.concatenate([[0], np.cumsum([len(t[5]) for t in tiles])])
        u_points = np.concatenate([points[t[0]] for t in tiles])
        u_tri = np.concatenate([t[1] + v_off[k] for k, t in enumerate(tiles)])
        u_shell = np.concatenate([t[2] + s_off[k] for k, t in enumerate(tiles)])
        u_patch = np.concatenate([t[3] + p_off[k] for k, t in enumerate(tiles)])
        u_fixed = np.concatenate([fixed[t[0]] for t in tiles])
        u_still = np.concatenate([still[t[0]] for t in tiles])
        u_group = np.repeat(np.arange(len(tiles)), np.diff(v_off))
        u_size = np.where(np.concatenate([big_shell[t[4]] for t in tiles]), 7, 6)
        u_plane = np.concatenate([plane_of_patch[t[5]] for t in tiles])
        u_eq = np.concatenate([plane_eq[t[5]] for t in tiles])
        tri, shell, patch = clean_complex(
            u_points, u_tri, u_shell, u_patch, self.spacing, surface=(*self.surface, u_plane), plane_eq=u_eq,
            shell_size=u_size, fixed=u_fixed, group=u_group, still=u_still,
        )  # fmt: skip
        g = u_group[tri[:, 0]]
        order = np.argsort(g, kind="stable")
        bounds = np.searchsorted(g[order], np.arange(len(tiles) + 1))
        for k, t in enumerate(tiles):
            r = order[bounds[k] : bounds[k + 1]]
            kept[t[-1]] = (
                tri[r] - v_off[k],
                shell[r] - s_off[k],
                patch[r] - p_off[k],
                u_points[v_off[k] : v_off[k + 1]].copy(),
            )
