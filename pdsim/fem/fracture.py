"""Topology changes of the fracturing FEM solid: crack-plane vertex splits, separation of pieces, boundary surfaces,
fracture energy.

The crack computation splits vertices, never elements: every element keeps its corners' rest positions, so no element
is created, inverted or degenerate, element arrays keep their meaning and the stable step does not change. A crack
surface is therefore made of element faces; what keeps it on the fracture plane (instead of a path along faces that
drifts away from it) is that each crack carries its plane.
For the elements whose largest principal stress exceeds their tensile strength, in one step:

1. the normal n: the direction of the largest principal stress of the volume-weighted mean stress over two vertex
   rings of elements around the element (:func:`separation_directions`; the single element's stress is noisy at a
   crack tip, where a coarse mesh mixes opening and shear around the split vertices);
2. the plane (:func:`choose_splits`): an element touching vertices of a crack (crack tips), or with one within
   NEAR_CRACK element sizes, continues that crack in its plane (the mean point and normal of the tips' planes; a
   crack keeps its normal, CRACK_TURN = 0); otherwise a new crack starts, through the corner nearest the plane
   through the element's centroid normal to n;
3. the vertex v: among the element's corners that leave at least MIN_SIDE elements on each side of the plane, the one
   nearest it (crack tips first on ties, then corner order); an element without one is skipped (it tries again
   later);
4. the new crack's plane is moved along n by one of PLANE_SHIFTS times the size of v's element star, the one whose
   opened surface has its vector area closest to n, a side left in several face-connected groups costing a score of
   1 per extra group (:func:`best_offsets`); on a structured mesh the six tetrahedra of a cube share its diagonal and
   a plane through their centroids leans the crack along it, while a moved plane keeps whole cubes on one side;
5. the elements around v are divided by the side of the plane their rest centroid lies on (:func:`plane_side`: a
   centroid within TIE of the plane is decided by a second direction in the plane), and those on the positive side
   get a new copy of v (same rest position, position and velocity); v and its copy keep the plane (its point moved
   to their projection onto it).

An element causes at most one split in its life (the solver then sets its strength to infinity): the load it sheds
moves to its neighbours along the crack front, which split in turn. Several elements over the threshold in one step
are split together (vectorised numpy over those elements): in order of decreasing stress (ties by element index), at
most one split per vertex per step. Deterministic.

After the splits, :func:`make_manifold` (:func:`separate_pieces`, :func:`separate_edge_fans`) duplicates every vertex
whose incident elements are no longer connected through faces that contain it and every edge held by several fans of
elements. This separates pieces that only touch at an edge or a point, and keeps every piece's boundary a closed
surface in which each edge has exactly two faces. It is a slot-graph construction (nodes: element corners, edges:
corners of one vertex in two elements sharing a face) labelled by pdsim.fragment_labels.connected_components (the one
labeller of pdsim), local to the split vertices, run only on steps where some element exceeded its strength.

Fracture energy (``FemBody(fracture_energy=G_c)`` [J/m^2], 0 by default):

- Griffith test (:func:`griffith_filter`): the step's splits and the separations they cause are made tentatively; a
  split is kept when the strain energy of the elements around its vertex (each element's energy shared by the splits
  around it), less the energy its vertices still owe, is at least G_c times the crack area A_s it opens (half the
  area of the faces it turns into boundary faces: both sides are counted; faces away from the split vertices go to
  the nearest split). The others are dropped and the rest made again, up to GRIFFITH_ROUNDS rounds (the solver).
- Dissipation (:func:`pay_fracture_energy`): every new crack face owes G_c times its area (one side), a third on
  each of its vertices. Each following step, the vertices owing energy and those sharing an element with them form
  groups; a group's free vertices' velocities relative to their mass-weighted mean are scaled so that its kinetic
  energy falls by min(relative kinetic energy, debt), which is subtracted from the debt. Momentum is unchanged and
  energy is never added.
- Energy balance: a split changes no position, velocity or element (the copies share their parent's lumped mass, the
  elements keep their strain), so it conserves kinetic plus strain energy exactly; the energy then falls by exactly
  what is paid, G_c times the crack area once the debt is paid (solver.crack_area, solver.fracture_dissipated;
  tests/test_fem_fracture.py: an overloaded bar, within 2 % of its initial energy, the time integration's error).

Limitations: a crack surface is a staircase of element faces: a piece's crack area is 1.08 (pull along a mesh axis) to
1.62 times the area of the section it spans on the plates of tests/test_fem_fracture.py (docs/fem_fracture.md); a crack
keeps the plane it started with (it does not curve; a new crack starts where an over-strength element has no crack
within NEAR_CRACK element sizes).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..fragment_labels import connected_components
from .mesh import TET_EDGES, TET_FACES, boundary_faces, interior_face_pairs, stable_order

MIN_SIDE = 2  # elements each side of a crack plane must keep around the split vertex
NEAR_CRACK = 2.0  # an over-stressed element continues a crack whose vertex is within this many element sizes
CRACK_TURN = 0.0  # weight of the element's direction against the crack's normal when a crack continues
PLANE_SHIFTS = (0.0, -0.35, 0.35)  # plane moves tried per split, in star sizes (the first wins ties)
TIE = 0.05  # a centroid this close to a crack plane (relative to the element size) is on it
SEPARATION_RINGS = 2  # vertex rings of elements over which the stress is averaged for the crack-plane normal

__all__ = [
    "best_offsets",
    "boundary_faces",
    "can_split",
    "choose_splits",
    "closed_surface_defects",
    "element_pieces",
    "griffith_filter",
    "make_manifold",
    "opened_faces",
    "pay_fracture_energy",
    "plane_side",
    "separate_edge_fans",
    "separate_pieces",
    "separation_directions",
    "split_vertices",
    "triangle_areas",
    "vertex_incidence",
]


def vertex_incidence(tets: np.ndarray, vertex_count: int):
    """CSR list of the corner slots (4 e + a) of each vertex: (offsets [vertex_count + 1], slots [4 element_count]),
    slots of a vertex in increasing order."""
    flat = np.asarray(tets, dtype=np.int64).ravel()
    slots = stable_order(flat)
    counts = np.bincount(flat, minlength=vertex_count)
    offsets = np.zeros(vertex_count + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    return offsets, slots


def can_split(tets: np.ndarray, elements: np.ndarray, vertex_count: int) -> np.ndarray:
    """Whether each of ``elements`` [k] has a corner with at least 2 MIN_SIDE elements around it (bool [k]). A split
    keeps MIN_SIDE of its corner's elements on each side of its plane (:func:`choose_splits`), so an element without
    such a corner (a lone element, one of a small group) never splits, whatever its stress: leaving it out of
    choose_splits changes none of the splits it picks."""
    counts = np.bincount(np.asarray(tets, dtype=np.int64).ravel(), minlength=vertex_count)
    return (counts[np.asarray(tets)[np.asarray(elements, dtype=np.int64)]] >= 2 * MIN_SIDE).any(axis=1)


def _expand_incident(vertices: np.ndarray, offsets: np.ndarray, slots: np.ndarray):
    """For each query vertex, its incident slots: (query index per entry, slot per entry), vectorised."""
    counts = offsets[vertices + 1] - offsets[vertices]
    rep = np.repeat(np.arange(len(vertices)), counts)
    start = np.repeat(offsets[vertices] - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return rep, slots[start + np.arange(int(counts.sum()))]


def plane_side(offset: np.ndarray, normal: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Whether points at ``offset`` [p, 3] from a plane's point lie on the positive side of the plane of unit
    ``normal`` [p, 3]. A point within TIE (relative to |``scale``| [p, 3], the element's size) of the plane is decided
    by a second direction in the plane, n x e with e the axis least aligned with n: on a structured mesh whole classes
    of elements have their centroid exactly on a crack plane, and sending them all to one side makes the crack surface
    lean (through a plate's thickness, for instance); the second direction sends mirror-image elements to opposite
    sides."""
    d = np.einsum("ij,ij->i", offset, normal)
    side = d > 0.0
    tied = np.flatnonzero(np.abs(d) <= TIE * np.linalg.norm(scale, axis=1))
    if tied.size:
        nt = normal[tied]
        second = np.cross(nt, np.eye(3)[np.argmin(np.abs(nt), axis=1)])
        side[tied] = np.einsum("ij,ij->i", offset[tied], second) > 0.0
    return side


def choose_splits(
    tets: np.ndarray,
    rest: np.ndarray,
    centroids: np.ndarray,
    elements: np.ndarray,
    directions: np.ndarray,
    stresses: np.ndarray,
    crack_vertex: np.ndarray,
    crack_plane: np.ndarray,
    *,
    incidence=None,
):
    """Picks the vertex and plane of each split.

    Args:
        tets: current element corners, [element_count, 4].
        rest: rest positions of the vertices [m], [vertex_count, 3].
        centroids: rest centroids of the elements [m], [element_count, 3].
        elements: elements over their strength, [k].
        directions: their crack-plane normals (rest frame, unit; :func:`separation_directions`), [k, 3].
        stresses: their largest principal stresses [Pa], [k].
        crack_vertex: vertices already on a crack surface, bool [vertex_count].
        crack_plane: per vertex, the crack plane it was split on: (point [m], unit normal), [vertex_count, 6] (NaN
            rows: not split on a plane).
        incidence: :func:`vertex_incidence` of ``tets`` when the caller has it (computed otherwise).

    Returns:
        (vertices [s], normals [s, 3], elements [s], anchors [s, 3], new_crack [s]): at most one split per vertex, in
        order of decreasing stress, with the element that caused each, a point of its plane and whether it starts a
        new crack (see the module docstring).
    """
    k = len(elements)
    if k == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, np.zeros((0, 3)), empty, np.zeros((0, 3)), np.zeros(0, dtype=bool)
    offsets, slots = vertex_incidence(tets, len(rest)) if incidence is None else incidence
    elements = np.asarray(elements, dtype=np.int64)
    cand = np.asarray(tets[elements], dtype=np.int64)  # [k, 4]
    n = np.asarray(directions, dtype=np.float64).copy()
    tip = crack_vertex[cand]
    planes = crack_plane[cand]  # [k, 4, 6]
    has = tip & np.isfinite(planes[..., 0])
    # an element near a crack but not touching it continues that crack: the plane of the nearest crack vertex
    # within NEAR_CRACK times the element's size (largest corner distance from its centroid)
    plane = np.zeros((k, 6))
    count = has.sum(axis=1)
    known = np.flatnonzero(crack_vertex & np.isfinite(crack_plane[:, 0]))
    lone = np.flatnonzero(count == 0)
    near_plane = np.full(k, -1, dtype=np.int64)
    if known.size and lone.size:
        size = np.linalg.norm(rest[cand[lone]] - centroids[elements[lone]][:, None, :], axis=2).max(axis=1)
        dist_near, near = cKDTree(rest[known]).query(centroids[elements[lone]], k=1)
        close = dist_near <= NEAR_CRACK * size
        near_plane[lone[close]] = known[near[close]]
    # the crack's plane: mean of the tip corners' planes (normals aligned with the element's direction)
    sign = np.where(np.einsum("kaj,kj->ka", np.nan_to_num(planes[..., 3:]), n) < 0.0, -1.0, 1.0)
    w = has.astype(np.float64)
    plane[:, :3] = np.einsum("ka,kaj->kj", w, np.nan_to_num(planes[..., :3])) / np.maximum(count, 1)[:, None]
    plane[:, 3:] = np.einsum("ka,kaj->kj", w * sign, np.nan_to_num(planes[..., 3:]))
    use_near = near_plane >= 0
    plane[use_near] = crack_plane[near_plane[use_near]]
    plane[use_near, 3:] *= np.where(np.einsum("kj,kj->k", plane[use_near, 3:], n[use_near]) < 0.0, -1.0, 1.0)[:, None]
    anchored = (count > 0) | use_near
    # a continuing crack keeps its plane's point and turns its normal toward the element's direction by CRACK_TURN
    length = np.linalg.norm(plane[anchored, 3:], axis=1, keepdims=True)
    # (tip planes whose normals cancel, all perpendicular to the element's direction: the element's direction)
    crack_n = np.where(length > 1.0e-6, plane[anchored, 3:] / np.maximum(length, 1.0e-300), n[anchored])
    turned = crack_n + CRACK_TURN * n[anchored]
    n[anchored] = turned / np.linalg.norm(turned, axis=1, keepdims=True)
    anchor = np.where(anchored[:, None], plane[:, :3], centroids[elements])
    # distance of each corner to the crack plane (the centroid plane for a new crack)
    dist = np.abs(np.einsum("kaj,kj->ka", rest[cand] - anchor[:, None, :], n))
    # the plane each candidate corner would split on: the crack's (anchored), else through the corner itself
    origin = np.where(anchored[:, None, None], anchor[:, None, :], rest[cand]).reshape(-1, 3)  # [4k, 3]
    # validity: both sides of the plane keep at least MIN_SIDE of the candidate's elements
    flat = cand.ravel()
    rep, inc_slots = _expand_incident(flat, offsets, slots)
    inc_elem = inc_slots // 4
    normal_rep = np.repeat(n, 4, axis=0)[rep]
    side = plane_side(centroids[inc_elem] - origin[rep], normal_rep, rest[flat[rep]] - centroids[inc_elem])
    plus = np.bincount(rep, weights=side, minlength=4 * k)
    total = np.bincount(rep, minlength=4 * k)
    valid = ((plus >= MIN_SIDE) & (total - plus >= MIN_SIDE)).reshape(k, 4)
    # per element (primary key): valid first, then nearest the plane, crack tips first, corner order
    row = np.repeat(np.arange(k), 4)
    corner = np.tile(np.arange(4), k)
    key = np.lexsort((corner, ~tip.ravel(), dist.ravel(), ~valid.ravel(), row))
    best = corner[key[::4]]
    ok = valid[np.arange(k), best]
    chosen = cand[np.arange(k), best][ok]
    normals = n[ok]
    source = elements[ok]
    anchor = np.where(anchored[:, None], anchor, rest[cand[np.arange(k), best]])[ok]
    new_crack = ~anchored[ok]
    strength_order = np.lexsort((source, -np.asarray(stresses, dtype=np.float64)[ok]))
    chosen, normals, source, anchor, new_crack = (
        a[strength_order] for a in (chosen, normals, source, anchor, new_crack)
    )
    _, first_idx = np.unique(chosen, return_index=True)
    keep = np.sort(first_idx)
    return chosen[keep], normals[keep], source[keep], anchor[keep], new_crack[keep]


def separation_directions(
    tets: np.ndarray, elements: np.ndarray, stress_of, volumes: np.ndarray, own: np.ndarray, *, incidence=None
):
    """Crack-plane normals of ``elements`` [k]: the direction of the largest principal stress of the volume-weighted
    mean stress over each element's neighbourhood (the elements sharing a vertex with it, each counted once per shared
    vertex), a nonlocal average in the spirit of O'Brien and Hodgins' separation tensor, averaged at the nodes. The
    single element's stress is noisy at a crack tip, where the stress of a coarse mesh mixes opening and shear around
    the split vertices; the average follows the load.

    Args:
        tets: element corners [m, 4]; elements: [k].
        stress_of: callable, element ids [r] -> their Cauchy stresses in the rest frame [Pa], [r, 3, 3].
        volumes: element volumes [m^3], [m].
        own: the elements' own principal directions [k, 3] (the signs of the result follow them).
        incidence: :func:`vertex_incidence` of ``tets`` when the caller has it (computed otherwise).

    Returns unit normals [k, 3]."""
    elements = np.asarray(elements, dtype=np.int64)
    k = len(elements)
    if k == 0:
        return np.zeros((0, 3))
    tets = np.asarray(tets, dtype=np.int64)
    m = len(tets)
    offsets, slots = vertex_incidence(tets, int(tets.max()) + 1) if incidence is None else incidence
    group, elem = np.arange(k), elements
    for _ in range(SEPARATION_RINGS):
        corners = tets[elem]  # [p, 4]
        rep, inc_slots = _expand_incident(corners.ravel(), offsets, slots)
        pair = np.unique(np.repeat(group, 4)[rep] * m + inc_slots // 4)
        group, elem = pair // m, pair % m
    ring, inverse = np.unique(elem, return_inverse=True)
    sigma = np.asarray(stress_of(ring), dtype=np.float64).reshape(-1, 9)[inverse]
    w = np.abs(np.asarray(volumes, dtype=np.float64)[ring])[inverse]
    t = np.stack([np.bincount(group, weights=w * sigma[:, i], minlength=k) for i in range(9)], axis=1)
    _, vecs = np.linalg.eigh(t.reshape(k, 3, 3))
    out = vecs[:, :, 2]
    sign = np.where(np.einsum("ij,ij->i", out, np.asarray(own, dtype=np.float64)) < 0.0, -1.0, 1.0)
    return out * sign[:, None]


def best_offsets(tets, rest, centroids, vertices, normals, anchors, search, *, incidence=None):
    """The plane point of each split, chosen among the crack plane moved along its normal by PLANE_SHIFTS times the
    vertex's star size (RMS distance of its elements' centroids from it): the one whose opened surface (the faces
    around the vertex between elements on different sides) has its vector area closest to the plane's normal, the
    unmoved plane on ties. Elements are whole, so the opened surface is a staircase of their faces; on a structured
    mesh a plane through element centroids cuts cells whose internal faces all lean one way (the six tetrahedra of a
    cube share its diagonal), and moving the plane by part of a cell keeps whole cells on one side. Only the splits
    that start a crack (``search``, bool [s]) move their plane; the crack then keeps it. Returns the plane
    points [s, 3] (:func:`split_vertices`' ``anchors``) and whether each split has a valid plane (bool [s]: each
    side keeps at least MIN_SIDE elements). A plane that leaves a side in several groups (connected through faces
    containing the vertex) loses 1 of its score per extra group: the extra groups become chips or side cracks.
    ``incidence``: :func:`vertex_incidence` of ``tets`` when the caller has it (computed otherwise)."""
    vertices = np.asarray(vertices, dtype=np.int64)
    k = len(vertices)
    normals = np.asarray(normals, dtype=np.float64)
    anchors = np.asarray(anchors, dtype=np.float64)
    if k == 0:
        return anchors, np.zeros(0, dtype=bool)
    tets = np.asarray(tets, dtype=np.int64)
    m = len(tets)
    offsets, slots = vertex_incidence(tets, len(rest)) if incidence is None else incidence
    rep, inc_slots = _expand_incident(vertices, offsets, slots)
    elem, corner = inc_slots // 4, inc_slots % 4
    c_off = centroids[elem] - rest[vertices][rep]
    size = np.sqrt(
        np.bincount(rep, weights=np.einsum("ij,ij->i", c_off, c_off), minlength=k)
        / np.maximum(np.bincount(rep, minlength=k), 1)
    )
    # (split, element) -> entry, for the neighbours across the faces containing the vertex
    key = rep * m + elem
    order = stable_order(key)
    sub = np.unique(elem)
    local = np.full(m, -1, dtype=np.int64)
    local[sub] = np.arange(len(sub))
    partner = np.full(4 * len(sub), -1, dtype=np.int64)
    pairs = interior_face_pairs(tets[sub])
    if len(pairs):
        partner[pairs[:, 0]] = pairs[:, 1] // 4
        partner[pairs[:, 1]] = pairs[:, 0] // 4
    opposite = np.array([3, 2, 1, 0])  # the corner each face of TET_FACES leaves out
    ent = np.repeat(np.arange(len(rep)), 4)
    face = np.tile(np.arange(4), len(rep))
    has_v = opposite[face] != corner[ent]
    ent, face = ent[has_v], face[has_v]
    nb = partner[4 * local[elem[ent]] + face]
    inside = nb >= 0
    ent, face, nb = ent[inside], face[inside], sub[nb[inside]]
    pos = np.searchsorted(key[order], rep[ent] * m + nb)
    nb_ent = order[pos]
    tri = rest[tets[elem[ent]][np.arange(len(ent))[:, None], TET_FACES[face]]]
    area = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # outward from the entry's element
    best = np.full(k, -np.inf)
    out = anchors.copy()
    n_ent = len(rep)
    for shift in PLANE_SHIFTS:
        origin = anchors + (shift * size)[:, None] * normals
        side = plane_side(centroids[elem] - origin[rep], normals[rep], c_off)
        plus = np.bincount(rep, weights=side, minlength=k)
        total = np.bincount(rep, minlength=k)
        # each side a single group, connected through faces containing the vertex (no chips, no side cracks)
        same = side[ent] == side[nb_ent]
        labels = connected_components(n_ent, ent[same], nb_ent[same])
        groups = np.unique(rep * n_ent + labels) // n_ent
        valid = (plus >= MIN_SIDE) & (total - plus >= MIN_SIDE) & (search | (shift == 0.0))
        extra = np.bincount(groups, minlength=k) - 2  # groups beyond one per side: each costs a score of 1
        cut = side[ent] & ~side[nb_ent]
        vec = np.stack([np.bincount(rep[ent[cut]], weights=area[cut, d], minlength=k) for d in range(3)], axis=1)
        cos = -np.einsum("ij,ij->i", vec, normals) / np.maximum(np.linalg.norm(vec, axis=1), 1.0e-300) - extra
        better = valid & (cos > best + 1.0e-9)
        best[better] = cos[better]
        out[better] = origin[better]
    return out, np.isfinite(best)


def split_vertices(
    tets: np.ndarray,
    rest: np.ndarray,
    centroids: np.ndarray,
    vertices: np.ndarray,
    normals,
    anchors=None,
    *,
    incidence=None,
):
    """Duplicates each vertex v_s for the elements around it whose rest centroid lies on the positive side of the
    plane through ``anchors[s]`` (default: v_s itself) normal to n_s. Returns (new tets, parent): parent[i] is the
    original vertex of vertex i (identity for the old ones; v_s for the copy vertex_count + s). ``incidence``:
    :func:`vertex_incidence` of ``tets`` when the caller has it (computed otherwise)."""
    tets = np.array(tets, dtype=np.int64)
    nv = len(rest)
    vertices = np.asarray(vertices, dtype=np.int64)
    parent = np.concatenate([np.arange(nv), vertices])
    if len(vertices) == 0:
        return tets, parent
    origin = rest[vertices] if anchors is None else np.asarray(anchors, dtype=np.float64)
    offsets, slots = vertex_incidence(tets, nv) if incidence is None else incidence
    rep, inc_slots = _expand_incident(vertices, offsets, slots)
    c = centroids[inc_slots // 4]
    side = plane_side(c - origin[rep], np.asarray(normals)[rep], rest[vertices][rep] - c)
    flat = tets.ravel()
    flat[inc_slots[side]] = nv + rep[side]
    return flat.reshape(-1, 4), parent


def opened_faces(before: np.ndarray, after: np.ndarray):
    """Faces a topology change opened: interior in ``before``, boundary in ``after`` (the same elements with new
    corners, [element_count, 4] each). Returns (faces [f, 3] in ``after``'s numbering, wound outward, element [f]);
    an opened interior face appears twice, once for each side. Local: only the elements around the vertices whose
    corners changed are examined."""
    before = np.asarray(before, dtype=np.int64)
    after = np.asarray(after, dtype=np.int64)
    changed = before != after
    if not changed.any():
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    touched = np.zeros(int(before.max()) + 1, dtype=bool)
    touched[before[changed]] = True
    sub = np.flatnonzero(touched[before].any(axis=1))
    _, fid0 = boundary_faces(before[sub], return_face_ids=True)
    faces1, fid1 = boundary_faces(after[sub], return_face_ids=True)
    new = ~np.isin(fid1, fid0)
    return faces1[new].astype(np.int64), sub[fid1[new] // 4]


def triangle_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Areas of triangles ``faces`` [f, 3] over ``points`` [n, 3] [m^2]."""
    x = points[np.asarray(faces, dtype=np.int64)]
    return 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)


def griffith_filter(tets, rest, vertices, tets_split, parent, element_energy, fracture_energy, sources, debt):
    """Which splits pay for their crack (Griffith): split s is kept when the strain energy of the elements around its
    vertex, sum W_e / k_e [J] (the most the split can release; k_e: the number of this step's splits around element
    e, which share its energy) less the fracture energy its vertices still owe (``debt`` [J] per vertex, shared the
    same way), is at least G_c of its source element times the crack area A_s it opens (half the area of the faces
    it turns into boundary faces, both sides counted). A face opened by several splits of the step is charged to the
    first of them, a face that holds no split vertex (a separation of pieces) to the split nearest to it.

    Args:
        tets, rest: corners and rest positions [m] before the splits.
        vertices: the split vertices [s]; tets_split, parent: the corners after the splits (and the separations
            they cause, :func:`make_manifold`) and the original vertex of each vertex.
        element_energy: strain energy per element [J]; fracture_energy: G_c per element [J/m^2]; sources: the element
            of each split [s].

    Returns:
        (keep bool [s], crack area A_s [m^2] [s], available energy [J] [s]).
    """
    vertices = np.asarray(vertices, dtype=np.int64)
    s = len(vertices)
    faces, _ = opened_faces(tets, tets_split)
    index = np.full(len(rest), s, dtype=np.int64)
    index[vertices] = np.arange(s)
    original = np.asarray(parent)[faces]
    owner = index[original].min(axis=1)
    area = triangle_areas(rest, original)
    lone = owner == s  # opened by the separation of pieces, away from the split vertices: the nearest split's
    if lone.any():
        owner[lone] = cKDTree(rest[vertices]).query(rest[original[lone]].mean(axis=1), k=1)[1]
    a_s = np.bincount(owner, weights=0.5 * area, minlength=s)
    offsets, slots = vertex_incidence(tets, len(rest))
    rep, inc_slots = _expand_incident(vertices, offsets, slots)
    elem = inc_slots // 4
    shared = np.bincount(elem, minlength=len(tets))[elem]  # an element's energy is shared by the splits around it
    e_s = np.bincount(rep, weights=np.asarray(element_energy, dtype=np.float64)[elem] / shared, minlength=s)
    # less the fracture energy its vertices still owe (each vertex's debt shared by the splits around it)
    pair = np.unique(np.repeat(rep, 4) * len(rest) + np.asarray(tets, dtype=np.int64)[elem].ravel())
    split_of, vert = pair // len(rest), pair % len(rest)
    owed = np.asarray(debt, dtype=np.float64)[vert] / np.bincount(vert, minlength=len(rest))[vert]
    e_s -= np.bincount(split_of, weights=owed, minlength=s)
    keep = e_s >= np.asarray(fracture_energy, dtype=np.float64)[sources] * a_s
    return keep, a_s, e_s


def pay_fracture_energy(tets, mass, velocity, debt, free):
    """Takes the fracture energy still owed from the motion around the cracks, never adding energy.

    The vertices owing energy (``debt`` [J] > 0) and the vertices sharing an element with them form groups (connected
    through those elements). In each group the free vertices' velocities relative to their mass-weighted mean v_c are
    scaled by sqrt(1 - r / K_c), where K_c = sum 1/2 m |v - v_c|^2 is the group's kinetic energy relative to v_c and
    r = min(K_c, D_c) the part of its debt D_c paid now: the group's momentum is unchanged, its kinetic energy falls by
    exactly r, and the debts of its vertices fall by the fraction r / D_c.

    Args:
        tets: element corners [m, 4]; mass: vertex masses [kg] [n]; velocity: [n, 3] [m/s]; debt: [n] [J];
        free: bool [n], vertices whose velocity may change (those under a boundary condition keep theirs).

    Returns:
        (new velocities [n, 3], new debts [n], energy paid [J]).
    """
    owe = debt > 0.0
    if not owe.any():
        return velocity, debt, 0.0
    tets = np.asarray(tets, dtype=np.int64)
    n = len(mass)
    near = tets[owe[tets].any(axis=1)]
    member = np.zeros(n, dtype=bool)
    member[near.ravel()] = True
    a = np.concatenate([near[:, 0], near[:, 0], near[:, 0]])
    b = np.concatenate([near[:, 1], near[:, 2], near[:, 3]])
    labels = connected_components(n, a, b)
    idx = np.flatnonzero(member)
    lab = labels[idx]
    groups, g = np.unique(lab, return_inverse=True)
    k = len(groups)
    mv = np.where(free[idx], mass[idx], 0.0)
    v = velocity[idx]
    m_c = np.bincount(g, weights=mv, minlength=k)
    p_c = np.stack([np.bincount(g, weights=mv * v[:, d], minlength=k) for d in range(3)], axis=1)
    v_c = p_c / np.maximum(m_c, 1.0e-300)[:, None]
    rel = v - v_c[g]
    k_c = np.bincount(g, weights=0.5 * mv * np.einsum("ij,ij->i", rel, rel), minlength=k)
    d_c = np.bincount(g, weights=debt[idx], minlength=k)
    r = np.minimum(k_c, d_c)
    scale = np.sqrt(np.clip(1.0 - r / np.maximum(k_c, 1.0e-300), 0.0, 1.0))
    out_v = velocity.copy()
    moved = free[idx]
    out_v[idx[moved]] = v_c[g[moved]] + scale[g[moved], None] * rel[moved]
    out_debt = debt.copy()
    out_debt[idx] *= 1.0 - r[g] / np.maximum(d_c[g], 1.0e-300)
    out_debt[out_debt < 1.0e-12 * max(float(d_c.max()), 1.0e-300)] = 0.0
    return out_v, out_debt, float(r.sum())


def separate_pieces(tets: np.ndarray, vertex_count: int, relabel: np.ndarray | None = None):
    """Gives every face-connected group of a vertex's incident elements its own copy of the vertex.

    ``tets`` may be a subset of the mesh's elements that holds every element of each vertex to relabel; ``relabel``
    (bool [vertex_count]) limits the copies to those vertices (default: all; vertices outside may have incomplete
    stars in a subset and are left alone).

    Returns (new tets, parent) with parent[i] the original vertex of vertex i; vertex ids below ``vertex_count`` keep
    the group holding their lowest slot, new copies are numbered from ``vertex_count`` in (vertex, slot) order."""
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
    lo, hi = min(a, b), max(a, b)
    return int(np.flatnonzero((TET_EDGES[:, 0] == lo) & (TET_EDGES[:, 1] == hi))[0])


def separate_edge_fans(tets: np.ndarray, vertex_count: int, dirty: np.ndarray | None = None):
    """Removes non-manifold edges: where the elements around an edge form several fans (crack surfaces meeting at
    the edge from two sides), every fan but the first (lowest slot) gets a new copy of the edge's lower vertex, which
    cuts the faces joining that fan to the rest of the vertex's elements (the crack grows by those faces).

    ``tets`` may be a subset holding every element of each ``dirty`` vertex (bool [vertex_count]); then only edges with
    a dirty endpoint are examined (their fans are complete in the subset).

    Returns (new tets, parent, changed)."""
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
    1, ... in the order of their smallest element (pdsim.fragment_labels.connected_components)."""
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
