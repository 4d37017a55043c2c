"""The sliver clean-up's edits carried from one rebuild to the next (step 6 of the method in
:mod:`pdsim.fragment_surfaces`), so that a rebuild cleans only where the complex changed.

A rebuild keeps a record of its complex before the clean-up (raw) and after it (clean), in one vertex numbering
(the clean-up removes triangles, adds triangles and moves vertices, it never adds vertices). The difference between
the two falls into **edit clusters**: the connected sets of vertices joined by the triangles the clean-up removed or
added (a moved vertex removes and adds every triangle around it). Each cluster's removed triangles and added
triangles have the same boundary in every shell, so a cluster can be applied on its own.

The next rebuild builds its raw complex as before (the clips of unchanged regions are reused bit for bit) and applies
every cluster of the record whose neighbourhood it finds unchanged: every vertex of the cluster is a vertex of the
new complex (within 1e-9 spacings), and the new complex's triangles around the cluster's vertices are exactly the
record's raw triangles there, in shells and patches that map one to one. Those clusters' removed triangles are
replaced by their added triangles (shells and patches renamed to the new complex's) and their moved vertices take
their cleaned positions. The clean-up then runs on the result; its rounds start from the triangles still flagged
(slivers and short edges), which lie where the regions changed, at the seams where changed and unchanged regions
meet, and wherever the last clean-up had left a flagged triangle it could not improve.

Where nothing changed the result holds the last clean-up's triangles (the same clusters, the same operations); a
cluster whose neighbourhood changed is cleaned again from the raw complex.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

__all__ = ["apply_edits", "canonical_corners", "complex_record"]

MATCH_TOLERANCE = 1e-9  # a record vertex and a new vertex closer than this many spacings are one vertex


def complex_record(raw, clean, origin) -> dict:
    """The record of one clean-up: ``raw`` and ``clean`` are (points [m] [v, 3], tri [f, 3], shell [f], patch [f])
    of the complex before and after it, in one vertex numbering; ``origin`` [f_clean] the raw triangle whose slot each
    clean triangle holds (pdsim/fragment_surfaces/cleanup.py: clean_complex's ``origin``). Returns a dict of int64 /
    float64 arrays (``raw_points``, ``raw_tri``, ..., ``clean_patch``, ``clean_origin``) that :func:`apply_edits`
    reads (and a checkpoint can store)."""
    out = {"clean_origin": np.array(origin, dtype=np.int64)}
    for prefix, parts in (("raw", raw), ("clean", clean)):
        points, tri, shell, patch = parts
        out[f"{prefix}_points"] = np.array(points, dtype=np.float64)
        out[f"{prefix}_tri"] = np.array(tri, dtype=np.int64)
        out[f"{prefix}_shell"] = np.array(shell, dtype=np.int64)
        out[f"{prefix}_patch"] = np.array(patch, dtype=np.int64)
    return out


def _same_raw(record: dict, points, tri, shell, patch) -> bool:
    """Whether the raw complex (points, tri, shell, patch) is the record's raw complex, bit for bit."""
    return (
        np.array_equal(record["raw_points"], points)
        and np.array_equal(record["raw_tri"], tri)
        and np.array_equal(record["raw_shell"], shell)
        and np.array_equal(record["raw_patch"], patch)
    )


def canonical_corners(tri: np.ndarray) -> np.ndarray:
    """Triangles [f, 3] rotated so that their smallest vertex id comes first (orientation kept)."""
    first = np.argmin(tri, axis=1)
    return np.take_along_axis(tri, (first[:, None] + np.arange(3)) % 3, axis=1)


def _match_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For each row of int array ``a`` [n, k], the index of the equal row of ``b`` [m, k] (rows of ``b`` distinct),
    or -1. int64 [n]."""
    if len(a) == 0 or len(b) == 0:
        return np.full(len(a), -1, dtype=np.int64)
    both = np.concatenate([b, a])
    order = np.lexsort(both.T[::-1])
    rows = both[order]
    same = np.concatenate([[False], np.all(rows[1:] == rows[:-1], axis=1)])
    group = np.cumsum(~same) - 1  # equal rows share a group
    first_b = np.full(group[-1] + 1, -1, dtype=np.int64)
    from_b = order < len(b)
    first_b[group[from_b]] = order[from_b]
    out = np.full(len(a), -1, dtype=np.int64)
    from_a = ~from_b
    out[order[from_a] - len(b)] = first_b[group[from_a]]
    return out


def _unique_rows(a: np.ndarray) -> np.ndarray:
    """The distinct rows of int array ``a`` [n, k], sorted lexicographically: ``np.unique(a, axis=0)``, by a sort
    of one int64 key per row (a lexsort when the key would not fit) instead of a sort of the rows as records."""
    if len(a) == 0:
        return a
    low = a.min(axis=0)
    span = a.max(axis=0).astype(np.int64) - low + 1
    if float(np.prod(span.astype(np.float64))) < 2.0**62:
        key = np.zeros(len(a), dtype=np.int64)
        for j in range(a.shape[1]):
            key = key * span[j] + (a[:, j] - low[j])
        first = np.unique(key, return_index=True)[1]
        return a[first]
    rows = a[np.lexsort(a.T[::-1])]
    return rows[np.concatenate([[True], np.any(rows[1:] != rows[:-1], axis=1)])]


def _pair_map(cluster, old, new, bad):
    """Per (cluster, old id) the one new id its matched triangles show; clusters where an old id shows two new ids
    are marked in ``bad`` (bool [clusters], changed in place). Returns (sorted keys [k, 2], new id of each [k])."""
    rows = _unique_rows(np.stack([cluster, old, new], axis=1))
    if len(rows) == 0:  # no matched triangle in any cluster
        return rows[:, :2], rows[:, 2]
    key = rows[:, :2]
    dup = np.all(key[1:] == key[:-1], axis=1)
    bad[rows[1:, 0][dup]] = True
    keep = np.concatenate([[True], ~dup])
    return key[keep], rows[keep, 2]


def _lookup(keys, values, query, bad, cluster):
    """Values of ``query`` rows [q, 2] among ``keys`` (from :func:`_pair_map`); clusters of missing rows are marked in
    ``bad``. Returns int64 [q] (-1 where missing)."""
    at = _match_rows(query, keys)
    bad[cluster[at < 0]] = True
    if len(values) == 0:
        return np.full(len(query), -1, dtype=np.int64)
    return np.where(at >= 0, values[np.maximum(at, 0)], -1)


def apply_edits(record: dict, points, tri, shell, patch, spacing: float):
    """Applies the record's edit clusters (see the module's docstring) to a new raw complex.

    Args:
        record: from :func:`complex_record` (the last rebuild's).
        points: the new complex's vertices [m] [v, 3]; tri: triangles [f, 3]; shell, patch: per triangle [f].
        spacing: particle spacing h [m].

    Returns:
        (points [v, 3] (a copy, moved vertices at their cleaned positions), tri [f', 3], shell [f'], patch [f'],
        slot [f'] (the new raw triangle whose slot each triangle holds, ascending: an added triangle takes the slot
        of the raw triangle it replaced), settled [f'] (bool: the triangle is the last clean-up's, and so is every
        triangle within two rings of it; cleanup.py: clean_complex's ``settled``), number of clusters applied,
        number of clusters). When the raw complex is the record's, bit for bit, the record's cleaned complex itself
        (and -1 clusters).
    """
    if _same_raw(record, points, tri, shell, patch):
        clean = [record[f"clean_{k}"] for k in ("points", "tri", "shell", "patch", "origin")]
        return (*clean, np.ones(len(clean[1]), dtype=bool), -1, -1)
    rp, rt, rs, rpa = (record[f"raw_{k}"] for k in ("points", "tri", "shell", "patch"))
    cp, ct, cs, cpa, co = (record[f"clean_{k}"] for k in ("points", "tri", "shell", "patch", "origin"))
    none = np.zeros(len(tri), dtype=bool)
    unchanged = (np.asarray(points, dtype=np.float64).copy(), tri, shell, patch, np.arange(len(tri)), none, 0, 0)
    n_r = rp.shape[0]
    moved = np.any(cp != rp, axis=1)
    raw_rows = np.concatenate([rs[:, None], rt], axis=1)  # a triangle listed from another corner counts as changed
    clean_rows = np.concatenate([cs[:, None], ct], axis=1)
    removed = (_match_rows(raw_rows, clean_rows) < 0) | moved[rt].any(axis=1)
    added = (_match_rows(clean_rows, raw_rows) < 0) | moved[ct].any(axis=1)
    if not removed.any() and not added.any():
        return unchanged
    # Edit clusters: vertices joined by the removed and added triangles (and each added triangle to the raw
    # triangle whose slot it holds).
    et = np.concatenate([rt[removed], ct[added]])
    a = np.concatenate([et[:, 0], et[:, 1], ct[added, 0]])
    b = np.concatenate([et[:, 1], et[:, 2], rt[co[added], 0]])
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n_r, n_r))
    _, comp = connected_components(graph, directed=False)
    touched = np.zeros(n_r, dtype=bool)
    touched[et.ravel()] = True
    ids, cluster_of = np.unique(comp[touched], return_inverse=True)
    cluster = np.full(n_r, -1, dtype=np.int64)
    cluster[touched] = cluster_of
    n_c = len(ids)
    bad = np.zeros(n_c, dtype=bool)
    # Record vertices -> new vertices (one to one, within MATCH_TOLERANCE h).
    points = np.asarray(points, dtype=np.float64)
    near_r = np.flatnonzero((cluster[rt] >= 0).any(axis=1))  # record raw triangles around the clusters
    need_ids = np.arange(n_r)
    dist, at = cKDTree(points).query(rp[need_ids], distance_upper_bound=MATCH_TOLERANCE * spacing)
    vmap = np.full(n_r, -1, dtype=np.int64)
    found = np.isfinite(dist)
    vmap[need_ids[found]] = at[found]
    hit, hits = np.unique(vmap[vmap >= 0], return_counts=True)
    if np.any(hits > 1):  # two record vertices on one new vertex: their triangles cannot be told apart
        dup = np.isin(vmap, hit[hits > 1])
        vmap[dup] = -1
    # A triangle near a cluster names every cluster among its corners.
    corner_cluster = cluster[rt[near_r]]
    unmapped = (vmap[rt[near_r]] < 0).any(axis=1)
    for k in range(3):
        c = corner_cluster[:, k]
        bad[c[(c >= 0) & unmapped]] = True
    # The new triangles around the clusters must be the record's raw triangles there.
    new_cluster = np.full(points.shape[0], -1, dtype=np.int64)
    ok_v = vmap >= 0
    new_cluster[vmap[ok_v]] = cluster[ok_v]
    near_q = np.flatnonzero((new_cluster[tri] >= 0).any(axis=1))
    mapped_rows = canonical_corners(np.where(vmap[rt[near_r]] >= 0, vmap[rt[near_r]], -1 - rt[near_r]))
    q_of_r = _match_rows(mapped_rows, canonical_corners(tri[near_q]))
    r_of_q = _match_rows(canonical_corners(tri[near_q]), mapped_rows)
    for k in range(3):
        c = corner_cluster[:, k]
        bad[c[(c >= 0) & (q_of_r < 0)]] = True
        c = new_cluster[tri[near_q, k]]
        bad[c[(c >= 0) & (r_of_q < 0)]] = True
    # Shells and patches: record id -> new id, one to one per cluster.
    m = q_of_r >= 0
    pair_c, pair_r, pair_q = [], [], []
    for k in range(3):
        c = corner_cluster[:, k]
        sel = m & (c >= 0)
        pair_c.append(c[sel])
        pair_r.append(near_r[sel])
        pair_q.append(near_q[q_of_r[sel]])
    pc, pr, pq = np.concatenate(pair_c), np.concatenate(pair_r), np.concatenate(pair_q)
    shell_keys, shell_new = _pair_map(pc, rs[pr], shell[pq], bad)
    patch_keys, patch_new = _pair_map(pc, rpa[pr], patch[pq], bad)
    add_ids = np.flatnonzero(added)
    add_c = cluster[ct[add_ids, 0]]
    add_shell = _lookup(shell_keys, shell_new, np.stack([add_c, cs[add_ids]], axis=1), bad, add_c)
    add_patch = _lookup(patch_keys, patch_new, np.stack([add_c, cpa[add_ids]], axis=1), bad, add_c)
    # Apply the clusters that passed.
    rem_ids = np.flatnonzero(removed)
    rem_ids = rem_ids[~bad[cluster[rt[rem_ids, 0]]]]  # a passed cluster's raw triangles all have their new rows
    drop = near_q[q_of_r[np.searchsorted(near_r, rem_ids)]]
    keep = np.ones(len(tri), dtype=bool)
    keep[drop] = False
    take = ~bad[add_c]
    add_slot = near_q[q_of_r[np.searchsorted(near_r, co[add_ids[take]])]]
    out_points = points.copy()
    mv = np.flatnonzero(moved & (cluster >= 0))
    mv = mv[~bad[cluster[mv]]]
    out_points[vmap[mv]] = cp[mv]
    slot = np.concatenate([np.flatnonzero(keep), add_slot])
    order = np.argsort(slot, kind="stable")
    out_tri = np.concatenate([tri[keep], vmap[ct[add_ids[take]]]])[order]
    out_shell = np.concatenate([shell[keep], add_shell[take]])[order]
    out_patch = np.concatenate([patch[keep], add_patch[take]])[order]
    # The last clean-up's triangles: its unchanged raw triangles found here, and the applied clusters' added ones.
    every = canonical_corners(np.where(vmap[rt] >= 0, vmap[rt], -1 - rt))
    q_all = _match_rows(every, canonical_corners(tri))
    ours = np.zeros(len(tri), dtype=bool)
    ours[q_all[(q_all >= 0) & ~removed]] = True
    ours = np.concatenate([ours[keep], np.ones(int(take.sum()), dtype=bool)])[order]
    seed = np.zeros(len(out_points), dtype=bool)
    seed[out_tri[~ours]] = True
    ring = seed.copy()
    ring[out_tri[seed[out_tri].any(axis=1)]] = True
    settled = ours & ~ring[out_tri].any(axis=1)
    return out_points, out_tri, out_shell, out_patch, slot[order], settled, int(n_c - bad.sum()), int(n_c)
