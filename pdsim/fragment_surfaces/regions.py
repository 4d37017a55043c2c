"""Fragment regions of a body: closed regions, one per fragment, that partition a neighbourhood of the solid
exactly (steps 1-3 of the method in :mod:`pdsim.fragment_surfaces`).

1. **Label grid** (:func:`build_lattice_grid`, :func:`grid_labels`). A regular grid of the particle spacing h,
   aligned with the particle lattice (particles sit on grid vertices), covers the input mesh's bounding box plus
   three layers. A vertex holding a particle takes its fragment. The other vertices inside the solid or within 1.8 h
   of its surface take the fragment with the largest Gaussian-weighted vote (sigma = h) among their 16 nearest
   particles, which continues a crack straight through the surface layer. All remaining vertices are "outside". (A
   tetrahedron of the grid that meets the solid has every vertex within its diameter sqrt(3) h of the solid, so the
   labelled vertices' regions cover the solid.) With ``on_lattice=False`` every vertex is labelled by the vote: the
   FEM draws its cracked bodies over their mesh vertices, which are no lattice and coincide where fracture split them.
2. **Multi-label marching tetrahedra** (:func:`partition_regions`). Every grid cube is split into the 6 tetrahedra
   of the Freudenthal (Kuhn) triangulation, the same in every cube, so neighbouring tetrahedra share faces. In a
   tetrahedron whose vertices carry two labels the interface is the marching-tetrahedra triangle or quad through
   points on the edges joining different labels. With three or four labels, each face that joins three labels gets a
   "Y" from a point inside the face to its three edge points, and the interface is the fan of triangles from a point
   inside the tetrahedron to these face curves. Every interface point (edge point, face point, tetrahedron point) is
   keyed by the simplex it lies on, so the two fragments meeting at an interface use the very same triangles with
   opposite orientations: the regions partition space exactly (no gap, no overlap), and each region's boundary is a
   closed 2-manifold (binary marching tetrahedra is never ambiguous, and the part of a tetrahedron's boundary that
   belongs to one label is always a disc).
3. **Smooth cracks** (:func:`_edge_fractions`). Each end u of a crossing edge fits a plane to the staircase between
   its fragment and the fragment across the edge: to the midpoints of the axis-aligned grid edges that join those
   two fragments in the 5x5x5 block around u, Gaussian-weighted (sigma = h), normal to their direction of least
   variance. The edge point is where the two end planes cross the edge (their mean), clamped to
   ``0.5 +- crack_smoothing`` of the edge (0 gives midpoints, lattice-stepped cracks). An end at a one-vertex-thick
   feature (the vertex behind it along the edge has another label) keeps its half edge, so single-particle debris
   and one-layer slabs keep their lattice cell. Edge points only slide along their edges, and face and tetrahedron
   points are averages of edge points, so the smoothing can never fold the partition.
3b. **Clear of the surface** (:func:`_off_surface`). Off the lattice (jittered particles, FEM vertices) a crack
   point closer than 0.05 h to the input surface moves within its simplex to 0.05 h outside it, since the clip would
   leave needles there too small for any clean-up. On the lattice the surface lies half a spacing from the
   particles, so crack points lie on it exactly (the clean-up handles those) or well clear of it, and nothing moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp
from scipy.spatial import cKDTree

from ..geometry import SolidShape
from ..kernels import fragment_surfaces as kf

__all__ = ["LatticeGrid", "build_lattice_grid", "grid_labels", "partition_regions"]

# Freudenthal tetrahedra of the unit cube: for a permutation (a, b, c) of the axes the vertices are
# 0, e_a, e_a + e_b, (1, 1, 1), ordered componentwise, so every edge runs from a lower to a higher corner.
_PERMS = ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0))
_EDGES = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
_EDGE_INDEX = {e: i for i, e in enumerate(_EDGES)}
_FACES = ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))


def _tet_offsets() -> np.ndarray:
    """Corner offsets of the 6 Freudenthal tetrahedra, int shape [6, 4, 3]."""
    out = np.zeros((6, 4, 3), dtype=np.int64)
    for p, (a, b, _) in enumerate(_PERMS):
        out[p, 1, a] = 1
        out[p, 2, a] = out[p, 2, b] = 1
        out[p, 3] = 1
    return out


def _mt_table() -> np.ndarray:
    """Marching-tetrahedra triangles for two labels, indexed by the bit code of the vertices 1..3 that share vertex
    0's label; int shape [8, 2, 3] of local edge indices (-1: no triangle). Orientation is fixed later, geometrically.
    """
    table = -np.ones((8, 2, 3), dtype=np.int64)
    for code in range(7):
        same = [0] + [j for j in (1, 2, 3) if code >> (j - 1) & 1]
        other = [j for j in range(4) if j not in same]
        if len(same) == 1 or len(other) == 1:
            lone = same[0] if len(same) == 1 else other[0]
            table[code, 0] = [_EDGE_INDEX[tuple(sorted((lone, j)))] for j in range(4) if j != lone]
        else:
            (a, b), (c, d) = same, other
            ac, ad, bd, bc = (_EDGE_INDEX[tuple(sorted(p))] for p in ((a, c), (a, d), (b, d), (b, c)))
            table[code, 0] = [ac, ad, bd]
            table[code, 1] = [ac, bd, bc]
    return table


_TET_OFFSETS = _tet_offsets()
_MT_TABLE = _mt_table()


def _dcode(d: np.ndarray) -> np.ndarray:
    """Code 1..7 of a 0/1 offset vector (4 dx + 2 dy + dz); shape [..., 3] -> [...]."""
    return 4 * d[..., 0] + 2 * d[..., 1] + d[..., 2]


SMOOTH_SIGMA = 1.0  # Gaussian weight width of the crack fits [cells]
SMOOTH_RADIUS = 2  # half width of the fit stencil [cells]: (2 r + 1)^3 grid vertices


def _edge_fractions(labels: np.ndarray, v: np.ndarray, w: np.ndarray, d: np.ndarray, smoothing: float) -> np.ndarray:
    """Where the interface crosses grid edges (step 3), as fractions t of the edge from v.

    Each end vertex u of an edge fits a plane to the staircase boundary between its fragment and the fragment across
    the edge: the midpoints of the axis-aligned grid edges within a (2 r + 1)^3 block around u that join those two
    fragments, Gaussian-weighted by their distance from u; the plane passes through their weighted mean, normal to
    the direction of least weighted variance. The edge point is the mean of the crossings of the two end vertices'
    planes with the edge (0.5 where neither plane crosses it at a usable angle), clamped to [0.5 - s, 0.5 + s]. An
    end at a one-vertex-thick feature along the edge (the vertex behind it has another label) may not shrink below its
    half edge, so debris and thin slabs keep their lattice cell.

    Args:
        labels: grid labels, int shape [nx, ny, nz] (-1: outside).
        v, w: flat grid indices of the edges' ends, int shape [e], w = v + d.
        d: edge direction in cells (0/1 entries), int shape [e, 3].
        smoothing: s in [0, 0.45].

    Returns:
        t, float64 shape [e].
    """
    _, ny, nz = labels.shape
    flat = labels.ravel()
    lv, lw = flat[v], flat[w]
    t = np.full(v.shape, 0.5)
    inner = (lv >= 0) & (lw >= 0)
    if smoothing <= 0.0 or not inner.any():
        return t
    r = SMOOTH_RADIUS
    size = 2 * r + 1
    offsets = np.stack(np.meshgrid(*(np.arange(-r, r + 1),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    padded = np.pad(labels, r + 1, mode="constant", constant_values=-1)
    pstrides = np.array([(ny + 2 * r + 2) * (nz + 2 * r + 2), nz + 2 * r + 2, 1], dtype=np.int64)
    # One plane per (end vertex, label across the edge): the boundary between exactly those two fragments.
    label_span = int(flat.max()) + 2
    pair = np.concatenate([v[inner] * label_span + lw[inner], w[inner] * label_span + lv[inner]])
    pairs, inverse = np.unique(pair, return_inverse=True)
    ends, across = pairs // label_span, pairs % label_span
    ijk = np.stack(np.unravel_index(ends, labels.shape), axis=1) + r + 1
    block = padded.ravel()[(ijk @ pstrides)[:, None] + (offsets @ pstrides)[None, :]].reshape(-1, size, size, size)
    mine = block == flat[ends][:, None, None, None]
    theirs = block == across[:, None, None, None]
    flags, points = [], []
    for axis in range(3):  # axis edges inside the block: (u, u + e_axis)
        lo_sl = [slice(None)] * 4
        hi_sl = [slice(None)] * 4
        lo_sl[axis + 1], hi_sl[axis + 1] = slice(0, size - 1), slice(1, size)
        lo_sl, hi_sl = tuple(lo_sl), tuple(hi_sl)
        joins = (mine[lo_sl] & theirs[hi_sl]) | (theirs[lo_sl] & mine[hi_sl])
        flags.append(joins.reshape(len(ends), -1))
        grid_pts = np.stack(np.meshgrid(*(np.arange(-r, r + 1 - (k == axis)) for k in range(3)), indexing="ij"), -1)
        points.append(grid_pts.reshape(-1, 3) + 0.5 * np.eye(3)[axis])
    flag = np.concatenate(flags, axis=1).astype(np.float64)  # [u, slots]
    pts = np.concatenate(points)  # [slots, 3] midpoints relative to u [cells]
    weight = flag * np.exp(-0.5 * (pts**2).sum(axis=1) / SMOOTH_SIGMA**2)
    total = weight.sum(axis=1)
    mean = (weight @ pts) / np.maximum(total, 1e-30)[:, None]
    second = (weight @ (pts[:, :, None] * pts[:, None, :]).reshape(-1, 9)).reshape(-1, 3, 3)
    cov = second / np.maximum(total, 1e-30)[:, None, None] - mean[:, :, None] * mean[:, None, :]
    normal = np.linalg.eigh(cov)[1][:, :, 0]  # direction of least variance
    count = inner.sum()
    dd = d[inner].astype(np.float64)
    crossings = []
    for ends_index, shift in ((inverse[:count], 0.0), (inverse[count:], -1.0)):
        nrm, m = normal[ends_index], mean[ends_index]
        nd = np.einsum("ij,ij->i", nrm, dd)
        usable = (np.abs(nd) > 0.2 * np.linalg.norm(dd, axis=1)) & (total[ends_index] > 0)
        crossings.append(
            (np.where(usable, np.einsum("ij,ij->i", nrm, m) / np.where(usable, nd, 1.0) - shift, 0.0), usable)
        )
    (t_v, ok_v), (t_w, ok_w) = crossings
    n_ok = ok_v.astype(np.float64) + ok_w
    t_in = np.where(n_ok > 0, (t_v * ok_v + t_w * ok_w) / np.maximum(n_ok, 1.0), 0.5)
    strides = np.array([ny * nz, nz, 1], dtype=np.int64)
    step = d[inner] @ strides
    low = np.where(flat[v[inner] - step] == lv[inner], 0.5 - smoothing, 0.5)
    high = np.where(flat[w[inner] + step] == lw[inner], 0.5 + smoothing, 0.5)
    t[inner] = np.clip(t_in, low, high)
    return t


SURFACE_GRAZE = 0.05  # interface points closer than this to the input surface [spacings] move off it


def _off_surface(pos: np.ndarray, corners: np.ndarray, grid_x: np.ndarray, distance: np.ndarray, h: float):
    """Interface points that would graze the input surface, moved just outside it (step 3b).

    A crack point within SURFACE_GRAZE h of the surface (inside or out) makes crack faces that meet it at a grazing
    angle, and the clip leaves needles and caps of a thousandth of a spacing there, too small to clean up. Each such
    point moves within its simplex (the grid edge, tetrahedron face or tetrahedron it is keyed by, whose corners are
    ``corners``) towards the corner farthest outside, to where the signed distance interpolated linearly over the
    simplex is SURFACE_GRAZE h (at most 0.9 of the way): the clip then cuts the crack faces there transversally.
    Points stay inside their simplices, so the regions still partition space, and the move depends on the simplex
    only, so every copy of a point moves alike.

    Args:
        pos: points [m], float64 [n, 3]; corners: their simplices' grid vertices, int [n, k] (k = 2, 3 or 4);
        grid_x: grid vertex positions [m]; distance: signed distance of every grid vertex to the surface [m]
            (negative inside, NaN: far outside); h: grid spacing [m].

    Returns:
        The points [m], float64 [n, 3].
    """
    x = np.array(pos, dtype=np.float64)
    if x.shape[0] == 0:
        return x
    corner_x = grid_x[corners]  # [n, k, 3]
    phi_c = np.nan_to_num(distance[corners], nan=10.0 * h)  # [n, k]
    # barycentric coordinates (least squares over the simplex's edges from its first corner, well conditioned
    # anywhere in the world) give the linear signed distance at the point
    edges = (corner_x[:, 1:] - corner_x[:, :1]) / h  # [n, k - 1, 3]
    gram = np.einsum("nid,njd->nij", edges, edges)
    rhs = np.einsum("nid,nd->ni", edges, (x - corner_x[:, 0]) / h)
    mu = np.linalg.solve(gram, rhs[..., None])[..., 0]  # [n, k - 1]
    lam = np.concatenate([1.0 - mu.sum(axis=1, keepdims=True), mu], axis=1)
    phi = np.einsum("nk,nk->n", lam, phi_c)
    far = np.argmax(phi_c, axis=1)
    phi_far = phi_c[np.arange(len(x)), far]
    target = SURFACE_GRAZE * h
    move = (np.abs(phi) < target) & (phi_far > target)
    step = np.clip((target - phi) / np.where(move, phi_far - phi, 1.0), 0.0, 0.9)
    x[move] += step[move, None] * (corner_x[np.arange(len(x)), far][move] - x[move])
    return x


def signed_distances(shape: SolidShape, points: np.ndarray, device: str) -> np.ndarray:
    """Signed distance [m] of points [m] [n, 3] to the surface of the closed ``shape``, negative inside, float64 [n]."""
    return closest_points(shape, points, device)[0]


def closest_points(shape: SolidShape, points: np.ndarray, device: str):
    """(signed distance [m] float64 [n], nearest point of the surface [m] float64 [n, 3]) of points [m] [n, 3] to
    the closed ``shape`` (negative inside); a Warp query in float32 relative to the shape's centre, so exact anywhere
    in the world."""
    centre = 0.5 * (shape.bounds[0] + shape.bounds[1])
    with wp.ScopedDevice(device):
        mesh = wp.Mesh(
            points=wp.array((shape.vertices - centre).astype(np.float32), dtype=wp.vec3),
            indices=wp.array(shape.faces.astype(np.int32).ravel(), dtype=wp.int32),
        )
        pts = wp.array((points - centre).astype(np.float32), dtype=wp.vec3)
        distance = wp.zeros(len(points), dtype=float)
        lo, hi = np.minimum(points.min(axis=0), shape.bounds[0]), np.maximum(points.max(axis=0), shape.bounds[1])
        max_dist = 2.0 * float(np.linalg.norm(hi - lo)) + 1.0
        near = wp.zeros(len(points), dtype=wp.vec3)
        kf.closest_points(mesh.id, pts, max_dist, distance, near)
        return distance.numpy().astype(np.float64), near.numpy().astype(np.float64) + centre


VOTE_COUNT = 16  # particles voting on the label of a grid vertex that holds no particle


@dataclass(frozen=True)
class LatticeGrid:
    """The label grid of a body (step 1); depends on the rest state only, so it is built once.

    Attributes:
        spacing: grid spacing h [m].
        dims: vertex counts along x, y, z, int shape [3].
        positions: grid vertex positions [m], float64 shape [vertex_count, 3], x-major (index (i ny + j) nz + k).
        owner: the particle sitting on each grid vertex, int64 shape [vertex_count]; -1 where there is none.
        voted: grid vertices near the solid that hold no particle, int64 shape [voted_count].
        voters: the VOTE_COUNT nearest particles of each voted vertex, int64 shape [voted_count, VOTE_COUNT].
        vote_weight: their weights exp(-d^2 / (2 h^2)), float64 shape [voted_count, VOTE_COUNT].
        surface_distance: signed distance [m] of each grid vertex to the input surface (negative inside), float64
            shape [vertex_count]; NaN on the grid's outermost layer (never labelled).
    """

    spacing: float
    dims: np.ndarray
    positions: np.ndarray
    owner: np.ndarray
    voted: np.ndarray
    voters: np.ndarray
    vote_weight: np.ndarray
    surface_distance: np.ndarray


def build_lattice_grid(
    rest_positions: np.ndarray, shape: SolidShape, spacing: float, *, device="cpu", on_lattice: bool = True
) -> LatticeGrid:
    """The grid of spacing h [m] aligned with the particles (rest positions [m], shape [n, 3]) around ``shape``.

    A tetrahedron of the grid that meets the solid has each vertex inside it or within its diameter sqrt(3) h of the
    surface; exactly those vertices (inside, or within 1.8 h) get a label, so the fragment regions cover the solid
    while hugging it. A vertex holding a particle takes that particle's fragment; the others take the fragment with
    the largest Gaussian-weighted vote among their VOTE_COUNT nearest particles, which continues a crack straight
    through the layer around the surface (the nearest particle alone would bend it along the surface normal).
    ``on_lattice=False`` says the particles are not lattice points (they may coincide, as the vertex copies of a
    cracked FEM mesh do): every vertex is then labelled by the vote, even where the particles happen to sit on
    grid vertices.
    """
    h = float(spacing)
    rest = np.asarray(rest_positions, dtype=np.float64)
    origin = rest.min(axis=0)  # a lattice point on every axis
    bounds = shape.bounds
    lo = np.floor((np.minimum(bounds[0], rest.min(axis=0)) - origin) / h).astype(np.int64) - 3
    hi = np.ceil((np.maximum(bounds[1], rest.max(axis=0)) - origin) / h).astype(np.int64) + 3
    dims = hi - lo + 1
    strides = np.array([dims[1] * dims[2], dims[2], 1], dtype=np.int64)
    ijk = np.stack(np.meshgrid(*(np.arange(d) for d in dims), indexing="ij"), axis=-1).reshape(-1, 3)
    positions = origin + (ijk + lo) * h
    owner = -np.ones(positions.shape[0], dtype=np.int64)
    cell = np.rint((rest - origin) / h).astype(np.int64) - lo
    if on_lattice and np.abs(origin + (cell + lo) * h - rest).max() <= 1e-6 * h:
        owner[cell @ strides] = np.arange(rest.shape[0])  # particles on grid vertices label their own
    surface_distance = np.full(positions.shape[0], np.nan)
    queried = np.flatnonzero(~np.any((ijk == 0) | (ijk == dims - 1), axis=1))  # the outer layer is outside
    surface_distance[queried] = signed_distances(shape, positions[queried], device)
    voted = np.flatnonzero((owner < 0) & (surface_distance <= 1.8 * h))  # inside or near (NaN compares False)
    k = min(VOTE_COUNT, rest.shape[0])
    dist, voters = cKDTree(rest).query(positions[voted], k=k)
    dist, voters = dist.reshape(len(voted), k), voters.reshape(len(voted), k)
    weight = np.exp(-0.5 * (dist / h) ** 2)
    return LatticeGrid(
        spacing=h,
        dims=dims,
        positions=positions,
        owner=owner,
        voted=voted,
        voters=voters,
        vote_weight=weight,
        surface_distance=surface_distance,
    )


def grid_labels(grid: LatticeGrid, fragment: np.ndarray) -> np.ndarray:
    """Fragment label of every grid vertex, int64 shape [nx, ny, nz]; -1 "outside" (see :func:`build_lattice_grid`).

    Args:
        grid: from :func:`build_lattice_grid`.
        fragment: fragment index per particle, int shape [particle_count].
    """
    labels = np.where(grid.owner >= 0, fragment[np.maximum(grid.owner, 0)], -1)
    if grid.voted.size:
        votes = fragment[grid.voters]  # [m, k]
        score = np.einsum("mk,mjk->mj", grid.vote_weight, votes[:, :, None] == votes[:, None, :])
        labels[grid.voted] = votes[np.arange(len(votes)), np.argmax(score, axis=1)]  # ties: the nearer voter
    return labels.reshape(tuple(int(x) for x in grid.dims))


def partition_regions(
    grid: LatticeGrid, fragment: np.ndarray, *, crack_smoothing: float = 0.45
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Closed regions, one per fragment, that partition a neighbourhood of the solid (steps 2-3).

    Args:
        grid: from :func:`build_lattice_grid`.
        fragment: fragment index per particle in 0..K-1, int shape [particle_count].
        crack_smoothing: edge points lie at t in [0.5 - s, 0.5 + s] along grid edges, s in [0, 0.45].

    Returns:
        K triples (vertices [m] float64 shape [v, 3], triangles int64 shape [f, 3], the fragment on the other side
        of each triangle int64 shape [f], -1 for "outside"), outward oriented; region k is empty (zero arrays) if
        no grid vertex carries fragment k. The union of the regions contains the solid, and
        two regions share only boundary triangles.
    """
    fragment = np.asarray(fragment, dtype=np.int64)
    k_count = int(fragment.max()) + 1
    nx, ny, nz = (int(d) for d in grid.dims)
    strides = np.array([ny * nz, nz, 1], dtype=np.int64)
    h = grid.spacing
    grid_x = grid.positions
    labels = grid_labels(grid, fragment)
    labels_flat = labels.ravel()
    # Mixed cubes (corners not all of one label), then their mixed tetrahedra.
    c0 = labels[:-1, :-1, :-1]
    mixed = np.zeros(c0.shape, dtype=bool)
    for dx, dy, dz in np.ndindex(2, 2, 2):
        mixed |= labels[dx : nx - 1 + dx, dy : ny - 1 + dy, dz : nz - 1 + dz] != c0
    base = np.argwhere(mixed)  # [m, 3] cube base corners
    tet_vid = ((base[:, None, None, :] + _TET_OFFSETS[None]) @ strides).reshape(-1, 4)  # [m*6, 4]
    tet_perm = np.tile(np.arange(6), base.shape[0])
    tet_base = np.repeat(base @ strides, 6)
    tet_lab = labels_flat[tet_vid]
    srt = np.sort(tet_lab, axis=1)
    nd = 1 + np.count_nonzero(srt[:, 1:] != srt[:, :-1], axis=1)
    keep = nd > 1
    tet_vid, tet_perm, tet_base, tet_lab, nd = tet_vid[keep], tet_perm[keep], tet_base[keep], tet_lab[keep], nd[keep]

    # Edge points of the 6 edges of every kept tetrahedron: key, position (t along the edge), crossing flag.
    ea = np.array([a for a, _ in _EDGES])
    eb = np.array([b for _, b in _EDGES])
    va, vb = tet_vid[:, ea], tet_vid[:, eb]  # [t, 6]
    la, lb = tet_lab[:, ea], tet_lab[:, eb]
    crossing = la != lb
    d_edge = _TET_OFFSETS[tet_perm][:, eb] - _TET_OFFSETS[tet_perm][:, ea]  # [t, 6, 3]
    edge_key = (va * 8 + _dcode(d_edge)) * 4
    t = np.full(va.shape, 0.5)
    _ukey, first, inverse = np.unique(edge_key[crossing], return_index=True, return_inverse=True)
    rows, cols = np.nonzero(crossing)
    t_unique = _edge_fractions(
        labels,
        va[rows[first], cols[first]],
        vb[rows[first], cols[first]],
        d_edge[rows[first], cols[first]],
        crack_smoothing,
    )
    t[rows, cols] = t_unique[inverse.ravel()]
    edge_pos = grid_x[va] + (t[..., None] * h) * d_edge  # [t, 6, 3]
    # Off the lattice (jittered particles, FEM vertices) crack points can come arbitrarily close to the surface; on it
    # the surface lies half a spacing from the particles, and crack points lie on it exactly or well clear of it.
    off_lattice = not (grid.owner >= 0).any()
    sd = grid.surface_distance
    if off_lattice:
        edge_pos[crossing] = _off_surface(edge_pos[crossing], np.stack([va[crossing], vb[crossing]], 1), grid_x, sd, h)

    keys, positions, tris, refs = [edge_key.ravel()], [edge_pos.reshape(-1, 3)], [], []

    def emit(rows, k0, k1, k2, ref_edge):
        """Triangles (k0, k1, k2) of tetrahedra ``rows`` separating the labels across local edge ``ref_edge``."""
        tris.append(np.stack([k0, k1, k2], axis=1))
        refs.append(np.stack([va[rows, ref_edge], vb[rows, ref_edge], la[rows, ref_edge], lb[rows, ref_edge]], 1))

    # Two labels: marching tetrahedra.
    two = np.flatnonzero(nd == 2)
    code = (
        (tet_lab[two, 1] == tet_lab[two, 0])
        + 2 * (tet_lab[two, 2] == tet_lab[two, 0])
        + 4 * (tet_lab[two, 3] == tet_lab[two, 0])
    )
    for slot in range(2):
        tab = _MT_TABLE[code, slot]  # [n2, 3] local edges
        ok = tab[:, 0] >= 0
        rows, tab = two[ok], tab[ok]
        k = edge_key[rows[:, None], tab]
        emit(rows, k[:, 0], k[:, 1], k[:, 2], tab[:, 0])

    # Three or four labels: fans from a point inside the tetrahedron to the face curves.
    many = np.flatnonzero(nd > 2)
    if many.size:
        cross_m = crossing[many]
        centre = (edge_pos[many] * cross_m[..., None]).sum(axis=1) / cross_m.sum(axis=1)[:, None]
        if off_lattice:
            centre = _off_surface(centre, tet_vid[many], grid_x, sd, h)
        centre_key = (tet_base[many] * 6 + tet_perm[many]) * 4 + 2
        keys.append(centre_key)
        positions.append(centre)
        for a, b, c in _FACES:
            eab, eac, ebc = _EDGE_INDEX[(a, b)], _EDGE_INDEX[(a, c)], _EDGE_INDEX[(b, c)]
            lab_a, lab_b, lab_c = tet_lab[many, a], tet_lab[many, b], tet_lab[many, c]
            same_ab, same_ac, same_bc = lab_a == lab_b, lab_a == lab_c, lab_b == lab_c
            equal_pairs = same_ab.astype(np.int8) + same_ac + same_bc  # 3: one label, 1: two labels, 0: three
            two_labels = equal_pairs == 1
            for lone_sel, e1, e2 in ((same_ab, eac, ebc), (same_ac, eab, ebc), (same_bc, eab, eac)):
                sel = two_labels & lone_sel
                rows = many[sel]
                emit(rows, edge_key[rows, e1], edge_key[rows, e2], centre_key[sel], np.full(rows.shape, e1))
            three = equal_pairs == 0
            if three.any():
                rows = many[three]
                offs = _TET_OFFSETS[tet_perm[rows]]
                face_key = (
                    tet_vid[rows, a] * 64 + _dcode(offs[:, b] - offs[:, a]) * 8 + _dcode(offs[:, c] - offs[:, b])
                ) * 4 + 1
                face_pos = (edge_pos[rows, eab] + edge_pos[rows, eac] + edge_pos[rows, ebc]) / 3.0
                if off_lattice:
                    face_pos = _off_surface(face_pos, tet_vid[rows][:, [a, b, c]], grid_x, sd, h)
                keys.append(face_key)
                positions.append(face_pos)
                for e in (eab, ebc, eac):
                    emit(rows, edge_key[rows, e], face_key, centre_key[three], np.full(rows.shape, e))

    all_keys = np.concatenate(keys)
    all_pos = np.concatenate(positions)
    ukeys, first = np.unique(all_keys, return_index=True)
    upos = all_pos[first]
    tri = np.searchsorted(ukeys, np.concatenate(tris))  # [f, 3] indices into upos
    ref = np.concatenate(refs)  # [f, 4]: (vertex u, vertex v, label u, label v)
    # Orient every triangle away from the label of vertex u (u and v lie on opposite sides of its plane).
    p0, p1, p2 = upos[tri[:, 0]], upos[tri[:, 1]], upos[tri[:, 2]]
    normal = np.cross(p1 - p0, p2 - p0)
    flip = np.einsum("ij,ij->i", normal, grid_x[ref[:, 0]] - p0) > 0.0
    tri[flip] = tri[flip][:, [0, 2, 1]]

    owner = np.concatenate([ref[:, 2], ref[:, 3]])
    across = np.concatenate([ref[:, 3], ref[:, 2]])
    owned = np.concatenate([tri, tri[:, [0, 2, 1]]])
    inside = owner >= 0
    owner, owned, across = owner[inside], owned[inside], across[inside]
    order = np.argsort(owner, kind="stable")
    owner, owned, across = owner[order], owned[order], across[order]
    starts = np.searchsorted(owner, np.arange(k_count + 1))
    regions = []
    for k in range(k_count):
        f = owned[starts[k] : starts[k + 1]]
        used, local = np.unique(f, return_inverse=True)
        regions.append((upos[used], local.reshape(-1, 3).astype(np.int64), across[starts[k] : starts[k + 1]]))
    return regions


# ---------------------------------------------------------------------------------------------------- the shell complex
# All fragments' shells as one complex: vertices shared between shells where they coincide, so the two sides of a crack
# use the same vertices (and, after _share_crack_faces, the same triangles). Patches: an outer face's patch is the plane
