"""Repair of surface meshes as artists export them into closed, consistently wound 2-manifold solids.

The steps, in order (:func:`repair_surface`):

1. **Weld** vertices closer than 1e-6 of the mesh's largest extent (at least 1e-8 m), by position alone: the copies
   that UV seams and split normals make become one vertex.
2. **Clean**: triangles with a repeated vertex and repeated triangles (the same three vertices) go.
3. **Sheets**: the triangles fall into parts (sets joined by shared vertices) and sheets (sets joined across edges
   that exactly two triangles share, wound against each other). Each sheet gets its own copies of its vertices, so
   an edge shared by three or more triangles (an eye touching a head, a fin on a shell) becomes a hole of the sheets
   that meet there.
4. **Cap holes**: every boundary loop of a sheet (a loop of edges used by one triangle) is closed by a fan of
   triangles from the loop's centroid, wound against the loop. A sheet whose cap would be larger than
   CAP_AREA_LIMIT of its own area is a card, not a solid with a hole (a flat sheet: 1; a teapot's lid opening:
   0.79), and encloses no volume.
5. **Rebuild** a part with a sheet that cannot be capped (a boundary vertex on two loops, or a capped sheet that
   manifold3d rejects): the part's signed distance (distance to its triangles, with the sign of the generalised
   winding number, Warp's BVH fast winding number) is sampled on a grid of REBUILD_CELLS cells across its largest
   extent and its zero level set is extracted with marching cubes (Warp), then simplified within REBUILD_SIMPLIFY
   cells (manifold3d). The part keeps its shape to about one cell (1/96 of its size), not its triangles.
6. **Pieces of no volume** (cards, stray triangles, closed pieces below NO_VOLUME of the cube of their largest
   extent) are dropped. A mesh left with nothing is refused (GeometryError: it encloses no volume).
7. **Union**: the closed pieces are joined with manifold3d's exact union (overlapping pieces become one solid;
   pieces wound inside out within an outward mesh are cavities and are subtracted). The result is a closed
   2-manifold, as the render surfaces' booleans need.

A mesh of one part that is closed and consistently wound after steps 1-2 is kept as it is (no union, no new
vertices).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import manifold3d
import numpy as np
import warp as wp
import warp.geometry
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .errors import GeometryError
from .kernels import sampling as ks

WELD_TOLERANCE = 1.0e-6  # vertices closer than this fraction of the mesh's largest extent are one vertex [-]
WELD_FLOOR = 1.0e-8  # ... and always those closer than this [m] (the tolerance of the former trimesh merge)
NO_VOLUME = 1.0e-6  # a part whose |volume| is below this fraction of its largest extent cubed encloses none [-]
CAP_AREA_LIMIT = 0.9  # a hole is capped when its cap's area is at most this fraction of its part's area [-]
REBUILD_CELLS = 96  # grid cells across the largest extent of a part rebuilt from its signed distance
REBUILD_SIMPLIFY = 0.25  # a rebuilt surface is simplified (manifold3d) within this fraction of a cell [-]


@dataclass(frozen=True)
class RepairReport:
    """What :func:`repair_surface` did to a mesh.

    Attributes:
        welded: vertices removed by welding coincident vertices.
        dropped_faces: triangles dropped (a repeated vertex, or a repeat of another triangle).
        triangulated: polygons of more than 3 corners that were split into triangles (counted in OBJ and OFF text;
            -1 where the format does not tell).
        parts: parts in the input (sets of triangles joined by shared vertices).
        holes_capped: boundary loops closed by a fan of triangles.
        rebuilt: parts rebuilt from their signed distance (they could not be capped).
        dropped_parts: pieces (sheets, rebuilt parts) that enclose no volume, dropped.
        united: closed pieces (capped sheets, rebuilt parts) joined with manifold3d's union (0: no union).
    """

    welded: int = 0
    dropped_faces: int = 0
    triangulated: int = -1
    parts: int = 1
    holes_capped: int = 0
    rebuilt: int = 0
    dropped_parts: int = 0
    united: int = 0

    def line(self, name: str) -> str:
        """One line naming the repairs of mesh ``name``, or '' when there were none."""
        done = []
        if self.welded:
            done.append(f"{self.welded} coincident vertices welded")
        if self.triangulated > 0:
            done.append(f"{self.triangulated} polygons triangulated")
        if self.dropped_faces:
            done.append(f"{self.dropped_faces} degenerate or repeated triangles dropped")
        if self.holes_capped:
            done.append(f"{self.holes_capped} holes capped")
        if self.rebuilt:
            done.append(f"{self.rebuilt} parts rebuilt from their winding number (they could not be capped)")
        if self.dropped_parts:
            done.append(f"{self.dropped_parts} pieces enclosing no volume dropped")
        if self.united:
            done.append(f"{self.united} pieces united")
        return f"pdsim: mesh '{name}': " + ", ".join(done) if done else ""


def count_polygons(text: str) -> int:
    """Faces of more than 3 corners in OBJ text ('f' lines with 4 or more vertex references) or OFF text (face rows
    starting with a corner count of 4 or more after the header)."""
    if re.match(r"\s*N?OFF", text):
        rows = text.splitlines()
        body = [r for r in rows if r.strip() and not r.lstrip().startswith("#")]
        if len(body) < 2:
            return 0
        nv, nf = (int(x) for x in body[1].split()[:2])
        counts = np.array([r.split(None, 1)[0] for r in body[2 + nv : 2 + nv + nf]], dtype=np.int64)
        return int((counts > 3).sum())
    return len(re.findall(r"^f(?:[ \t]+\S+){4,}", text, flags=re.M))


def weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vertices [m] [v, 3] closer than max(WELD_TOLERANCE x largest extent, WELD_FLOOR) become one (the lowest index
    of each cluster keeps its position); unreferenced vertices go. Returns (vertices [u, 3], faces [f, 3] int64)."""
    size = float(np.ptp(vertices, axis=0).max()) if len(vertices) else 0.0
    tol = max(WELD_TOLERANCE * size, WELD_FLOOR)
    pairs = cKDTree(vertices).query_pairs(tol, output_type="ndarray")
    n = len(vertices)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    _, first, label = np.unique(label, return_index=True, return_inverse=True)
    faces = label.reshape(-1)[faces]
    used, faces = np.unique(faces, return_inverse=True)
    return vertices[first[used]], faces.reshape(-1, 3)


def clean_faces(faces: np.ndarray) -> np.ndarray:
    """The triangles [f, 3] without those that repeat a vertex and without repeats of an earlier triangle (the same
    three vertices in any order), in their input order."""
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    faces = faces[ok]
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    return faces[np.sort(first)]


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected component of each of n nodes joined by the edges (a[i], b[i]), int64 [n]."""
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


def edge_counts(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per directed edge of the triangles (3 per triangle, [3 f, 2]): the edges, how many triangles use the edge
    either way, and how many use it in this same direction."""
    d = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    und = np.sort(d, axis=1)
    _, inv, cnt = np.unique(und[:, 0] * n + und[:, 1], return_inverse=True, return_counts=True)
    _, dinv, dcnt = np.unique(d[:, 0] * n + d[:, 1], return_inverse=True, return_counts=True)
    return d, cnt[inv.reshape(-1)], dcnt[dinv.reshape(-1)]


def is_closed(faces: np.ndarray, n: int) -> bool:
    """True when every edge of the triangles [f, 3] (over n vertices) has exactly two triangles, wound against each
    other (a closed, consistently oriented surface)."""
    if len(faces) == 0:
        return False
    _, both, same = edge_counts(faces, n)
    return bool(np.all(both == 2) and np.all(same == 1))


def signed_volumes(vertices: np.ndarray, faces: np.ndarray, part: np.ndarray, parts: int) -> np.ndarray:
    """Signed volume [m^3] enclosed by the triangles of each part (signed-tetrahedron sums), float64 [parts]. The
    vertices are taken relative to their bounding-box centre, so the sums do not lose digits far from the origin."""
    v = vertices - 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    t = v[faces]
    vol = np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])) / 6.0
    return np.bincount(part, weights=vol, minlength=parts)


def cap_holes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """Closes every boundary loop of the triangles [f, 3] with a fan from the loop's centroid.

    Returns (vertices [v + loops, 3], faces [f + boundary edges, 3], a vertex of each loop int64 [loops], bad
    vertices: bool [v], True where a loop is not simple (a boundary vertex with other than one edge in and one out)).
    """
    n = len(vertices)
    d, both, _ = edge_counts(faces, n)
    bnd = d[both == 1]
    bad = np.zeros(n, dtype=bool)
    if len(bnd) == 0:
        return vertices, faces, np.zeros(0, dtype=np.int64), bad
    out_deg = np.bincount(bnd[:, 0], minlength=n)
    in_deg = np.bincount(bnd[:, 1], minlength=n)
    on = (out_deg > 0) | (in_deg > 0)
    bad = on & ((out_deg != 1) | (in_deg != 1))
    loop = _components(n, bnd[:, 0], bnd[:, 1])
    ids, loop_of_vertex = np.unique(loop[on], return_inverse=True)
    count = np.bincount(loop_of_vertex, minlength=len(ids)).astype(np.float64)
    centroid = (
        np.stack(
            [np.bincount(loop_of_vertex, weights=vertices[on][:, a], minlength=len(ids)) for a in range(3)], axis=1
        )
        / count[:, None]
    )
    index = np.full(n, -1, dtype=np.int64)
    index[np.flatnonzero(on)] = loop_of_vertex
    cap = np.stack([bnd[:, 1], bnd[:, 0], n + index[bnd[:, 0]]], axis=1)
    owner = np.flatnonzero(on)[np.unique(loop_of_vertex, return_index=True)[1]]
    return np.concatenate([vertices, centroid]), np.concatenate([faces, cap]), owner, bad


def rebuild_part(vertices: np.ndarray, faces: np.ndarray, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """A closed surface of the solid that triangles [f, 3] bound by their generalised winding number: the zero level
    set of their signed distance on a grid of REBUILD_CELLS cells across the largest extent (2 cells of margin),
    by marching cubes. Returns (vertices [m] [u, 3] float64, outward triangles [t, 3] int64)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = 0.5 * (lo + hi)
    cell = float((hi - lo).max()) / REBUILD_CELLS
    counts = np.ceil((hi - lo) / cell).astype(np.int64) + 5
    start = centre - 0.5 * (counts - 1) * cell  # relative to the centre: float32 keeps the digits
    axes = [start[a] - centre[a] + cell * np.arange(counts[a]) for a in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    with wp.ScopedDevice(device):
        mesh = wp.Mesh(
            points=wp.array((vertices - centre).astype(np.float32), dtype=wp.vec3),
            indices=wp.array(faces.astype(np.int32).ravel(), dtype=wp.int32),
            support_winding_number=True,
        )
        pts = wp.array(grid.astype(np.float32), dtype=wp.vec3)
        sdf = ks.winding_signed_distance(mesh, pts, float(np.linalg.norm(counts * cell)) + 1.0)
        mc = warp.geometry.IsoSurfaceMarchingCubes(
            int(counts[0]), int(counts[1]), int(counts[2]),
            lower=tuple(float(a[0]) for a in axes), upper=tuple(float(a[-1]) for a in axes),
        )  # fmt: skip
        mc.surface(sdf.reshape((int(counts[0]), int(counts[1]), int(counts[2]))), 0.0)
        v = mc.verts.numpy().astype(np.float64) + centre
        f = mc.indices.numpy().astype(np.int64).reshape(-1, 3)
    v, f = weld(v, f)
    f = clean_faces(f)
    if len(f) == 0:
        return v, f
    if signed_volumes(v, f, np.zeros(len(f), dtype=np.int64), 1)[0] < 0.0:
        f = f[:, ::-1]
    solid = _manifold(v, f)
    if solid is None:
        return v, f
    mesh = solid.simplify(REBUILD_SIMPLIFY * cell).to_mesh64()
    return np.asarray(mesh.vert_properties, np.float64)[:, :3].copy(), np.asarray(mesh.tri_verts, np.int64).reshape(
        -1, 3
    )


def _manifold(vertices: np.ndarray, faces: np.ndarray):
    """manifold3d solid of a closed surface, or None when manifold3d rejects it."""
    m = manifold3d.Manifold(
        manifold3d.Mesh64(np.ascontiguousarray(vertices, np.float64), np.ascontiguousarray(faces, np.uint64))
    )
    return m if m.status() == manifold3d.Error.NoError else None


def repair_surface(vertices, faces, source: str, triangulated: int = -1, device: str = "cpu"):
    """Repairs a triangle surface (see the module's steps) into a closed, outward-wound 2-manifold.

    Args:
        vertices: positions [m] [v, 3]; faces: triangles [f, 3] (vertex indices).
        source: the file or shape name, for messages.
        triangulated: polygons split into triangles before this call (reported), -1 when not known.

    Returns:
        (vertices [m] float64 [u, 3], triangles int32 [t, 3] wound counter-clockwise from outside, RepairReport).

    Raises:
        GeometryError: the mesh is empty, or it encloses no volume (every part is flat or empty after the repair).
    """
    v0 = np.asarray(vertices, dtype=np.float64)
    f0 = np.asarray(faces, dtype=np.int64)
    v, f = weld(v0, f0)
    welded = len(np.unique(f0)) - len(v)
    f = clean_faces(f)
    dropped_faces = len(f0) - len(f)
    if len(f) == 0:
        raise GeometryError(f"{source}: the mesh is empty (all triangles are degenerate)")
    v, f = v[np.unique(f)], np.unique(f, return_inverse=True)[1].reshape(-1, 3)
    n = len(v)
    part = _components(n, np.concatenate([f[:, 0], f[:, 1]]), np.concatenate([f[:, 1], f[:, 2]]))
    parts = int(part.max()) + 1
    report = {"welded": welded, "dropped_faces": dropped_faces, "triangulated": triangulated, "parts": parts}
    if parts == 1 and is_closed(f, n):
        if signed_volumes(v, f, np.zeros(len(f), dtype=np.int64), 1)[0] < 0.0:
            f = f[:, ::-1]
        _check_volume(v, f, source)
        return v, f.astype(np.int32), RepairReport(**report)

    # Sheets: triangles joined across edges that exactly two triangles share, wound against each other. Each sheet
    # gets its own copies of its vertices, so an edge shared by three or more triangles becomes a boundary of the
    # sheets that meet there (a character's eyes touching its head), to be capped like any hole.
    sheet = _sheets(f, n)
    sheets = int(sheet.max()) + 1
    group_of_sheet = np.zeros(sheets, dtype=np.int64)
    group_of_sheet[sheet] = part[f[:, 0]]
    uniq, inv = np.unique(sheet[np.repeat(np.arange(len(f)), 3)] * n + f.ravel(), return_inverse=True)
    vs, fs, owner_sheet = v[uniq % n], inv.reshape(-1, 3), uniq // n
    ns = len(vs)
    d, both, same = edge_counts(fs, ns)
    vc, fc, owner, bad_vertex = cap_holes(vs, fs)
    bad = np.zeros(sheets, dtype=bool)  # sheets that cannot be capped
    bad[owner_sheet[d[(both > 2) | (same > 1), 0]]] = True
    bad[owner_sheet[bad_vertex]] = True
    face_sheet = np.concatenate([owner_sheet, owner_sheet[owner]])[fc[:, 0]]
    t = vc[fc]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    sheet_area = np.bincount(face_sheet[: len(fs)], weights=area[: len(fs)], minlength=sheets)
    cap_area = np.bincount(fc[len(fs) :, 2] - ns, weights=area[len(fs) :], minlength=len(owner))
    card = np.zeros(sheets, dtype=bool)  # sheets with a hole as large as themselves: cards, not solids
    card[owner_sheet[owner[cap_area > CAP_AREA_LIMIT * sheet_area[owner_sheet[owner]]]]] = True
    vol = signed_volumes(vc, fc, face_sheet, sheets)
    size = _part_sizes(vc, fc, face_sheet, sheets)
    solid = [None] * sheets
    for k in np.flatnonzero(~bad & ~card):  # one manifold3d solid per sheet (sheets are few; the work is in manifold3d)
        solid[k] = _manifold(*_compact(vc, fc[face_sheet == k]))
        bad[k] = solid[k] is None
    rebuild = np.zeros(parts, dtype=bool)  # parts with a sheet that cannot be capped are rebuilt whole
    rebuild[group_of_sheet[bad]] = True
    keep = ~rebuild[group_of_sheet]
    if vol[keep].sum() < 0.0:  # the mesh is wound inwards
        fc, vol = fc[:, ::-1], -vol
        solid = [None if m is None else _manifold(*_compact(vc, fc[face_sheet == k])) for k, m in enumerate(solid)]
    empty = card | (np.abs(vol) <= NO_VOLUME * size**3)
    solids = [solid[k] for k in np.flatnonzero(keep & ~empty & (vol > 0.0))]
    cavities = [
        _manifold(*_compact(vc, fc[face_sheet == k][:, ::-1])) for k in np.flatnonzero(keep & ~empty & (vol < 0.0))
    ]
    dropped = int((keep & empty).sum())
    for g in np.flatnonzero(rebuild):
        pv, pf = rebuild_part(*_compact(v, f[part[f[:, 0]] == g]), device=device)
        m = _manifold(pv, pf) if len(pf) else None
        if m is None or m.volume() <= NO_VOLUME * float(np.ptp(pv, axis=0).max()) ** 3:
            dropped += 1
        else:
            solids.append(m)
    if not solids:
        raise GeometryError(
            f"{source}: the mesh encloses no volume: its {parts} part(s) are flat or open sheets (cards: a hole larger "
            f"than {CAP_AREA_LIMIT:g} of the sheet's area is not capped, and a closed piece below {NO_VOLUME:g} of "
            "its size cubed is empty), so there is nothing to fill; give the surface a thickness (e.g. Blender's "
            "Solidify modifier) or close it"
        )
    result = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add) if len(solids) > 1 else solids[0]
    if cavities:
        result = result - manifold3d.Manifold.batch_boolean(cavities, manifold3d.OpType.Add)
    mesh = result.to_mesh64()
    rv = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3].copy()
    rf = np.asarray(mesh.tri_verts, dtype=np.int64).reshape(-1, 3)
    capped = keep[owner_sheet[owner]] & ~empty[owner_sheet[owner]]
    report.update(
        holes_capped=int(capped.sum()),
        rebuilt=int(rebuild.sum()),
        dropped_parts=dropped,
        united=len(solids) + len(cavities) if len(solids) + len(cavities) > 1 else 0,
    )
    return rv, rf.astype(np.int32), RepairReport(**report)


def _sheets(faces: np.ndarray, n: int) -> np.ndarray:
    """Sheet of each triangle [f]: triangles are joined across an edge that exactly two triangles share, wound
    against each other (a consistently oriented 2-manifold piece), int64 [f]."""
    d, both, same = edge_counts(faces, n)
    und = np.sort(d, axis=1)
    key = und[:, 0] * n + und[:, 1]
    order = np.argsort(key, kind="stable")
    k = key[order]
    pair = (k[:-1] == k[1:]) & (both[order[:-1]] == 2) & (same[order[:-1]] == 1)
    return _components(len(faces), order[:-1][pair] // 3, order[1:][pair] // 3)


def _compact(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the vertices the triangles use, the triangles renumbered)."""
    used, inv = np.unique(f, return_inverse=True)
    return v[used], inv.reshape(-1, 3)


def _part_sizes(v: np.ndarray, f: np.ndarray, face_part: np.ndarray, parts: int) -> np.ndarray:
    """Largest bounding-box extent [m] of each part's triangles, float64 [parts]."""
    pv = np.repeat(face_part, 3)
    pts = v[f.ravel()]
    lo = np.stack([np.full(parts, np.inf)] * 3, axis=1)
    hi = -lo
    np.minimum.at(lo, pv, pts)
    np.maximum.at(hi, pv, pts)
    return np.where(np.isfinite(lo[:, 0]), (hi - lo).max(axis=1), 0.0)


def _check_volume(v: np.ndarray, f: np.ndarray, source: str) -> None:
    """GeometryError when the closed surface encloses no volume."""
    size = float(np.ptp(v, axis=0).max())
    if not signed_volumes(v, f, np.zeros(len(f), dtype=np.int64), 1)[0] > NO_VOLUME * size**3:
        raise GeometryError(
            f"{source}: the mesh encloses no volume (its closed surface bounds less than {NO_VOLUME:g} of its size "
            "cubed: a flat or doubled-over sheet), so there is nothing to fill; give the surface a thickness"
        )
