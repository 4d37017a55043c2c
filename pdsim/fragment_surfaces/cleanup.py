"""Sliver clean-up of the shell complex (step 6 of the method in :mod:`pdsim.fragment_surfaces`), and the mesh
checks the surfaces share.

The complex holds all fragments' shells at once: vertices shared between shells where they coincide, so the two sides
of a crack use the same vertices and the same triangles (pdsim/fragment_surfaces/booleans.py builds it). Patches: an
outer face's patch is the plane of its input triangle (coplanar input triangles share one); a crack face's patch is
its pair of regions.

The booleans cut triangles near their corners and marching tetrahedra puts crack points near grid vertices, which
leaves needles and caps. Rounds of edge collapses (:func:`_collapse_round`: edges shorter than 0.3 h and the shortest
side of every triangle with an angle under 5 degrees) and edge flips (:func:`_flip_round`: the longest side of such a
triangle, inside one patch; a flip never creates an edge the shell has in either direction, and one round never
creates the same edge twice) remove them, so both sides of a crack change alike. A collapse moves a vertex onto a
neighbour only if the neighbour lies on every input plane of the vertex (its cracks may slide: a crack's rim moves
along a box edge or across a face, both sides alike), so outer faces stay exactly on the input surface, sharp edges
and corners stay put and the volumes still add up exactly; the link condition keeps every shell a closed 2-manifold.
What the link condition blocks (needles at crack junctions on the outer surface, where the ends of a short edge have
three common neighbours) is then relaxed (:func:`_relax_round`): the vertices of the remaining slivers move towards
the mean of their neighbours, projected onto their input planes (a rim vertex slides in its face or along its
crease, a corner stays), when that widens the smallest angle around them and turns no triangle by more than 30
degrees; moves change no connectivity, so the shells stay closed and still partition the solid. Faceted curved
inputs (a sphere whose facets are smaller than h) keep more slivers, since no vertex may leave its facet.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

__all__ = ["SHORT_EDGE", "SLIVER_ANGLE", "clean_complex", "shells_closed", "triangle_angles"]

SLIVER_ANGLE = 5.0  # triangles with a smaller angle [degrees] are slivers
RELAX_TURN = 30.0  # largest turn [degrees] of a triangle when the rest-space clean-up moves a vertex
SHORT_EDGE = 0.3  # edges shorter than this many spacings are collapsed
_MAX_CLEAN_ROUNDS = 40


def _corner_angles(t: np.ndarray) -> np.ndarray:
    """Interior angles [degrees], float64 shape [f, 3], of triangles given by their corners [m] [f, 3, 3] (angle at
    corner i)."""
    out = np.empty(t.shape[:2], dtype=np.float64)
    side = [t[:, (i + 1) % 3] - t[:, i] for i in range(3)]  # side i runs from corner i to corner i + 1
    length = [np.sqrt((e * e).sum(axis=1)) for e in side]
    for i in range(3):  # corner i: between side i and the reverse of side i + 2
        j = (i + 2) % 3
        cos = -np.einsum("ij,ij->i", side[i], side[j]) / np.maximum(length[i] * length[j], 1e-300)
        out[:, i] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def triangle_angles(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Interior angles [degrees], float64 shape [f, 3] (angle at corner i of each triangle of ``tri`` [f, 3])."""
    return _corner_angles(points[tri])


def shells_closed(tri: np.ndarray, shell: np.ndarray, vertex_count: int) -> np.ndarray:
    """Per shell, whether its triangles form a closed, consistently oriented surface: every directed edge occurs
    once and its reverse once. ``tri`` [f, 3] global vertex ids, ``shell`` [f] shell index; returns bool
    [shell.max() + 1] (True for shells without triangles)."""
    count = int(shell.max()) + 1 if len(shell) else 0
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    s = np.tile(shell, 3)
    key = (s * vertex_count + a) * vertex_count + b
    rev = (s * vertex_count + b) * vertex_count + a
    order = np.argsort(key)
    sk = key[order]
    dup = np.zeros(len(sk), dtype=bool)  # the directed edge occurs more than once
    same = sk[1:] == sk[:-1]
    dup[1:] |= same
    dup[:-1] |= same
    bad_edge = np.zeros(len(key), dtype=bool)
    bad_edge[order] = dup
    pos = np.minimum(np.searchsorted(sk, rev), max(len(sk) - 1, 0))
    if len(sk):
        bad_edge |= sk[pos] != rev  # its reverse is missing
    bad = np.zeros(count, dtype=bool)
    bad[s[bad_edge]] = True
    return ~bad


def _undirected_edges(tri: np.ndarray, vertex_count: int):
    """Unique undirected edges of ``tri`` [f, 3]: (low ends [e], high ends [e], edge of each triangle side [f, 3]);
    side j of a triangle joins its corners j and j + 1."""
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    key = np.minimum(a, b) * vertex_count + np.maximum(a, b)
    uk, inverse = np.unique(key, return_inverse=True)
    return uk // vertex_count, uk % vertex_count, inverse.reshape(3, -1).T


def _on_planes(inc, plane_eq, points, src, dst, spacing):
    """Bool [c]: ``dst`` lies (within 1e-7 h) on the plane of every input-plane patch of ``src`` (``inc``: vertex x
    patch incidence, ``plane_eq`` [p, 4] unit normal and offset of each patch, NaN for crack patches)."""
    rows = inc[src].tocoo()
    eq = plane_eq[rows.col]
    dist = np.abs(np.einsum("ij,ij->i", eq[:, :3], points[dst[rows.row]]) - eq[:, 3])
    bad = ~np.isnan(eq[:, 0]) & ~(dist <= 1e-7 * spacing)
    out = np.ones(len(src), dtype=bool)
    out[rows.row[bad]] = False
    return out


def _rank_in_group(group_of: np.ndarray) -> np.ndarray:
    """Int [n]: each item's index among the items of its group, for ``group_of`` [n] non-decreasing (the items of
    one group consecutive)."""
    return np.arange(len(group_of)) - np.searchsorted(group_of, group_of)


def _independent_choice(rows, cols, prio, count, size) -> np.ndarray:
    """Luby-style choice of operations whose zones do not meet: operation ``rows[i]`` touches item ``cols[i]`` (items
    0..size-1), ``prio`` [count] orders them (smaller first, distinct). In passes, every open operation that is the
    smallest on all its items wins, and the items of the winners close their rivals. Returns bool [count]."""
    chosen = np.zeros(count, dtype=bool)
    open_ = np.ones(count, dtype=bool)
    blocked = np.zeros(size, dtype=bool)
    while open_.any():
        live = open_[rows]
        best = np.full(size, np.inf)
        np.minimum.at(best, cols[live], prio[rows[live]])
        win = open_ & (np.bincount(rows[best[cols] != prio[rows]], minlength=count) == 0)
        chosen |= win
        blocked[cols[win[rows]]] = True
        open_ &= np.bincount(rows[blocked[cols]], minlength=count) == 0
    return chosen


def _collapse_round(
    points,
    tri,
    shell,
    patch,
    spacing,
    short_edge,
    sliver_angle,
    plane_eq=None,
    movable=None,
    shell_size=None,
    fixed=None,
    group=None,
):
    """One round of edge collapses on the complex (see :func:`clean_complex`). Returns (triangles after the round
    [f, 3], mask [f] of the triangles that keep an area, number of collapses; 0: nothing left to do). With
    ``movable`` (bool [v]) only those vertices may move onto a neighbour; with ``fixed`` (bool [v]) no edge with a
    fixed end collapses, nor one that narrows a triangle holding a fixed vertex into a sliver. ``shell_size``:
    None, or the vertex count of each shell (int [shell count]) when ``tri`` is part of a larger complex (default:
    counted in ``tri``). ``group``: None, or the group of each vertex (int [v], non-decreasing in the vertex id),
    whose ties are broken within the group (see :func:`clean_complex`)."""
    n_v = points.shape[0]
    lo, hi, side_edge = _undirected_edges(tri, n_v)
    length = np.linalg.norm(points[lo] - points[hi], axis=1)
    cand = length < short_edge * spacing
    angles = triangle_angles(points, tri)
    sliver = angles.min(axis=1) < sliver_angle
    if sliver.any():  # the shortest side of every sliver (needles and caps), up to one spacing
        side_len = length[side_edge[sliver]]
        shortest = side_edge[sliver][np.arange(sliver.sum()), np.argmin(side_len, axis=1)]
        cand[shortest[length[shortest] < spacing]] = True
    if not cand.any():
        return tri, np.ones(len(tri), dtype=bool), 0
    e_idx = np.flatnonzero(cand)
    # Direction: u -> v only if every patch of u is a patch of v (u then moves within its own patches).
    p_count = int(patch.max()) + 1
    inc = csr_matrix((np.ones(3 * len(tri)), (tri.T.ravel(), np.tile(patch, 3))), shape=(n_v, p_count))
    inc.data[:] = 1.0
    inc.sum_duplicates()
    inc.data[:] = 1.0
    n_patch = np.asarray(inc.sum(axis=1)).ravel()
    eu, ev = lo[e_idx], hi[e_idx]
    common = np.asarray(inc[eu].multiply(inc[ev]).sum(axis=1)).ravel()
    u_into_v = common == n_patch[eu]
    v_into_u = common == n_patch[ev]
    if plane_eq is not None:  # or: the target lies on every input plane of the source (crack patches may slide)
        u_into_v |= _on_planes(inc, plane_eq, points, eu, ev, spacing)
        v_into_u |= _on_planes(inc, plane_eq, points, ev, eu, spacing)
    if movable is not None:
        u_into_v &= movable[eu]
        v_into_u &= movable[ev]
    if fixed is not None:
        free = ~fixed[eu] & ~fixed[ev]
        u_into_v &= free
        v_into_u &= free
    ok = u_into_v | v_into_u
    src = np.where(u_into_v, eu, ev)[ok]
    dst = np.where(u_into_v, ev, eu)[ok]
    if group is None:
        prio = length[e_idx][ok] + 1e-12 * spacing * np.arange(ok.sum()) / max(ok.sum(), 1)
    else:  # the same tie-break within each group as on the group alone
        g_of = group[eu[ok]]
        count = np.bincount(g_of)[g_of]
        prio = length[e_idx][ok] + 1e-12 * spacing * _rank_in_group(g_of) / np.maximum(count, 1)
    if src.size == 0:
        return tri, np.ones(len(tri), dtype=bool), 0
    # Independent collapses: the zones (source and its neighbours) of two chosen collapses never meet.
    adj = csr_matrix((np.ones(2 * len(lo)), (np.concatenate([lo, hi]), np.concatenate([hi, lo]))), shape=(n_v, n_v))
    zone = adj[src].tocoo()
    rows = np.concatenate([zone.row, np.arange(len(src))])
    cols = np.concatenate([zone.col, src])
    chosen = _independent_choice(rows, cols, prio, len(src), n_v)
    src, dst = src[chosen], dst[chosen]
    # Link condition in every shell that holds the source.
    sv = np.unique(shell[:, None] * n_v + tri)  # (shell, vertex) pairs present
    s_of, v_of = sv // n_v, sv % n_v
    order = np.argsort(v_of, kind="stable")
    starts = np.searchsorted(v_of[order], np.arange(n_v + 1))
    per = starts[src + 1] - starts[src]
    c_rep = np.repeat(np.arange(len(src)), per)
    pos_in = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per)
    shells_c = s_of[order][starts[src][c_rep] + pos_in]
    a_dir = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b_dir = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    s_dir = np.tile(shell, 3)
    row_key = np.searchsorted(sv, s_dir * n_v + a_dir)
    nbr = csr_matrix((np.ones(len(a_dir)), (row_key, b_dir)), shape=(len(sv), n_v))
    nbr.data[:] = 1.0
    nbr.sum_duplicates()
    nbr.data[:] = 1.0
    su = np.searchsorted(sv, shells_c * n_v + src[c_rep])
    dst_key = shells_c * n_v + dst[c_rep]
    sd = np.minimum(np.searchsorted(sv, dst_key), len(sv) - 1)
    dst_in_shell = sv[sd] == dst_key
    edge_in_shell = np.asarray(nbr[su, dst[c_rep]]).ravel() > 0
    common_nbrs = np.asarray(nbr[su].multiply(nbr[sd]).sum(axis=1)).ravel()
    if shell_size is None:
        shell_size = np.bincount(s_of, minlength=int(shell.max()) + 1)
    shell_size = shell_size[shells_c]
    good = np.where(dst_in_shell, edge_in_shell & (common_nbrs == 2) & (shell_size > 6), True)
    link_ok = np.bincount(c_rep[~good], minlength=len(src)) == 0
    src, dst = src[link_ok], dst[link_ok]
    if src.size == 0:
        return tri, np.ones(len(tri), dtype=bool), 0
    # Geometry: no triangle that keeps its area may turn by more than 60 degrees (slivers and triangles of short
    # edges only, whose normals mean little, may).
    moved = np.arange(n_v)
    moved[src] = dst
    new = moved[tri]
    touched = np.any(new != tri, axis=1)
    degenerate = (new[:, 0] == new[:, 1]) | (new[:, 1] == new[:, 2]) | (new[:, 2] == new[:, 0])
    check = np.flatnonzero(touched & ~degenerate)
    t_old, t_new = points[tri[check]], points[new[check]]
    n_old = np.cross(t_old[:, 1] - t_old[:, 0], t_old[:, 2] - t_old[:, 0])
    n_new = np.cross(t_new[:, 1] - t_new[:, 0], t_new[:, 2] - t_new[:, 0])
    dot = np.einsum("ij,ij->i", n_old, n_new)
    significant = ~sliver[check] & (length[side_edge[check]].max(axis=1) >= short_edge * spacing)
    turned = (dot <= 0.5 * np.linalg.norm(n_old, axis=1) * np.linalg.norm(n_new, axis=1)) & significant
    if fixed is not None:  # no collapse may narrow a triangle at a fixed vertex into a sliver (no round could undo it)
        a_new = _min_angles(t_new)
        turned |= fixed[new[check]].any(axis=1) & (a_new < sliver_angle) & (a_new < _min_angles(t_old))
    if turned.any():
        which = np.full(n_v, -1)
        which[src] = np.arange(len(src))
        bad_src = which[tri[check[turned]]]
        keep = np.ones(len(src), dtype=bool)
        keep[bad_src[bad_src >= 0]] = False
        src, dst = src[keep], dst[keep]
        moved = np.arange(n_v)
        moved[src] = dst
        new = moved[tri]
        degenerate = (new[:, 0] == new[:, 1]) | (new[:, 1] == new[:, 2]) | (new[:, 2] == new[:, 0])
    return new, ~degenerate, len(src)


def _flip_round(points, tri, shell, patch, sliver_angle, fixed=None, vertex_group=None):
    """One round of edge flips (see :func:`clean_complex`): the longest side ab of a sliver (a, b, c) whose twin
    (b, a, d) in the same shell lies in the same patch becomes cd, giving (c, a, d) and (d, b, c), when cd is not an
    edge of that shell yet, both new triangles keep the old orientation and the smaller angle grows. A flip is done in
    every shell holding the pair (both sides of a crack) or in none. With ``fixed`` (bool [v]) c and d must not be
    fixed; ``vertex_group`` as ``group`` in :func:`_collapse_round`. Returns (triangles [f, 3], number of flips)."""
    n_v = points.shape[0]
    f_count = len(tri)
    angles = triangle_angles(points, tri)
    amin = angles.min(axis=1)
    sliver = np.flatnonzero(amin < sliver_angle)
    if sliver.size == 0:
        return tri, 0
    # The longest side of a sliver is opposite its largest angle: corner j's opposite side joins j + 1 and j + 2.
    j = np.argmax(angles[sliver], axis=1)
    a = tri[sliver, (j + 1) % 3]
    b = tri[sliver, (j + 2) % 3]
    c = tri[sliver, j]
    # Twin: the triangle of the same shell holding the directed edge b -> a.
    da = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    db = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    dapex = np.concatenate([tri[:, 2], tri[:, 0], tri[:, 1]])
    dface = np.tile(np.arange(f_count), 3)
    dkey = (np.tile(shell, 3) * n_v + da) * n_v + db
    order = np.argsort(dkey)
    skey = dkey[order]
    want = (shell[sliver] * n_v + b) * n_v + a
    pos = np.minimum(np.searchsorted(skey, want), len(skey) - 1)
    found = skey[pos] == want
    t2 = np.where(found, dface[order][pos], 0)
    d = np.where(found, dapex[order][pos], 0)
    ok = found & (patch[t2] == patch[sliver]) & (c != d)
    if fixed is not None:
        ok &= ~fixed[c] & ~fixed[d]
    # cd must not be an edge of the shell already (either direction).
    for e0, e1 in ((c, d), (d, c)):
        ekey = (shell[sliver] * n_v + e0) * n_v + e1
        pos2 = np.minimum(np.searchsorted(skey, ekey), len(skey) - 1)
        ok &= skey[pos2] != ekey
    # Geometry: orientation kept and the smaller angle grows.
    t_new1 = np.stack([c, a, d], axis=1)
    t_new2 = np.stack([d, b, c], axis=1)
    n_old = np.cross(points[b] - points[a], points[c] - points[a]) + np.cross(
        points[a] - points[b], points[d] - points[b]
    )
    for tn in (t_new1, t_new2):
        p = points[tn]
        n_new = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        ok &= np.einsum("ij,ij->i", n_new, n_old) > 0.0
    new_min = np.minimum(triangle_angles(points, t_new1).min(axis=1), triangle_angles(points, t_new2).min(axis=1))
    ok &= new_min > np.minimum(amin[sliver], amin[t2]) + 1e-6
    # All shells or none: group the candidates by (edge, patch).
    group_key = (np.minimum(a, b) * n_v + np.maximum(a, b)) * (int(patch.max()) + 1) + patch[sliver]
    _, group = np.unique(group_key, return_inverse=True)
    group = group.reshape(-1)
    all_ok = np.bincount(group[~ok], minlength=group.max() + 1) == 0
    ok &= all_ok[group]
    cand = np.flatnonzero(ok)
    if cand.size == 0:
        return tri, 0
    # Each triangle in at most one flip (smallest angle first; the copies of one flip win together).
    if vertex_group is None:
        prio = amin[sliver][cand] + 1e-9 * group[cand] / max(group.max(), 1)
    else:  # the same tie-break within each vertex group as on the group alone
        g_of = vertex_group[np.minimum(a, b)]
        first = np.full(int(g_of.max()) + 1, group.max() + 1)
        np.minimum.at(first, g_of, group)
        last = np.zeros(len(first), dtype=np.int64)
        np.maximum.at(last, g_of, group)
        local = group - first[g_of]
        prio = amin[sliver][cand] + 1e-9 * local[cand] / np.maximum(last - first, 1)[g_of[cand]]
    faces = np.concatenate([sliver[cand], t2[cand]])
    rows = np.tile(np.arange(len(cand)), 2)
    chosen = _independent_choice(rows, faces, prio, len(cand), f_count)
    pick = cand[chosen]
    g_ok = np.zeros(group.max() + 1, dtype=bool)
    g_ok[group[pick]] = True
    g_cnt = np.bincount(group[cand], minlength=group.max() + 1)
    g_pick = np.bincount(group[pick], minlength=group.max() + 1)
    pick = pick[g_pick[group[pick]] == g_cnt[group[pick]]]  # every copy of the flip was chosen
    # Two flips of one round may not create the same edge in one shell: keep the first flip of each such edge (and
    # drop every copy of a flip that loses in some shell).
    new_key = (shell[sliver[pick]] * n_v + np.minimum(c[pick], d[pick])) * n_v + np.maximum(c[pick], d[pick])
    _, first_of = np.unique(new_key, return_index=True)
    dup = np.ones(len(pick), dtype=bool)
    dup[first_of] = False
    if dup.any():
        bad_group = np.zeros(group.max() + 1, dtype=bool)
        bad_group[group[pick[dup]]] = True
        pick = pick[~bad_group[group[pick]]]
    out = tri.copy()
    out[sliver[pick]] = t_new1[pick]
    out[t2[pick]] = t_new2[pick]
    return out, len(pick)


def _flip_near_slivers(points, tri, shell, patch, sliver_angle, fixed=None, group=None):
    """:func:`_flip_round` on the triangles within two rings of the slivers of ``tri`` (:func:`_neighbourhood`),
    in those triangles' own vertex numbering: they hold every sliver, its twins and every edge its flip could
    create, so the round decides as on all of ``tri``. ``fixed``, ``group``: per vertex, as in :func:`_flip_round`.
    Returns (triangles [f, 3], number of flips)."""
    sliver = _min_angles(points[tri]) < sliver_angle
    if not sliver.any():
        return tri, 0
    sub = _neighbourhood(tri, sliver, len(points))[0]
    verts, local = np.unique(tri[sub], return_inverse=True)
    out, flipped = _flip_round(
        points[verts],
        local.reshape(-1, 3),
        shell[sub],
        patch[sub],
        sliver_angle,
        None if fixed is None else fixed[verts],
        None if group is None else group[verts],
    )
    if flipped == 0:
        return tri, 0
    tri = tri.copy()
    tri[sub] = verts[out]
    return tri, flipped


def _relax_round(
    points,
    tri,
    patch,
    plane_eq,
    sliver_angle,
    max_turn=30.0,
    surface=None,
    steps=(0.25, 0.5, 1.0),
    caps=False,
    fixed=None,
    group=None,
):
    """One round of vertex moves against the slivers that collapses and flips leave (see :func:`clean_complex`).

    The ends of the shortest side of every sliver move towards the mean of their neighbours, projected onto the
    planes of their input patches (a vertex on one input plane slides in it, on two along their crease; on three
    or more, or with no plane equations, it stays put; crack patches may bend a little, both sides alike). A move
    (the largest of ``steps`` of the way) is taken when the smallest angle of the vertex's triangles grows and none
    of them (but slivers) turns by more than ``max_turn`` degrees; moved vertices share no triangle. With ``surface``
    (input vertices [m], triangles, plane id per triangle, plane id per patch (-1: crack)) a vertex must also stay
    inside an input triangle of each of its planes (a facet's plane reaches beyond the facet). ``points`` [v, 3] is
    changed in place. With ``caps`` the candidates are instead the obtuse corners of the slivers, moved away from
    the long side to a fifth of its length from it (where the neighbours' mean does not help a flat cap). ``fixed``
    (bool [v]): vertices that stay; ``group`` as in :func:`_collapse_round`. Returns the number of vertices moved,
    or with ``group`` the vertices moved per group (int [group count])."""
    n_v = points.shape[0]
    angles = triangle_angles(points, tri)
    amin = angles.min(axis=1)
    sliver = np.flatnonzero(amin < sliver_angle)
    none = 0 if group is None else np.zeros(int(group.max()) + 1, dtype=np.int64)
    if sliver.size == 0 or plane_eq is None:
        return none
    cand = np.unique(tri[sliver])  # needles: the ends of the short side move; caps: the corner by the long side
    if fixed is not None:
        cand = cand[~fixed[cand]]
    # Input planes of each candidate (at most two allowed).
    p_count = plane_eq.shape[0]
    inc = csr_matrix((np.ones(3 * len(tri)), (tri.T.ravel(), np.tile(patch, 3))), shape=(n_v, p_count))
    inc.sum_duplicates()
    rows = inc[cand].tocoo()
    planar = ~np.isnan(plane_eq[rows.col, 0])
    r_row, r_eq = rows.row[planar], plane_eq[rows.col[planar]]
    n_planes = np.bincount(r_row, minlength=len(cand))
    keep = n_planes <= 2
    # Neighbour means.
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    adj = csr_matrix((np.ones(len(a)), (a, b)), shape=(n_v, n_v))
    adj.data[:] = 1.0
    adj.sum_duplicates()
    adj.data[:] = 1.0
    adj = adj.maximum(adj.T).tocsr()
    deg = np.asarray(adj[cand].sum(axis=1)).ravel()
    target = (adj[cand] @ points) / np.maximum(deg, 1.0)[:, None]
    if caps:  # the obtuse corner C of each sliver, away from its long side AB
        j = np.argmax(angles[sliver], axis=1)
        corner, end_a, end_b = tri[sliver, j], tri[sliver, (j + 1) % 3], tri[sliver, (j + 2) % 3]
        ab = points[end_b] - points[end_a]
        length = np.linalg.norm(ab, axis=1)
        along = np.einsum("ij,ij->i", points[corner] - points[end_a], ab) / np.maximum(length, 1e-300) ** 2
        foot = points[end_a] + along[:, None] * ab
        away = points[corner] - foot
        height = np.linalg.norm(away, axis=1)
        ok = height > 1e-9 * length
        goal = foot + away / np.maximum(height, 1e-300)[:, None] * (0.2 * length)[:, None]
        first = np.unique(corner[ok], return_index=True)[1]
        pick = np.isin(cand, corner[ok][first])
        where = np.searchsorted(corner[ok][first], cand[pick])
        cand, target, keep = cand[pick], goal[ok][first][where], keep[pick]
        rows = inc[cand].tocoo()
        planar = ~np.isnan(plane_eq[rows.col, 0])
        r_row, r_eq = rows.row[planar], plane_eq[rows.col[planar]]
    # Project onto the planes: x = target - N^T (N N^T)^+ (N target - d), N the [k, 3] plane normals.
    normals = np.zeros((len(cand), 2, 3))
    offsets = np.zeros((len(cand), 2))
    slot = np.arange(len(r_row)) - np.searchsorted(r_row, r_row)
    ok_slot = slot < 2
    normals[r_row[ok_slot], slot[ok_slot]] = r_eq[ok_slot, :3]
    offsets[r_row[ok_slot], slot[ok_slot]] = r_eq[ok_slot, 3]
    own_patch = np.full((len(cand), 2), -1, dtype=np.int64)
    own_patch[r_row[ok_slot], slot[ok_slot]] = rows.col[planar][ok_slot]
    gram = np.einsum("cij,ckj->cik", normals, normals)
    resid = np.einsum("cij,cj->ci", normals, target) - offsets
    target = target - np.einsum("cji,cj->ci", normals, np.einsum("cij,cj->ci", np.linalg.pinv(gram), resid))
    cand, target, own_patch = cand[keep], target[keep], own_patch[keep]
    if cand.size == 0:
        return none
    # Triangles around each candidate, and the moves that help.
    vt = csr_matrix((np.ones(3 * len(tri)), (tri.T.ravel(), np.tile(np.arange(len(tri)), 3))), shape=(n_v, len(tri)))
    vt.sum_duplicates()
    ring = vt[cand].tocoo()
    c_of, f_of = ring.row, ring.col
    old_min = np.full(len(cand), np.inf)
    np.minimum.at(old_min, c_of, amin[f_of])
    t_old = points[tri[f_of]]
    n_old = np.cross(t_old[:, 1] - t_old[:, 0], t_old[:, 2] - t_old[:, 0])
    best_step = np.zeros(len(cand))
    major = _min_angles(t_old) >= sliver_angle  # slivers may turn, these may not
    corner = tri[f_of] == cand[c_of][:, None]
    for step in steps:
        pos = points[cand] + step * (target - points[cand])
        t_new = t_old.copy()
        t_new[corner] = np.repeat(pos[c_of], corner.sum(axis=1), axis=0)
        n_new = np.cross(t_new[:, 1] - t_new[:, 0], t_new[:, 2] - t_new[:, 0])
        cos_ok = np.einsum("ij,ij->i", n_old, n_new) >= np.cos(np.radians(max_turn)) * np.linalg.norm(
            n_old, axis=1
        ) * np.linalg.norm(n_new, axis=1)
        a_new = np.full(len(cand), np.inf)
        np.minimum.at(a_new, c_of, _min_angles(t_new))
        turned = np.bincount(c_of[~cos_ok & major], minlength=len(cand)) > 0
        better = (a_new > old_min + 1e-6) & ~turned
        if surface is not None:
            better &= _on_input_planes(pos, own_patch, surface)
        best_step = np.where(better, step, best_step)
    move = best_step > 0.0
    if not move.any():
        return none
    # Independent moves: no two moved vertices share a triangle (smallest angle first).
    cand, target, best_step, prio = cand[move], target[move], best_step[move], old_min[move]
    ring = vt[cand].tocoo()
    tie = np.arange(len(cand)) if group is None else _rank_in_group(group[cand])
    chosen = _independent_choice(ring.row, ring.col, prio + 1e-12 * tie, len(cand), len(tri))
    c = cand[chosen]
    points[c] += best_step[chosen][:, None] * (target[chosen] - points[c])
    if group is None:
        return int(chosen.sum())
    return np.bincount(group[c], minlength=len(none))


_INPUT_INDEX: OrderedDict = OrderedDict()  # id(input triangles) -> (triangles, vertices, corners, tree, reach)
_INPUT_INDEX_SIZE = 16  # input surfaces kept (a body's is the same array object at every rebuild)


def _input_index(sv, sf):
    """(corners [f, 3, 3], k-d tree of the triangles' centroids, largest centroid-to-corner distance) of the input
    triangles ``sf`` of vertices ``sv``: made once per input surface and kept (the entries hold the arrays, so their
    ids stay theirs), since every relaxation round of every rebuild asks for them and they grow with the input
    mesh, not with the work."""
    key = id(sf)
    hit = _INPUT_INDEX.get(key)
    if hit is not None and hit[0] is sf and hit[1] is sv:
        _INPUT_INDEX.move_to_end(key)
        return hit[2:]
    corners = sv[sf]
    centroid = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroid[:, None, :], axis=2).max()) * (1.0 + 1e-9) + 1e-300
    _INPUT_INDEX[key] = (sf, sv, corners, cKDTree(centroid), reach)
    while len(_INPUT_INDEX) > _INPUT_INDEX_SIZE:
        _INPUT_INDEX.popitem(last=False)
    return corners, _INPUT_INDEX[key][3], reach


def _on_input_planes(pos, own_patch, surface) -> np.ndarray:
    """Bool [c]: each point pos [c, 3] lies in an input triangle of each of its planes (``own_patch`` [c, 2] patch
    ids, -1 for none; ``surface`` as in :func:`_relax_round`), within 1e-9 of the triangle's size. Only the triangles
    whose centroid lies within the largest centroid-to-corner distance of a point can hold it (a k-d tree query)."""
    sv, sf, splane, plane_of_patch = surface
    ok = np.ones(len(pos), dtype=bool)
    corners, centroids, reach = _input_index(sv, sf)
    pairs = cKDTree(pos).sparse_distance_matrix(centroids, reach, output_type="ndarray")
    near_c, near_t = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    for k in range(own_patch.shape[1]):
        has = own_patch[:, k] >= 0
        q = np.where(has, plane_of_patch[np.maximum(own_patch[:, k], 0)], -1)
        has &= q >= 0
        sel = has[near_c] & (splane[near_t] == q[near_c])
        pair_c, pair_t = near_c[sel], near_t[sel]
        a, b, c = (corners[pair_t, i] for i in range(3))
        n = np.cross(b - a, c - a)
        nn = np.einsum("ij,ij->i", n, n)
        p = pos[pair_c]
        bary = [
            np.einsum("ij,ij->i", np.cross(c - b, p - b), n),
            np.einsum("ij,ij->i", np.cross(a - c, p - c), n),
            np.einsum("ij,ij->i", np.cross(b - a, p - a), n),
        ]
        inside = np.all(np.stack(bary, axis=1) >= -1e-9 * nn[:, None], axis=1)
        found = np.zeros(len(pos), dtype=bool)
        np.logical_or.at(found, pair_c, inside)
        ok &= found | ~has
    return ok


def _min_angles(t: np.ndarray) -> np.ndarray:
    """Smallest interior angle [degrees] of triangles given by their corners [m] [f, 3, 3]."""
    return _corner_angles(t).min(axis=1)


def clean_complex(
    points,
    tri,
    shell,
    patch,
    spacing,
    *,
    short_edge=SHORT_EDGE,
    sliver_angle=SLIVER_ANGLE,
    crack_patch=None,
    surface=None,
    planes_from=None,
    origin=None,
    settled=None,
    plane_eq=None,
    shell_size=None,
    fixed=None,
    group=None,
    still=None,
):
    """Removes slivers from the shell complex by edge collapses that keep every shell a closed 2-manifold.

    Candidates are edges shorter than ``short_edge`` spacings and the shortest side (up to one spacing) of every
    triangle with an angle below ``sliver_angle`` [degrees]; given ``crack_patch``, at first only those of the crack
    triangles and of the triangles within two vertex rings of them (the input's own triangles elsewhere are kept as
    they are, short or thin: the input's detail, at no cost that grows with the input; their vertices are held as
    ``fixed`` ones, so the work never spreads over the input). A collapse moves one end u
    onto the other end v (no new positions: outer faces stay exactly on the input surface, sharp edges and corners
    stay put) and is allowed when

    - every patch of u is a patch of v (u stays on its planes and cracks: interior points may move onto rims,
      creases and junctions, never the reverse), or, given ``crack_patch``, v lies on the plane of every input
      patch of u (u's cracks may then slide: a crack's rim moves along a box edge or across a face, both sides
      alike, while outer faces stay on the input planes and volumes still add up),
    - in every shell holding u and v, the edge uv exists and u and v share exactly two neighbours (the link
      condition, which keeps the shell a 2-manifold), and the shell has more than 6 vertices,
    - no remaining triangle turns by more than 60 degrees.

    Collapses of one round have disjoint neighbourhoods (chosen shortest first), so they are checked and applied
    together, vectorised; the two sides of a crack share vertices and triangles, so both sides collapse alike. Each
    round also flips edges (:func:`_flip_round`); when neither collapses nor flips are left, the vertices of the
    remaining slivers are moved (:func:`_relax_round`; ``points`` is changed in place) and the rounds go on. Every
    round works on the triangles within two rings of the flagged ones (a side under ``short_edge`` spacings or an
    angle under ``sliver_angle``), where every candidate's neighbourhood lies: only the vertices within one ring of a
    flagged triangle's vertices take part in its collapses, flips and moves (they alone have all their triangles in
    the round; a collapse of a vertex beyond them would leave its other triangles behind and open the shell), and
    closedness is checked only on the edges near them.

    Args:
        points: vertex positions [m], float64 [v, 3].
        tri: triangles (global vertex ids), int64 [f, 3]; shell: shell of each triangle, int [f];
        patch: patch id of each triangle, int [f].
        spacing: particle spacing h [m].
        surface: (input vertices [m], triangles, plane id per triangle, plane id per patch (-1 on crack patches)):
            lets the vertices of slivers left over slide within the input surface (see :func:`_relax_round`); None:
            only vertices off the input planes move.
        crack_patch: bool [patch count], True for crack patches (the others are planar input patches); None: the
            strict patch rule only.
        planes_from: (points [m], tri, patch) whose triangles give each input-plane patch its plane (default: the
            complex given), e.g. the raw complex when ``tri`` already holds an earlier clean-up's edits.
        origin: None, or an int array [f] carried along with the triangles (a triangle keeps its slot through
            collapses and flips): then returned as a fourth element, for the surviving triangles.
        settled: None, or bool [f]: triangles an earlier clean-up left as they are with their whole neighbourhood
            (pdsim/fragment_surfaces/edits.py). They are not flagged until something within two rings of them
            changes, so the rounds work where the complex changed, not on what an earlier clean-up could not
            improve (short input edges, slivers of a faceted input).
        plane_eq: None, or the unit normal and offset of each patch's input plane, float64 [patch count, 4] (NaN rows
            for crack patches): used instead of the planes taken from ``planes_from``.
        shell_size: None, or the vertex count of each shell [shell count] in the whole complex when ``tri`` is a
            part of it (default: the counts within each round's triangles).
        fixed: None, or bool [v]: vertices that keep their position and whose triangles may lack from ``tri`` (the
            border of a part of a larger complex): no collapse, flip or move involves them beyond their triangles
            in ``tri``, so the part stays joined to the rest.
        group: None, or int [v] (non-decreasing in the vertex id, every triangle's vertices in one group): the
            groups are cleaned independently, each as if it were cleaned alone (its rounds stop on their own, ties
            are broken within the group), so a group's result depends on its own triangles only.
        still: None, or bool [v]: vertices that the vertex moves leave in place (they may still collapse).

    Returns:
        (tri, shell, patch) after the collapses (triangles that became degenerate removed), and the surviving
        triangles' ``origin`` when given.
    """
    if plane_eq is None and crack_patch is not None:  # unit normal and offset of every input-plane patch (NaN: cracks)
        f_points, f_tri, f_patch = (points, tri, patch) if planes_from is None else planes_from
        p_count = max(int(patch.max()), int(f_patch.max())) + 1
        t = f_points[f_tri]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        normal = np.stack([np.bincount(f_patch, n[:, a], p_count) for a in range(3)], axis=1)
        normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
        offset = np.einsum("ij,ij->i", normal[f_patch], t.mean(axis=1))
        offset = np.bincount(f_patch, offset, p_count) / np.maximum(np.bincount(f_patch, minlength=p_count), 1)
        plane_eq = np.concatenate([normal, offset[:, None]], axis=1)
        plane_eq[np.asarray(crack_patch, dtype=bool)] = np.nan
    flag = _needs_work(points, tri, spacing, short_edge, sliver_angle)
    if crack_patch is not None:  # the input's own triangles, away from the cracks, are left as the input has them:
        near = _near_cracks(tri, np.asarray(crack_patch, dtype=bool)[patch], len(points))
        flag &= near
        away = np.ones(len(points), dtype=bool)  # their vertices are held, so the work never spreads over the input
        away[tri[near]] = False
        fixed = away if fixed is None else fixed | away
    if settled is not None:
        settled = np.asarray(settled, dtype=bool)
        flag &= ~settled
    done = None if group is None else np.zeros(int(group.max()) + 1, dtype=bool)  # groups that stopped
    for _ in range(_MAX_CLEAN_ROUNDS):
        # A round works on the triangles within two rings of the flagged ones (every triangle that holds a vertex of a
        # flagged triangle or one of its neighbours): they hold every candidate's neighbourhood in every shell, so
        # the round decides there as it would on the whole complex, and nothing outside them changes.
        if done is not None:
            flag &= ~done[group[tri[:, 0]]]
        if not flag.any():
            break
        sub, active = _neighbourhood(tri, flag, len(points))
        ts, ss, ps = tri[sub], shell[sub], patch[sub]
        # the vertices outside the round's one ring (whose triangles may lack from sub) are held: a collapse or flip
        # there would change triangles the round does not see and open the shell (and a settled triangle's short
        # side never collapses with half its neighbourhood seen)
        held = ~active if fixed is None else fixed | ~active
        unmoved = held if still is None else held | still
        new, keep, collapsed = _collapse_round(
            points, ts, ss, ps, spacing, short_edge, sliver_angle, plane_eq, shell_size=shell_size, fixed=held,
            group=group,
        )  # fmt: skip
        t1, s1, p1 = new[keep], ss[keep], ps[keep]
        t0 = t1.copy()
        t1, flipped = _flip_near_slivers(points, t1, s1, p1, sliver_angle, held, group)
        if group is not None:
            tri, shell, patch, flag, settled, origin = _group_round(
                points, (tri, shell, patch, flag, settled, origin), sub, active, (ts, ss, ps, new, keep, t0, t1),
                (held, unmoved), group, done, plane_eq, surface, spacing, short_edge, sliver_angle,
            )  # fmt: skip
            continue
        if collapsed == 0 and flipped == 0:
            # vertex moves change no connectivity: the shells stay closed
            around = np.unique(t1) if settled is not None else None
            before = None if around is None else points[around].copy()
            relax = _relax_round(
                points, t1, p1, plane_eq, sliver_angle, max_turn=RELAX_TURN, surface=surface, fixed=unmoved
            )
            if relax == 0:
                break
            flag[sub] = _needs_work(points, t1, spacing, short_edge, sliver_angle)
            if settled is not None:
                settled, flag = _unsettle(points, tri, settled, flag, around[(points[around] != before).any(axis=1)],
                                          spacing, short_edge, sliver_angle)  # fmt: skip
            continue
        # the shells this round changed must still be closed (a rare configuration the checks missed: stop here)
        changed = np.concatenate([ss[~keep | (new != ts).any(axis=1)], s1[(t1 != t0).any(axis=1)]])
        if not _closed_near(t1, s1, active, np.unique(changed), len(points)):
            break
        tri, shell, patch, flag, settled, origin = _apply_round(
            points, (tri, shell, patch, flag, settled, origin), sub, (ts, new, keep, t0, t1), spacing, short_edge,
            sliver_angle,
        )  # fmt: skip
    return (tri, shell, patch) if origin is None else (tri, shell, patch, origin)


def _apply_round(points, state, sub, round_, spacing, short_edge, sliver_angle):
    """The complex after a round of collapses and flips on its triangles ``sub`` (ids): ``state`` = (tri, shell,
    patch, flag, settled, origin) before, ``round_`` = (the triangles ``ts`` = tri[sub], after the collapses ``new``
    with ``keep`` the rows that keep an area, ``t0`` = new[keep], after the flips ``t1``). Returns the new state."""
    tri, shell, patch, flag, settled, origin = state
    ts, new, keep, t0, t1 = round_
    whole = np.ones(len(tri), dtype=bool)
    whole[sub[~keep]] = False
    tri, flag = tri.copy(), flag.copy()
    tri[sub[keep]] = t1
    redo = (t1 != ts[keep]).any(axis=1)  # the others keep their flags (collapses and flips move no vertex)
    flag[sub[keep][redo]] = _needs_work(points, t1[redo], spacing, short_edge, sliver_angle)
    if settled is not None:  # what is within two rings of the round's changes is looked at again
        moved = np.concatenate([ts[~keep | (new != ts).any(axis=1)].ravel(), t1[(t1 != t0).any(axis=1)].ravel()])
        settled, flag = _unsettle(points, tri, settled, flag, moved, spacing, short_edge, sliver_angle)
        settled = settled[whole]
    tri, shell, patch, flag = tri[whole], shell[whole], patch[whole], flag[whole]
    if origin is not None:
        origin = origin[whole]
    return tri, shell, patch, flag, settled, origin


def _group_round(points, state, sub, active, round_, fixed, group, done, plane_eq, surface, spacing, short_edge,
                 sliver_angle):  # fmt: skip
    """One round of :func:`clean_complex` with independent groups: each group whose collapses and flips
    (``round_`` = (ts, ss, ps, new, keep, t0, t1) as in :func:`_apply_round`, with the shells and patches of ``ts``)
    changed something keeps them if its shells stay closed (else it stops, as it would alone: ``done`` is updated);
    each other group moves vertices (:func:`_relax_round`) and stops when none moves. ``fixed`` = (the vertices
    held, those that vertex moves leave in place). Returns the new state."""
    tri, shell, patch, flag, settled, origin = state
    ts, ss, ps, new, keep, t0, t1 = round_
    fixed, unmoved = fixed
    g_sub = group[ts[:, 0]]
    touched = ~keep | (new != ts).any(axis=1)
    touched[np.flatnonzero(keep)[(t1 != t0).any(axis=1)]] = True
    busy = np.zeros(len(done), dtype=bool)
    busy[g_sub[touched]] = True
    s1 = ss[keep]
    if busy.any():  # closedness near the round's free vertices, per group
        changed = np.unique(np.concatenate([ss[~keep | (new != ts).any(axis=1)], s1[(t1 != t0).any(axis=1)]]))
        open_v = _open_near(t1, s1, active & ~fixed, changed, len(points))
        failed = np.zeros(len(done), dtype=bool)
        failed[group[open_v]] = True
        failed &= busy
        if failed.any():  # those groups keep their triangles from before the round, and stop
            undo = failed[g_sub]
            rows = ts.copy()
            rows[keep] = t1
            rows[undo] = ts[undo]
            new = np.where(undo[:, None], ts, new)
            keep = keep | undo
            t1 = rows[keep]
            t0 = np.where(undo[keep][:, None], t1, new[keep])
            done |= failed
            busy &= ~failed
    idle = ~done & ~busy
    idle_rows = idle[g_sub]
    if idle_rows.any():  # vertex moves change no connectivity: the shells stay closed
        ti = ts[idle_rows]
        around = np.unique(ti) if settled is not None else None
        before = None if around is None else points[around].copy()
        moved = _relax_round(
            points, ti, ps[idle_rows], plane_eq, sliver_angle, max_turn=RELAX_TURN, surface=surface,
            fixed=unmoved | ~idle[group], group=group,
        )  # fmt: skip
        done |= idle & (moved == 0)
        flag = flag.copy()
        flag[sub[idle_rows]] = _needs_work(points, ti, spacing, short_edge, sliver_angle)
        if settled is not None:
            settled, flag = _unsettle(points, tri, settled, flag, around[(points[around] != before).any(axis=1)],
                                      spacing, short_edge, sliver_angle)  # fmt: skip
    if not busy.any():
        return tri, shell, patch, flag, settled, origin
    return _apply_round(points, (tri, shell, patch, flag, settled, origin), sub, (ts, new, keep, t0, t1), spacing,
                        short_edge, sliver_angle)  # fmt: skip


def _unsettle(points, tri, settled, flag, vertices, spacing, short_edge, sliver_angle):
    """(settled, flag) after a round that changed the triangles around ``vertices`` (ids): the settled triangles
    within two rings of them are settled no more, and flagged when they need work; the others keep their flags."""
    near = settled & _two_rings(tri, vertices, len(points))
    flag = flag.copy()
    flag[near] = _needs_work(points, tri[near], spacing, short_edge, sliver_angle)
    flag &= ~(settled & ~near)
    return settled & ~near, flag


def _two_rings(tri, vertices, vertex_count) -> np.ndarray:
    """Bool [f]: the triangle of ``tri`` [f, 3] holds a vertex within one ring of one of ``vertices`` (ids)."""
    seed = np.zeros(vertex_count, dtype=bool)
    seed[vertices] = True
    ring = seed.copy()
    ring[tri[seed[tri].any(axis=1)]] = True
    return ring[tri].any(axis=1)


def _needs_work(points, tri, spacing, short_edge, sliver_angle) -> np.ndarray:
    """Bool [f]: the triangle has a side shorter than ``short_edge`` spacings or an angle under ``sliver_angle``
    [degrees] (a round of :func:`clean_complex` has to look at it)."""
    t = points[tri]
    side = np.linalg.norm(t[:, [1, 2, 0]] - t, axis=2)
    return (side.min(axis=1) < short_edge * spacing) | (_min_angles(t) < sliver_angle)


def _near_cracks(tri, crack, vertex_count) -> np.ndarray:
    """Bool [f]: the triangle is a crack triangle (``crack`` [f]) or lies within two vertex rings of one (where the
    clip cut input triangles and made new vertices)."""
    near = np.zeros(vertex_count, dtype=bool)
    near[tri[crack]] = True
    near[tri[near[tri].any(axis=1)]] = True
    return near[tri].any(axis=1)


def _neighbourhood(tri, flag, vertex_count):
    """The triangles a clean-up round works on: (ids [k] of the triangles holding a vertex within one ring of a
    flagged triangle's vertex, ascending; bool [v] of those active vertices, whose every triangle is among the ids).
    Every clean-up candidate (a side or corner of a flagged triangle) has its whole neighbourhood there."""
    seed = np.zeros(vertex_count, dtype=bool)
    seed[tri[flag]] = True
    active = seed.copy()
    active[tri[seed[tri].any(axis=1)]] = True
    return np.flatnonzero(active[tri].any(axis=1)), active


def _open_near(tri, shell, active, shells, vertex_count) -> np.ndarray:
    """Ids of the ``active`` vertices at which, in the shells ``shells`` (ids, ascending), a directed edge of ``tri``
    [f, 3] (with ``shell`` [f]) occurs more than once or without its reverse. ``tri`` must hold every triangle of
    those shells that has an active vertex, so the counts are those of the whole shells (an incremental closedness
    check)."""
    a = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    b = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    s = np.tile(shell, 3)
    pos = np.minimum(np.searchsorted(shells, s), max(len(shells) - 1, 0))
    sel = (active[a] | active[b]) & (shells[pos] == s) if len(shells) else np.zeros(len(a), dtype=bool)
    a, b, s = a[sel], b[sel], s[sel]
    if not len(a):
        return np.zeros(0, dtype=np.int64)
    key = (s * vertex_count + a) * vertex_count + b
    order = np.argsort(key)
    sk = key[order]
    bad = np.zeros(len(sk), dtype=bool)
    same = sk[1:] == sk[:-1]
    bad[1:] |= same
    bad[:-1] |= same
    bad_edge = np.zeros(len(key), dtype=bool)
    bad_edge[order] = bad
    rev = (s * vertex_count + b) * vertex_count + a
    bad_edge |= sk[np.minimum(np.searchsorted(sk, rev), len(sk) - 1)] != rev
    return np.unique(np.where(active[a[bad_edge]], a[bad_edge], b[bad_edge]))


def _closed_near(tri, shell, active, shells, vertex_count) -> bool:
    """Whether, in the shells ``shells`` (ids, ascending), every directed edge with an ``active`` end occurs once
    among ``tri`` [f, 3] (with ``shell`` [f]) and its reverse once (see :func:`_open_near`)."""
    return len(_open_near(tri, shell, active, shells, vertex_count)) == 0
