"""Reading a USD stage for the preview: its renderable Mesh and Points prims, frames, bounds and ground, and each
frame's world-space geometry with its colours (``StageReader.frame``)."""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom
from scipy.spatial import cKDTree

from ..errors import ParameterError
from ..output.usd_files import check_cache_files
from .camera import horizontal_axes
from .colors import CRACK, NEUTRAL, Coloring, linear
from .options import POINTS_MODES


def _triangulate(counts: np.ndarray, indices: np.ndarray, holes: np.ndarray | None):
    """Fan triangulation of polygons: (triangles [t, 3] point indices, face of each triangle [t], face-vertex index
    of each corner [t, 3]). Faces with fewer than 3 vertices and hole faces give no triangles."""
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]) if len(counts) else np.zeros(0, np.int64)
    ntri = np.maximum(counts - 2, 0)
    if holes is not None and len(holes):
        h = np.asarray(holes, dtype=np.int64)
        ntri[h[(h >= 0) & (h < len(counts))]] = 0
    face = np.repeat(np.arange(len(counts)), ntri)
    k = np.arange(int(ntri.sum())) - np.repeat(np.cumsum(ntri) - ntri, ntri)  # triangle number within its face
    s = starts[face]
    corner = np.stack([s, s + k + 1, s + k + 2], axis=1)
    return np.asarray(indices, dtype=np.int64)[corner], face, corner


def _expand(values, interpolation: str, n_faces: int, n_points: int, n_fv: int, tri, face, corner):
    """Per-corner values [t, 3, ...] of a mesh primvar, or None when its length does not fit its interpolation."""
    v = np.asarray(values)
    if v.ndim == 0 or len(v) == 0:
        return None
    if interpolation == "constant":
        return np.broadcast_to(v[0], (len(tri), 3, *v.shape[1:]))
    if interpolation == "uniform" and len(v) == n_faces:
        return np.repeat(v[face][:, None], 3, axis=1)
    if interpolation in ("vertex", "varying") and len(v) == n_points:
        return v[tri]
    if interpolation == "faceVarying" and len(v) == n_fv:
        return v[corner]
    return None


def _scalar(values: np.ndarray) -> np.ndarray:
    """Scalar per element: the values themselves, or the length of vector values [..., k]."""
    v = np.asarray(values)
    if v.dtype == bool:
        v = v.astype(np.int32)
    if v.ndim >= 2 and v.shape[-1] > 1:
        return np.linalg.norm(v.astype(np.float64), axis=-1)
    return v[..., 0] if v.ndim >= 2 else v


def _matrix(xf_cache, prim) -> np.ndarray:
    """Local-to-world matrix of a prim, float64 [4, 4], row-vector convention (p' = p M[:3, :3] + M[3, :3])."""
    return np.array(xf_cache.GetLocalToWorldTransform(prim), dtype=np.float64)


def _transform(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    if np.allclose(m, np.eye(4)):
        return points
    return points @ m[:3, :3] + m[3, :3]


def _primvar(prim, name: str, t):
    """(values, interpolation) of the primvar ``name`` at time code t (indexed primvars flattened), or None."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(name)
    if not pv or not pv.HasValue():
        return None
    values = pv.ComputeFlattened(t)
    if values is None:
        return None
    try:
        arr = np.asarray(values)
    except (TypeError, ValueError):
        return None
    if arr.dtype.kind not in "biuf":
        return None
    if arr.ndim == 0:
        arr = arr.reshape(1)
    return arr, str(pv.GetInterpolation())


COLLIDER_GROUP = "colliders"  # the prim under the default prim that holds colliders and projectiles (RigidView.group)
GROUND_NAME = "ground"  # the name of the scene's ground plane's prim (pdsim/colliders.py: GroundPlane.name)


def _is_collider(path) -> bool:
    """True for a prim path under ``/<default prim>/colliders`` (a static collider or a projectile)."""
    parts = str(path).split("/")
    return len(parts) > 3 and parts[2] == COLLIDER_GROUP


@dataclass
class FrameGeometry:
    """One frame's renderable geometry, world coordinates [m]."""

    surf_points: list = field(default_factory=list)  # float64 [v, 3] per mesh
    surf_tris: list = field(default_factory=list)  # int [t, 3] per mesh (local indices)
    surf_colors: list = field(default_factory=list)  # linear float32 [t, 3, 3] per mesh
    surf_normals: list = field(default_factory=list)  # float32 [t, 3, 3] per mesh (zeros: use the face normal)
    centers: list = field(default_factory=list)  # float64 [s, 3] per points prim
    radii: list = field(default_factory=list)  # float64 [s] per points prim
    colors: list = field(default_factory=list)  # linear float32 [s, 3] per points prim


def _under_instancer(prim) -> bool:
    """Whether ``prim`` lies under a ``UsdGeom.PointInstancer`` (a prototype, not drawn where it stands)."""
    parent = prim.GetParent()
    while parent and not parent.IsPseudoRoot():
        if parent.IsA(UsdGeom.PointInstancer):
            return True
        parent = parent.GetParent()
    return False


class StageReader:
    """A USD stage opened for rendering: its renderable prims, up axis and frames."""

    def __init__(self, path: str, points: str = "auto"):
        if points not in POINTS_MODES:
            raise ParameterError("points", points, "one of " + ", ".join(POINTS_MODES))
        self.points_mode = points

        readable = "an existing, readable USD file (.usd, .usda, .usdc)"
        if not isinstance(path, str | os.PathLike) or not os.path.isfile(path):
            raise ParameterError("cache", os.fspath(path) if isinstance(path, os.PathLike) else path, readable)
        path = os.fspath(path)
        if Sdf.FileFormat.FindByExtension(os.path.splitext(path)[1].lstrip(".").lower() or "x"):
            check_cache_files(path)  # a clip-layout cache without its frames folder would open with no points
        try:
            if not Sdf.FileFormat.FindByExtension(os.path.splitext(path)[1].lstrip(".").lower() or "x"):
                raise ParameterError("cache", path, readable)
            stage = Usd.Stage.Open(path)
        except Tf.ErrorException:
            stage = None
        if stage is None:
            raise ParameterError("cache", path, readable)
        self.path = path
        self.stage = stage
        self.ground_prims = set()
        self.up = np.array([0.0, 1.0, 0.0]) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else np.eye(3)[2]
        self.meshes, self.points = [], []
        guides = []
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Points):
                if _under_instancer(prim):  # a point instancer's prototype (debris) is drawn only as instances
                    continue
                if UsdGeom.Imageable(prim).ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
                    guides.append(prim)  # a body's particles under its surface stay drawable (below)
                    continue
                (self.meshes if prim.IsA(UsdGeom.Mesh) else self.points).append(prim)
        # a body's Points prim <name> is covered by its surface mesh <name>_surface when there is one
        # a body's Points prim <b> is covered by its surface <b>_surface or render mesh <b>_render (a Mesh, or an
        # Xform of fragment meshes) beside it; a visible <b>_render stands for <b>_surface
        self._roots = {prim.GetPath(): self._surface_root(prim) for prim in self.meshes}
        self.surface_of = {}
        for root, body in self._roots.values():
            if body is not None:
                self.surface_of.setdefault(body.GetPath(), set()).add(root)
        # the particles pdsim writes as guides (Scene.run(render_points=False)) are drawn as before (--points all):
        # guide Points prims that are a surface's body; other guides (crack events) are not drawn
        self.points += [p for p in guides if p.IsA(UsdGeom.Points) and p.GetPath() in self.surface_of]
        if not self.meshes and not self.points:
            raise ParameterError("cache", path, "a USD stage with at least one UsdGeom.Mesh or UsdGeom.Points prim")
        if stage.HasAuthoredTimeCodeRange():
            start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
            self.frames = list(range(math.ceil(start), math.floor(end) + 1)) or [round(start)]
        else:
            samples = set()
            for prim in self.meshes + self.points:
                samples.update(UsdGeom.PointBased(prim).GetPointsAttr().GetTimeSamples())
            self.frames = sorted({round(s) for s in samples}) or [0]
            self.frames = list(range(self.frames[0], self.frames[-1] + 1))
        self.fps = float(stage.GetFramesPerSecond() or stage.GetTimeCodesPerSecond() or 24.0)

    # -- queries -----------------------------------------------------------------------------------------------------

    def visible(self, prim, t) -> bool:
        return UsdGeom.Imageable(prim).ComputeVisibility(t) != UsdGeom.Tokens.invisible

    def drawn_points(self, t) -> list:
        """The Points prims drawn at time t: all visible ones (mode "all"), none (mode "none"), or (mode "auto") the
        visible ones that are not covered by a visible sibling surface mesh ``<name>_surface``."""
        if self.points_mode == "none":
            return []
        out = []
        for prim in self.points:
            if not self.visible(prim, t):
                continue
            covers = self.surface_of.get(prim.GetPath(), ())
            if self.points_mode == "auto" and any(self.visible(root, t) for root in covers):
                continue
            out.append(prim)
        return out

    def primvar_names(self) -> list[str]:
        """Names of the numeric primvars with a value on any renderable prim."""
        names = set()
        for prim in self.meshes + self.points:
            for pv in UsdGeom.PrimvarsAPI(prim).GetPrimvarsWithValues():
                names.add(pv.GetPrimvarName())
        return sorted(names)

    @staticmethod
    def _surface_root(mesh_prim):
        """(R, B): the prim R named ``<b>_surface`` or ``<b>_render`` that the mesh is or lies under and the Points
        prim B named ``<b>`` beside R (a body's surface, render mesh or fragment prims and the body's points), or
        (None, None)."""
        prim = mesh_prim
        while prim and not prim.IsPseudoRoot():
            name = prim.GetName()
            for suffix in ("_surface", "_render"):
                if name.endswith(suffix) and len(name) > len(suffix):
                    body = prim.GetParent().GetChild(name[: -len(suffix)])
                    if body and body.IsA(UsdGeom.Points):
                        return prim, body
            prim = prim.GetParent()
        return None, None

    def source_points(self, mesh_prim):
        """The body's Points prim ``<b>`` of a mesh that is or lies under ``<b>_surface`` / ``<b>_render``, or None."""
        return self._roots[mesh_prim.GetPath()][1]

    def drawn_meshes(self, t) -> list:
        """The meshes drawn at time t: the visible ones, less the ground-like ones and a body's ``<b>_surface`` when
        its ``<b>_render`` is visible."""
        out = []
        for prim in self.meshes:
            if prim.GetPath() in self.ground_prims or not self.visible(prim, t):
                continue
            root, body = self._roots[prim.GetPath()]
            if root is not None and root.GetName().endswith("_surface"):
                render = root.GetParent().GetChild(body.GetName() + "_render")
                if render and render.GetPath() != root.GetPath() and self.visible(render, t):
                    continue
            out.append(prim)
        return out

    def _mesh_topology(self, prim, t):
        """(world points float64 [v, 3], triangles [t, 3], face [t], corner [t, 3], face count, face-vertex count)
        of a mesh at time t, or None when it has no usable points or faces."""
        mesh = UsdGeom.Mesh(prim)
        pts = mesh.GetPointsAttr().Get(t)
        counts = mesh.GetFaceVertexCountsAttr().Get(t)
        idx = mesh.GetFaceVertexIndicesAttr().Get(t)
        if pts is None or counts is None or idx is None or len(pts) == 0 or len(counts) == 0:
            return None
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        counts, idx = np.asarray(counts, dtype=np.int64), np.asarray(idx, dtype=np.int64)
        if counts.sum() != len(idx) or (len(idx) and (idx.min() < 0 or idx.max() >= len(pts))):
            return None  # inconsistent topology at this time: skip the prim rather than render garbage
        holes = mesh.GetHoleIndicesAttr().Get(t)
        tri, face, corner = _triangulate(counts, idx, None if holes is None else np.asarray(holes))
        if len(tri) == 0:
            return None
        return pts, tri, face, corner, len(counts), len(idx)

    def _points(self, prim, t):
        """(points float64 [n, 3] local, radii float64 [n]) of a Points prim at t, or None."""
        geom = UsdGeom.Points(prim)
        pts = geom.GetPointsAttr().Get(t)
        if pts is None or len(pts) == 0:
            return None
        pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
        widths = geom.GetWidthsAttr().Get(t)
        w = np.asarray(widths, dtype=np.float64) if widths is not None else np.zeros(0)
        if len(w) == len(pts):
            radii = 0.5 * w
        elif len(w) >= 1:
            radii = np.full(len(pts), 0.5 * w[0])
        else:
            radii = np.full(len(pts), np.nan)  # filled in by the caller from the scene size
        return pts, radii

    def bounds(self, frames, *, detect_ground: bool = True) -> tuple[np.ndarray, np.ndarray, float | None]:
        """(lo, hi) [m] of the bodies over ``frames`` (points grown by their radii; the prims under
        ``/World/colliders``, the scene's colliders and projectiles, are left out unless there is nothing else) and
        the ground height [m] along the up axis of a ground-like mesh if there is one (else None): a mesh
        perpendicular to the up axis
        (thickness below 1e-6 of its width), below the middle of all other geometry and at least as wide as it, or
        named ``ground`` (pdsim writes the scene's ground plane as such a quad, /World/ground, which debris may fly
        past). It is left out of the box and of the
        rendering; the preview's ground plane, at its height, stands for it. ``detect_ground=False`` keeps the
        ground-like prims found by an earlier call and returns None for the height."""
        boxes = {}  # prim path -> (lo, hi)
        if detect_ground:
            self.ground_prims = set()
        for f in frames:
            xf = UsdGeom.XformCache(f)
            for prim in self.drawn_meshes(f) + self.drawn_points(f):
                if prim.IsA(UsdGeom.Mesh):
                    pts = UsdGeom.Mesh(prim).GetPointsAttr().Get(f)
                    if pts is None or len(pts) == 0:
                        continue
                    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
                    r = 0.0
                else:
                    got = self._points(prim, f)
                    if got is None:
                        continue
                    pts, radii = got
                    r = float(np.nanmax(radii)) if np.isfinite(radii).any() else 0.0
                p = _transform(pts, _matrix(xf, prim))
                lo, hi = p.min(axis=0) - r, p.max(axis=0) + r
                key = prim.GetPath()
                if key in boxes:
                    lo, hi = np.minimum(boxes[key][0], lo), np.maximum(boxes[key][1], hi)
                boxes[key] = (lo, hi)
        if not boxes:
            raise ParameterError("cache", self.path, "a cache whose prims have points in the selected frames")
        ground = None
        if detect_ground and len(boxes) > 1:
            e1, e2 = horizontal_axes(self.up)
            for key, (lo, hi) in boxes.items():
                others = [b for k, b in boxes.items() if k != key]
                olo = np.min([b[0] for b in others], axis=0)
                ohi = np.max([b[1] for b in others], axis=0)
                span = hi - lo
                horizontal = max(abs(span @ e1), abs(span @ e2))
                oh = max(abs((ohi - olo) @ e1), abs((ohi - olo) @ e2))
                height, others_mid = float(lo @ self.up), float(0.5 * (olo + ohi) @ self.up)
                flat = abs(span @ self.up) <= 1.0e-6 * horizontal
                wide = horizontal >= oh or key.name == GROUND_NAME  # pdsim's own ground, whatever flies past it
                if flat and wide and height <= others_mid:
                    self.ground_prims.add(key)
                    ground = height
        kept = [b for k, b in boxes.items() if k not in self.ground_prims] or list(boxes.values())
        bodies = [b for k, b in boxes.items() if k not in self.ground_prims and not _is_collider(k)]
        kept = bodies or kept
        lo = np.min([b[0] for b in kept], axis=0)
        hi = np.max([b[1] for b in kept], axis=0)
        return lo, hi, ground

    # -- colours -----------------------------------------------------------------------------------------------------

    def attribute_values(self, name: str, frames) -> list[np.ndarray]:
        """The scalar values of primvar ``name`` on every renderable prim over ``frames`` (for its range)."""
        out = []
        for f in frames:
            for prim in self.meshes + self.points:
                got = _primvar(prim, name, f)
                if got is not None:
                    out.append(_scalar(got[0]).ravel())
        return out

    def frame(self, t, color: Coloring, default_radius: float) -> FrameGeometry:
        """The geometry and colours of all visible renderable prims at time code t."""
        geo = FrameGeometry()
        xf = UsdGeom.XformCache(t)
        for prim in self.drawn_meshes(t):
            topo = self._mesh_topology(prim, t)
            if topo is None:
                continue
            pts, tri, face, corner, n_faces, n_fv = topo
            m = _matrix(xf, prim)
            world = _transform(pts, m)
            expand = functools.partial(
                _expand, n_faces=n_faces, n_points=len(pts), n_fv=n_fv, tri=tri, face=face, corner=corner
            )
            colors = None
            if color.name is not None:
                got = _primvar(prim, color.name, t)
                per_corner = None if got is None else expand(_scalar(got[0]), got[1])
                if per_corner is None:
                    per_corner = self._transferred(prim, color.name, t, world, xf, expand)
                if per_corner is not None:
                    colors = linear(color.map(per_corner))
            if colors is None:
                colors = self._base_colors(prim, t, expand, face, len(tri))
            normals = np.zeros((len(tri), 3, 3), np.float32)
            got = self._normals(prim, t)
            if got is not None:
                n = expand(*got)
                if n is not None and n.shape[-1:] == (3,):
                    a = m[:3, :3]
                    n = np.asarray(n, np.float64) @ np.linalg.inv(a).T
                    normals = (n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-30)).astype(np.float32)
            geo.surf_points.append(world)
            geo.surf_tris.append(tri)
            geo.surf_colors.append(np.asarray(colors, np.float32))
            geo.surf_normals.append(normals)
        for prim in self.drawn_points(t):
            got = self._points(prim, t)
            if got is None:
                continue
            pts, radii = got
            m = _matrix(xf, prim)
            world = _transform(pts, m)
            scale = float(np.cbrt(abs(np.linalg.det(m[:3, :3])))) if not np.allclose(m, np.eye(4)) else 1.0
            radii = np.where(np.isfinite(radii), radii * scale, default_radius)
            colors = None
            if color.name is not None:
                pv = _primvar(prim, color.name, t)
                if pv is not None:
                    v = _scalar(pv[0])
                    if len(v) == len(pts):
                        colors = linear(color.map(v))
                    elif len(v) >= 1:
                        colors = linear(color.map(np.broadcast_to(v[:1], (len(pts),))))
            if colors is None:  # displayColor (linear RGB) where authored, else neutral
                colors = np.broadcast_to(linear(NEUTRAL), (len(pts), 3))
                dc = _primvar(prim, "displayColor", t)
                if dc is not None and dc[0].ndim == 2 and dc[0].shape[1] == 3:
                    if len(dc[0]) == len(pts):
                        colors = dc[0]
                    elif len(dc[0]) >= 1:
                        colors = np.broadcast_to(dc[0][0], (len(pts), 3))
            geo.centers.append(world)
            geo.radii.append(radii)
            geo.colors.append(np.asarray(colors, np.float32))
        return geo

    def _normals(self, prim, t):
        """(normals, interpolation) authored on a mesh (``primvars:normals`` before ``normals``), or None."""
        got = _primvar(prim, "normals", t)
        if got is not None:
            return got
        mesh = UsdGeom.Mesh(prim)
        values = mesh.GetNormalsAttr().Get(t)
        if values is None or len(values) == 0:
            return None
        return np.asarray(values, dtype=np.float64).reshape(-1, 3), str(mesh.GetNormalsInterpolation())

    def _base_colors(self, prim, t, expand, face, n_tris) -> np.ndarray:
        """Linear per-corner colours [t, 3, 3] without an attribute: ``displayColor`` (linear RGB, as USD has it)
        where authored; else neutral with the crack faces (primvar ``crack`` == 1 or GeomSubset ``crack``) in the
        crack colour."""
        dc = _primvar(prim, "displayColor", t)
        if dc is not None and dc[0].ndim == 2 and dc[0].shape[1] == 3:
            colors = expand(*dc)
            if colors is not None:
                return np.asarray(colors, np.float32)
        colors = np.array(np.broadcast_to(linear(NEUTRAL), (n_tris, 3, 3)), dtype=np.float32)
        crack = np.zeros(n_tris, bool)
        got = _primvar(prim, "crack", t)
        if got is not None:
            c = expand(*got)
            if c is not None and c.ndim == 2:
                crack |= c[:, 0] == 1
        for subset in UsdGeom.Subset.GetGeomSubsets(UsdGeom.Imageable(prim), UsdGeom.Tokens.face):
            if subset.GetPrim().GetName() == "crack":
                idx = subset.GetIndicesAttr().Get(t)
                if idx is not None and len(idx):
                    in_subset = np.zeros(max(int(face.max(initial=0)), int(np.max(idx))) + 1, bool)
                    in_subset[np.asarray(idx, dtype=np.int64)] = True
                    crack |= in_subset[face]
        colors[crack] = linear(CRACK)
        return colors

    def _transferred(self, prim, name, t, world, xf, expand):
        """Per-corner values of ``name`` for a body's surface, fragment or render mesh from the body's Points prim
        (the value of the nearest point of each vertex), or None."""
        source = self.source_points(prim)
        if source is None:
            return None
        got = _primvar(source, name, t)
        pts = self._points(source, t)
        if got is None or pts is None:
            return None
        values = _scalar(got[0])
        if len(values) != len(pts[0]):
            return None
        _, nearest = cKDTree(_transform(pts[0], _matrix(xf, source))).query(world)
        return expand(values[nearest], "vertex")
