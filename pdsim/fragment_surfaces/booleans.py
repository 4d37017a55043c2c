"""The boolean build of fragment surfaces (steps 3a, 4 and 5 of the method in :mod:`pdsim.fragment_surfaces`):
the refined input surface, each region clipped by it with manifold3d's exact mesh booleans, and all clipped shells
joined into one complex whose cracks are triangulated once.

3a. **Refined input** (:func:`refine_surface`). Before the clip, the input surface is refined to edges of about h
    with manifold3d's ``refine_to_length`` (planar subdivision: planes stay planes, box edges and corners stay sharp;
    an input whose edges are all at most h is kept as it is). An unbroken body is this refined surface, so it bends
    with the particles everywhere, not only at the input's vertices.
4. **Clip** (:func:`clip_regions`). ``region ∩ input surface`` (manifold3d, every triangle of both meshes its own
   face id so that manifold3d keeps the triangulations) gives each region's shell. Faces from the input are outer
   faces, the rest are crack faces (told apart by manifold3d's original ids; the source triangle tells the region
   across a crack face and the input plane of an outer face). A region is clipped against the cut of the input by a
   box around it (:class:`InputCuts`), and a region whose vertices and triangles are unchanged since the last
   rebuild takes its previous clip.
5. **Shared complex** (:func:`shared_complex`). All shells' vertices that coincide (within 1e-9 h) become one vertex,
   and each crack is triangulated once: the lower region's crack triangles, reversed, replace the higher region's (a
   shell whose sides do not match keeps its own, checked). The two sides of a crack thus use the very same
   triangles. Then the slivers go (step 6, pdsim/fragment_surfaces/cleanup.py). Where two sides of a crack still
   differ (manifold3d resolves a crack point exactly on an input plane differently in the two booleans) those shells
   keep their own crack triangles.
"""

from __future__ import annotations

import hashlib

import manifold3d
import numpy as np
from scipy.spatial import cKDTree

from ..fragment_labels import connected_components
from .cleanup import clean_complex, shells_closed
from .edits import apply_edits, canonical_corners, complex_record

__all__ = ["InputCuts", "clip_regions", "input_manifold", "plane_groups", "refine_surface", "shared_complex"]


def plane_groups(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Plane id of each triangle, int64 shape [f]: triangles of vertices [m] [v, 3] / faces [f, 3] share an id when
    their planes agree (unit normal to 1e-9, offset to 1e-9 of the mesh size). Degenerate triangles get their own."""
    t = vertices[faces]
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 0.0
    n = n / np.where(ok, norm, 1.0)[:, None]
    size = float(np.ptp(vertices, axis=0).max()) or 1.0
    offset = np.einsum("ij,ij->i", n, t[:, 0]) / size
    key = np.round(np.concatenate([n, offset[:, None]], axis=1) * 1e9).astype(np.int64)
    key[~ok] = np.stack([np.arange(len(faces))[~ok]] * 4, axis=1) + (1 << 40)
    return np.unique(key, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)


def _manifold(vertices: np.ndarray, faces: np.ndarray):
    """The manifold3d solid of vertices [m] [v, 3] and triangles [f, 3], every triangle its own face id (so that
    manifold3d's output tells the source triangle of each face)."""
    f = np.ascontiguousarray(faces, dtype=np.uint64)
    mesh = manifold3d.Mesh64(
        np.ascontiguousarray(vertices, dtype=np.float64), f, face_id=np.arange(len(f), dtype=np.uint64)
    )
    return manifold3d.Manifold(mesh)


def refine_surface(vertices: np.ndarray, faces: np.ndarray, spacing: float):
    """The input surface refined to edges of about ``spacing`` h [m] with manifold3d's ``refine_to_length``: every
    edge longer than h is split into equal pieces and each triangle is filled by planar subdivision, so planes stay
    planes and sharp edges stay sharp (the surface is unchanged, only the triangles are smaller).

    Returns:
        (vertices [m] float64 [v, 3], triangles int64 [f, 3], plane id of each triangle int64 [f] (see
        :func:`plane_groups`, computed on the input triangles and inherited by their pieces)).
    """
    groups = plane_groups(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    t = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    if np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).max() <= spacing:  # fine already: the input itself
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), groups
    solid = _manifold(vertices, faces)
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"manifold3d rejects the input mesh ({solid.status()})")
    mesh = solid.refine_to_length(float(spacing)).to_mesh64()
    v = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    f = np.asarray(mesh.tri_verts, dtype=np.int64).reshape(-1, 3)
    origin = np.asarray(mesh.face_id, dtype=np.int64)
    return v, f, groups[origin]


def _merge_coincident(points: np.ndarray, owner: np.ndarray, tol: float) -> np.ndarray:
    """Global vertex id of each point [m] [p, 3]: points of different shells (``owner`` [p]) closer than ``tol`` [m]
    are one vertex; points of the same shell stay apart. Returns int64 [p]."""
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    pairs = pairs[owner[pairs[:, 0]] != owner[pairs[:, 1]]] if len(pairs) else pairs.reshape(0, 2)
    return connected_components(points.shape[0], pairs[:, 0], pairs[:, 1])


def input_manifold(surface, name: str):
    """The (refined) input surface ``surface`` = (vertices [m] [v, 3], triangles [f, 3], plane ids [f]) as a
    manifold3d solid marked as an original, every triangle its own face id.

    Raises:
        ValueError: manifold3d rejects the mesh (``name`` is the shape's name in the message).
    """
    v, f, _ = surface
    solid = _manifold(v, f)
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"'{name}': manifold3d rejects the input mesh ({solid.status()})")
    return solid.as_original()


CUT_TILE = 4.0  # edge of the finest tiles of the input's cuts [spacings] (see InputCuts)
CUT_MARGIN = 0.37  # gap between a region's bounding box and its cut's box [spacings] (off the grid's planes)


class InputCuts:
    """The (refined) input surface as a manifold3d solid, and its cuts by the boxes of a hierarchy of tiles, so that
    the clip of a small region costs what the input near it costs, not the whole input.

    Level l has tiles of edge ``T_l = CUT_TILE h 2^l``; the cut of tile i of level l is ``solid ∩ box`` with the box
    the tile grown by one tile on every side (3 T_l wide), made on first use from the cut of level l + 1 that holds
    that box (the one whose tile's start is nearest the box's: a box of level l, 3 T_l wide, then lies in that 6 T_l
    wide box of level l + 1), so a cut costs what its parent holds. A region is clipped against the cut of the
    finest level whose tiles are at least its bounding box grown by ``CUT_MARGIN`` h on every side, at the tile
    holding the grown box's lower corner (the box then lies inside the cut's box); regions as large as the input use
    the whole solid. As point sets ``region ∩ cut = region ∩ solid``; input triangles that cross a cut's box are split
    there, so the triangulation of the outer faces may differ from a clip against the whole solid. A cut keeps the
    solid's original id and face ids (manifold3d carries them through booleans), and its tolerance.

    Attributes:
        solid: the whole input solid (:func:`input_manifold`).
        cut_count: cuts made so far.
    """

    def __init__(self, surface, name: str, spacing: float):
        self.solid = input_manifold(surface, name)
        v = np.asarray(surface[0], dtype=np.float64)
        self.margin = CUT_MARGIN * float(spacing)
        self.tile = CUT_TILE * float(spacing)
        self.origin = v.min(axis=0) - self.margin
        self.extent = float(np.ptp(v, axis=0).max()) + 2.0 * self.margin
        self._cuts: dict = {}
        self.cut_count = 0

    def for_box(self, lo: np.ndarray, hi: np.ndarray):
        """The solid to clip a region with bounding box ``lo``, ``hi`` [m] against: a tile's cut or the solid."""
        lo, hi = lo - self.margin, hi + self.margin
        size = float((hi - lo).max())
        level = max(int(np.ceil(np.log2(max(size, 1e-300) / self.tile))), 0)
        return self._cut(level, np.floor((lo - self.origin) / (self.tile * 2.0**level)).astype(np.int64))

    def _cut(self, level: int, index: np.ndarray):
        """The cut of tile ``index`` [3] of ``level``, or the solid where a tile there spans the input."""
        t = self.tile * 2.0**level
        if t >= self.extent:
            return self.solid
        key = (level, *(int(i) for i in index))
        cut = self._cuts.get(key)
        if cut is None:
            corner = self.origin + (index - 1.0) * t  # the box: the tile grown by one tile, 3 t wide
            parent = self._cut(level + 1, np.floor((corner - self.origin) / (2.0 * t) + 0.5).astype(np.int64))
            box = manifold3d.Manifold.cube((3.0 * t,) * 3).translate(tuple(float(c) for c in corner))
            cut = (parent ^ box).set_tolerance(self.solid.get_tolerance())
            self._cuts[key] = cut
            self.cut_count += 1
        return cut


def _clip_key(rv: np.ndarray, rf: np.ndarray) -> bytes:
    """A digest of a region's vertices and triangles (bit for bit): equal digests, equal clips."""
    digest = hashlib.blake2b(digest_size=20)
    for a in (np.ascontiguousarray(rv, dtype=np.float64), np.ascontiguousarray(rf, dtype=np.int64)):
        digest.update(str(a.shape).encode())
        digest.update(a.tobytes())
    return digest.digest()


def clip_regions(
    regions,
    cuts: InputCuts,
    plane: np.ndarray,
    spacing: float,
    simplify: float,
    body_name: str,
    *,
    reuse: dict | None = None,
):
    """Region ∩ input surface for every region (step 4; manifold3d).

    Args:
        regions: per region (vertices [m] [v, 3], triangles [f, 3], region across each triangle [f]), from
            :func:`pdsim.fragment_surfaces.regions.partition_regions`.
        cuts: the input surface and its cuts (:class:`InputCuts`); plane: plane id of each input triangle [f_in].
        spacing: particle spacing h [m]; simplify: manifold3d's simplification tolerance [spacings] (0: none).
        body_name: the body's name, for the error message.
        reuse: None, or the clips of the previous call, by :func:`_clip_key` of their region; a region whose vertices
            and triangles are those of a previous region, bit for bit, takes that clip (the same booleans on the
            same input give the same result). The dict is replaced by this call's clips.

    Returns:
        (pieces, clips made): per region (vertices [m] [v, 3], triangles [f, 3], region across each triangle [f]
        (-1 on outer faces), plane id of each triangle [f] (-1 on crack faces)), and how many regions were clipped
        (the others reused).

    Raises:
        RuntimeError: a region is not a manifold.
    """
    solid_id = cuts.solid.original_id()
    empty = (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
    pieces, made, kept = [], 0, {}
    for k, (rv, rf, racross) in enumerate(regions):
        if rf.shape[0] == 0:
            pieces.append(empty)
            continue
        key = None if reuse is None else _clip_key(rv, rf)
        clip = None if reuse is None else reuse.get(key)
        if clip is None:
            clip = _clip(rv, rf, cuts, solid_id, spacing, simplify, f"region {k} of '{body_name}'")
            made += 1
        if key is not None:
            kept[key] = clip
        if clip is None or clip[1].size == 0:
            pieces.append(empty)
            continue
        points, tri, outer, src = clip
        across = np.where(outer, -1, racross[np.where(outer, 0, np.minimum(src, len(racross) - 1))])
        planes = np.where(outer, plane[np.where(outer, np.minimum(src, len(plane) - 1), 0)], -1)
        pieces.append((points, tri, across, planes))
    if reuse is not None:
        reuse.clear()
        reuse.update(kept)
    return pieces, made


def _clip(rv, rf, cuts: InputCuts, solid_id: int, spacing: float, simplify: float, what: str):
    """One region (vertices [m] [v, 3], triangles [f, 3]) ∩ the input: (points [m] [p, 3], triangles [t, 3], outer
    flag [t], source triangle [t]: an input triangle on outer faces, a region triangle on crack faces)."""
    region_solid = _manifold(rv, rf)
    if region_solid.status() != manifold3d.Error.NoError:
        raise RuntimeError(f"{what} is not a manifold ({region_solid.status()})")
    piece = region_solid ^ cuts.for_box(rv.min(axis=0), rv.max(axis=0))
    if simplify > 0.0:
        piece = piece.simplify(simplify * spacing)
    piece = piece.to_mesh64()
    tri = np.asarray(piece.tri_verts, dtype=np.int64).reshape(-1, 3)
    run_start = np.asarray(piece.run_index, dtype=np.int64) // 3
    run_id = np.asarray(piece.run_original_id, dtype=np.int64)
    outer = np.repeat(run_id == solid_id, np.diff(run_start))
    src = np.asarray(piece.face_id, dtype=np.int64)
    return np.asarray(piece.vert_properties, dtype=np.float64)[:, :3], tri, outer, src


def shared_complex(
    pieces, k_count: int, surface, spacing: float, *, simplify: float, clean: bool, record=None, tiles=None,
    left_out=None,
):  # fmt: skip
    """All regions' shells as one complex (vertices shared between shells), crack faces shared by both sides and
    slivers removed (steps 5-6).

    Args:
        pieces: per region, from :func:`clip_regions`; k_count: number of regions.
        surface: the (refined) input surface (vertices [m], triangles, plane id per triangle).
        spacing: particle spacing h [m].
        simplify: > 0 when the pieces were simplified: the sides are then kept independent (no sharing, no clean-up).
        clean: remove slivers (:func:`pdsim.fragment_surfaces.cleanup.clean_complex`).
        record: None, or a dict holding the last clean-up's record (empty: none yet): its edits are applied where the
            complex is unchanged before the clean-up runs (pdsim/fragment_surfaces/edits.py), and the dict is replaced
            by this clean-up's record (emptied when no clean-up ran or it failed).
        tiles: None, or the body's :class:`pdsim.fragment_surfaces.tiles.TiledCleanup`: the clean-up then runs tile
            by tile (``record`` is not used).
        left_out: None, or a region without a shell (its piece empty): the crack faces towards it are one-sided.

    Returns:
        (points [m] [p, 3], tri [f, 3], shell [f], crack flag [f], patch [f], shared, clean_failed); a patch is an
        input plane or the crack between one pair of regions. ``clean_failed`` is True when the clean-up left a
        shell open (its result is then dropped), False when it succeeded, None when it did not run.
    """
    vcount = np.array([p[0].shape[0] for p in pieces], dtype=np.int64)
    fcount = np.array([p[1].shape[0] for p in pieces], dtype=np.int64)
    voff = np.concatenate([[0], np.cumsum(vcount)])
    points = np.concatenate([p[0] for p in pieces])
    tri = np.concatenate([p[1] for p in pieces]) + np.repeat(voff[:-1], fcount)[:, None]
    shell = np.repeat(np.arange(k_count), fcount)
    across = np.concatenate([p[2] for p in pieces])
    planes = np.concatenate([p[3] for p in pieces])
    crack = (across >= 0).astype(np.int32)
    if len(tri) == 0:  # no region meets the input (e.g. every particle left out as a chip)
        return points, tri, shell, crack, np.zeros(0, dtype=np.int64), True, None
    plane_count = int(surface[2].max()) + 1

    def patches(shell, across, planes):
        lo, hi = np.minimum(shell, across), np.maximum(shell, across)
        patch = np.where(across >= 0, plane_count + lo * k_count + hi, planes)
        return np.unique(patch, return_inverse=True)[1].reshape(-1)

    if simplify > 0.0:  # independent sides: no sharing, no clean-up
        return points, tri, shell, crack, patches(shell, across, planes), False, None
    gid = _merge_coincident(points, np.repeat(np.arange(k_count), vcount), 1e-9 * spacing)
    used, gid = np.unique(gid, return_inverse=True)
    first = np.zeros(len(used), dtype=np.int64)
    first[gid[::-1]] = np.arange(len(gid))[::-1]
    points = points[first]
    tri = gid[tri]
    # One triangulation per crack: the lower region's triangles, reversed, replace the higher region's.
    primary = (across >= 0) & (shell < across) & (across != (-1 if left_out is None else left_out))
    secondary = (across >= 0) & (shell > across)
    copies = tri[primary][:, [0, 2, 1]]
    tri2 = np.concatenate([tri[~secondary], copies])
    shell2 = np.concatenate([shell[~secondary], across[primary]])
    across2 = np.concatenate([across[~secondary], shell[primary]])
    planes2 = np.concatenate([planes[~secondary], planes[primary]])
    closed = shells_closed(tri2, shell2, len(points))
    if not closed.all():  # sides that do not match: those shells keep their own crack triangles
        bad = ~closed
        drop_copy = np.concatenate([np.zeros((~secondary).sum(), bool), bad[across[primary]]])
        restore = secondary & bad[shell]
        tri2 = np.concatenate([tri2[~drop_copy], tri[restore]])
        shell2 = np.concatenate([shell2[~drop_copy], shell[restore]])
        across2 = np.concatenate([across2[~drop_copy], across[restore]])
        planes2 = np.concatenate([planes2[~drop_copy], planes[restore]])
        if not shells_closed(tri2, shell2, len(points)).all():
            return (
                np.concatenate([p[0] for p in pieces]),
                np.concatenate([p[1] for p in pieces]) + np.repeat(voff[:-1], fcount)[:, None],
                shell,
                crack,
                patches(shell, across, planes),
                False,
                None,
            )
    patch = patches(shell2, across2, planes2)
    previous = dict(record) if record else None
    if record is not None:
        record.clear()
    if clean:
        is_crack_patch = np.zeros(int(patch.max()) + 1, dtype=bool)
        is_crack_patch[patch[across2 >= 0]] = True
        plane_of_patch = np.full(len(is_crack_patch), -1, dtype=np.int64)
        plane_of_patch[patch[across2 < 0]] = planes2[across2 < 0]
        if tiles is not None:
            points3, tri3, shell3, patch3 = tiles.clean(points, tri2, shell2, patch, plane_of_patch)
            if shells_closed(tri3, shell3, len(points3)).all():
                crack3 = is_crack_patch[patch3].astype(np.int32)
                return points3, canonical_corners(tri3), shell3, crack3, patch3, True, False
            return points, tri2, shell2, (across2 >= 0).astype(np.int32), patch, True, True
        raw = (points.copy(), tri2, shell2, patch, np.arange(len(tri2)), None, 0, 0)
        start = raw if previous is None else apply_edits(previous, *raw[:4], spacing)
        for first in (start, raw) if previous is not None else (raw,):
            points = first[0].copy()
            if first[6] < 0:  # the last rebuild's raw complex: its clean-up's result
                tri3, shell3, patch3, origin3 = first[1:5]
            else:
                tri3, shell3, patch3, origin3 = clean_complex(
                    points,
                    *first[1:4],
                    spacing,
                    crack_patch=is_crack_patch,
                    surface=(*surface, plane_of_patch),
                    planes_from=(raw[0], tri2, patch),
                    origin=first[4],
                    settled=first[5],
                )
            if shells_closed(tri3, shell3, len(points)).all():
                if record is not None:
                    record.update(complex_record(raw[:4], (points, tri3, shell3, patch3), origin3))
                # crack flag of each surviving triangle: look it up through its patch; each triangle listed from
                # its smallest vertex id (the clean-up's flips leave either corner first)
                crack3 = is_crack_patch[patch3].astype(np.int32)
                return points, canonical_corners(tri3), shell3, crack3, patch3, True, False
        points = raw[0]
        return points, tri2, shell2, (across2 >= 0).astype(np.int32), patch, True, True
    return points, tri2, shell2, (across2 >= 0).astype(np.int32), patch, True, None
