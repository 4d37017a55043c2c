"""USD animation caches streamed frame by frame: one small layer per frame, stitched by value clips.

Layout on disk (docs/cache_format.md is the reference)::

    cache.usdc                          top-level layer: stage metadata, prim and attribute declarations, static
                                        values (point widths, collider geometry), visibility of fragment prims, and the
                                        value-clip metadata on /World that points at the layers below
    cache.frames/<run>/frame.000000.usdc   the time samples of frame 0 (points, velocities, normals, primvars,
                                        reactions, transforms, the frame's simulated time), written once
    cache.frames/<run>/manifest.usdc    the attributes the frame layers sample (clip set "default")
    cache.frames/<run>/topology_<mesh>.000000.usdc   a mesh's topology (faces, per-face primvars, face subsets) at a
                                        frame where it changed (clip set "topology_<mesh>", one clip per change)
    cache.frames/<run>/topology_<mesh>.manifest.usdc

``Usd.Stage.Open("cache.usdc")`` plays the animation back. The per-frame clips are template clips
(``templateAssetPath`` ``./cache.frames/<run>/frame.######.usdc``, start, end, stride 1), so the top-level layer keeps
a constant size whatever the frame count; the topology clip sets list their clips (one per topology change), so a
mesh's ``faceVertexIndices`` has time samples exactly where its topology changed.

Memory: a frame's samples live in an anonymous layer until :meth:`UsdCache.end_frame` writes it to its file and drops
it; the cache keeps only the top-level layer (declarations and static data), the manifests and the list of topology
changes, so memory does not grow with the number of frames.

Crash safety: :meth:`UsdCache.end_frame` writes the frame's layers (to a temporary name, then ``os.replace``), then
the manifests when new attributes appeared, then the top-level layer (temporary file and ``os.replace``). A process
killed at any moment (``kill -9``) leaves a top-level layer that names only complete frame files: every finished
frame, except at most the one being finished when the process died.

Re-runs: a run that fails must not destroy an earlier cache at the same path. When ``path`` already exists, the new
run writes its top-level layer to ``<stem>.partial<suffix>`` beside it and replaces ``path`` with it (``os.replace``,
atomic) only when it closes successfully; the earlier cache stays untouched until then, and after a failure the
finished frames of the failed run can be opened from the partial file. When ``path`` does not exist the run writes
to ``path`` directly, so a crash leaves the frames finished so far there. A successful run removes the frame folders
that no top-level layer beside it refers to any more (the replaced run's, those of killed runs).

Resuming: ``UsdCache(path, ..., append_frame=F, append_run=run)`` reopens the cache of an interrupted run at its
finished frame F and continues it (``pdsim run --resume``): it takes over the run folder, manifests, topology clips
and prims (:meth:`UsdCache.existing` gives their handles), drops what was written after F (rewriting the top-level
layer atomically at once, then deleting the later frame files) and writes on as a new run would, so the finished
cache plays as an uninterrupted run's.

Packing: ``UsdCache(path, ..., pack=True)`` (the runs' default layout) packs the finished run into one self-contained
file at ``path`` when it closes successfully (``usd_pack``: clip by clip, to a temporary name renamed over ``path``)
and removes the run folder; a failed packing leaves ``path`` and the clip cache as they were.

Modules: this one holds :class:`UsdCache` (prim declarations and the per-frame samples); ``usd_layout`` the prim
handles and definitions, ``usd_stream`` the files on disk (:class:`FrameStream`), ``usd_values`` the checked arrays and
USD values, ``usd_files`` the reading of finished caches, ``usd_pack`` their packing into one file.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade

from .usd_layout import (
    MeshHandle,
    PointsHandle,
    XformHandle,
    default_topology_set,
    define_face_subset,
    define_material,
    define_mesh,
    define_origin,
    define_points,
    define_world,
    reopened_handles,
)
from .usd_sparse import SparsePrims
from .usd_stream import FrameLayer, FrameStream, PendingFrame
from .usd_values import (
    check_array,
    check_cache_settings,
    check_primvar_kinds,
    identifier,
    mesh_samples,
    points_samples,
    pose_values,
    subset_samples,
    type_names,
)

if TYPE_CHECKING:
    from typing import Self

__all__ = ["UsdCache"]


def _relative(positions, origin):
    """``positions`` [stage units] relative to ``origin`` (float64 [3]) in float64, or as given when it is None."""
    if origin is None:
        return positions
    a = np.asarray(positions)
    real = np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)
    if a.ndim != 2 or a.shape[1] != 3 or not real:
        return positions  # the shape and dtype checks of the samples name what is wrong
    return a.astype(np.float64) - origin


class UsdCache(SparsePrims):
    """Writes a USD animation cache (``.usdc``/``.usda``/``.usd``) frame by frame, streaming and crash-safe.

    Typical use::

        with UsdCache("out/cache.usdc", fps=24.0) as cache:
            particles = cache.add_points("particles", widths=radii * 2, primvars={"damage": "float"})
            for frame in range(frame_count):
                ...  # simulate
                cache.write_points(particles, frame, positions, primvars={"damage": damage})
                cache.end_frame(frame, time=frame * frame_time)

    Time codes are frame numbers; ``timeCodesPerSecond = framesPerSecond = fps`` (the playback rate). The simulated
    time of each frame [s] goes into the time-sampled attribute ``pdsim:time`` of ``/World``. Only frames finished
    with :meth:`end_frame` reach the cache. Leaving the ``with`` block normally makes the run a success (see the module
    docstring for what that changes when ``path`` existed before); an exception (KeyboardInterrupt too) leaves the
    finished frames readable, at ``path`` or, when ``path`` held an earlier cache, at :attr:`partial_path`.

    Args:
        path: Output file; the extension picks the format of every layer (``.usd`` is written as binary crate).
        fps: Playback frames per second [1/s]; > 0.
        start_frame: First frame (``startTimeCode``); frames before it are rejected.
        up_axis: ``"Y"`` or ``"Z"``.
        meters_per_unit: Length of one stage unit [m]; > 0.
        save_interval_s: Minimum wall-clock time between rewrites of the top-level layer [s]; 0 (default) rewrites it
            after every frame, which is what bounds a crash's loss to one frame. The frame layers are always written
            when their frame finishes.
        metadata: Extra ``customLayerData`` under the key ``pdsim`` (e.g. ``{"frameTime": 2e-6}``).
        append_frame: Reopen the cache pdsim wrote at ``path`` (or at :attr:`partial_path`, see ``append_run``) and
            continue it after this finished frame: the run folder, manifests, topology clips and prims are taken over
            (:meth:`existing` gives the prims' handles), the frames after ``append_frame`` are dropped (their samples
            in the top-level layer, their files, the prims defined while writing them), and the top-level layer is
            rewritten at once (atomically) to end at ``append_frame``. ``fps``, ``up_axis``, ``meters_per_unit`` and
            ``start_frame`` must be the cache's. Success then replaces ``path`` when the reopened top-level layer is
            the partial one, as for a new run.
        append_run: With ``append_frame``: the run id (``customLayerData pdsim:run``) the reopened cache must hold;
            the top-level layer is the one of ``partial_path`` and ``path`` that holds it. None: ``partial_path`` when
            it exists, else ``path``.
        pack: On success, pack the run into one self-contained file at ``path`` (pdsim.output.usd_pack.pack_cache:
            value clips baked into time samples, the run folder removed); the frames stream into the run folder while
            running either way. False (default): ``path`` stays the top-level layer of the clip layout.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        fps: float,
        start_frame: int = 0,
        up_axis: str = "Z",
        meters_per_unit: float = 1.0,
        save_interval_s: float = 0.0,
        metadata: dict | None = None,
        append_frame: int | None = None,
        append_run: str | None = None,
        pack: bool = False,
    ):
        self.path = check_cache_settings(path, fps, start_frame, up_axis, meters_per_unit, save_interval_s)
        self.fps = float(fps)
        self.start_frame = int(start_frame)
        self.save_interval_s = float(save_interval_s)
        self.metadata = dict(metadata or {})
        self._stream = FrameStream(
            self.path,
            start_frame=self.start_frame,
            save_interval_s=self.save_interval_s,
            metadata=self.metadata,
            pack=bool(pack),
        )
        self.frames_dir = self._stream.frames_dir
        self.partial_path = self._stream.partial_path
        self._types = type_names()
        self._names: dict[str, set[str]] = {"/World": set()}  # parent path -> child identifiers
        self._pending: dict[int, PendingFrame] = {}
        self._handles: dict[str, object] = {}  # prim path -> handle, for the prims of a reopened cache
        self._closed = False
        if append_frame is not None:
            if isinstance(append_frame, bool) or int(append_frame) != append_frame:
                raise ValueError(f"append_frame={append_frame!r} must be an integer")
            self._reopen(int(append_frame), append_run, up_axis, float(meters_per_unit))
            return
        if append_run is not None:
            raise ValueError("append_run is given only with append_frame")

        self._stream.start()
        self.run_id = self._stream.run_id
        self.run_dir = self._stream.run_dir
        self._layer = Sdf.Layer.CreateAnonymous(f"pdsim_cache{self.path.suffix.lower()}")
        self._stage = Usd.Stage.Open(self._layer)
        define_world(self._stage, self.fps, self.start_frame, up_axis, float(meters_per_unit))

    # ------------------------------------------------------------------ properties

    @property
    def frames_written(self) -> int:
        """Number of frames finished with :meth:`end_frame`."""
        return self._stream.frames_written

    @property
    def last_frame(self) -> int | None:
        """The last finished frame (of this run or, for a reopened cache, the frame it was reopened at); None before
        the first."""
        return self._stream.last_finished

    @property
    def stage(self):
        """The in-memory ``Usd.Stage`` of the top-level layer's declarations (no time samples; for inspection)."""
        return self._stage

    @property
    def top_level_path(self) -> Path:
        """Where the top-level layer of this run is being written: ``path``, or :attr:`partial_path` while an earlier
        cache at ``path`` is kept until this run succeeds."""
        return self._stream.top_path

    # ------------------------------------------------------------------ prims

    def _reopen(self, frame: int, run: str | None, up_axis: str, meters_per_unit: float) -> None:
        """Take over the cache at ``path`` (or ``partial_path``) at its finished frame ``frame`` (append_frame)."""
        layer = self._stream.reopen(frame, run, self.fps, up_axis, meters_per_unit)
        self.run_id = self._stream.run_id
        self.run_dir = self._stream.run_dir
        self._layer = layer
        self._stage = Usd.Stage.Open(layer)
        for prim in self._stage.TraverseAll():
            path = str(prim.GetPath())
            self._names.setdefault(path, set())
            self._names.setdefault(str(prim.GetPath().GetParentPath()), set()).add(prim.GetName())
        self._stream.write_top(layer)  # the cache now ends at ``frame``, atomically
        self._stream.remove_frames_after(frame)
        self._handles = reopened_handles(self, self._stream, frame)

    def existing(self, path: str):
        """The handle (PointsHandle, MeshHandle, XformHandle) of a prim of a reopened cache (``append_frame``), by prim
        path, e.g. ``/World/bar``; ValueError when the cache holds no such prim."""
        self._check_open()
        handle = self._handles.get(path)
        if handle is None:
            raise ValueError(
                f"the reopened cache {str(self._stream.top_path)!r} holds no Points, Mesh or Xform prim {path!r}"
            )
        return handle

    def _define_path(self, name: str, parent: XformHandle | None = None) -> str:
        if not isinstance(name, str) or not name:
            raise ValueError(f"prim name {name!r} must be a non-empty string")
        base = "/World" if parent is None else parent.path
        if parent is not None and (not isinstance(parent, XformHandle) or parent._cache is not self):
            raise ValueError(f"parent must be an XformHandle of this cache, got {parent!r}")
        ident = identifier(name)
        names = self._names.setdefault(base, set())
        if ident in names:
            raise ValueError(f"prim name {name!r} (as USD identifier {ident!r}) is already used under {base}")
        names.add(ident)
        path = f"{base}/{ident}"
        last = self._stream.last_finished
        frame = self.start_frame if last is None else last + 1
        if frame > self.start_frame:  # a reopened cache drops the prims defined after the frame it resumes at
            self._stream.defined_at[path] = frame
        return path

    def add_xform(self, name: str, *, parent: XformHandle | None = None) -> XformHandle:
        """Define a ``UsdGeom.Xform`` at ``/World/<name>`` (or under ``parent``) to group prims."""
        self._check_open()
        path = self._define_path(name, parent)
        UsdGeom.Xform.Define(self._stage, path)
        self._names[path] = set()
        return XformHandle(path=path, _cache=self)

    def add_material(self, name: str, color) -> str:
        """Define a placeholder material ``/World/Looks/<name>`` (a ``UsdPreviewSurface`` of diffuse ``color``, linear
        RGB in [0, 1]) once and return its path; :meth:`bind_material` binds it. Renderers and DCC tools show it until
        a user binds their own material to the same prims."""
        self._check_open()
        c = np.asarray(color, dtype=np.float64)
        if c.shape != (3,) or not (np.isfinite(c).all() and (c >= 0).all() and (c <= 1).all()):
            raise ValueError(f"color={color!r} must be 3 numbers in [0, 1]")
        if "/World/Looks" not in self._names:
            self._define_path("Looks")
            UsdGeom.Scope.Define(self._stage, "/World/Looks")
            self._names["/World/Looks"] = set()
        path = f"/World/Looks/{identifier(name)}"
        if self._stage.GetPrimAtPath(path):
            return path
        self._define_path(name, XformHandle("/World/Looks", self))
        define_material(self._stage, path, c)
        return path

    def bind_material(self, prim_path: str, material_path: str) -> None:
        """Bind the material at ``material_path`` to the prim (mesh or face subset) at ``prim_path``."""
        self._check_open()
        prim = self._stage.GetPrimAtPath(prim_path)
        material = UsdShade.Material(self._stage.GetPrimAtPath(material_path))
        if not prim or not material:
            raise ValueError(f"no prim {prim_path!r} or no material {material_path!r} in this cache")
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)

    def add_points(
        self,
        name: str,
        *,
        widths: np.ndarray,
        primvars: dict[str, str] | None = None,
        parent: XformHandle | None = None,
        origin=None,
        purpose: str | None = None,
    ) -> PointsHandle:
        """Define a ``UsdGeom.Points`` prim at ``/World/<name>``.

        Args:
            name: Prim name; made into a valid USD identifier (``"body 1"`` -> ``"body_1"``).
            widths: Point diameters [stage units], shape [point_count]; written once (not time-sampled).
            primvars: ``{name: kind}`` with kind ``"float"`` (values shape [point_count]), ``"int"`` (shape
                [point_count]), ``"vector3f"`` or ``"color3f"`` (shape [point_count, 3]); vertex interpolation.
                ``displayColor`` (kind color3f) is the USD display colour.
            parent: Group to define the prim under (default ``/World``).
            origin: The prim's static double-precision ``xformOp:translate`` [stage units] (3 numbers);
                :meth:`write_points` then stores ``positions - origin`` as float32. None: no transform, world
                positions stored as float32.
            purpose: ``"guide"`` (drawn by viewers that show guides, left out of renders and of Blender's import
                unless asked), ``"render"``, ``"proxy"``, or None (``default``: always drawn).

        Returns:
            Handle for :meth:`write_points`.
        """
        self._check_open()
        primvars = dict(primvars or {})
        w = check_array("widths", widths, shape=(-1,), shape_text="[point_count]")
        if (w < 0).any():
            raise ValueError("widths must be >= 0")
        check_primvar_kinds(primvars, "primvar")

        path = self._define_path(name, parent)
        if purpose not in (None, "guide", "render", "proxy"):
            raise ValueError(f"purpose={purpose!r} must be 'guide', 'render', 'proxy' or None")
        define_points(self._stage, path, w, primvars, self._types)
        if purpose is not None:
            UsdGeom.Imageable(self._stage.GetPrimAtPath(path)).CreatePurposeAttr(purpose)
        o = None if origin is None else define_origin(self._stage, path, origin)
        return PointsHandle(
            path=path, point_count=int(w.shape[0]), primvar_kinds=primvars, _cache=self, _widths=w, origin=o
        )

    def write_points(
        self,
        handle: PointsHandle,
        frame: int,
        positions: np.ndarray,
        *,
        velocities: np.ndarray | None = None,
        primvars: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Time-sample point positions (and optionally velocities and primvars) and the extent at ``frame``.

        Args:
            handle: From :meth:`add_points` of this cache.
            frame: Frame number (time code); must be after the last finished frame.
            positions: Point positions [stage units], shape [point_count, 3]; stored as float32 (relative to the
                handle's ``origin`` when it has one: pass float64 world positions to keep their precision).
            velocities: Point velocities [stage units/s], shape [point_count, 3].
            primvars: ``{name: values}`` for primvars declared in :meth:`add_points`; shape [point_count] for
                ``"float"``/``"int"``, [point_count, 3] for ``"vector3f"``/``"color3f"``. Primvars left out get no
                sample.

        Raises:
            ValueError: Wrong shape, dtype or non-finite values (the message names the array and the expected shape),
                unknown primvar, or a frame already finished.
        """
        self._check_handle(handle, PointsHandle)
        layer = self._frame_layer(frame).samples
        samples = points_samples(handle, _relative(positions, handle.origin), velocities, primvars)
        for attr, kind, value in samples:
            self._sample(layer, "default", handle.path, attr, kind, value)

    def add_mesh(
        self,
        name: str,
        *,
        face_primvars: dict[str, str] | None = None,
        vertex_primvars: dict[str, str] | None = None,
        normals: str | None = None,
        subsets: tuple[str, ...] | list[str] = (),
        parent: XformHandle | None = None,
        animated_transform: bool = False,
        topology_set: str | None = None,
        origin=None,
    ) -> MeshHandle:
        """Define a triangle ``UsdGeom.Mesh`` (``subdivisionScheme = none``) at ``/World/<name>``.

        Args:
            name: Prim name; made into a valid USD identifier.
            face_primvars: Per-face (uniform) primvars, ``{name: kind}`` (``"float"``, ``"int"``, ``"vector3f"``,
                ``"color3f"``); written with the topology (``displayColor``: a colour per face, every frame).
            vertex_primvars: Per-vertex primvars ``{name: kind}``, written every frame (``displayColor``: a colour per
                vertex).
            normals: ``"faceVarying"`` (one normal per face corner, shape [3 x triangle_count, 3]), ``"vertex"``
                ([vertex_count, 3]) or None (no normals).
            subsets: Names of face subsets to declare (``UsdGeom.Subset`` children of family ``materialBind``, e.g.
                ``("crack",)``); their face indices are written with the topology.
            parent: Group to define the prim under (default ``/World``).
            animated_transform: Declare ``xformOp:translate`` and ``xformOp:orient`` for :meth:`write_transform`.
            topology_set: Name of the value-clip set holding the mesh's topology; meshes that share one (the fragment
                prims of a surface) must be written with faces on the same frames. Default: a set of its own,
                ``topology_<prim path under /World>``.
            origin: A static double-precision ``xformOp:translate`` [stage units] (3 numbers) the vertices of
                :meth:`write_mesh` are stored relative to (float32 ``points - origin``); not with
                ``animated_transform``.

        Returns:
            Handle for :meth:`write_mesh`.
        """
        self._check_open()
        fkinds = dict(face_primvars or {})
        vkinds = dict(vertex_primvars or {})
        check_primvar_kinds(fkinds, "face primvar")
        check_primvar_kinds(vkinds, "vertex primvar")
        if set(fkinds) & set(vkinds):
            raise ValueError(f"primvars {sorted(set(fkinds) & set(vkinds))} declared both per face and per vertex")
        if normals not in (None, "faceVarying", "vertex"):
            raise ValueError(f"normals={normals!r} must be 'faceVarying', 'vertex' or None")
        if animated_transform and origin is not None:
            raise ValueError("origin is a static transform: not with animated_transform")
        path = self._define_path(name, parent)
        self._names[path] = set()
        mesh = define_mesh(self._stage, path, fkinds, vkinds, normals, self._types)
        subsets = tuple(subsets)
        for s in subsets:
            define_face_subset(self._stage, self._define_path(s, XformHandle(path, self)))
        if subsets:
            UsdGeom.Subset.SetFamilyType(mesh, "materialBind", UsdGeom.Tokens.nonOverlapping)
        if animated_transform:
            mesh.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
            mesh.AddOrientOp(UsdGeom.XformOp.PrecisionFloat)
        o = None if origin is None else define_origin(self._stage, path, origin)
        if topology_set is None:
            topology_set = default_topology_set(path)
        elif not (isinstance(topology_set, str) and topology_set.startswith("topology_")):
            raise ValueError(f"topology_set={topology_set!r} must be a string starting with 'topology_'")
        self._stream.manifests.setdefault(topology_set, {})
        return MeshHandle(
            path=path,
            topology_set=topology_set,
            face_primvar_kinds=fkinds,
            vertex_primvar_kinds=vkinds,
            normals=normals,
            subsets=subsets,
            _cache=self,
            _transform=animated_transform,
            origin=o,
        )

    def write_mesh(
        self,
        handle: MeshHandle,
        frame: int,
        points: np.ndarray,
        faces: np.ndarray | None = None,
        *,
        velocities: np.ndarray | None = None,
        normals: np.ndarray | None = None,
        face_primvars: dict[str, np.ndarray] | None = None,
        vertex_primvars: dict[str, np.ndarray] | None = None,
        subsets: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Time-sample a mesh at ``frame``: vertex positions, extent, and optionally velocities, normals and primvars;
        the topology when ``faces`` is given.

        Pass ``faces`` on the first call and on every frame where the topology (or the vertex count) changes; on the
        other frames the last topology (faces, per-face primvars, subsets) is written again into the frame's layer,
        since each frame layer of the cache is complete on its own.

        Args:
            handle: From :meth:`add_mesh` of this cache.
            frame: Frame number (time code); must be after the last finished frame.
            points: Vertex positions [stage units], shape [vertex_count, 3]; stored as float32 (relative to the
                handle's ``origin`` when it has one).
            faces: Triangles as vertex indices, int shape [triangle_count, 3], values in [0, vertex_count).
            velocities: Vertex velocities [stage units/s], shape [vertex_count, 3].
            normals: Unit normals, shape [3 x triangle_count, 3] (faceVarying: one per face corner, in the order of
                ``faces.ravel()``) or [vertex_count, 3] (vertex), as declared in :meth:`add_mesh`.
            face_primvars: Values of declared per-face primvars, shape [triangle_count] (or [triangle_count, 3] for
                vector3f/color3f); only together with ``faces``, except ``displayColor``, which may change every frame.
            vertex_primvars: Values of declared per-vertex primvars, shape [vertex_count] or [vertex_count, 3].
            subsets: ``{subset name: face indices (int [k])}`` of declared subsets; only together with ``faces``.

        Raises:
            ValueError: Wrong shape or values, a vertex count that changes without new faces, or missing faces on the
                first call.
        """
        self._check_handle(handle, MeshHandle)
        pending = self._frame_layer(frame)
        samples, topology, nv, nf = mesh_samples(
            handle, _relative(points, handle.origin), faces, velocities, normals, face_primvars, vertex_primvars
        )
        if topology is not None:
            topology += subset_samples(handle, subsets, nf)
            handle._has_topology = True
            handle._face_count = nf
            handle.vertex_count = nv
            layer = pending.topology_layer(handle.topology_set)
            for prim_path, attr, kind, value in topology:
                self._sample(layer, handle.topology_set, prim_path, attr, kind, value)
        elif subsets:
            raise ValueError("subsets are written with the topology: pass faces too")
        for attr, kind, value in samples:
            self._sample(pending.samples, "default", handle.path, attr, kind, value)

    def set_mesh(
        self,
        handle: MeshHandle,
        points: np.ndarray,
        faces: np.ndarray,
        *,
        normals: np.ndarray | None = None,
        velocities: np.ndarray | None = None,
        face_primvars: dict[str, np.ndarray] | None = None,
        subsets: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Write a static mesh (a collider's or a rigid piece's geometry) once, as default values of the top-level
        layer (no time samples). Arguments as :meth:`write_mesh`."""
        self._check_handle(handle, MeshHandle)
        if handle._has_topology:
            raise ValueError(f"mesh {handle.path} already has geometry")
        samples, topology, nv, nf = mesh_samples(handle, points, faces, velocities, normals, face_primvars, None)
        topology += subset_samples(handle, subsets, nf) if handle.subsets else []
        prim = self._stage.GetPrimAtPath(handle.path)
        for attr, _kind, value in samples:
            prim.GetAttribute(attr).Set(value)
        for path, attr, _kind, value in topology:
            self._stage.GetPrimAtPath(path).GetAttribute(attr).Set(value)
        self._stream.manifests.pop(handle.topology_set, None)
        handle._has_topology = True
        handle.vertex_count, handle._face_count = nv, nf

    def write_transform(self, handle: MeshHandle, frame: int | None, translation, orientation) -> None:
        """The prim's transform: ``translation`` [stage units] (3 numbers) and ``orientation``, a unit quaternion
        (x, y, z, w); time-sampled at ``frame``, or the static (default) value when ``frame`` is None. The mesh must
        have been declared with ``animated_transform=True``. Points p of the mesh are placed at
        ``translation + rotate(orientation, p)``."""
        self._check_handle(handle, MeshHandle)
        if not handle._transform:
            raise ValueError(f"mesh {handle.path} was declared without animated_transform")
        tv, qv = pose_values(translation, orientation)
        if frame is None:  # a static pose: default values (an animated one must have none: they would hide the clips)
            prim = self._stage.GetPrimAtPath(handle.path)
            prim.GetAttribute("xformOp:translate").Set(tv)
            prim.GetAttribute("xformOp:orient").Set(qv)
            return
        layer = self._frame_layer(frame).samples
        self._sample(layer, "default", handle.path, "xformOp:translate", "double3", tv)
        self._sample(layer, "default", handle.path, "xformOp:orient", "quatf", qv)

    def write_visibility(self, handle, frame: int, visible: bool) -> None:
        """Time-sample the visibility of a prim from ``frame`` on (``inherited`` or ``invisible``), held until the next
        sample. Written into the top-level layer (few samples: a fragment appears or disappears once), so ``frame`` may
        be a finished frame: a prim that appears at frame 40 is hidden from the first frame on by a sample at that
        frame, written together with its first samples (both reach the disk when the current frame finishes)."""
        self._check_open()
        if int(frame) != frame or frame < self.start_frame:
            raise ValueError(f"frame={frame!r} must be an integer >= start_frame {self.start_frame}")
        attr = UsdGeom.Imageable(self._stage.GetPrimAtPath(handle.path)).CreateVisibilityAttr()
        value = UsdGeom.Tokens.inherited if visible else UsdGeom.Tokens.invisible
        last = self._stream.last_finished
        if last is not None and frame <= last:
            attr.Set(value, float(frame))
        else:
            self._frame_layer(frame).top_samples.append((attr, value))

    def write_vector(self, handle, frame: int, name: str, value) -> None:
        """Time-sample a custom double3 attribute ``pdsim:<name>`` (e.g. ``reaction:grip``, a boundary condition's
        reaction force [N]) on the prim of ``handle`` at ``frame``."""
        self._check_open()
        layer = self._frame_layer(frame).samples
        v = np.asarray(value, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name!r}: a vector of 3 finite numbers, got {value!r}")
        attr_name = "pdsim:" + ":".join(identifier(part) for part in name.split(":"))
        prim = self._stage.GetPrimAtPath(handle.path)
        if not prim.GetAttribute(attr_name):
            prim.CreateAttribute(attr_name, self._types["double3"], custom=True)
        self._sample(layer, "default", handle.path, attr_name, "double3", Gf.Vec3d(*v.tolist()))

    def _sample(self, layer: FrameLayer, clip_set: str, prim_path: str, name: str, kind: str, value) -> None:
        type_name = self._types[kind]
        path = layer.sample(prim_path, name, type_name, value)
        manifest = self._stream.manifests[clip_set]
        if path not in manifest:
            manifest[path] = type_name

    # ------------------------------------------------------------------ frames and saving

    def end_frame(self, frame: int, *, time: float | None = None) -> None:
        """Finish ``frame`` (and any earlier written frames): write their layers, then the top-level layer.

        Sets ``endTimeCode = frame``. Data written for later frames stays pending.

        Args:
            frame: Frame number; must be after the last finished frame.
            time: Simulated time of the frame [s], written to ``/World.pdsim:time``; None writes no sample.
        """
        pending = self._frame_layer(frame)
        frame = pending.frame
        if time is not None:
            t = float(time)
            if not math.isfinite(t):
                raise ValueError(f"time={time!r} must be a finite number [s]")
            self._sample(pending.samples, "default", "/World", "pdsim:time", "double", t)
        self._stream.finish(frame, self._pending, self._layer)

    def save(self) -> None:
        """Write the top-level layer now when it is behind the last finished frame (it is written after every frame
        unless ``save_interval_s`` > 0)."""
        self._check_open()
        if self._stream.top_written != self._stream.last_finished:
            self._stream.write_top(self._layer)

    def close(self, success: bool = True) -> None:
        """Finish the cache; frames written but not finished are dropped. Idempotent.

        ``success`` (the run completed): when ``path`` held an earlier cache, the new one replaces it now; the partial
        cache of an earlier failed run (``<stem>.partial<suffix>``) and the frame folders that no top-level layer
        beside ``path`` refers to any more are removed. Otherwise (a failed run) an earlier cache at
        ``path`` stays untouched and the finished frames of this run are at :attr:`top_level_path`.
        """
        if self._closed:
            return
        self._pending.clear()
        try:
            self._stream.close(self._layer, success)
        finally:
            self._closed = True
            self._stage = None
            self._layer = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close(success=exc_type is None)
        stream = self._stream
        if exc is not None and stream.frames_written and stream.staged and hasattr(exc, "add_note"):
            exc.add_note(
                f"pdsim: the earlier cache {str(self.path)!r} was kept; the frames {self.start_frame}.."
                f"{stream.last_finished} finished by this run are in {str(self.partial_path)!r}"
            )
        return False

    # ------------------------------------------------------------------ checks

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"UsdCache for {str(self.path)!r} is closed")

    def _check_handle(self, handle, cls) -> None:
        self._check_open()
        if not isinstance(handle, cls) or handle._cache is not self:
            raise ValueError(f"expected a {cls.__name__} from this cache, got {handle!r}")

    def _check_frame(self, frame) -> int:
        self._check_open()
        if int(frame) != frame:
            raise ValueError(f"frame={frame!r} must be an integer")
        frame = int(frame)
        if frame < self.start_frame:
            raise ValueError(f"frame {frame} is before start_frame {self.start_frame}")
        last = self._stream.last_finished
        if last is not None and frame <= last:
            raise ValueError(f"frame {frame} is not after the last finished frame {last}")
        return frame

    def _frame_layer(self, frame) -> PendingFrame:
        frame = self._check_frame(frame)
        pending = self._pending.get(frame)
        if pending is None:
            pending = self._pending[frame] = PendingFrame(frame, self._stream.suffix)
        return pending
