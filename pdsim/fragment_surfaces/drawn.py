"""The drawn surface (step 9 of the method in :mod:`pdsim.fragment_surfaces`): the shells as drawn in one frame.

Material that stretches or crumbles without separating (particles with damage below the chip threshold whose
neighbours move apart by up to their spacing) stretches and squeezes the triangles embedded in it. Each frame, edges
drawn longer than 3 h are split at their rest-space midpoints (:func:`_split_long_edges`: a triangle with one, two or
three long sides splits in two, three or four; conforming, so shells stay closed), and the new vertices are embedded
in the particles exactly as the shells' vertices (their own MLS shape functions), so the drawn surface keeps
following the material at about the particle spacing; this repeats until no edge is longer than 3 h. Then, if the
crack faces hold a triangle with an angle under 5 degrees, rounds of edge flips (as in step 6, now at the current
positions) and of vertex moves (step 6's relaxation, with no plane constraint, turns of up to 60 degrees and steps
down to a tenth of the way; then the obtuse corners of flat caps moved away from their long side, and the relaxation
again) remove them before the frame is written (:func:`_unsliver`). Added vertices still at a sliver (crushed
material brings midpoints next to each other or onto a line between their neighbours) merge into a neighbour by the
edge collapses of step 6, in drawn space, and the flips and moves run again (up to three rounds); an added vertex
left with three triangles at a sliver (inside the triangle of its neighbours) is then removed
(:func:`_drop_three_fans`). Splits and clean-up alternate up to six times. This depends on the frame's positions
only (a resumed run draws the same). The faces and vertex count change only on frames that need it. Each round of
flips, moves or merges works only on the triangles around the corners of its candidates (slivers; for merges also
the short sides at added vertices), in their own vertex numbering, which decides as a round over the whole surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import vstack

from .cleanup import (
    SHORT_EDGE,
    SLIVER_ANGLE,
    _collapse_round,
    _flip_round,
    _relax_round,
    _undirected_edges,
    triangle_angles,
)

__all__ = ["DrawnSurface", "drawn_surface", "longest_edge"]

DEFORMED_ROUNDS = 16  # rounds of edge flips, then of vertex moves, per frame against slivers made by the motion
MAX_DRAWN_EDGE = 3.0  # drawn edges longer than this [spacings] are split at their rest-space midpoints
SPLIT_ROUNDS = 4  # rounds of edge splits per pass (each halves the longest edge)
REFINE_PASSES = 6  # passes of splits and sliver clean-up per frame
UNSLIVER_ROUNDS = 3  # rounds of flips, moves and merges of added vertices per clean-up


@dataclass
class DrawnSurface:
    """A surface as drawn in one frame (:func:`drawn_surface`).

    Attributes:
        points: vertex positions [m], float64 [vertex_count + added, 3]: the shells' vertices, then the vertices
            added on split edges.
        faces: triangles int32 [f, 3] into ``points``.
        face_parent: the face of :attr:`FragmentSurfaces.faces` each triangle comes from (shell, fragment, crack
            flag), int [f].
        added: None, or the added vertices as (rest points [m] [a, 3], shell [a], MLS shape functions), for
            :meth:`FragmentSurfaces.vertex_velocities` ``at=``.
    """

    points: np.ndarray
    faces: np.ndarray
    face_parent: np.ndarray
    added: tuple | None


def drawn_surface(
    x, faces, rest_vertices, vertex_shell, face_shell, face_patch, face_crack, spacing, embed, place
) -> DrawnSurface:
    """The surface to draw in one frame: the shells' vertices at ``x``; edges drawn longer than ``MAX_DRAWN_EDGE``
    spacings split at their rest-space midpoints, which are embedded in the particles like every vertex; slivers made
    by the motion flipped away and relaxed (their vertices move towards their neighbours). Depends on the frame's
    positions only, not on earlier frames.

    Args:
        x: the shells' vertices at this frame [m], float64 [vertex_count, 3].
        faces: the shells' triangles, int [f, 3]; face_shell, face_patch, face_crack: shell, patch and crack flag
            (1: crack face) of each, int [f].
        rest_vertices: the shells' vertices in rest space [m], float64 [vertex_count, 3]; vertex_shell: shell of each
            vertex, int [vertex_count].
        spacing: particle spacing h [m].
        embed: ``embed(rest points [q, 3], shell [q])`` -> their MLS shape functions, sparse [q, particle_count].
        place: ``place((rest points, shell, shape functions))`` -> the embedded points at this frame [m] [q, 3].
    """
    faces = faces.astype(np.int64)
    parent = np.arange(len(faces))
    rest, shell = rest_vertices, vertex_shell
    phis = []
    limit = MAX_DRAWN_EDGE * spacing
    for _ in range(REFINE_PASSES):
        for _ in range(SPLIT_ROUNDS):
            out = _split_long_edges(x, faces, limit)
            if out is None:
                break
            lo, hi, faces, from_face = out
            mid_rest = 0.5 * (rest[lo] + rest[hi])
            mid_shell = shell[lo]
            at = (mid_rest, mid_shell, embed(mid_rest, mid_shell))
            phis.append(at[2])
            x = np.concatenate([x, place(at)])
            rest, shell = np.concatenate([rest, mid_rest]), np.concatenate([shell, mid_shell])
            parent = parent[from_face]
        faces, parent = _unsliver(x, faces, parent, face_shell, face_patch, face_crack, len(rest_vertices), spacing)
        if longest_edge(x, faces) <= limit:
            break
    added = None
    if phis:
        n0 = len(rest_vertices)
        keep = np.ones(len(x), dtype=bool)  # added vertices that a removal left without triangles go
        keep[n0:] = np.bincount(faces.ravel(), minlength=len(x))[n0:] > 0
        new_index = np.cumsum(keep) - 1
        faces, x = new_index[faces], x[keep]
        k = keep[n0:]
        added = (rest[n0:][k], shell[n0:][k], vstack(phis).tocsr()[np.flatnonzero(k)])
    return DrawnSurface(x, faces.astype(np.int32), parent, added)


def _unsliver(x, faces, parent, shell_of, patch_of, crack_of, first_added, spacing):
    """Against the crack triangles under SLIVER_ANGLE of the drawn ``faces`` (face i descends from the shells' face
    ``parent[i]``, whose shell, patch and crack flag are ``shell_of``, ``patch_of``, ``crack_of`` [parent]), up to
    UNSLIVER_ROUNDS times: edge flips, vertex moves (in place on ``x`` [m]), then edge collapses (``spacing`` h [m])
    that merge added vertices (index >= ``first_added``) into a neighbour; last, added vertices of three triangles at
    such slivers are removed (:func:`_drop_three_fans`). Returns (faces, parent)."""
    face_shell, face_patch = shell_of[parent], patch_of[parent]
    free = np.full((int(patch_of.max()) + 1, 4), np.nan)  # no input plane holds in deformed space
    movable = np.arange(len(x)) >= first_added  # only added vertices merge into a neighbour
    for _ in range(UNSLIVER_ROUNDS):
        crack = crack_of[parent] == 1
        if not crack.any() or triangle_angles(x, faces[crack]).min() >= SLIVER_ANGLE:
            return faces, parent
        amin = triangle_angles(x, faces).min(axis=1)  # kept up to date on the triangles the rounds change
        for _ in range(DEFORMED_ROUNDS):
            sub = _near_slivers(faces, amin, len(x))
            if sub is None:
                break
            verts, local = _compact(faces[sub])
            out, flipped = _flip_round(x[verts], local, face_shell[sub], face_patch[sub], SLIVER_ANGLE)
            if flipped == 0:
                break
            out = verts[out]
            changed = sub[(out != faces[sub]).any(axis=1)]
            faces = faces.copy()
            faces[sub] = out
            amin[changed] = triangle_angles(x, faces[changed]).min(axis=1)
        for caps in (False, True, False):
            for _ in range(DEFORMED_ROUNDS):
                sub = _near_slivers(faces, amin, len(x))
                if sub is None:
                    break
                verts, local = _compact(faces[sub])
                xs = x[verts]
                moved = _relax_round(
                    xs,
                    local,
                    face_patch[sub],
                    free,
                    SLIVER_ANGLE,
                    max_turn=60.0,
                    steps=(0.1, 0.25, 0.5, 1.0),
                    caps=caps,
                )
                if moved == 0:
                    break
                x[verts] = xs
                amin[sub] = triangle_angles(x, faces[sub]).min(axis=1)  # moved vertices are slivers' corners
        # what is left: added vertices that crushed material brought next to others (needles) or onto a line
        # between them (caps) merge into a neighbour (edge collapses as in step 6)
        merged = 0
        for _ in range(DEFORMED_ROUNDS):
            sub = _near_merges(x, faces, movable, spacing)
            if sub is None:
                break
            verts, local = _compact(faces[sub])
            new, keep, collapsed = _collapse_round(
                x[verts],
                local,
                face_shell[sub],
                face_patch[sub],
                spacing,
                SHORT_EDGE,
                SLIVER_ANGLE,
                movable=movable[verts],
                shell_size=_small_shell_sizes(faces, face_shell),
            )
            if collapsed == 0:
                break
            merged += collapsed
            faces = faces.copy()
            faces[sub] = verts[new]
            whole = np.ones(len(faces), dtype=bool)
            whole[sub] = keep
            faces, parent = faces[whole], parent[whole]
            face_shell, face_patch = face_shell[whole], face_patch[whole]
        if merged == 0:
            break
    return _drop_three_fans(x, faces, parent, face_patch, first_added, SLIVER_ANGLE)


def _around(faces, flag, vertex_count):
    """Ids (ascending) of the triangles of ``faces`` [f, 3] that hold a vertex of a ``flag``-ged triangle (bool
    [f]; ``vertex_count`` vertices)."""
    seed = np.zeros(vertex_count, dtype=bool)
    seed[faces[flag]] = True
    return np.flatnonzero(seed[faces].any(axis=1))


def _near_slivers(faces, amin, vertex_count):
    """Ids (ascending) of the triangles a round of flips or vertex moves works on: those holding a vertex of a
    triangle whose smallest angle ``amin`` [f] [degrees] is under SLIVER_ANGLE; None when there is no such triangle.
    They hold every sliver with its twins and every triangle around its corners (so every edge a flip could create
    and every corner's neighbours), so a round there decides as a round over all ``faces`` and changes nothing
    else."""
    sliver = amin < SLIVER_ANGLE
    if not sliver.any():
        return None
    return _around(faces, sliver, vertex_count)


def _near_merges(x, faces, movable, spacing):
    """Ids (ascending) of the triangles a round of merges (edge collapses of ``movable`` vertices) works on: those
    holding a vertex of a sliver or of a triangle with a side under SHORT_EDGE spacings (``spacing`` h [m]), that
    holds a ``movable`` vertex (bool [v]); every candidate collapse of the round lies there with the triangles
    around both its ends (its zone, link and turn). None when there is none."""
    t = x[faces]
    side = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2).min(axis=1)
    flag = (side < SHORT_EDGE * spacing) | (triangle_angles(x, faces).min(axis=1) < SLIVER_ANGLE)
    flag &= movable[faces].any(axis=1)
    if not flag.any():
        return None
    return _around(faces, flag, len(x))


def _small_shell_sizes(faces, face_shell):
    """The vertex count of each shell (int [shell count]) where it may be 6 or less, else its face count: a closed,
    oriented shell of 6 vertices or less is a sphere of at most 8 faces, so shells of more faces have more than 6
    vertices (all that the collapses' link condition asks)."""
    size = np.bincount(face_shell, minlength=int(face_shell.max()) + 1) if len(face_shell) else np.zeros(0, int)
    small = np.flatnonzero((size > 0) & (size <= 8))
    if small.size:
        pick = np.isin(face_shell, small)
        pairs = np.unique(face_shell[pick][:, None] * (int(faces.max()) + 1) + faces[pick])
        size[small] = np.bincount(pairs // (int(faces.max()) + 1), minlength=len(size))[small]
    return size


def _compact(tri):
    """(the vertex ids of triangles ``tri`` [k, 3], ascending; ``tri`` in those ids' positions), so that a round
    works on arrays of the triangles' own size, not of the whole surface's vertex count."""
    verts, local = np.unique(tri, return_inverse=True)
    return verts, local.reshape(tri.shape)


def _drop_three_fans(x, faces, parent, face_patch, first_added, sliver_angle):
    """Removes added vertices (index >= ``first_added``) that sit at a sliver with exactly three triangles around
    them, all of one patch: the fan (v, a, b), (v, b, c), (v, c, a) becomes the triangle (a, b, c) (same
    orientation and parent) when that triangle's smallest angle is larger than the fan's and the surface holds no
    triangle on a, b, c yet. Such a vertex lies inside the triangle of its neighbours (a split followed by flips)
    and adds no detail. Returns (faces, parent); the removed vertices keep no triangle."""
    n = len(x)
    amin = triangle_angles(x, faces).min(axis=1)
    valence = np.bincount(faces.ravel(), minlength=n)
    cand = np.unique(faces[amin < sliver_angle])
    cand = cand[(cand >= first_added) & (valence[cand] == 3)]
    if cand.size == 0:
        return faces, parent
    is_cand = np.zeros(n, dtype=bool)
    is_cand[cand] = True
    hit = is_cand[faces]
    shared = hit.sum(axis=1) > 1  # fans that share a triangle are left alone
    f_idx, corner = np.nonzero(hit)
    v = faces[f_idx, corner]
    order = np.argsort(v, kind="stable")
    f_idx, corner, v = f_idx[order].reshape(-1, 3), corner[order].reshape(-1, 3), v[order].reshape(-1, 3)
    p = faces[f_idx, (corner + 1) % 3]
    q = faces[f_idx, (corner + 2) % 3]
    a, b = p[:, 0], q[:, 0]
    c = p.sum(axis=1) - a - b
    # A closed fan: the sides p -> q form the cycle a -> b -> c -> a.
    cycle = np.sort(q, axis=1) == np.sort(np.stack([b, c, a], axis=1), axis=1)
    ok = cycle.all(axis=1) & ~shared[f_idx].any(axis=1)
    ok &= (face_patch[f_idx] == face_patch[f_idx[:, :1]]).all(axis=1)
    new = np.stack([a, b, c], axis=1)
    ok &= triangle_angles(x, new).min(axis=1) > amin[f_idx].min(axis=1)
    rows = np.concatenate([np.sort(faces, axis=1), np.sort(new, axis=1)])
    row_id = np.unique(rows, axis=0, return_inverse=True)[1].reshape(-1)
    exists = np.isin(row_id[len(faces) :], row_id[: len(faces)])
    ok &= ~exists
    if not ok.any():
        return faces, parent
    drop = np.zeros(len(faces), dtype=bool)
    drop[f_idx[ok].ravel()] = True
    faces = np.concatenate([faces[~drop], new[ok]])
    parent = np.concatenate([parent[~drop], parent[f_idx[ok, 0]]])
    return faces, parent


def longest_edge(x: np.ndarray, faces: np.ndarray) -> float:
    """Longest edge [m] of triangles ``faces`` [f, 3] at points ``x`` [v, 3] (0 without triangles)."""
    if len(faces) == 0:
        return 0.0
    t = x[faces]
    return float(np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).max())


def _split_long_edges(x: np.ndarray, faces: np.ndarray, limit: float):
    """Splits every edge longer than ``limit`` [m] at points ``x`` [v, 3] at its midpoint (new vertices v, v + 1,
    ... in edge order), keeping the triangulation conforming and every triangle's orientation: a triangle with one
    long side splits in two, with two in three (the quad left beside the corner between them split along its
    shorter diagonal, measured at ``x`` with the new vertices at the edges' midpoints), with three in four.

    Returns:
        None when no edge is longer than ``limit``; else (low ends [e], high ends [e] of the split edges,
        triangles int64 [f', 3], the input triangle of each [f'])."""
    n = len(x)
    lo, hi, side = _undirected_edges(faces, n)
    long = np.linalg.norm(x[lo] - x[hi], axis=1) > limit
    if not long.any():
        return None
    new_id = np.full(len(lo), -1, dtype=np.int64)
    new_id[long] = n + np.arange(int(long.sum()))
    m = new_id[side]  # m[i, j]: new vertex on side j (corners j, j + 1) of triangle i, or -1
    count = (m >= 0).sum(axis=1)
    # Rotate each triangle so that its marked sides come first: one mark on side 0, two on sides 0 and 1.
    r = np.where(count == 1, np.argmax(m >= 0, axis=1), np.where(count == 2, (np.argmin(m >= 0, axis=1) + 1) % 3, 0))
    idx = (np.arange(3)[None, :] + r[:, None]) % 3
    c = np.take_along_axis(faces, idx, axis=1)
    mm = np.take_along_axis(m, idx, axis=1)
    mid = 0.5 * (x[lo[long]] + x[hi[long]])
    xx = np.concatenate([x, mid])
    out, src = [faces[count == 0]], [np.flatnonzero(count == 0)]
    one = np.flatnonzero(count == 1)
    c0, c1, c2, m0 = c[one, 0], c[one, 1], c[one, 2], mm[one, 0]
    out += [np.stack([c0, m0, c2], 1), np.stack([m0, c1, c2], 1)]
    src += [one, one]
    two = np.flatnonzero(count == 2)
    c0, c1, c2, m0, m1 = c[two, 0], c[two, 1], c[two, 2], mm[two, 0], mm[two, 1]
    diag_a = np.linalg.norm(xx[c0] - xx[m1], axis=1) <= np.linalg.norm(xx[m0] - xx[c2], axis=1)
    out += [
        np.stack([m0, c1, m1], 1),
        np.where(diag_a[:, None], np.stack([c0, m0, m1], 1), np.stack([c0, m0, c2], 1)),
        np.where(diag_a[:, None], np.stack([c0, m1, c2], 1), np.stack([m0, m1, c2], 1)),
    ]
    src += [two, two, two]
    three = np.flatnonzero(count == 3)
    c0, c1, c2, m0, m1, m2 = (c[three, 0], c[three, 1], c[three, 2], mm[three, 0], mm[three, 1], mm[three, 2])
    out += [np.stack([c0, m0, m2], 1), np.stack([m0, c1, m1], 1), np.stack([m2, m1, c2], 1), np.stack([m0, m1, m2], 1)]
    src += [three] * 4
    return lo[long], hi[long], np.concatenate(out).astype(np.int64), np.concatenate(src)
