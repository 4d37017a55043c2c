"""Topology changes of the fracturing FEM solid: crack-plane vertex splits, separation of pieces, boundary surfaces.

The slides' crack computation (shared/seeds/fem_slides.txt, DESIGN.md section 3) for every element whose largest
principal stress exceeds its tensile strength:

1. pick one of its four corners v: a crack-tip vertex first (one already on a crack surface), then the corner nearest
   the plane through the element's rest centroid normal to the principal direction n; only corners whose split leaves
   elements on both sides qualify (the next corner is tried otherwise; an element with no qualifying corner is skipped);
2. classify the elements around v by the side of the plane (v, n) their rest centroid lies on;
3. give the elements on the positive side a new copy of v (same rest position, position and velocity).

An element causes at most one split in its life (the solver then sets its strength to infinity): the load it sheds
moves to its neighbours along the crack front, which split in turn, so cracks propagate element by element instead
of an over-stressed element shedding all four corners and crumbling into single-element chips.

Several elements over the threshold in one step are split together (vectorised numpy over those elements): in order
of decreasing stress (ties by element index), at most one split per vertex per step. Deterministic.

After the splits, :func:`separate_pieces` duplicates every vertex whose incident elements are no longer connected
through faces that contain it (vertex "stars" split into several face-connected groups). This separates pieces that
only touch at an edge or a point, and keeps every piece's boundary a closed surface in which each edge has exactly
two faces. It is the same slot-graph construction for the whole mesh (nodes: element corners, edges: corners of one
vertex in two elements sharing a face), labelled by pdsim.graph.connected_components (the one labeller of pdsim):
O(element_count) per event, run only on steps where some element exceeded its strength.
"""

from __future__ import annotations

import numpy as np

from .mesh import TET_FACES, boundary_faces, interior_face_pairs

MIN_SIDE = 2  # elements each side of a crack plane must keep around the split vertex

__all__ = [
    "boundary_faces",
    "choose_splits",
    "closed_surface_defects",
    "element_pieces",
    "separate_pieces",
    "split_vertices",
    "vertex_incidence",
]


def vertex_incidence(tets: np.ndarray, vertex_count: int):
    """CSR list of the corner slots (4 e + a) of each vertex: (offsets [vertex_count + 1], slots [4 element_count]),
    slots of a vertex in increasing order."""
    flat = np.asarray(tets, dtype=np.int64).ravel()
    slots = np.argsort(flat, kind="stable")
    counts = np.bincount(flat, minlength=vertex_count)
    offsets = np.zeros(vertex_count + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, slots


def _expand_incident(vertices: np.ndarray, offsets: np.ndarray, slots: np.ndarray):
    """For each query vertex, its incident slots: (query index per entry, slot per entry), vectorised."""
    counts = offsets[vertices + 1] - offsets[vertices]
    rep = np.repeat(np.arange(len(vertices)), counts)
    start = np.repeat(offsets[vertices] - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return rep, slots[start + np.arange(int(counts.sum()))]


def choose_splits(
    tets: np.ndarray,
    rest: np.ndarray,
    centroids: np.ndarray,
    elements: np.ndarray,
    directions: np.ndarray,
    stresses: np.ndarray,
    crack_vertex: np.ndarray,
):
    """Picks the vertex and plane of each split.

    Args:
        tets: current element corners, [element_count, 4].
        rest: rest positions of the vertices [m], [vertex_count, 3].
        centroids: rest centroids of the elements [m], [element_count, 3].
        elements: elements over their strength, [k].
        directions: their principal directions (rest frame, unit), [k, 3].
        stresses: their largest principal stresses [Pa], [k].
        crack_vertex: vertices already on a crack surface, bool [vertex_count].

    Returns:
        (vertices [s], normals [s, 3], elements [s]): at most one split per vertex, in order of decreasing stress, with
        the element that caused each.
    """
    k = len(elements)
    if k == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    offsets, slots = vertex_incidence(tets, len(rest))
    cand = np.asarray(tets[elements], dtype=np.int64)  # [k, 4]
    n = np.asarray(directions, dtype=np.float64)
    dist = np.abs(np.einsum("kaj,kj->ka", rest[cand] - centroids[elements][:, None, :], n))
    # validity: both sides of the plane through the candidate keep at least one element
    flat = cand.ravel()
    rep, inc_slots = _expand_incident(flat, offsets, slots)
    inc_elem = inc_slots // 4
    normal_rep = np.repeat(n, 4, axis=0)[rep]
    side = np.einsum("ij,ij->i", centroids[inc_elem] - rest[flat[rep]], normal_rep) > 0.0
    plus = np.bincount(rep, weights=side, minlength=4 * k)
    total = np.bincount(rep, minlength=4 * k)
    valid = ((plus >= MIN_SIDE) & (total - plus >= MIN_SIDE)).reshape(k, 4)
    tip = crack_vertex[cand]
    # per element (primary key): valid first, crack tips first, then nearest the centroid plane, then corner order
    row = np.repeat(np.arange(k), 4)
    corner = np.tile(np.arange(4), k)
    key = np.lexsort((corner, dist.ravel(), ~tip.ravel(), ~valid.ravel(), row))
    best = corner[key[::4]]
    ok = valid[np.arange(k), best]
    chosen = cand[np.arange(k), best][ok]
    normals = n[ok]
    source = np.asarray(elements)[ok]
    strength_order = np.lexsort((source, -np.asarray(stresses, dtype=np.float64)[ok]))
    chosen, normals, source = chosen[strength_order], normals[strength_order], source[strength_order]
    _, first_idx = np.unique(chosen, return_index=True)
    keep = np.sort(first_idx)
    return chosen[keep], normals[keep], source[keep]


def split_vertices(tets: np.ndarray, rest: np.ndarray, centroids: np.ndarray, vertices: np.ndarray, normals):
    """Duplicates each vertex v_s for the elements around it whose rest centroid lies on the positive side of the
    plane through v_s normal to n_s. Returns (new tets, parent): parent[i] is the original vertex of vertex i
    (identity for the old ones; v_s for the copy vertex_count + s)."""
    tets = np.array(tets, dtype=np.int64)
    nv = len(rest)
    parent = np.concatenate([np.arange(nv), np.asarray(vertices, dtype=np.int64)])
    if len(vertices) == 0:
        return tets, parent
    offsets, slots = vertex_incidence(tets, nv)
    rep, inc_slots = _expand_incident(np.asarray(vertices, dtype=np.int64), offsets, slots)
    side = np.einsum("ij,ij->i", centroids[inc_slots // 4] - rest[vertices][rep], np.asarray(normals)[rep]) > 0.0
    flat = tets.ravel()
    flat[inc_slots[side]] = nv + rep[side]
    return flat.reshape(-1, 4), parent


def separate_pieces(tets: np.ndarray, vertex_count: int, relabel: np.ndarray | None = None):
    """Gives every face-connected group of a vertex's incident elements its own copy of the vertex.

    ``tets`` may be a subset of the mesh's elements that holds every element of each vertex to relabel; ``relabel``
    (bool [vertex_count]) limits the copies to those vertices (default: all; vertices outside may have incomplete
    stars in a subset and are left alone).

    Returns (new tets, parent) with parent[i] the original vertex of vertex i; vertex ids below ``vertex_count`` keep
    the group holding their lowest slot, new copies are numbered from ``vertex_count`` in (vertex, slot) order."""
    from ..graph import connected_components

    tets = np.asarray(tets, dtype=np.int64)
    m = tets.shape[0]
    flat = tets.ravel()
    pairs = interior_face_pairs(tets)  # face ids 4 e + k
    if len(pairs):
        e = pairs // 4
        loc = pairs % 4
        corners = TET_FACES[loc]  # [p, 2, 3] local corners of each face in both elements
        verts = np.take_along_axis(tets[e.ravel()].reshape(-1, 2, 4), corners, axis=2)
        order = np.argsort(verts, axis=2)
        corners = np.take_along_axis(corners, order, axis=2)  # aligned by vertex id across the two elements
        a = (4 * e[:, 0, None] + corners[:, 0]).ravel()
        b = (4 * e[:, 1, None] + corners[:, 1]).ravel()
    else:
        a = b = np.zeros(0, dtype=np.int64)
    labels = connected_components(4 * m, a, b)
    # one representative (lowest slot) per component
    comp_first = np.full(labels.max() + 1, 4 * m, dtype=np.int64)
    np.minimum.at(comp_first, labels, np.arange(4 * m))
    comp_vertex = flat[comp_first]
    # per vertex, the component with the lowest first slot keeps the id
    order = np.lexsort((comp_first, comp_vertex))
    is_first = np.ones(len(order), dtype=bool)
    is_first[1:] = comp_vertex[order][1:] != comp_vertex[order][:-1]
    if relabel is not None:
        is_first |= ~relabel[comp_vertex[order]]
    new_id = np.empty(len(order), dtype=np.int64)
    new_id[order[is_first]] = comp_vertex[order[is_first]]
    extra = order[~is_first]
    new_id[extra] = vertex_count + np.arange(len(extra))
    parent = np.concatenate([np.arange(vertex_count), comp_vertex[extra]])
    return new_id[labels].reshape(m, 4), parent


def _edge_fans(tets: np.ndarray):
    """Edge slots (6 e + k, edge k of TET_EDGES in element e) grouped into fans: two slots of one edge are joined when
    their elements share a face containing the edge. Returns (edge key per slot [6m], fan label per slot [6m])."""
    from ..graph import connected_components
    from .mesh import TET_EDGES

    m = tets.shape[0]
    ev = np.sort(tets[:, TET_EDGES], axis=2)  # [m, 6, 2]
    n = int(tets.max()) + 1
    key = (ev[..., 0] * n + ev[..., 1]).ravel()
    pairs = interior_face_pairs(tets)
    # the three edges of face k of an element, as local edge indices (faces from TET_FACES)
    face_edges = np.array(
        [[_local_edge(a, b) for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))] for f in TET_FACES]
    )
    if len(pairs):
        e = pairs // 4
        le = face_edges[pairs % 4]  # [p, 2, 3] local edges, not aligned between the two elements
        ka = key.reshape(m, 6)[e[:, 0, None], le[:, 0]]
        kb = key.reshape(m, 6)[e[:, 1, None], le[:, 1]]
        oa = np.argsort(ka, axis=1)
        ob = np.argsort(kb, axis=1)
        a = (6 * e[:, 0, None] + np.take_along_axis(le[:, 0], oa, axis=1)).ravel()
        b = (6 * e[:, 1, None] + np.take_along_axis(le[:, 1], ob, axis=1)).ravel()
    else:
        a = b = np.zeros(0, dtype=np.int64)
    return key, connected_components(6 * m, a, b)


def _local_edge(a: int, b: int) -> int:
    from .mesh import TET_EDGES

    lo, hi = min(a, b), max(a, b)
    return int(np.flatnonzero((TET_EDGES[:, 0] == lo) & (TET_EDGES[:, 1] == hi))[0])


def separate_edge_fans(tets: np.ndarray, vertex_count: int, dirty: np.ndarray | None = None):
    """Removes non-manifold edges: where the elements around an edge form several fans (crack surfaces meeting at
    the edge from two sides), every fan but the first (lowest slot) gets a new copy of the edge's lower vertex, which
    cuts the faces joining that fan to the rest of the vertex's elements (the crack grows by those faces).

    ``tets`` may be a subset holding every element of each ``dirty`` vertex (bool [vertex_count]); then only edges with
    a dirty endpoint are examined (their fans are complete in the subset).

    Returns (new tets, parent, changed)."""
    from .mesh import TET_EDGES

    tets = np.asarray(tets, dtype=np.int64)
    m = tets.shape[0]
    key, labels = _edge_fans(tets)
    # fans per edge key: unique (key, label), first fan of each key (lowest slot) is kept
    slot = np.arange(6 * m)
    fan_first = np.full(labels.max() + 1, 6 * m, dtype=np.int64)
    np.minimum.at(fan_first, labels, slot)
    fan_key = key[fan_first]
    order = np.lexsort((fan_first, fan_key))
    keep = np.ones(len(order), dtype=bool)
    keep[1:] = fan_key[order][1:] != fan_key[order][:-1]
    if dirty is not None:
        n_key = int(tets.max()) + 1
        keep |= ~(dirty[fan_key[order] // n_key] | dirty[fan_key[order] % n_key])
    extra_fans = order[~keep]  # fan labels that need a new vertex
    parent = np.arange(vertex_count)
    if extra_fans.size == 0:
        return tets, parent, False
    new_vertex = np.full(labels.max() + 1, -1, dtype=np.int64)
    new_vertex[extra_fans] = vertex_count + np.arange(extra_fans.size)
    slot_new = new_vertex[labels]
    sel = np.flatnonzero(slot_new >= 0)
    elem, loc = sel // 6, sel % 6
    lower = np.minimum(tets[elem, TET_EDGES[loc, 0]], tets[elem, TET_EDGES[loc, 1]])
    corner = np.argmax(tets[elem] == lower[:, None], axis=1)
    out = tets.copy()
    out[elem, corner] = slot_new[sel]
    n = int(tets.max()) + 1
    parent = np.concatenate([parent, fan_key[extra_fans] // n])
    return out, parent, True


def make_manifold(tets: np.ndarray, vertex_count: int, dirty_vertices=None, *, max_rounds: int = 50):
    """:func:`separate_pieces`, then :func:`separate_edge_fans` and again until no edge has several fans.

    With ``dirty_vertices`` (the vertices just split and their copies) the work is local: only the vertices sharing
    an element with a dirty vertex can change (a face's identity changes only when one of its vertices does), so the
    graphs are built on the elements around them; without, the whole mesh is examined. Returns (new tets, parent)."""
    tets = np.array(tets, dtype=np.int64)
    parent = np.arange(vertex_count)
    seeds = None if dirty_vertices is None else np.unique(np.asarray(dirty_vertices, dtype=np.int64))
    for _ in range(max_rounds):
        nv = len(parent)
        if seeds is None:
            sub = np.arange(len(tets))
            dirty = np.ones(nv, dtype=bool)
        else:
            near = np.zeros(nv, dtype=bool)
            near[seeds] = True
            around = np.flatnonzero(near[tets].any(axis=1))
            dirty = np.zeros(nv, dtype=bool)
            dirty[tets[around].ravel()] = True
            sub = np.flatnonzero(dirty[tets].any(axis=1))
        part, p1 = separate_pieces(tets[sub], nv, relabel=dirty)
        dirty = np.concatenate([dirty, np.ones(len(p1) - nv, dtype=bool)])
        part2, p2, changed = separate_edge_fans(part, len(p1), dirty)
        tets[sub] = part2
        parent = parent[p1[p2]]
        if not changed:
            break
        # the vertices cut by the fan separation (and their copies) seed the next round
        moved = np.flatnonzero(p2 != np.arange(len(p2)))
        seeds = np.unique(np.concatenate([moved, p2[moved]]))
    return tets, parent


def element_pieces(tets: np.ndarray):
    """Face-connected pieces: (piece count, piece label per element int64 [element_count]); pieces are numbered 0,
    1, ... in the order of their smallest element (pdsim.graph.connected_components)."""
    from ..graph import connected_components

    m = len(tets)
    pairs = interior_face_pairs(tets) // 4
    labels = connected_components(m, pairs[:, 0], pairs[:, 1])
    return (int(labels.max()) + 1 if m else 0), labels


def closed_surface_defects(faces: np.ndarray) -> int:
    """Number of directed edges of a triangle surface that do not have exactly one opposite edge, or that occur more
    than once (0 for a closed, consistently oriented, edge-manifold surface)."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return 0
    a = f[:, [0, 1, 2]].ravel()
    b = f[:, [1, 2, 0]].ravel()
    n = int(f.max()) + 1
    fwd = a * n + b
    rev = b * n + a
    uf, cf = np.unique(fwd, return_counts=True)
    dup = int((cf > 1).sum())
    missing = int((~np.isin(rev, uf)).sum())
    return dup + missing
