"""Writes method-neutral views (pdsim/output/views.py) into a USD cache (pdsim/output/usd.py), frame by frame.

The first views of a name declare its prim: ``UsdGeom.Points`` at ``/World/<body>`` for a PointsView, a
``UsdGeom.Mesh`` at ``/World/<name>`` for a MeshView (or, with ``fragments_as_prims``, an Xform ``/World/<name>`` with
one Mesh ``fragment_<id>`` per fragment), and a Mesh with a transform at ``/World/colliders/<name>`` (``/World/ground``
for the ground) for a RigidView. Points and mesh prims get a static double-precision ``xformOp:translate`` at the
rest centre of their first view (:func:`rest_centre`) and store their float32 points relative to it, so positions keep
float32's precision around the body wherever it is; rigid bodies store their mesh in the body frame with a double
translate. A surface with a ``crack`` face attribute gets the face subsets ``outer`` and ``crack`` (a partition of its
faces) bound to the materials ``pdsim_outer`` and ``pdsim_crack``, and the per-face ``material_index`` (0, 1). An
EventsView becomes the guide Points ``/World/<body>_crack_events``; with ``debris_particles`` the small fragments
become the instances of ``/World/<body>_debris`` (pdsim/output/debris.py). docs/cache_format.md describes every prim
and attribute.

Normals are computed here from each frame's points and faces (vectorised numpy): faces are grouped around each vertex
into smooth fans, split at edges whose dihedral angle exceeds ``sharp_angle`` (30 degrees by default), so a box keeps
crisp edges while a sphere shades smoothly. The fans are computed when the topology changes and kept until the next
change, so shading does not flicker as edges bend past the threshold during an animation; each frame's normals are the
angle-weighted mean of the current face normals over each fan.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .debris import chunk_prototype, small_fragments, without_fragments
from .views import EventsView, MeshView, PointsView, RigidView, attribute_kind

SHARP_ANGLE_DEG = 30.0

# the colour ramp of displayColor for real-valued attributes (a viridis-like ramp, linear RGB): stops at 0, 1/4, ... 1
_RAMP = np.array(
    [
        [0.063, 0.000, 0.170],
        [0.050, 0.160, 0.400],
        [0.020, 0.420, 0.370],
        [0.350, 0.720, 0.100],
        [0.980, 0.820, 0.030],
    ]
)


# ------------------------------------------------------------------------------------------------------------ normals


def _face_geometry(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit face normals (float64 [f, 3], zero for degenerate faces) and corner angles [rad] (float64 [f, 3])."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    n = np.cross(b - a, c - a)
    length = np.linalg.norm(n, axis=1)
    unit = np.divide(n, length[:, None], out=np.zeros_like(n), where=length[:, None] > 0.0)
    corners = np.stack([a, b, c], axis=1)  # [f, 3, 3]
    e1 = np.roll(corners, -1, axis=1) - corners  # to the next corner
    e2 = np.roll(corners, 1, axis=1) - corners  # to the previous corner
    angles = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=2), np.einsum("fki,fki->fk", e1, e2))
    return unit, angles


def smoothing_groups(points: np.ndarray, faces: np.ndarray, sharp_angle: float = SHARP_ANGLE_DEG):
    """Smooth fans of face corners: corners of one vertex are in one group when the faces around the vertex are joined
    by edges whose dihedral angle is at most ``sharp_angle`` [deg] (boundary, non-manifold and inconsistently wound
    edges split).

    Args:
        points: vertex positions [m], float [v, 3].
        faces: triangles, int [f, 3].
        sharp_angle: dihedral angle [deg] above which an edge is sharp.

    Returns:
        (labels, count): the group of each corner (int [3 f], in the order of ``faces.ravel()``) and the number of
        groups.
    """
    faces = np.asarray(faces, dtype=np.int64)
    nf = len(faces)
    if nf == 0:
        return np.zeros(0, np.int64), 0
    unit, _ = _face_geometry(points, faces)
    nv = int(faces.max()) + 1
    a = faces.ravel()  # corner c holds vertex a[c]; its half-edge runs a[c] -> b[c]
    b = faces[:, [1, 2, 0]].ravel()
    key = np.minimum(a, b) * nv + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    start = np.r_[True, ks[1:] != ks[:-1]]
    group = np.cumsum(start) - 1
    pair = start & (np.bincount(group)[group] == 2)  # first half-edge of each edge with exactly two faces
    at = np.flatnonzero(pair)
    h1, h2 = order[at], order[at + 1]
    f1, f2 = h1 // 3, h2 // 3
    cos_sharp = math.cos(math.radians(sharp_angle))
    smooth = (a[h1] == b[h2]) & (np.einsum("ij,ij->i", unit[f1], unit[f2]) >= cos_sharp)
    h1, h2 = h1[smooth], h2[smooth]
    n1 = 3 * (h1 // 3) + (h1 % 3 + 1) % 3  # corner after h1 in its face: vertex b[h1] = a[h2]
    n2 = 3 * (h2 // 3) + (h2 % 3 + 1) % 3  # corner after h2: vertex b[h2] = a[h1]
    rows = np.r_[h1, n1]
    cols = np.r_[n2, h2]
    graph = coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(3 * nf, 3 * nf))
    count, labels = connected_components(graph, directed=False)
    return labels.astype(np.int64), int(count)


def _groups_are_per_vertex(faces: np.ndarray, labels: np.ndarray) -> bool:
    """True when every vertex has a single smooth group (vertex normals represent the shading exactly)."""
    a = np.asarray(faces, dtype=np.int64).ravel()
    if a.size == 0:
        return True
    vertex_groups = np.unique(a * (int(labels.max()) + 1) + labels).size
    return vertex_groups == np.unique(a).size


def corner_normals(points: np.ndarray, faces: np.ndarray, labels: np.ndarray, count: int) -> np.ndarray:
    """Unit normal of each face corner (float64 [3 f, 3], order of ``faces.ravel()``): the angle-weighted mean of the
    face normals over the corner's smooth group (``smoothing_groups``). Degenerate groups take their face's normal, or
    +z where that is degenerate too."""
    faces = np.asarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return np.zeros((0, 3))
    unit, angles = _face_geometry(points, faces)
    weighted = np.repeat(unit, 3, axis=0) * angles.reshape(-1, 1)
    sums = np.stack([np.bincount(labels, weights=weighted[:, k], minlength=count) for k in range(3)], axis=1)
    n = sums[labels]
    length = np.linalg.norm(n, axis=1)
    bad = ~(length > 1.0e-30)
    n[~bad] /= length[~bad, None]
    if bad.any():
        fallback = np.repeat(unit, 3, axis=0)[bad]
        fallback[np.linalg.norm(fallback, axis=1) == 0.0] = (0.0, 0.0, 1.0)
        n[bad] = fallback
    return n


def vertex_normals(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Angle-weighted vertex normals (float64 [v, 3]); +z for vertices in no face or only in degenerate faces."""
    faces = np.asarray(faces, dtype=np.int64)
    nv = len(points)
    labels = faces.ravel()
    n = np.tile([0.0, 0.0, 1.0], (nv, 1))
    if len(faces):
        per_corner = corner_normals(points, faces, labels, nv)
        n[labels] = per_corner
    return n


class _Shading:
    """Smooth groups of one mesh topology and the normal interpolation they are written with."""

    def __init__(self, points, faces, sharp_angle: float, interpolation: str | None):
        self.faces = np.asarray(faces, dtype=np.int64)
        self.labels, self.count = smoothing_groups(points, self.faces, sharp_angle)
        if interpolation is None:
            interpolation = "vertex" if _groups_are_per_vertex(self.faces, self.labels) else "faceVarying"
        self.interpolation = interpolation

    @classmethod
    def restored(cls, faces, labels, count: int, interpolation: str) -> _Shading:
        """The smooth groups of a checkpoint (:meth:`ViewWriter.checkpoint`), as computed when the topology changed."""
        shading = cls.__new__(cls)
        shading.faces = np.asarray(faces, dtype=np.int64)
        shading.labels = np.asarray(labels, dtype=np.int64)
        shading.count = int(count)
        shading.interpolation = str(interpolation)
        return shading

    def normals(self, points) -> np.ndarray:
        if self.interpolation == "faceVarying":
            return corner_normals(points, self.faces, self.labels, self.count)
        return vertex_normals(points, self.faces)


# ------------------------------------------------------------------------------------------------------------ colours


def color_ramp(values: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Linear RGB colours (float32 [n, 3]) of real ``values`` [n] mapped linearly from [lo, hi] onto the ramp (values
    outside are clamped)."""
    v = np.asarray(values, dtype=np.float64)
    span = hi - lo
    t = np.clip((v - lo) / span, 0.0, 1.0) if span > 0 else np.zeros_like(v)
    t = np.nan_to_num(t, nan=0.0)
    stops = np.linspace(0.0, 1.0, len(_RAMP))
    return np.stack([np.interp(t, stops, _RAMP[:, k]) for k in range(3)], axis=1).astype(np.float32)


def category_colors(ids: np.ndarray) -> np.ndarray:
    """Distinct linear RGB colours (float32 [n, 3]) for integer ``ids`` [n] (golden-ratio hues, the same id always gets
    the same colour)."""
    ids = np.asarray(ids, dtype=np.int64)
    h = np.mod(ids * 0.6180339887498949, 1.0) * 6.0
    s, v = 0.65, 0.9
    k = np.floor(h).astype(np.int64) % 6
    f = h - np.floor(h)
    p, q, t = v * (1 - s), v * (1 - s * f), v * (1 - s * (1 - f))
    table = np.stack(
        [
            np.stack([np.full_like(f, v), t, np.full_like(f, p)], 1),
            np.stack([q, np.full_like(f, v), np.full_like(f, p)], 1),
            np.stack([np.full_like(f, p), np.full_like(f, v), t], 1),
            np.stack([np.full_like(f, p), q, np.full_like(f, v)], 1),
            np.stack([t, np.full_like(f, p), np.full_like(f, v)], 1),
            np.stack([np.full_like(f, v), np.full_like(f, p), q], 1),
        ]
    )  # [6, n, 3]
    return table[k, np.arange(len(ids))].astype(np.float32)


class _Colors:
    """displayColor from one attribute: integer attributes get a colour per id, vectors their length on the ramp,
    real values the ramp over ``color_range`` (default [0, 1])."""

    def __init__(self, attribute: str | None, color_range):
        self.attribute = attribute
        if color_range is None:
            self.lo, self.hi = 0.0, 1.0
        else:
            lo, hi = (float(x) for x in color_range)
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise ValueError(f"color_range={color_range!r} must be two finite numbers lo < hi")
            self.lo, self.hi = lo, hi

    def __call__(self, values) -> np.ndarray:
        a = np.asarray(values)
        if np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_:
            return category_colors(a)
        if a.ndim == 2:
            a = np.linalg.norm(a, axis=1)
        return color_ramp(a, self.lo, self.hi)


# ------------------------------------------------------------------------------------------------------------ writer


def _kind_of(name: str, values) -> str:
    """The primvar kind of an attribute: the shared kind of a known name, else from the values."""
    try:
        return attribute_kind(name)
    except KeyError:
        a = np.asarray(values)
        if a.ndim == 2:
            return "vector3f"
        return "int" if (np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_) else "float"


# the materialBind face subsets of a surface with a crack attribute, a partition of its faces: the input surface
# ("outer", material index 0) and the faces made by fracture ("crack", 1), bound to the materials
# /World/Looks/<material> of these diffuse colours (linear RGB; distinct hues, so that a render shows which is which)
_SUBSETS = ("outer", "crack")
_SUBSET_MATERIALS = {"outer": ("pdsim_outer", (0.45, 0.47, 0.5)), "crack": ("pdsim_crack", (0.85, 0.22, 0.03))}
MATERIAL_INDEX = "material_index"  # per-face primvar: the index of the face's subset in _SUBSETS (0 outer, 1 crack)


def _crack_subsets(crack) -> dict:
    """Face indices of the subsets ``outer`` (crack == 0) and ``crack`` (crack != 0): every face in exactly one."""
    c = np.asarray(crack) != 0
    return {"outer": np.flatnonzero(~c), "crack": np.flatnonzero(c)}


def material_index(crack) -> np.ndarray:
    """The per-face material index (int32 [f]: 0 on the input surface, 1 on faces made by fracture) of the per-face
    ``crack`` attribute: Blender reads it into its faces' material index on every frame, and the mesh's material slots
    are ``pdsim_outer``, ``pdsim_crack`` in that order."""
    return (np.asarray(crack) != 0).astype(np.int32)


def rest_centre(points) -> np.ndarray:
    """The centre of the bounding box of ``points`` [m] (float64 [3]; zeros for no points): the origin of the
    double-precision transform a body's prims are written relative to."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(p) == 0 or not np.isfinite(p).all():
        return np.zeros(3)
    return 0.5 * (p.min(axis=0) + p.max(axis=0))


def _typed(kind: str, values) -> np.ndarray:
    return np.asarray(values, dtype=np.int32 if kind == "int" else np.float32)


class _MeshEntry:
    def __init__(self, handle, fractures: bool, *, split: bool):
        self.handle = handle  # MeshHandle, or XformHandle with fragments as prims
        self.fractures = fractures
        self.split = split  # fragments as prims
        self.version = None
        self.shading: _Shading | None = None
        self.first_frame = None
        self.fragments: dict[int, object] = {}  # fragment id -> MeshHandle
        self.visible: set[int] = set()  # fragment ids present on the last frame
        self.sampled: set[int] = set()  # fragment ids with visibility samples
        self.pieces = {}  # per fragment id: (face rows, vertex ids, local faces)
        self.topology = None  # (faces, face attributes, vertex count) of the last topology written
        self.restored = False  # restored from a checkpoint: the next frame compares its topology with ``topology``
        self.origin = None  # the rest centre [m] its prims are written relative to (float64 [3])

    def same_topology(self, view: MeshView, faces: np.ndarray) -> bool:
        """Whether ``view`` has the topology last written (faces, vertex count and face attributes)."""
        old_faces, old_attributes, old_count = self.topology
        if len(view.points) != old_count or not np.array_equal(faces, old_faces):
            return False
        if set(view.face_attributes) != set(old_attributes):
            return False
        return all(np.array_equal(np.asarray(a), old_attributes[k]) for k, a in view.face_attributes.items())


class ViewWriter:
    """Turns each frame's views into time samples of ``cache`` (a UsdCache).

    Args:
        cache: the UsdCache.
        color_attribute: name of an attribute to colour points and meshes by (``primvars:displayColor``), e.g.
            ``"damage"``; None (default) writes no colours. Meshes are coloured when they carry it as a face or vertex
            attribute.
        color_range: (lo, hi) mapped onto the colour ramp for real values; default (0, 1).
        fragments_as_prims: write each fragment of a surface that has a ``fragment`` face attribute as its own Mesh
            ``/World/<surface>/fragment_<id>`` (stable names; invisible before it appears and after it is gone).
        sharp_angle: dihedral angle [deg] above which an edge splits the normals.
        velocity_scale: factor from the views' velocities [m/s of simulated time] to the cache's ``velocities``,
            which USD defines per second of playback (time codes per second): the scene's time_scale = simulated
            seconds per played second (frame_time x fps); 1 (default) when a frame lasts 1/fps simulated seconds.
            Renderers extrapolate positions by velocities x (time codes / timeCodesPerSecond) for motion blur, so
            slow-motion caches need the scaled velocities.
        render_points: False (default): the Points prim of a body that has a surface or render mesh in the views is
            written with ``purpose = guide`` (renderers and Blender's importer leave it out; ``pdsim preview`` still
            draws it); True: ``purpose`` is left at ``default``, so the particles render too. A body without a mesh
            (the lattice) always renders its points.
        debris_particles: fragments of fewer points than this (a PointsView's ``fragment`` attribute) whose body has a
            ``<body>_surface`` mesh are taken out of that mesh and written as instances of the point instancer
            ``/World/<body>_debris`` (pdsim/output/debris.py); 0 (default): none.
    """

    def __init__(
        self,
        cache,
        *,
        color_attribute: str | None = None,
        color_range=None,
        fragments_as_prims: bool = False,
        sharp_angle: float = SHARP_ANGLE_DEG,
        velocity_scale: float = 1.0,
        render_points: bool = False,
        debris_particles: int = 0,
    ):
        if not (math.isfinite(sharp_angle) and 0.0 <= sharp_angle <= 180.0):
            raise ValueError(f"sharp_angle={sharp_angle!r} must be in [0, 180] degrees")
        if not (math.isfinite(velocity_scale) and velocity_scale > 0.0):
            raise ValueError(f"velocity_scale={velocity_scale!r} must be a finite number > 0")
        self.velocity_scale = float(velocity_scale)
        self.render_points = bool(render_points)
        if isinstance(debris_particles, bool) or int(debris_particles) != debris_particles or debris_particles < 0:
            raise ValueError(f"debris_particles={debris_particles!r} must be an integer >= 0 (0: no debris)")
        self.debris_particles = int(debris_particles)
        self._debris = {}  # body name -> InstancerHandle
        self._events = {}  # body name -> SparsePointsHandle
        self.cache = cache
        self.colors = _Colors(color_attribute, color_range)
        self.fragments_as_prims = bool(fragments_as_prims)
        self.sharp_angle = float(sharp_angle)
        self._points = {}  # name -> PointsHandle
        self._meshes: dict[str, _MeshEntry] = {}
        self._rigid = {}  # name -> MeshHandle
        self._groups = {}  # group name -> XformHandle

    def write(self, frame: int, views) -> None:
        """Writes the views of ``frame`` (the caller finishes the frame with ``cache.end_frame``)."""
        meshes = {view.name for view in views if isinstance(view, MeshView)}
        if self.debris_particles > 0:
            views = self._split_debris(frame, views, meshes)
        for view in views:
            if isinstance(view, PointsView):
                covered = f"{view.name}_surface" in meshes or f"{view.name}_render" in meshes
                self._write_points(frame, view, guide=covered and not self.render_points)
            elif isinstance(view, EventsView):
                self._write_events(frame, view)
            elif isinstance(view, MeshView):
                self._write_mesh(frame, view)
            elif isinstance(view, RigidView):
                self._write_rigid(frame, view)
            else:
                raise TypeError(f"not an output view: {view!r}")

    def checkpoint(self) -> dict:
        """What :meth:`restore` needs to continue writing into the same cache after a restart (pdsim.checkpoint): the
        prims written so far by view name, and per mesh its last topology, smooth groups (fixed when the topology
        changed, so normals continue bit for bit) and fragment prims. Plain values and numpy arrays."""
        meshes = {}
        for i, (name, e) in enumerate(self._meshes.items()):
            faces, attributes, vertex_count = e.topology
            meshes[str(i)] = {
                "name": name,
                "path": e.handle.path,
                "fractures": e.fractures,
                "split": e.split,
                "first_frame": int(e.first_frame),
                "faces": np.asarray(faces, dtype=np.int64),
                "vertex_count": int(vertex_count),
                "face_attributes": {k: np.asarray(a) for k, a in attributes.items()},
                "labels": np.asarray(e.shading.labels, dtype=np.int64),
                "count": int(e.shading.count),
                "interpolation": e.shading.interpolation,
                "fragments": [[int(fid), h.path] for fid, h in e.fragments.items()],
                "visible": sorted(int(f) for f in e.visible),
                "sampled": sorted(int(f) for f in e.sampled),
                "origin": np.asarray(e.origin, dtype=np.float64),
            }
        return {
            "debris": [[name, h.path] for name, h in self._debris.items()],
            "events": [[name, h.path] for name, h in self._events.items()],
            "points": [[name, h.path] for name, h in self._points.items()],
            "meshes": meshes,
            "rigid": [[group, name, h.path] for (group, name), h in self._rigid.items()],
            "groups": [[group, h.path] for group, h in self._groups.items()],
        }

    def restore(self, state: dict) -> None:
        """Re-attach to the prims of a :meth:`checkpoint` in a cache reopened at the checkpoint's frame
        (``UsdCache(..., append_frame=)``): the next frames continue them as an uninterrupted run would (same prims,
        topology samples only where the topology changes, the same smooth groups)."""
        cache = self.cache
        self._points = {str(name): cache.existing(path) for name, path in state["points"]}
        self._debris = {str(name): cache.existing(path) for name, path in state.get("debris", [])}
        self._events = {str(name): cache.existing(path) for name, path in state.get("events", [])}
        self._groups = {str(group): cache.existing(path) for group, path in state["groups"]}
        self._rigid = {(group, str(name)): cache.existing(path) for group, name, path in state["rigid"]}
        self._meshes = {}
        for _, m in sorted(state["meshes"].items(), key=lambda item: int(item[0])):
            entry = _MeshEntry(cache.existing(m["path"]), bool(m["fractures"]), split=bool(m["split"]))
            entry.first_frame = int(m["first_frame"])
            entry.shading = _Shading.restored(m["faces"], m["labels"], m["count"], m["interpolation"])
            attributes = {k: np.asarray(a) for k, a in m["face_attributes"].items()}
            entry.topology = (entry.shading.faces, attributes, int(m["vertex_count"]))
            entry.restored = True
            entry.fragments = {int(fid): cache.existing(path) for fid, path in m["fragments"]}
            entry.visible = {int(f) for f in m["visible"]}
            entry.sampled = {int(f) for f in m["sampled"]}
            entry.origin = np.asarray(m["origin"], dtype=np.float64)
            if entry.split:
                entry.pieces = self._split(attributes["fragment"], int(m["vertex_count"]), entry.shading.faces)
            self._meshes[str(m["name"])] = entry

    def _velocities(self, velocities):
        """Velocities [m/s simulated] as the cache's velocities [m per played second] (float64), or None."""
        if velocities is None:
            return None
        return np.asarray(velocities, dtype=np.float64) * self.velocity_scale

    # -- points -------------------------------------------------------------------------------------------------
    def _write_points(self, frame: int, view: PointsView, guide: bool = False) -> None:
        handle = self._points.get(view.name)
        color = self.colors.attribute
        if handle is None:
            kinds = {k: attribute_kind(k) for k in view.attributes}
            if color is not None and color in view.attributes:
                kinds["displayColor"] = "color3f"
            widths = np.broadcast_to(np.asarray(view.widths, dtype=np.float32), (len(view.positions),))
            handle = self.cache.add_points(
                view.name,
                widths=np.ascontiguousarray(widths),
                primvars=kinds,
                origin=rest_centre(view.positions),
                purpose="guide" if guide else None,
            )
            self._points[view.name] = handle
        values = {k: _typed(handle.primvar_kinds[k], a) for k, a in view.attributes.items()}
        if "displayColor" in handle.primvar_kinds:
            values["displayColor"] = self.colors(view.attributes[color])
        self.cache.write_points(
            handle,
            frame,
            np.asarray(view.positions, dtype=np.float64),
            velocities=self._velocities(view.velocities),
            primvars=values,
        )
        for name, force in view.reactions.items():
            self.cache.write_vector(handle, frame, f"reaction:{name}", force)

    # -- debris and crack events --------------------------------------------------------------------------------
    def _split_debris(self, frame: int, views, meshes: set) -> list:
        """The views with the fragments of fewer than ``debris_particles`` points taken out of their body's surface;
        writes those fragments as the instances of ``/World/<body>_debris`` (empty on frames without any)."""
        removed = {}
        for view in views:
            if not isinstance(view, PointsView) or f"{view.name}_surface" not in meshes:
                continue
            debris = small_fragments(view, self.debris_particles)
            if debris is None:
                continue
            handle = self._debris.get(view.name)
            if handle is None:
                points, faces = chunk_prototype()
                material = self.cache.add_material(*_SUBSET_MATERIALS["crack"])
                handle = self.cache.add_instancer(
                    f"{view.name}_debris", points, faces, material=material, origin=rest_centre(view.positions)
                )
                self._debris[view.name] = handle
            self.cache.write_instancer(
                handle,
                frame,
                debris.positions,
                velocities=self._velocities(debris.velocities),
                orientations=debris.orientations,
                scales=debris.sizes,
                ids=debris.ids,
            )
            removed[f"{view.name}_surface"] = debris.ids
        out = []
        for view in views:
            ids = removed.get(view.name) if isinstance(view, MeshView) else None
            kept = ids is None or "fragment" not in view.face_attributes
            out.append(view if kept else without_fragments(view, ids))
        return out

    def _write_events(self, frame: int, view: EventsView) -> None:
        """The crack events of a body at ``frame`` as the points of ``/World/<body>_crack_events``, with their normals
        and ``primvars:energy`` [J]: markers that drive effects, not geometry, so a guide of zero widths (renderers
        leave guides out; Blender 5.0.1's Cycles crashes rendering an empty point cloud, and the events are empty on
        most frames)."""
        handle = self._events.get(view.name)
        if handle is None:
            handle = self.cache.add_sparse_points(
                f"{view.name}_crack_events", primvars={"energy": "float"}, origin=view.origin, purpose="guide"
            )
            self._events[view.name] = handle
        self.cache.write_sparse_points(
            handle,
            frame,
            np.asarray(view.positions, dtype=np.float64),
            widths=np.zeros(len(view.positions), np.float32),
            normals=view.normals,
            primvars={"energy": view.energies},
        )

    # -- meshes -------------------------------------------------------------------------------------------------
    def _mesh_kinds(self, view: MeshView):
        face = {k: _kind_of(k, a) for k, a in view.face_attributes.items()}
        if "crack" in face:
            face[MATERIAL_INDEX] = "int"
        vertex = {k: _kind_of(k, a) for k, a in view.vertex_attributes.items()}
        color = self.colors.attribute
        if color is not None and color in face:
            face["displayColor"] = "color3f"
        elif color is not None and color in vertex:
            vertex["displayColor"] = "color3f"
        return face, vertex

    def _write_mesh(self, frame: int, view: MeshView) -> None:
        entry = self._meshes.get(view.name)
        faces = np.asarray(view.faces, dtype=np.int64).reshape(-1, 3)
        fractures = "crack" in view.face_attributes or "fragment" in view.face_attributes
        created = entry is None
        if entry is None:
            origin = rest_centre(view.points)
            if self.fragments_as_prims and "fragment" in view.face_attributes:
                entry = _MeshEntry(self.cache.add_xform(view.name), fractures, split=True)
            else:
                face, vertex = self._mesh_kinds(view)
                # a surface that can fracture gets corner normals: cracks open sharp edges later
                shading = _Shading(view.points, faces, self.sharp_angle, "faceVarying" if fractures else None)
                handle = self.cache.add_mesh(
                    view.name,
                    face_primvars=face,
                    vertex_primvars=vertex,
                    normals=shading.interpolation,
                    subsets=_SUBSETS if "crack" in view.face_attributes else (),
                    origin=origin,
                )
                entry = _MeshEntry(handle, fractures, split=False)
                entry.shading = shading
                self._bind_subsets(handle)
            entry.first_frame = frame
            entry.origin = origin
            self._meshes[view.name] = entry
        if entry.restored:  # topology versions do not survive a restart: compare the topology itself
            changed = not entry.same_topology(view, faces)
            entry.restored = False
        else:
            changed = entry.version != view.topology_version
        if changed and (entry.shading is None or not created):
            interpolation = "faceVarying" if entry.shading is None else entry.shading.interpolation
            entry.shading = _Shading(view.points, faces, self.sharp_angle, interpolation)
        if changed:
            attributes = {k: np.array(a) for k, a in view.face_attributes.items()}
            entry.topology = (entry.shading.faces, attributes, len(view.points))
        normals = entry.shading.normals(view.points)
        if entry.split:
            self._write_fragments(frame, view, entry, faces, normals, changed)
        else:
            self._write_whole_mesh(frame, view, entry, faces, normals, changed)
        entry.version = view.topology_version

    def _bind_subsets(self, handle) -> None:
        """Bind the materials ``pdsim_outer`` and ``pdsim_crack`` to the mesh's subsets ``outer`` and ``crack``."""
        for name in handle.subsets:
            material = self.cache.add_material(*_SUBSET_MATERIALS[name])
            self.cache.bind_material(f"{handle.path}/{name}", material)

    def _color_values(self, view: MeshView, rows=None, verts=None) -> tuple[dict, dict]:
        """displayColor values ({face}, {vertex}) of a mesh view (of the given face rows and vertices)."""
        color = self.colors.attribute
        if color is None:
            return {}, {}
        if color in view.face_attributes:
            a = np.asarray(view.face_attributes[color])
            return {"displayColor": self.colors(a if rows is None else a[rows])}, {}
        if color in view.vertex_attributes:
            a = np.asarray(view.vertex_attributes[color])
            return {}, {"displayColor": self.colors(a if verts is None else a[verts])}
        return {}, {}

    def _write_whole_mesh(self, frame, view: MeshView, entry: _MeshEntry, faces, normals, changed: bool) -> None:
        handle = entry.handle
        face_color, vertex_color = self._color_values(view)
        vertex = {k: _typed(handle.vertex_primvar_kinds[k], a) for k, a in view.vertex_attributes.items()}
        vertex.update(vertex_color)
        kwargs = {}
        if changed:
            face = {k: _typed(handle.face_primvar_kinds[k], a) for k, a in view.face_attributes.items()}
            face.update(face_color)
            if MATERIAL_INDEX in handle.face_primvar_kinds:
                face[MATERIAL_INDEX] = material_index(view.face_attributes["crack"])
            kwargs["face_primvars"] = face
            if handle.subsets:
                kwargs["subsets"] = _crack_subsets(view.face_attributes["crack"])
        elif face_color:
            kwargs["face_primvars"] = face_color
        self.cache.write_mesh(
            handle,
            frame,
            np.asarray(view.points, dtype=np.float64),
            faces if changed else None,
            velocities=self._velocities(view.velocities),
            normals=normals,
            vertex_primvars=vertex,
            **kwargs,
        )

    @staticmethod
    def _split(fragment, vertex_count: int, faces: np.ndarray) -> dict:
        """Per fragment id (``fragment``: the fragment id of each face): (its face rows [k], its vertex ids [m], its
        faces in local vertex indices [k, 3])."""
        frag = np.asarray(fragment, dtype=np.int64)
        nv = max(int(vertex_count), 1)
        order = np.argsort(frag, kind="stable")
        ids, starts = np.unique(frag[order], return_index=True)
        ends = np.r_[starts[1:], len(order)]
        key = np.repeat(frag - frag.min() if len(frag) else frag, 3) * nv + faces.ravel()
        ukey, inverse = np.unique(key, return_inverse=True)
        ufrag = ukey // nv
        block = np.searchsorted(ufrag, ufrag, side="left")
        local = (np.arange(len(ukey)) - block)[inverse.ravel()].reshape(-1, 3)
        vstart = np.searchsorted(ufrag, ids - (frag.min() if len(frag) else 0), side="left")
        vend = np.searchsorted(ufrag, ids - (frag.min() if len(frag) else 0), side="right")
        out = {}
        for i, fid in enumerate(ids.tolist()):  # a loop over fragments, not over points or faces
            rows = order[starts[i] : ends[i]]
            out[fid] = (rows, ukey[vstart[i] : vend[i]] % nv, local[rows])
        return out

    def _write_fragments(self, frame, view: MeshView, entry: _MeshEntry, faces, normals, changed: bool) -> None:
        if changed:
            entry.pieces = self._split(view.face_attributes["fragment"], len(view.points), faces)
        face_kinds, vertex_kinds = self._mesh_kinds(view)
        corner = normals.reshape(-1, 3, 3)
        points = np.asarray(view.points, dtype=np.float64)
        velocities = self._velocities(view.velocities)
        present = set(entry.pieces)
        for fid, (rows, verts, local) in entry.pieces.items():
            handle = entry.fragments.get(fid)
            if handle is None:
                handle = self.cache.add_mesh(
                    f"fragment_{fid}",
                    face_primvars=face_kinds,
                    vertex_primvars=vertex_kinds,
                    normals="faceVarying",
                    subsets=_SUBSETS if "crack" in view.face_attributes else (),
                    parent=entry.handle,
                    topology_set="topology_" + entry.handle.path[len("/World/") :].replace("/", "_"),
                    origin=entry.origin,
                )
                entry.fragments[fid] = handle
                self._bind_subsets(handle)
                if frame > entry.first_frame:  # hidden before it appeared
                    self.cache.write_visibility(handle, entry.first_frame, False)
                    self.cache.write_visibility(handle, frame, True)
                    entry.sampled.add(fid)
            elif fid not in entry.visible:  # back again
                self.cache.write_visibility(handle, frame, True)
            face_color, vertex_color = self._color_values(view, rows, verts)
            vertex = {k: _typed(vertex_kinds[k], np.asarray(a)[verts]) for k, a in view.vertex_attributes.items()}
            vertex.update(vertex_color)
            kwargs = {}
            if changed:
                face = {k: _typed(face_kinds[k], np.asarray(a)[rows]) for k, a in view.face_attributes.items()}
                face.update(face_color)
                if MATERIAL_INDEX in face_kinds:
                    face[MATERIAL_INDEX] = material_index(np.asarray(view.face_attributes["crack"])[rows])
                kwargs["face_primvars"] = face
                if handle.subsets:
                    kwargs["subsets"] = _crack_subsets(np.asarray(view.face_attributes["crack"])[rows])
            elif face_color:
                kwargs["face_primvars"] = face_color
            self.cache.write_mesh(
                handle,
                frame,
                points[verts],
                local if changed else None,
                velocities=None if velocities is None else velocities[verts],
                normals=corner[rows].reshape(-1, 3),
                vertex_primvars=vertex,
                **kwargs,
            )
        for fid in entry.visible - present:  # gone (merged into no other piece): hidden from now on
            if fid not in entry.sampled:  # visible until now: say so, or the first sample would hold back in time
                self.cache.write_visibility(entry.fragments[fid], entry.first_frame, True)
                entry.sampled.add(fid)
            self.cache.write_visibility(entry.fragments[fid], frame, False)
        entry.visible = present

    # -- rigid bodies -------------------------------------------------------------------------------------------
    def _write_rigid(self, frame: int, view: RigidView) -> None:
        key = (view.group, view.name)
        handle = self._rigid.get(key)
        if handle is None:
            parent = None
            if view.group is not None:
                parent = self._groups.get(view.group)
                if parent is None:
                    parent = self._groups[view.group] = self.cache.add_xform(view.group)
            faces = np.asarray(view.faces, dtype=np.int64).reshape(-1, 3)
            crack = view.face_attributes.get("crack")
            shading = _Shading(view.points, faces, self.sharp_angle, None if crack is None else "faceVarying")
            kinds = {k: _kind_of(k, a) for k, a in view.face_attributes.items()}
            values = {k: _typed(kinds[k], np.asarray(a)) for k, a in view.face_attributes.items()}
            if crack is not None:  # the surface's material hooks: subsets, bound materials, material index
                kinds[MATERIAL_INDEX] = "int"
                values[MATERIAL_INDEX] = material_index(np.asarray(crack))
            handle = self.cache.add_mesh(
                view.name, face_primvars=kinds, normals=shading.interpolation, parent=parent, animated_transform=True,
                subsets=_SUBSETS if crack is not None else (),
            )  # fmt: skip
            points = np.asarray(view.points, dtype=np.float64)
            self.cache.set_mesh(
                handle, points, faces, normals=shading.normals(points), velocities=np.zeros_like(points),
                face_primvars=values, subsets=None if crack is None else _crack_subsets(crack),
            )  # fmt: skip
            self._bind_subsets(handle)
            self._rigid[key] = handle
            if frame > self.cache.start_frame:  # a piece that appears mid-run: hidden before it
                self.cache.write_visibility(handle, self.cache.start_frame, False)
                self.cache.write_visibility(handle, frame, True)
            if view.static:
                self.cache.write_transform(handle, None, view.translation, view.orientation)
        if not view.static:
            self.cache.write_transform(handle, frame, view.translation, view.orientation)
        if view.velocity is not None:  # per played second, as the points' velocities; degrees as USD's rotations
            self.cache.write_vector(handle, frame, "velocity", np.asarray(view.velocity) * self.velocity_scale)
            omega = np.degrees(np.asarray(view.angular_velocity, dtype=np.float64)) * self.velocity_scale
            self.cache.write_vector(handle, frame, "angularVelocity", omega)


__all__ = ["SHARP_ANGLE_DEG", "ViewWriter", "category_colors", "color_ramp", "corner_normals", "smoothing_groups"]
