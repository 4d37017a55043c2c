"""Renderable fracture surfaces: one closed, outward-oriented triangle shell per fragment of a peridynamic body.

Method
------
The input surface mesh is kept in rest space. When the fragment labels change (:meth:`FragmentSurfaces.update_topology`)
each fragment's rest-space shape is rebuilt as ``region(fragment) ∩ input mesh`` with manifold3d's exact mesh
booleans, where the fragments' regions partition space exactly. Outer faces are therefore pieces of the input
triangles (same positions) and crack faces are pieces of the region boundaries:

1. **Label grid.** A regular grid of the particle spacing h, aligned with the particle lattice (particles sit on grid
   vertices), covers the input mesh's bounding box plus three layers. A vertex holding a particle takes its fragment.
   The other vertices inside the solid or within 1.8 h of its surface take the fragment with the largest
   Gaussian-weighted vote (sigma = h) among their 16 nearest particles, which continues a crack straight through the
   surface layer. All remaining vertices are "outside". (A tetrahedron of the grid that meets the solid has every
   vertex within its diameter sqrt(3) h of the solid, so the labelled vertices' regions cover the solid.) With
   ``on_lattice=False`` every vertex is labelled by the vote: the FEM draws its cracked bodies over their mesh
   vertices (pdsim/fem/solver.py), which are no lattice and coincide where fracture split them.
2. **Partition of space: multi-label marching tetrahedra.** Every grid cube is split into the 6 tetrahedra of the
   Freudenthal (Kuhn) triangulation, the same in every cube, so neighbouring tetrahedra share faces. In a tetrahedron
   whose vertices carry two labels the interface is the marching-tetrahedra triangle or quad through points on the
   edges joining different labels. With three or four labels, each face that joins three labels gets a "Y" from a
   point inside the face to its three edge points, and the interface is the fan of triangles from a point inside the
   tetrahedron to these face curves. Every interface point (edge point, face point, tetrahedron point) is keyed by
   the simplex it lies on, so the two fragments meeting at an interface use the very same triangles with opposite
   orientations. The regions thus partition space exactly (no gap, no overlap: a closed crack renders closed). Each
   region's boundary is a closed 2-manifold by construction: binary marching tetrahedra is never ambiguous, and the
   part of a tetrahedron's boundary that belongs to one label is always a disc.
3. **Smooth cracks.** Edge points at edge midpoints give lattice-stepped cracks. Instead, each end u of a crossing
   edge fits a plane to the staircase between its fragment and the fragment across the edge. The plane is fitted to
   the midpoints of the axis-aligned grid edges that join those two fragments in the 5x5x5 block around u,
   Gaussian-weighted (sigma = h), normal to their direction of least variance. The edge point is where the two end
   planes cross the edge (their mean), clamped to ``0.5 +- crack_smoothing`` of the edge (default 0.45; 0 gives
   midpoints). An end at a one-vertex-thick feature (the vertex behind it along the edge has another label) keeps its
   half edge, so single-particle debris and one-layer slabs keep their lattice cell. Edge points only slide along
   their edges, and face and tetrahedron points are averages of edge points, so the smoothing can never fold the
   partition. Measured on a sphere of radius 10 h: a planar crack at any angle has crack vertices within 0.012 h rms
   of a plane away from the surface (0.33 h rms with midpoints). Voronoi cracks away from junctions are within
   0.06 h rms (0.24 h with midpoints). The rim, within about one spacing of the outer surface, is rougher (about 0.1 h
   rms).
3a. **Refined input.** Before the clip, the input surface is refined to edges of about h with manifold3d's
    ``refine_to_length`` (planar subdivision: planes stay planes, box edges and corners stay sharp; an input whose
    edges are all at most h is kept as it is). An unbroken body is this refined surface, so it bends with the particles
    everywhere, not only at the input's vertices.
3b. **Clear of the surface.** Off the lattice (jittered particles, FEM vertices) a crack point (edge, face or
    tetrahedron point) can fall a thousandth of a spacing from the input surface, and the clip then leaves needles
    too small for any clean-up. Such points (closer than 0.05 h) move within their simplex to 0.05 h outside the
    surface (:func:`_off_surface`). On the lattice the surface lies half a spacing from the particles, so crack
    points lie on it exactly (the clean-up handles those) or well clear of it, and nothing moves.
4. **Clip.** ``region ∩ input surface`` (manifold3d, every triangle of both meshes its own face id so that manifold3d
   keeps the triangulations) gives each region's shell. Faces from the input are outer faces, the rest are crack
   faces (told apart by manifold3d's original ids; the source triangle tells the region across a crack face and the
   input plane of an outer face).
5. **Shared complex.** All shells' vertices that coincide (within 1e-9 h) become one vertex, and each crack is
   triangulated once: the lower region's crack triangles, reversed, replace the higher region's (a shell whose sides
   do not match keeps its own, checked). The two sides of a crack thus use the very same triangles.
6. **Slivers** (:func:`clean_complex`). The booleans cut triangles near their corners and marching tetrahedra puts
   crack points near grid vertices, which leaves needles and caps. Rounds of edge collapses (edges shorter than 0.3 h
   and the shortest side of every triangle with an angle under 5 degrees) and edge flips (the longest side of such a
   triangle, inside one patch; a flip never creates an edge the shell has in either direction, and one round never
   creates the same edge twice) remove them on the shared complex, so both sides of a crack change alike. A collapse
   moves a vertex onto a neighbour only if the neighbour lies on every input plane of the vertex (its cracks may
   slide: a crack's rim moves along a box edge or across a face, both sides alike), so outer faces stay exactly on
   the input surface, sharp edges and corners stay put and the volumes still add up exactly; the link condition
   keeps every shell a closed 2-manifold. What the link condition blocks (needles at crack junctions on the outer
   surface, where the ends of a short edge have three common neighbours) is then relaxed: the vertices of the
   remaining slivers move towards the mean of their neighbours, projected onto their input planes (a rim vertex
   slides in its face or along its crease, a corner stays), when that widens the smallest angle around them and
   turns no triangle by more than 30 degrees; moves change no connectivity, so the shells stay closed and still
   partition the solid. Where two sides of a crack still differ
   (manifold3d resolves a crack point exactly on an input plane differently in the two booleans; frame 8 of the
   wall, two shells) those shells keep their own crack triangles. Faceted curved inputs (a sphere whose facets are
   smaller than h) keep more slivers, since no vertex may leave its facet.
7. **Damage.** Regions are the fragments (connected components of live bonds), except that a particle whose damage
   reaches ``damage_threshold`` (default 0.5: about 0.38 next to a clean crack through the bulk, so clean cracks
   still show through the fragments) becomes a chip of its own. Its cell separates from its neighbours' in the frame
   it loses that share of its bonds, so a hole through a wall shows as soon as the damage crosses the wall, not when
   the last bond joining the debris breaks.
8. **Motion.** Each shell vertex follows the particles of its own region only:
   ``x_v = T_F(X_v) + sum_k phi_vk r_k``. Here ``T_F`` is the region's best-fit rigid motion (Kabsch, from its
   particles' rest and current positions; the minimal rotation for collinear regions, a translation for single
   particles), and ``r_k`` is the k-th neighbour particle's deviation from ``T_F``. The ``phi_vk`` are
   moving-least-squares shape functions (linear basis, weights ``exp(-(d / 1.25 h)^2)`` over the 20 nearest
   particles of the same region): a partition of unity, exact for affine fields up to a 1e-3 ridge. They are
   precomputed at each topology change as a sparse matrix [vertex_count, particle_count], so a frame is a rigid fit
   per shell and one sparse product. Rigidly moving regions move their shells exactly rigidly, an affine deformation
   is reproduced to about 1e-3 h, and vertices next to clamped particles stay put (default cantilever: 0.0015 h).
   Vertex velocities are the time derivative of this map, ``v_v = c' + w x R (X_v - Xc) + sum_k phi_vk (v_k - c' -
   w x R (X_k - Xc))`` with the mean velocity c' and the best-fit angular velocity w of the region's particles.
9. **Drawn surface** (:meth:`FragmentSurfaces.drawn`). Material that stretches or crumbles without separating
   (particles with damage below the chip threshold whose neighbours move apart by up to their spacing) stretches and
   squeezes the triangles embedded in it. Each frame, edges drawn longer than 3 h are split at their rest-space
   midpoints (a triangle with one, two or three long sides splits in two, three or four; conforming, so shells stay
   closed), and the new vertices are embedded in the particles exactly as in step 8 (their own MLS shape functions),
   so the drawn surface keeps following the material at about the particle spacing; this repeats until no edge is
   longer than 3 h. Then, if the crack faces hold a triangle with an angle under 5 degrees, rounds of edge flips
   (as in step 6, now at the current positions) and of vertex moves (step 6's relaxation, with no plane constraint,
   turns of up to 60 degrees and steps down to a tenth of the way; then the obtuse corners of flat caps moved away
   from their long side, and the relaxation again) remove them before the frame is written. Added vertices still at
   a sliver (crushed material brings midpoints next to each other or onto a line between their neighbours) merge
   into a neighbour by the edge collapses of step 6, in drawn space, and the flips and moves run again (up to three
   rounds); an added vertex left with three triangles at a sliver (inside the triangle of its neighbours) is then
   removed. Splits and clean-up alternate up to six times. This depends on the frame's positions only (a resumed
   run draws the same). The faces and vertex count change only on frames that need it; velocities of added
   vertices are those of step 8 at their rest points. Measured on the brittle wall of
   tests/test_pd_render_surfaces.py (h = 1 cm, frames 0-8): no crack triangle under 5 degrees at rest or as drawn,
   on the lattice (smallest 5.08 degrees at rest, 5.00 drawn; before the relaxation and this pass: 2.35 at rest
   and 0.28 drawn, 6-36 slivers per frame) and with jittered particles (5.12 and 5.10; before the off-surface move
   of step 3b: 0.12 degrees, up to 180 slivers per frame); no triangle is longer than 2.6 h at rest and 3.0 h as
   drawn (4.2 h before the splits).

USD: one ``UsdGeom.Mesh`` per body at ``/World/<body>_surface`` holds every shell. It carries the uniform (per-face)
int primvars ``fragment`` (the fragment label; chips carry their particle's fragment) and ``crack`` (1 on crack
faces, 0 on faces of the input surface). Points, vertex velocities and extent are written every frame;
``faceVertexCounts``, ``faceVertexIndices`` and the two primvars only on the first frame and on frames where the
regions changed.

Cost (2-core CPU): a rebuild is one boolean per region plus the clean-up, about 0.1-0.3 s for a few fragments of
a 5k-particle body and about 0.5-2 s for the wall above with 200-260 chips; a frame's vertex update is a rigid fit
and a sparse product (a few ms for 20k vertices).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import SolidShape

__all__ = ["FragmentSurfaces"]

NEIGHBOR_COUNT = 20  # particles per vertex in the moving-least-squares interpolation
MLS_WIDTH = 1.25  # Gaussian width of the MLS weights [spacings]
_MLS_RIDGE = 1.0e-3  # ridge on the linear MLS terms (in units of h^2 times the weight sum): keeps A invertible

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
    """Where the interface crosses grid edges (step 3 of the method), as fractions t of the edge from v.

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
    """Interface points that would graze the input surface, moved just outside it (step 2 of the method).

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


def _signed_distances(shape: SolidShape, points: np.ndarray, device: str) -> np.ndarray:
    """Signed distance [m] of points [m] [n, 3] to the surface of the closed ``shape``, negative inside, float64 [n]."""
    import warp as wp

    from .kernels import fragment_surfaces as kf

    centre = 0.5 * (shape.bounds[0] + shape.bounds[1])  # float32 relative to the shape: exact anywhere in the world
    with wp.ScopedDevice(device):
        mesh = wp.Mesh(
            points=wp.array((shape.vertices - centre).astype(np.float32), dtype=wp.vec3),
            indices=wp.array(shape.faces.astype(np.int32).ravel(), dtype=wp.int32),
        )
        pts = wp.array((points - centre).astype(np.float32), dtype=wp.vec3)
        distance = wp.zeros(len(points), dtype=float)
        lo, hi = np.minimum(points.min(axis=0), shape.bounds[0]), np.maximum(points.max(axis=0), shape.bounds[1])
        max_dist = 2.0 * float(np.linalg.norm(hi - lo)) + 1.0
        wp.launch(kf.signed_distance_to_solid, dim=len(points), inputs=[mesh.id, pts, max_dist, distance])
        return distance.numpy().astype(np.float64)


VOTE_COUNT = 16  # particles voting on the label of a grid vertex that holds no particle


@dataclass(frozen=True)
class LatticeGrid:
    """The label grid of a body (step 1 of the method); depends on the rest state only, so it is built once.

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
    from scipy.spatial import cKDTree

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
    surface_distance[queried] = _signed_distances(shape, positions[queried], device)
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
    """Closed regions, one per fragment, that partition a neighbourhood of the solid (steps 2-3 of the method).

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
# of its input triangle (coplanar input triangles share one); a crack face's patch is its pair of regions.

SLIVER_ANGLE = 5.0  # triangles with a smaller angle [degrees] are slivers
RELAX_TURN = 30.0  # largest turn [degrees] of a triangle when the rest-space clean-up moves a vertex
DEFORMED_ROUNDS = 16  # rounds of edge flips, then of vertex moves, per frame against slivers made by the motion
MAX_DRAWN_EDGE = 3.0  # drawn edges longer than this [spacings] are split at their rest-space midpoints (step 9)
SPLIT_ROUNDS = 4  # rounds of edge splits per pass (each halves the longest edge)
REFINE_PASSES = 6  # passes of splits and sliver clean-up per frame
UNSLIVER_ROUNDS = 3  # rounds of flips, moves and merges of added vertices per clean-up
SHORT_EDGE = 0.3  # edges shorter than this many spacings are collapsed
_MAX_CLEAN_ROUNDS = 40


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


def refine_surface(vertices: np.ndarray, faces: np.ndarray, spacing: float):
    """The input surface refined to edges of about ``spacing`` h [m] with manifold3d's ``refine_to_length``: every
    edge longer than h is split into equal pieces and each triangle is filled by planar subdivision, so planes stay
    planes and sharp edges stay sharp (the surface is unchanged, only the triangles are smaller).

    Returns:
        (vertices [m] float64 [v, 3], triangles int64 [f, 3], plane id of each triangle int64 [f] (see
        :func:`plane_groups`, computed on the input triangles and inherited by their pieces)).
    """
    import manifold3d

    groups = plane_groups(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    t = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    if np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).max() <= spacing:  # fine already: the input itself
        return np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), groups
    f0 = np.ascontiguousarray(faces, dtype=np.uint64)
    solid = manifold3d.Manifold(
        manifold3d.Mesh64(
            np.ascontiguousarray(vertices, dtype=np.float64), f0, face_id=np.arange(len(f0), dtype=np.uint64)
        )
    )
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"manifold3d rejects the input mesh ({solid.status()})")
    mesh = solid.refine_to_length(float(spacing)).to_mesh64()
    v = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    f = np.asarray(mesh.tri_verts, dtype=np.int64).reshape(-1, 3)
    origin = np.asarray(mesh.face_id, dtype=np.int64)
    return v, f, groups[origin]


def triangle_angles(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Interior angles [degrees], float64 shape [f, 3] (angle at corner i of each triangle of ``tri`` [f, 3])."""
    t = points[tri]
    out = np.empty(tri.shape, dtype=np.float64)
    for i in range(3):
        a = t[:, (i + 1) % 3] - t[:, i]
        b = t[:, (i + 2) % 3] - t[:, i]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        out[:, i] = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return out


def _merge_coincident(points: np.ndarray, owner: np.ndarray, tol: float) -> np.ndarray:
    """Global vertex id of each point [m] [p, 3]: points of different shells (``owner`` [p]) closer than ``tol`` [m]
    are one vertex; points of the same shell stay apart. Returns int64 [p]."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    pairs = pairs[owner[pairs[:, 0]] != owner[pairs[:, 1]]] if len(pairs) else pairs.reshape(0, 2)
    n = points.shape[0]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return label.astype(np.int64)


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
    uk, counts = np.unique(key, return_counts=True)
    bad_edge = (counts[np.searchsorted(uk, key)] != 1) | ~np.isin(rev, uk)
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
        win = open_.copy()
        np.logical_and.at(win, rows, best[cols] == prio[rows])
        chosen |= win
        blocked[cols[win[rows]]] = True
        hit = np.zeros(count, dtype=bool)
        np.logical_or.at(hit, rows, blocked[cols])
        open_ &= ~hit
    return chosen


def _collapse_round(points, tri, shell, patch, spacing, short_edge, sliver_angle, plane_eq=None, movable=None):
    """One round of edge collapses on the complex (see :func:`clean_complex`). Returns (triangles after the round
    [f, 3], mask [f] of the triangles that keep an area, number of collapses; 0: nothing left to do). With
    ``movable`` (bool [v]) only those vertices may move onto a neighbour."""
    from scipy.sparse import csr_matrix

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
    ok = u_into_v | v_into_u
    src = np.where(u_into_v, eu, ev)[ok]
    dst = np.where(u_into_v, ev, eu)[ok]
    prio = length[e_idx][ok] + 1e-12 * spacing * np.arange(ok.sum()) / max(ok.sum(), 1)
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
    shell_size = np.bincount(s_of, minlength=int(shell.max()) + 1)[shells_c]
    good = np.where(dst_in_shell, edge_in_shell & (common_nbrs == 2) & (shell_size > 6), True)
    link_ok = np.ones(len(src), dtype=bool)
    np.logical_and.at(link_ok, c_rep, good)
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


def _flip_round(points, tri, shell, patch, sliver_angle):
    """One round of edge flips (see :func:`clean_complex`): the longest side ab of a sliver (a, b, c) whose twin
    (b, a, d) in the same shell lies in the same patch becomes cd, giving (c, a, d) and (d, b, c), when cd is not an
    edge of that shell yet, both new triangles keep the old orientation and the smaller angle grows. A flip is done in
    every shell holding the pair (both sides of a crack) or in none. Returns (triangles [f, 3], number of flips)."""
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
    all_ok = np.ones(group.max() + 1, dtype=bool)
    np.logical_and.at(all_ok, group, ok)
    ok &= all_ok[group]
    cand = np.flatnonzero(ok)
    if cand.size == 0:
        return tri, 0
    # Each triangle in at most one flip (smallest angle first; the copies of one flip win together).
    prio = amin[sliver][cand] + 1e-9 * group[cand] / max(group.max(), 1)
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


def _relax_round(
    points, tri, patch, plane_eq, sliver_angle, max_turn=30.0, surface=None, steps=(0.25, 0.5, 1.0), caps=False
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
    the long side to a fifth of its length from it (where the neighbours' mean does not help a flat cap). Returns
    the number of vertices moved."""
    from scipy.sparse import csr_matrix

    n_v = points.shape[0]
    angles = triangle_angles(points, tri)
    amin = angles.min(axis=1)
    sliver = np.flatnonzero(amin < sliver_angle)
    if sliver.size == 0 or plane_eq is None:
        return 0
    cand = np.unique(tri[sliver])  # needles: the ends of the short side move; caps: the corner by the long side
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
        return 0
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
    for step in steps:
        pos = points[cand] + step * (target - points[cand])
        t_new = t_old.copy()
        corner = tri[f_of] == cand[c_of][:, None]
        t_new[corner] = np.repeat(pos[c_of], corner.sum(axis=1), axis=0)
        n_new = np.cross(t_new[:, 1] - t_new[:, 0], t_new[:, 2] - t_new[:, 0])
        cos_ok = np.einsum("ij,ij->i", n_old, n_new) >= np.cos(np.radians(max_turn)) * np.linalg.norm(
            n_old, axis=1
        ) * np.linalg.norm(n_new, axis=1)
        a_new = np.full(len(cand), np.inf)
        np.minimum.at(a_new, c_of, _min_angles(t_new))
        turned = np.zeros(len(cand), dtype=bool)
        np.logical_or.at(turned, c_of, ~cos_ok & (_min_angles(t_old) >= sliver_angle))
        better = (a_new > old_min + 1e-6) & ~turned
        if surface is not None:
            better &= _on_input_planes(pos, own_patch, surface)
        best_step = np.where(better, step, best_step)
    move = best_step > 0.0
    if not move.any():
        return 0
    # Independent moves: no two moved vertices share a triangle (smallest angle first).
    cand, target, best_step, prio = cand[move], target[move], best_step[move], old_min[move]
    ring = vt[cand].tocoo()
    chosen = _independent_choice(ring.row, ring.col, prio + 1e-12 * np.arange(len(cand)), len(cand), len(tri))
    c = cand[chosen]
    points[c] += best_step[chosen][:, None] * (target[chosen] - points[c])
    return int(chosen.sum())


def _on_input_planes(pos, own_patch, surface) -> np.ndarray:
    """Bool [c]: each point pos [c, 3] lies in an input triangle of each of its planes (``own_patch`` [c, 2] patch
    ids, -1 for none; ``surface`` as in :func:`_relax_round`), within 1e-9 of the triangle's size. Only the triangles
    whose centroid lies within the largest centroid-to-corner distance of a point can hold it (a k-d tree query)."""
    from scipy.spatial import cKDTree

    sv, sf, splane, plane_of_patch = surface
    ok = np.ones(len(pos), dtype=bool)
    corners = sv[sf]
    centroid = corners.mean(axis=1)
    reach = float(np.linalg.norm(corners - centroid[:, None, :], axis=2).max()) * (1.0 + 1e-9) + 1e-300
    pairs = cKDTree(pos).sparse_distance_matrix(cKDTree(centroid), reach, output_type="ndarray")
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
    """Smallest interior angle [degrees] of triangles given by their corners [f, 3, 3]."""
    out = np.full(t.shape[0], 180.0)
    for i in range(3):
        a = t[:, (i + 1) % 3] - t[:, i]
        b = t[:, (i + 2) % 3] - t[:, i]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        out = np.minimum(out, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return out


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
):
    """Removes slivers from the shell complex by edge collapses that keep every shell a closed 2-manifold.

    Candidates are edges shorter than ``short_edge`` spacings and the shortest side (up to one spacing) of every
    triangle with an angle below ``sliver_angle`` [degrees]. A collapse moves one end u onto the other end v (no new
    positions: outer faces stay exactly on the input surface, sharp edges and corners stay put) and is allowed when

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
    remaining slivers are moved (:func:`_relax_round`; ``points`` is changed in place) and the rounds go on.

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

    Returns:
        (tri, shell, patch) after the collapses (triangles that became degenerate removed).
    """
    plane_eq = None
    if crack_patch is not None:  # unit normal and offset of every input-plane patch (NaN: crack patches)
        p_count = int(patch.max()) + 1
        t = points[tri]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        normal = np.stack([np.bincount(patch, n[:, a], p_count) for a in range(3)], axis=1)
        normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
        offset = np.einsum("ij,ij->i", normal[patch], t.mean(axis=1))
        offset = np.bincount(patch, offset, p_count) / np.maximum(np.bincount(patch, minlength=p_count), 1)
        plane_eq = np.concatenate([normal, offset[:, None]], axis=1)
        plane_eq[np.asarray(crack_patch, dtype=bool)] = np.nan
    for _ in range(_MAX_CLEAN_ROUNDS):
        new, keep, collapsed = _collapse_round(points, tri, shell, patch, spacing, short_edge, sliver_angle, plane_eq)
        t1, s1, p1 = new[keep], shell[keep], patch[keep]
        t0 = t1.copy()
        t1, flipped = _flip_round(points, t1, s1, p1, sliver_angle)
        if collapsed == 0 and flipped == 0:
            # vertex moves change no connectivity: the shells stay closed
            if _relax_round(points, t1, p1, plane_eq, sliver_angle, max_turn=RELAX_TURN, surface=surface) == 0:
                break
            tri, shell, patch = t1, s1, p1
            continue
        # the shells this round changed must still be closed (a rare configuration the checks missed: stop here)
        changed = np.concatenate([shell[~keep | (new != tri).any(axis=1)], s1[(t1 != t0).any(axis=1)]])
        touched = np.isin(s1, np.unique(changed))
        if not shells_closed(t1[touched], s1[touched], len(points)).all():
            break
        tri, shell, patch = t1, s1, p1
    return tri, shell, patch


def _rigid_fit(rest: np.ndarray, current: np.ndarray, group: np.ndarray, group_count: int):
    """Best-fit rigid motion per group (Kabsch), vectorised over groups.

    Args:
        rest: rest positions [m], shape [n, 3]; current: current positions [m], shape [n, 3].
        group: group index per point in 0..group_count-1, int shape [n].

    Returns:
        (rest centroids [m] [g, 3], current centroids [m] [g, 3], rotations [g, 3, 3]). Groups whose points are
        collinear get the minimal rotation taking the rest axis to the current axis; single points the identity.
    """
    count = np.bincount(group, minlength=group_count).astype(np.float64)
    inv = 1.0 / np.maximum(count, 1.0)
    rest_c = np.stack([np.bincount(group, rest[:, a], group_count) for a in range(3)], axis=1) * inv[:, None]
    cur_c = np.stack([np.bincount(group, current[:, a], group_count) for a in range(3)], axis=1) * inv[:, None]
    y = current - cur_c[group]
    x = rest - rest_c[group]
    prod = (y[:, :, None] * x[:, None, :]).reshape(-1, 9)
    cov = np.stack([np.bincount(group, prod[:, j], group_count) for j in range(9)], axis=1).reshape(-1, 3, 3)
    u, s, vt = np.linalg.svd(cov)
    det = np.sign(np.linalg.det(u @ vt))
    det[det == 0] = 1.0
    rot = u @ (np.concatenate([np.ones((len(det), 2)), det[:, None]], axis=1)[:, :, None] * vt)
    # Degenerate groups. Collinear: minimal rotation from the rest axis vt[0] to the current axis u[:, 0].
    scale = np.maximum(s[:, 0], 1e-300)
    collinear = (s[:, 1] <= 1e-6 * scale) & (s[:, 0] > 0.0)
    if collinear.any():
        a = vt[collinear, 0]
        b = u[collinear, :, 0]
        axis = np.cross(a, b)
        sin = np.linalg.norm(axis, axis=1)
        cos = np.einsum("ij,ij->i", a, b)
        k = axis / np.maximum(sin, 1e-300)[:, None]
        kx = np.zeros((len(k), 3, 3))
        kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
        kx = kx - kx.transpose(0, 2, 1)
        eye = np.broadcast_to(np.eye(3), kx.shape)
        rot_c = eye + sin[:, None, None] * kx + (1.0 - cos)[:, None, None] * (kx @ kx)
        aligned = sin < 1e-12
        rot_c[aligned & (cos > 0.0)] = np.eye(3)
        flipped = aligned & (cos <= 0.0)  # turned end for end: half turn about an axis perpendicular to a
        if flipped.any():
            af = a[flipped]
            helper = np.eye(3)[np.argmin(np.abs(af), axis=1)]
            perp = np.cross(af, helper)
            perp /= np.linalg.norm(perp, axis=1)[:, None]
            rot_c[flipped] = 2.0 * perp[:, :, None] * perp[:, None, :] - np.eye(3)
        rot[collinear] = rot_c
    rot[s[:, 0] <= 0.0] = np.eye(3)
    return rest_c, cur_c, rot


DAMAGE_THRESHOLD = 0.5  # particles with at least this damage become chips of their own (step 6 of the method)


class FragmentSurfaces:
    """Closed, outward-oriented triangle shells of the fragments of one body, and their motion with the particles.

    See the module docstring for the method.

    Args:
        shape: the body's input surface in rest space (closed, outward oriented).
        rest_positions: particle rest positions [m], shape [n, 3], in the order of the labels and positions passed
            later (the body's sorted order).
        spacing: particle lattice spacing h [m].
        body_name: body label; the USD mesh is ``/World/<body_name>_surface``.
        crack_smoothing: how far crack points may slide from grid-edge midpoints, in [0, 0.45] of an edge (0: no
            smoothing, lattice-stepped cracks).
        simplify: if > 0, each clipped shell is simplified by manifold3d (edge collapses that move the surface by at
            most ``simplify * spacing``); about 0.05 halves the triangle count of crack-rich shells. The two sides of
            a crack are then simplified independently and match only within that tolerance, and the sliver clean-up
            is skipped; 0 (default) keeps the shared, cleaned complex.
        refine: refine the input surface to edges of about one spacing, so that an unbroken surface bends with
            the particles (default: True, unless ``simplify`` is set; False keeps the input triangles).
        damage_threshold: particles whose damage reaches this value become chips of their own, in (0, 1]; see
            :meth:`update_topology`.
        clean: remove slivers by edge collapses (default True).
        on_lattice: the particles are points of a lattice of this spacing (default True), so that those sitting on
            grid vertices label them; False labels every grid vertex by the vote of its nearest particles (particles
            anywhere, possibly coinciding: the vertices of a cracked FEM mesh, see :func:`build_lattice_grid`).
        device: Warp device of the one-off grid-near-mesh query.

    Attributes:
        fragment_ids: fragment label of each shell (chips carry their particle's fragment label; several shells
            may share one), int shape [shell_count].
        rest_vertices: all shells' vertices in rest space [m], float64 shape [vertex_count, 3], shell after shell.
        faces: all shells' triangles, int32 shape [face_count, 3], indices into ``rest_vertices``.
        face_fragment: fragment label of each face, int32 shape [face_count].
        face_crack: 1 for crack faces, 0 for faces from the input surface, int32 shape [face_count].
        vertex_fragment: shell index (0..shell_count-1) of each vertex, int shape [vertex_count].
        version: number of topology rebuilds (0: the intact input mesh).
        rebuild_seconds: wall time of the last rebuild [s].
    """

    def __init__(
        self,
        shape: SolidShape,
        rest_positions: np.ndarray,
        spacing: float,
        body_name: str,
        *,
        crack_smoothing: float = 0.45,
        simplify: float = 0.0,
        refine: bool | None = None,
        damage_threshold: float = DAMAGE_THRESHOLD,
        clean: bool = True,
        on_lattice: bool = True,
        device: str = "cpu",
    ):
        rest = np.asarray(rest_positions, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or rest.shape[0] == 0:
            raise ValueError(f"rest_positions must have shape [n, 3] with n > 0, got {list(rest.shape)}")
        if not (np.isfinite(spacing) and spacing > 0):
            raise ValueError(f"spacing={spacing!r} must be a finite number > 0")
        if not 0.0 <= crack_smoothing <= 0.45:
            raise ValueError(f"crack_smoothing={crack_smoothing!r} must lie in [0, 0.45]")
        if not (np.isfinite(simplify) and 0.0 <= simplify <= 0.5):
            raise ValueError(f"simplify={simplify!r} must lie in [0, 0.5] (a fraction of the spacing)")
        if not (np.isfinite(damage_threshold) and 0.0 < damage_threshold <= 1.0):
            raise ValueError(f"damage_threshold={damage_threshold!r} must lie in (0, 1]")
        self.shape = shape
        self.rest_positions = rest
        self.spacing = float(spacing)
        self.body_name = body_name
        self.crack_smoothing = float(crack_smoothing)
        self.simplify = float(simplify)
        self.damage_threshold = float(damage_threshold)
        self.clean = bool(clean)
        self.on_lattice = bool(on_lattice)
        self.version = 0
        self._key: np.ndarray | None = None
        self._view_faces: np.ndarray | None = None  # the faces of the last view, of rebuild _view_of, and their version
        self._view_of = -1
        self._view_version = 0
        self._manifold_mesh = None
        self._grid: LatticeGrid | None = None
        self.device = device
        self.rebuild_seconds = 0.0
        self.clean_failed = False
        v, f = np.asarray(shape.vertices, np.float64), np.asarray(shape.faces, np.int64)
        if refine is None:
            refine = self.simplify == 0.0
        if refine:
            self._surface = refine_surface(v, f, self.spacing)
        else:
            self._surface = (v, f, plane_groups(v, f))
        n = rest.shape[0]
        self._set_topology(np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64))

    @property
    def particle_count(self) -> int:
        return self.rest_positions.shape[0]

    @property
    def fragment_count(self) -> int:
        """Number of shells (fragments, and chips of damaged particles)."""
        return int(self.fragment_ids.shape[0])

    @property
    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per shell: (rest vertices [m] float64 [v_i, 3], triangles int32 [f_i, 3] indexing those vertices)."""
        out = []
        for k in range(self.fragment_count):
            v0, v1 = self._vertex_ranges[k], self._vertex_ranges[k + 1]
            f0, f1 = self._face_ranges[k], self._face_ranges[k + 1]
            out.append((self.rest_vertices[v0:v1], self.faces[f0:f1] - v0))
        return out

    # ------------------------------------------------------------------ topology

    def region_keys(self, labels, damage=None) -> np.ndarray:
        """Region of each particle, int64 [particle_count]: its fragment label, or ``-1 - index`` (a chip of its
        own) where ``damage`` reaches ``damage_threshold``."""
        labels = np.asarray(labels)
        if labels.shape != (self.particle_count,) or not np.issubdtype(labels.dtype, np.integer):
            raise ValueError(f"labels must be ints of shape [{self.particle_count}], got {labels.dtype} {labels.shape}")
        key = labels.astype(np.int64)
        if damage is not None:
            damage = np.asarray(damage, dtype=np.float64)
            if damage.shape != (self.particle_count,):
                raise ValueError(f"damage must have shape [{self.particle_count}], got {list(damage.shape)}")
            chip = damage >= self.damage_threshold
            key = np.where(chip, -1 - np.arange(self.particle_count), key)
        return key

    def update_topology(self, labels, damage=None) -> bool:
        """Rebuilds the shells if the regions changed since the last call.

        Regions are the fragments, except that every particle whose damage reaches ``damage_threshold`` is a region
        (a chip) of its own: its cell separates from its neighbours' as soon as it loses that share of its bonds,
        before the fragment splits, so a hole through a wall shows as soon as damage crosses the wall.

        Args:
            labels: fragment label per particle, int shape [particle_count] (any non-negative ints; equal labels
                mean the same fragment), e.g. ``FragmentTracker.body_labels(b)``.
            damage: damage per particle [-], shape [particle_count], or None (fragments only).

        Returns:
            True when the shells were rebuilt.
        """
        import time

        key = self.region_keys(labels, damage)
        if self._key is not None and np.array_equal(key, self._key):
            return False
        t0 = time.perf_counter()
        self._set_topology(key, np.asarray(labels, dtype=np.int64))
        self.rebuild_seconds = time.perf_counter() - t0
        self.version += 1
        return True

    def _input_manifold(self):
        import manifold3d

        if self._manifold_mesh is None:
            v, f, _ = self._surface
            mesh = manifold3d.Mesh64(
                np.ascontiguousarray(v, dtype=np.float64),
                np.ascontiguousarray(f, dtype=np.uint64),
                face_id=np.arange(len(f), dtype=np.uint64),
            )
            solid = manifold3d.Manifold(mesh)
            if solid.status() != manifold3d.Error.NoError:
                raise ValueError(f"'{self.shape.name}': manifold3d rejects the input mesh ({solid.status()})")
            self._manifold_mesh = solid.as_original()
        return self._manifold_mesh

    def _set_topology(self, key: np.ndarray, labels: np.ndarray) -> None:
        ids, first, region = np.unique(key, return_index=True, return_inverse=True)
        region = region.reshape(-1)
        self._key = key.copy()
        k_count = ids.shape[0]
        if k_count == 1:  # intact: the (refined) input surface
            points, tri, tri_patch = self._surface
            tri_shell = np.zeros(len(tri), dtype=np.int64)
            tri_crack = np.zeros(len(tri), dtype=np.int32)
            shared = True
        else:
            points, tri, tri_shell, tri_crack, tri_patch, shared = self._clipped_complex(region, k_count)
        self._split_shells(points, tri, tri_shell, tri_crack, tri_patch, labels[first], region, k_count, shared)
        self._build_interpolation()

    def _clipped_pieces(self, region: np.ndarray, k_count: int):
        """Region ∩ input surface for every region (manifold3d). Returns per region (vertices [v, 3], triangles
        [f, 3], region across each triangle [f] (-1 on outer faces), plane id of each triangle [f] (-1 on crack
        faces))."""
        import manifold3d

        solid = self._input_manifold()
        solid_id = solid.original_id()
        plane = self._surface[2]
        if self._grid is None:
            self._grid = build_lattice_grid(
                self.rest_positions, self.shape, self.spacing, device=self.device, on_lattice=self.on_lattice
            )
        regions = partition_regions(self._grid, region, crack_smoothing=self.crack_smoothing)
        empty = (np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64))
        pieces = []
        for k, (rv, rf, racross) in enumerate(regions):
            if rf.shape[0] == 0:
                pieces.append(empty)
                continue
            mesh = manifold3d.Mesh64(rv, rf.astype(np.uint64), face_id=np.arange(len(rf), dtype=np.uint64))
            region_solid = manifold3d.Manifold(mesh)
            if region_solid.status() != manifold3d.Error.NoError:
                raise RuntimeError(f"region {k} of '{self.body_name}' is not a manifold ({region_solid.status()})")
            piece = region_solid ^ solid
            if self.simplify > 0.0:
                piece = piece.simplify(self.simplify * self.spacing)
            piece = piece.to_mesh64()
            tri = np.asarray(piece.tri_verts, dtype=np.int64).reshape(-1, 3)
            if tri.size == 0:
                pieces.append(empty)
                continue
            run_start = np.asarray(piece.run_index, dtype=np.int64) // 3
            run_id = np.asarray(piece.run_original_id, dtype=np.int64)
            outer = np.repeat(run_id == solid_id, np.diff(run_start))
            src = np.asarray(piece.face_id, dtype=np.int64)
            across = np.where(outer, -1, racross[np.where(outer, 0, np.minimum(src, len(racross) - 1))])
            planes = np.where(outer, plane[np.where(outer, np.minimum(src, len(plane) - 1), 0)], -1)
            pieces.append((np.asarray(piece.vert_properties, dtype=np.float64)[:, :3], tri, across, planes))
        return pieces

    def _clipped_complex(self, region: np.ndarray, k_count: int):
        """All regions' shells as one complex (vertices shared between shells), crack faces shared by both sides
        and slivers removed. Returns (points [p, 3], tri [f, 3], shell [f], crack flag [f], patch [f], shared); a
        patch is an input plane or the crack between one pair of regions."""
        pieces = self._clipped_pieces(region, k_count)
        vcount = np.array([p[0].shape[0] for p in pieces], dtype=np.int64)
        fcount = np.array([p[1].shape[0] for p in pieces], dtype=np.int64)
        voff = np.concatenate([[0], np.cumsum(vcount)])
        points = np.concatenate([p[0] for p in pieces])
        tri = np.concatenate([p[1] for p in pieces]) + np.repeat(voff[:-1], fcount)[:, None]
        shell = np.repeat(np.arange(k_count), fcount)
        across = np.concatenate([p[2] for p in pieces])
        planes = np.concatenate([p[3] for p in pieces])
        crack = (across >= 0).astype(np.int32)
        plane_count = int(self._surface[2].max()) + 1

        def patches(shell, across, planes):
            lo, hi = np.minimum(shell, across), np.maximum(shell, across)
            patch = np.where(across >= 0, plane_count + lo * k_count + hi, planes)
            return np.unique(patch, return_inverse=True)[1].reshape(-1)

        if self.simplify > 0.0:  # independent sides: no sharing, no clean-up
            return points, tri, shell, crack, patches(shell, across, planes), False
        gid = _merge_coincident(points, np.repeat(np.arange(k_count), vcount), 1e-9 * self.spacing)
        used, gid = np.unique(gid, return_inverse=True)
        first = np.zeros(len(used), dtype=np.int64)
        first[gid[::-1]] = np.arange(len(gid))[::-1]
        points = points[first]
        tri = gid[tri]
        # One triangulation per crack: the lower region's triangles, reversed, replace the higher region's.
        primary = (across >= 0) & (shell < across)
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
                )
        patch = patches(shell2, across2, planes2)
        if self.clean:
            is_crack_patch = np.zeros(int(patch.max()) + 1, dtype=bool)
            is_crack_patch[patch[across2 >= 0]] = True
            plane_of_patch = np.full(len(is_crack_patch), -1, dtype=np.int64)
            plane_of_patch[patch[across2 < 0]] = planes2[across2 < 0]
            tri3, shell3, patch3 = clean_complex(
                points,
                tri2,
                shell2,
                patch,
                self.spacing,
                crack_patch=is_crack_patch,
                surface=(*self._surface, plane_of_patch),
            )
            if shells_closed(tri3, shell3, len(points)).all():
                # crack flag of each surviving triangle: look it up through its patch
                crack3 = is_crack_patch[patch3].astype(np.int32)
                self.clean_failed = False
                return points, tri3, shell3, crack3, patch3, True
            self.clean_failed = True
        return points, tri2, shell2, (across2 >= 0).astype(np.int32), patch, True

    def _split_shells(
        self, points, tri, tri_shell, tri_crack, tri_patch, region_fragment, region, k_count, shared
    ) -> None:
        """Per-shell vertex copies (shell after shell), faces, attributes and the particle -> shell map."""
        n_p = points.shape[0]
        order = np.argsort(tri_shell, kind="stable")
        tri, tri_shell, tri_crack = tri[order], tri_shell[order], tri_crack[order]
        self._face_patch = np.asarray(tri_patch, dtype=np.int64)[order]
        pair = np.unique(tri_shell[:, None] * n_p + tri)  # (shell, vertex), sorted by shell
        faces = np.searchsorted(pair, tri_shell[:, None] * n_p + tri)
        pair_shell = pair // n_p
        kept = np.unique(tri_shell)
        shell_index = -np.ones(k_count, dtype=np.int64)
        shell_index[kept] = np.arange(len(kept))
        self.fragment_ids = region_fragment[kept].astype(np.int32)
        self.rest_vertices = points[pair % n_p]
        self.faces = faces.astype(np.int32)
        self.face_fragment = region_fragment[tri_shell].astype(np.int32)
        self.face_crack = tri_crack.astype(np.int32)
        self.vertex_fragment = shell_index[pair_shell]
        self.shared = bool(shared)
        fcounts = np.bincount(shell_index[tri_shell], minlength=len(kept))
        vcounts = np.bincount(self.vertex_fragment, minlength=len(kept))
        self._vertex_ranges = np.concatenate([[0], np.cumsum(vcounts)])
        self._face_ranges = np.concatenate([[0], np.cumsum(fcounts)])
        self._face_shell = shell_index[tri_shell]
        self._particle_shell = shell_index[region]

    def _build_interpolation(self) -> None:
        """MLS shape functions of every vertex over the NEIGHBOR_COUNT nearest particles of its own shell, as a
        sparse matrix [vertex_count, particle_count]."""
        from scipy.spatial import cKDTree

        shell = self._particle_shell
        particles = np.flatnonzero(shell >= 0)
        # A fourth coordinate far apart per shell keeps every query inside the vertex's own shell.
        span = float(np.ptp(np.concatenate([self.rest_positions, self.shape.vertices]), axis=0).max())
        self._lift = 10.0 * (span + self.spacing)
        pts = np.concatenate([self.rest_positions[particles], (shell[particles] * self._lift)[:, None]], axis=1)
        self._tree = (cKDTree(pts), particles)
        self._phi = self._embedding(self.rest_vertices, self.vertex_fragment)

    def _embedding(self, rest_points: np.ndarray, shell: np.ndarray):
        """MLS shape functions of rest points [m] [q, 3] of shells ``shell`` [q] over the NEIGHBOR_COUNT nearest
        particles of their own shell: sparse [q, particle_count]."""
        from scipy.sparse import csr_matrix

        h = self.spacing
        tree, particles = self._tree
        part_shell = self._particle_shell
        vtx = np.concatenate([rest_points, (shell * self._lift)[:, None]], axis=1)
        k = min(NEIGHBOR_COUNT, particles.shape[0])
        dist, idx = tree.query(vtx, k=k, workers=-1)
        dist, idx = dist.reshape(len(vtx), k), idx.reshape(len(vtx), k)
        idx = particles[idx]
        valid = part_shell[idx] == shell[:, None]
        # Gaussian weights exp(-(d / (MLS_WIDTH h))^2), scaled by exp((d_min / (MLS_WIDTH h))^2) against underflow
        # (MLS shape functions do not change when all weights are scaled alike).
        d_min = np.min(np.where(valid, dist, np.inf), axis=1)
        w = np.where(valid, np.exp(-(dist**2 - d_min[:, None] ** 2) / (MLS_WIDTH * h) ** 2), 0.0)
        p = np.concatenate(
            [np.ones((len(vtx), k, 1)), (self.rest_positions[idx] - rest_points[:, None, :]) / h], axis=2
        )
        moment = np.einsum("vk,vki,vkj->vij", w, p, p)
        moment[:, 1:, 1:] += (_MLS_RIDGE * w.sum(axis=1))[:, None, None] * np.eye(3)
        rhs = np.zeros((len(vtx), 4, 1))
        rhs[:, 0, 0] = 1.0
        y = np.linalg.solve(moment, rhs)[..., 0]
        phi = w * np.einsum("vki,vi->vk", p, y)
        rows = np.repeat(np.arange(len(vtx)), k)
        out = csr_matrix((phi.ravel(), (rows, idx.ravel())), shape=(len(vtx), self.particle_count))
        out.sum_duplicates()
        return out

    # ------------------------------------------------------------------ motion

    def _fit(self, x: np.ndarray):
        """Rigid fit per shell at particle positions x [m] [particle_count, 3]: (selected particles [s], their shell
        [s], rest centroids [g, 3], current centroids [g, 3], rotations [g, 3, 3])."""
        if x.shape != (self.particle_count, 3):
            raise ValueError(f"positions must have shape [{self.particle_count}, 3], got {list(x.shape)}")
        shell = self._particle_shell
        sel = np.flatnonzero(shell >= 0)
        rest_c, cur_c, rot = _rigid_fit(self.rest_positions[sel], x[sel], shell[sel], self.fragment_count)
        return sel, shell[sel], rest_c, cur_c, rot

    def vertex_positions(self, positions, at=None) -> np.ndarray:
        """All shells' vertices at the current particle positions: ``x_v = T(X_v) + sum_k phi_vk r_k`` (rigid fit
        of the shell's particles plus the MLS-interpolated residuals, a sparse product).

        Args:
            positions: particle positions [m], shape [particle_count, 3].
            at: None (the shells' vertices), or other rest points embedded like them: (rest points [m] [q, 3],
                shell of each [q], their shape functions from :meth:`_embedding`).

        Returns:
            Vertex positions [m], float64 shape [vertex_count, 3] (shell after shell, as ``rest_vertices``).
        """
        rest_v, g, phi = (self.rest_vertices, self.vertex_fragment, self._phi) if at is None else at
        x = np.asarray(positions, dtype=np.float64)
        sel, group, rest_c, cur_c, rot = self._fit(x)
        rigid_p = cur_c[group] + np.einsum("nij,nj->ni", rot[group], self.rest_positions[sel] - rest_c[group])
        residual = np.zeros_like(x)
        residual[sel] = x[sel] - rigid_p
        out = cur_c[g] + np.einsum("nij,nj->ni", rot[g], rest_v - rest_c[g])
        return out + phi @ residual

    def vertex_velocities(self, positions, velocities, at=None) -> np.ndarray:
        """Vertex velocities [m/s], float64 [vertex_count, 3]: the time derivative of :meth:`vertex_positions`,
        ``v_v = c' + w x R (X_v - Xc) + sum_k phi_vk (v_k - c' - w x R (X_k - Xc))``, where c' is the mean velocity
        of the shell's particles and w their best-fit angular velocity (least squares, exact for a rigid motion).

        Args:
            positions: particle positions [m], [particle_count, 3]; velocities: particle velocities [m/s], same shape.
            at: as in :meth:`vertex_positions`.
        """
        rest_v, g, phi = (self.rest_vertices, self.vertex_fragment, self._phi) if at is None else at
        x = np.asarray(positions, dtype=np.float64)
        v = np.asarray(velocities, dtype=np.float64)
        if v.shape != x.shape:
            raise ValueError(f"velocities must have shape {list(x.shape)}, got {list(v.shape)}")
        sel, group, rest_c, cur_c, rot = self._fit(x)
        count = self.fragment_count
        n = np.maximum(np.bincount(group, minlength=count), 1).astype(np.float64)
        v_c = np.stack([np.bincount(group, v[sel, a], count) for a in range(3)], axis=1) / n[:, None]
        r = x[sel] - cur_c[group]
        dv = v[sel] - v_c[group]
        ang = np.cross(r, dv)
        ang_mom = np.stack([np.bincount(group, ang[:, a], count) for a in range(3)], axis=1)
        rr = np.einsum("ni,nj->nij", r, r).reshape(-1, 9)
        outer = np.stack([np.bincount(group, rr[:, j], count) for j in range(9)], axis=1).reshape(-1, 3, 3)
        inertia = np.trace(outer, axis1=1, axis2=2)[:, None, None] * np.eye(3) - outer
        scale = np.maximum(np.trace(inertia, axis1=1, axis2=2), 1e-300)[:, None, None]
        omega = np.einsum("gij,gj->gi", np.linalg.pinv(inertia / scale, rcond=1e-9), ang_mom / scale[:, :, 0])
        arm_p = np.einsum("nij,nj->ni", rot[group], self.rest_positions[sel] - rest_c[group])
        residual = np.zeros_like(v)
        residual[sel] = v[sel] - v_c[group] - np.cross(omega[group], arm_p)
        arm_v = np.einsum("nij,nj->ni", rot[g], rest_v - rest_c[g])
        return v_c[g] + np.cross(omega[g], arm_v) + phi @ residual

    def fragment_vertex_positions(self, positions) -> list[np.ndarray]:
        """Per shell, its vertices at the current particle positions: list of [v_i, 3] arrays [m]."""
        x = self.vertex_positions(positions)
        return [x[self._vertex_ranges[k] : self._vertex_ranges[k + 1]] for k in range(self.fragment_count)]

    # ------------------------------------------------------------------ output
    def view(self, positions, velocities=None):
        """The surface as a MeshView ``<body>_surface`` for particle ``positions`` [m] (shape [particle_count, 3])
        and ``velocities`` [m/s] (same shape; None: no vertex velocities): the drawn surface of :meth:`drawn`
        (vertices moved by the particles, long edges split, slivers flipped and relaxed), vertex velocities,
        topology version, faces and the per-face ``fragment`` and ``crack``."""
        from .output.views import MeshView

        d = self.drawn(positions)
        if self._view_faces is None or self._view_of != self.version or not np.array_equal(d.faces, self._view_faces):
            self._view_faces, self._view_of = d.faces, self.version
            self._view_version += 1
        vel = None
        if velocities is not None:
            vel = self.vertex_velocities(positions, velocities)
            if d.added is not None:
                vel = np.concatenate([vel, self.vertex_velocities(positions, velocities, at=d.added)])
        return MeshView(
            name=f"{self.body_name}_surface",
            points=d.points,
            velocities=vel,
            topology_version=self._view_version,
            faces=d.faces,
            face_attributes={"fragment": self.face_fragment[d.face_parent], "crack": self.face_crack[d.face_parent]},
        )

    def drawn(self, positions) -> DrawnSurface:
        """The surface to draw at particle ``positions`` [m] [particle_count, 3] (step 9 of the method): the
        vertices of :meth:`vertex_positions`; edges drawn longer than ``MAX_DRAWN_EDGE`` spacings split at their
        rest-space midpoints, which are embedded in the particles like every vertex; slivers made by the motion
        flipped away and relaxed (their vertices move towards their neighbours). Depends on the positions only, not
        on earlier frames."""
        x = self.vertex_positions(positions)
        faces = self.faces.astype(np.int64)
        parent = np.arange(len(faces))
        rest, shell = self.rest_vertices, self.vertex_fragment
        phis = []
        limit = MAX_DRAWN_EDGE * self.spacing
        for _ in range(REFINE_PASSES):
            for _ in range(SPLIT_ROUNDS):
                out = _split_long_edges(x, faces, limit)
                if out is None:
                    break
                lo, hi, faces, from_face = out
                mid_rest = 0.5 * (rest[lo] + rest[hi])
                mid_shell = shell[lo]
                at = (mid_rest, mid_shell, self._embedding(mid_rest, mid_shell))
                phis.append(at[2])
                x = np.concatenate([x, self.vertex_positions(positions, at=at)])
                rest, shell = np.concatenate([rest, mid_rest]), np.concatenate([shell, mid_shell])
                parent = parent[from_face]
            faces, parent = self._unsliver(x, faces, parent)
            if _longest_edge(x, faces) <= limit:
                break
        added = None
        if phis:
            from scipy.sparse import vstack

            n0 = len(self.rest_vertices)
            keep = np.ones(len(x), dtype=bool)  # added vertices that a removal left without triangles go
            keep[n0:] = np.bincount(faces.ravel(), minlength=len(x))[n0:] > 0
            new_index = np.cumsum(keep) - 1
            faces, x = new_index[faces], x[keep]
            k = keep[n0:]
            added = (rest[n0:][k], shell[n0:][k], vstack(phis).tocsr()[np.flatnonzero(k)])
        return DrawnSurface(x, faces.astype(np.int32), parent, added)

    def _unsliver(self, x, faces, parent):
        """Against the crack triangles under SLIVER_ANGLE of the drawn ``faces`` (face i descends from
        ``self.faces[parent[i]]``), up to UNSLIVER_ROUNDS times: edge flips, vertex moves (in place on ``x``), then
        edge collapses that merge added vertices into a neighbour; last, added vertices of three triangles at such
        slivers are removed (:func:`_drop_three_fans`). Returns (faces, parent)."""
        face_shell, face_patch = self._face_shell[parent], self._face_patch[parent]
        free = np.full((int(self._face_patch.max()) + 1, 4), np.nan)  # no input plane holds in deformed space
        movable = np.arange(len(x)) >= len(self.rest_vertices)  # only added vertices merge into a neighbour
        for _ in range(UNSLIVER_ROUNDS):
            crack = self.face_crack[parent] == 1
            if not crack.any() or triangle_angles(x, faces[crack]).min() >= SLIVER_ANGLE:
                return faces, parent
            for _ in range(DEFORMED_ROUNDS):
                faces, flipped = _flip_round(x, faces, face_shell, face_patch, SLIVER_ANGLE)
                if flipped == 0:
                    break
            for caps in (False, True, False):
                for _ in range(DEFORMED_ROUNDS):
                    moved = _relax_round(
                        x,
                        faces,
                        face_patch,
                        free,
                        SLIVER_ANGLE,
                        max_turn=60.0,
                        steps=(0.1, 0.25, 0.5, 1.0),
                        caps=caps,
                    )
                    if moved == 0:
                        break
            # what is left: added vertices that crushed material brought next to others (needles) or onto a line
            # between them (caps) merge into a neighbour (edge collapses as in step 6)
            merged = 0
            for _ in range(DEFORMED_ROUNDS):
                new, keep, collapsed = _collapse_round(
                    x, faces, face_shell, face_patch, self.spacing, SHORT_EDGE, SLIVER_ANGLE, movable=movable
                )
                if collapsed == 0:
                    break
                merged += collapsed
                faces, parent = new[keep], parent[keep]
                face_shell, face_patch = face_shell[keep], face_patch[keep]
            if merged == 0:
                break
        return _drop_three_fans(x, faces, parent, face_patch, len(self.rest_vertices), SLIVER_ANGLE)


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


@dataclass
class DrawnSurface:
    """A surface as drawn in one frame (:meth:`FragmentSurfaces.drawn`).

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


def _longest_edge(x: np.ndarray, faces: np.ndarray) -> float:
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
