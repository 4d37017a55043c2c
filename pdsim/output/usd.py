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
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from typing import Self

__all__ = [
    "MeshHandle",
    "PointsHandle",
    "UsdCache",
    "XformHandle",
    "cache_files",
    "cache_run",
    "flatten_cache",
    "read_tet_mesh",
    "validate_usd",
]

CACHE_FORMAT_VERSION = 2  # customLayerData pdsim:cacheFormat (1: the single-layer caches written before the clips)
_SUFFIXES = (".usdc", ".usda", ".usd")
_PRIMVAR_KINDS = ("float", "int", "vector3f", "color3f")
_FRAME_DIGITS = 6


@dataclass(eq=False)
class XformHandle:
    """A ``UsdGeom.Xform`` prim that groups other prims (``/World/colliders``, the fragment prims of a surface)."""

    path: str
    _cache: UsdCache | None = field(default=None, repr=False)


@dataclass(eq=False)
class PointsHandle:
    """A ``UsdGeom.Points`` prim of a :class:`UsdCache`; returned by :meth:`UsdCache.add_points`.

    Attributes:
        path: Prim path, e.g. ``/World/particles``.
        point_count: Number of points (fixed for the whole cache).
        primvar_kinds: Declared primvars, ``{name: kind}`` with kind in ``{"float", "int", "vector3f", "color3f"}``.
    """

    path: str
    point_count: int
    primvar_kinds: dict[str, str]
    _cache: UsdCache = field(repr=False)
    _widths: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, np.float32))


@dataclass(eq=False)
class MeshHandle:
    """A ``UsdGeom.Mesh`` prim of a :class:`UsdCache`; returned by :meth:`UsdCache.add_mesh`.

    Attributes:
        path: Prim path, e.g. ``/World/bar_surface``.
        vertex_count: Number of vertices of the current topology (0 until the first ``write_mesh`` with faces).
        face_primvar_kinds: Per-face (uniform) primvars ``{name: kind}``.
        vertex_primvar_kinds: Per-vertex primvars ``{name: kind}``.
        normals: Interpolation of the ``normals`` attribute (``"faceVarying"``, ``"vertex"``) or None (no normals).
        subsets: Names of the face subsets (``UsdGeom.Subset`` children, family ``materialBind``).
    """

    path: str
    vertex_count: int = 0
    face_primvar_kinds: dict[str, str] = field(default_factory=dict)
    vertex_primvar_kinds: dict[str, str] = field(default_factory=dict)
    normals: str | None = None
    subsets: tuple[str, ...] = ()
    _cache: UsdCache | None = field(default=None, repr=False)
    topology_set: str = ""  # name of the value-clip set that holds its topology
    _has_topology: bool = field(default=False, repr=False)
    _face_count: int = field(default=0, repr=False)
    _transform: bool = field(default=False, repr=False)  # xformOps declared (animated transform)


def _type_names():
    from pxr import Sdf

    t = Sdf.ValueTypeNames
    return {
        "float": t.FloatArray,
        "int": t.IntArray,
        "vector3f": t.Vector3fArray,
        "color3f": t.Color3fArray,
        "points": t.Point3fArray,
        "normals": t.Normal3fArray,
        "extent": t.Float3Array,
        "double3": t.Double3,
        "double": t.Double,
        "quatf": t.Quatf,
        "token": t.Token,
    }


def _vt_array(kind: str, values: np.ndarray):
    """A Vt array of a primvar kind from a checked numpy array."""
    from pxr import Vt

    return {
        "float": Vt.FloatArray,
        "int": Vt.IntArray,
        "vector3f": Vt.Vec3fArray,
        "color3f": Vt.Vec3fArray,
        "points": Vt.Vec3fArray,
        "normals": Vt.Vec3fArray,
    }[kind].FromNumpy(values)


def _check_array(name: str, array, *, shape: tuple[int, ...], shape_text: str, kind: str = "float") -> np.ndarray:
    """Return ``array`` as a C-contiguous numpy array after checking its shape, dtype kind and finiteness.

    Args:
        name: Name used in error messages.
        array: Array-like value.
        shape: Expected shape; ``-1`` matches any length on that axis.
        shape_text: Expected shape as shown to the user, e.g. ``"[point_count, 3] = [100, 3]"``.
        kind: ``"float"`` (converted to float32) or ``"int"`` (integer or bool, converted to int32).

    Raises:
        ValueError: Wrong shape, wrong dtype kind, or non-finite values.
    """
    a = np.asarray(array)
    if a.ndim != len(shape) or any(e != -1 and e != s for e, s in zip(shape, a.shape, strict=False)):
        raise ValueError(f"{name} has shape {list(a.shape)}; expected {shape_text}")
    if kind == "int":
        if not (np.issubdtype(a.dtype, np.integer) or a.dtype == np.bool_):
            raise ValueError(f"{name} must hold integers, got dtype {a.dtype}")
        if a.size and (a.min() < np.iinfo(np.int32).min or a.max() > np.iinfo(np.int32).max):
            raise ValueError(f"{name} has values outside the int32 range")
        return np.ascontiguousarray(a, dtype=np.int32)
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
        raise ValueError(f"{name} must hold real numbers, got dtype {a.dtype}")
    a = np.ascontiguousarray(a, dtype=np.float32)
    if not np.isfinite(a).all():
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise ValueError(
            f"{name} (shape {shape_text}) has {bad} non-finite values (NaN or inf) after conversion to float32"
        )
    return a


def _primvar_array(label: str, kind: str, values, n: int, count_name: str) -> np.ndarray:
    """A checked primvar array of ``n`` elements of ``kind``."""
    if kind in ("vector3f", "color3f"):
        return _check_array(label, values, shape=(n, 3), shape_text=f"[{count_name}, 3] = [{n}, 3]")
    return _check_array(label, values, shape=(n,), shape_text=f"[{count_name}] = [{n}]", kind=kind)


def _extent(lo: np.ndarray, hi: np.ndarray):
    """Return a ``Vt.Vec3fArray`` extent ``[min, max]`` from two float arrays of shape [3]."""
    from pxr import Gf, Vt

    return Vt.Vec3fArray([Gf.Vec3f(*(float(v) for v in lo)), Gf.Vec3f(*(float(v) for v in hi))])


def _export(layer, target: Path) -> None:
    """Export ``layer`` to ``target`` atomically: a temporary file in the same folder with the same extension (so USD
    picks the same format), then ``os.replace``."""
    tmp = target.with_name(f".{target.name}.tmp{target.suffix}")
    try:
        if not layer.Export(str(tmp)):
            raise OSError(f"USD could not export a layer to {str(tmp)!r}")
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.remove(tmp)
        raise


class _FrameLayer:
    """The samples of one frame for one clip set: an anonymous layer of ``over`` prim specs with time samples at the
    frame."""

    def __init__(self, frame: int, suffix: str):
        from pxr import Sdf

        self.frame = frame
        self.layer = Sdf.Layer.CreateAnonymous(f"pdsim_frame{suffix}")

    def sample(self, prim_path: str, name: str, type_name, value) -> str:
        """Author ``value`` at the frame on ``prim_path.name``; returns the attribute path."""
        from pxr import Sdf

        prim = self.layer.GetPrimAtPath(prim_path) or Sdf.CreatePrimInLayer(self.layer, prim_path)
        spec = prim.attributes.get(name) if name in prim.attributes else None
        if spec is None:
            spec = Sdf.AttributeSpec(prim, name, type_name)
        self.layer.SetTimeSample(spec.path, float(self.frame), value)
        return str(spec.path)


class _Frame:
    """What one frame writes: the layer of the per-frame clip set, the layers of the topology clip sets that change at
    the frame, and samples of the top-level layer (visibility) applied when the frame finishes."""

    def __init__(self, frame: int, suffix: str):
        self.frame = frame
        self.suffix = suffix
        self.samples = _FrameLayer(frame, suffix)
        self.topology: dict[str, _FrameLayer] = {}
        self.top_samples: list = []  # (Usd attribute of the top-level layer, value)

    def topology_layer(self, clip_set: str) -> _FrameLayer:
        layer = self.topology.get(clip_set)
        if layer is None:
            layer = self.topology[clip_set] = _FrameLayer(self.frame, self.suffix)
        return layer


class UsdCache:
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
    ):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in _SUFFIXES:
            raise ValueError(f"path {str(path)!r} must end in one of {', '.join(_SUFFIXES)}")
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps={fps!r} must be a finite number > 0")
        if up_axis not in ("Y", "Z"):
            raise ValueError(f"up_axis={up_axis!r} must be 'Y' or 'Z'")
        if not (math.isfinite(meters_per_unit) and meters_per_unit > 0):
            raise ValueError(f"meters_per_unit={meters_per_unit!r} must be a finite number > 0")
        if not (math.isfinite(save_interval_s) and save_interval_s >= 0):
            raise ValueError(f"save_interval_s={save_interval_s!r} must be a finite number >= 0")
        if int(start_frame) != start_frame or start_frame < 0:
            raise ValueError(f"start_frame={start_frame!r} must be an integer >= 0")
        if not self.path.parent.is_dir():
            raise ValueError(f"folder {str(self.path.parent)!r} of the cache does not exist")
        if self.path.is_dir():
            raise ValueError(f"path {str(path)!r} is a folder")

        from pxr import Sdf, Usd, UsdGeom

        self.fps = float(fps)
        self.start_frame = int(start_frame)
        self.save_interval_s = float(save_interval_s)
        self.metadata = dict(metadata or {})
        self._suffix = ".usda" if suffix == ".usda" else ".usdc"  # frame layers: text for text caches, else crate
        self.frames_dir = self.path.with_name(f"{self.path.stem}.frames")
        self.partial_path = self.path.with_name(f"{self.path.stem}.partial{self.path.suffix}")
        self._types = _type_names()
        self._names: dict[str, set[str]] = {"/World": set()}  # parent path -> child identifiers
        self._pending: dict[int, _Frame] = {}
        # clip set -> {attribute path: Sdf type name} of every attribute its clips sample; "default" holds the
        # per-frame samples, "topology_<mesh>" the topology of a mesh (or of a surface's fragment prims)
        self._manifests: dict[str, dict[str, object]] = {"default": {}}
        self._manifests_written: dict[str, int] = {}  # clip set -> size of its manifest on disk
        self._topology_frames: dict[str, list[int]] = {}  # topology clip set -> frames of its clips
        self._defined_at: dict[str, int] = {}  # prim path -> the frame being written when it was defined (> start)
        self._handles: dict[str, object] = {}  # prim path -> handle, for the prims of a reopened cache
        self._last_finished: int | None = None
        self._frames_written = 0
        self._top_written = None  # last frame whose top-level layer is on disk
        self._last_save_end = time.monotonic()
        self._closed = False
        if append_frame is not None:
            if isinstance(append_frame, bool) or int(append_frame) != append_frame:
                raise ValueError(f"append_frame={append_frame!r} must be an integer")
            self._reopen(int(append_frame), append_run, up_axis, float(meters_per_unit))
            return
        if append_run is not None:
            raise ValueError("append_run is given only with append_frame")

        self._staged = self.path.exists()  # an earlier cache is there: replace it only on success
        self._top_path = self.partial_path if self._staged else self.path
        self.run_id = self._new_run_id()
        self.run_dir = self.frames_dir / self.run_id
        self.run_dir.mkdir(parents=True)

        self._layer = Sdf.Layer.CreateAnonymous(f"pdsim_cache{suffix}")
        self._stage = Usd.Stage.Open(self._layer)
        stage = self._stage
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(self.start_frame)
        stage.SetEndTimeCode(self.start_frame)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        time_attr = world.GetPrim().CreateAttribute("pdsim:time", Sdf.ValueTypeNames.Double, custom=True)
        time_attr.SetDocumentation("simulated time of the frame [s]")

    # ------------------------------------------------------------------ properties

    @property
    def frames_written(self) -> int:
        """Number of frames finished with :meth:`end_frame`."""
        return self._frames_written

    @property
    def last_frame(self) -> int | None:
        """The last finished frame (of this run or, for a reopened cache, the frame it was reopened at); None before
        the first."""
        return self._last_finished

    @property
    def stage(self):
        """The in-memory ``Usd.Stage`` of the top-level layer's declarations (no time samples; for inspection)."""
        return self._stage

    @property
    def top_level_path(self) -> Path:
        """Where the top-level layer of this run is being written: ``path``, or :attr:`partial_path` while an earlier
        cache at ``path`` is kept until this run succeeds."""
        return self._top_path

    # ------------------------------------------------------------------ prims

    def _reopen(self, frame: int, run: str | None, up_axis: str, meters_per_unit: float) -> None:
        """Take over the cache at ``path`` (or ``partial_path``) at its finished frame ``frame`` (append_frame)."""
        from pxr import Sdf, Usd

        candidates = [p for p in (self.partial_path, self.path) if p.is_file()]
        if not candidates:
            raise FileNotFoundError(f"no cache at {str(self.path)!r} (nor {str(self.partial_path)!r}) to continue")
        infos = {p: _pdsim_info(p) for p in candidates}
        if run is not None:
            matches = [p for p in candidates if infos[p].get("run") == run]
            if not matches:
                found = ", ".join(f"{p.name}: {infos[p].get('run')!r}" for p in candidates)
                raise ValueError(f"no cache beside {str(self.path)!r} holds the run {run!r} (found {found})")
            top = matches[0]
        else:
            top = candidates[0]
        info = infos[top]
        if info.get("cacheFormat") != CACHE_FORMAT_VERSION or not info.get("run") or not info.get("frames"):
            raise ValueError(f"{str(top)!r} is not a pdsim cache of format {CACHE_FORMAT_VERSION}")
        self._staged = top == self.partial_path
        self._top_path = top
        self.run_id = str(info["run"])
        self.run_dir = self.frames_dir / self.run_id
        if (self.path.parent / str(info["frames"])).resolve() != self.run_dir.resolve() or not self.run_dir.is_dir():
            raise ValueError(f"the run folder {str(self.run_dir)!r} of {str(top)!r} is missing")

        source = Sdf.Layer.OpenAsAnonymous(str(top))
        checks = {
            "fps": (source.timeCodesPerSecond, self.fps),
            "start_frame": (source.startTimeCode, float(self.start_frame)),
            "up_axis": (source.pseudoRoot.GetInfo("upAxis"), up_axis),
            "meters_per_unit": (source.pseudoRoot.GetInfo("metersPerUnit"), meters_per_unit),
        }
        for name, (theirs, mine) in checks.items():
            if theirs != mine:
                raise ValueError(f"{name}={mine!r} differs from the cache's {theirs!r} ({str(top)!r})")
        last = int(source.endTimeCode)
        if not self.start_frame <= frame <= last:
            raise ValueError(
                f"append_frame={frame} is not a finished frame of {str(top)!r} (frames {self.start_frame}..{last})"
            )
        old_clips = dict(source.GetPrimAtPath("/World").GetInfo("clips") or {})

        # the top-level layer without its clips and without what the frames after ``frame`` added
        layer = Sdf.Layer.CreateAnonymous(f"pdsim_cache{self.path.suffix.lower()}")
        layer.TransferContent(source)
        del source
        world = layer.GetPrimAtPath("/World")
        for key in ("clips", "clipSets"):
            if world.HasInfo(key):
                world.ClearInfo(key)
        layer.customLayerData = {}
        defined = {str(k): int(v) for k, v in dict(info.get("definedAt", {})).items()}
        removed = sorted((p for p, f in defined.items() if f > frame), key=lambda p: p.count("/"))
        for path in removed:
            spec = layer.GetPrimAtPath(path)
            if spec is not None:  # None: its parent went first
                del layer.GetPrimAtPath(Sdf.Path(path).GetParentPath()).nameChildren[spec.name]
        self._defined_at = {p: f for p, f in defined.items() if f <= frame}

        def drop_later(path):
            if path.IsPropertyPath():
                for t in layer.ListTimeSamplesForPath(path):
                    if t > frame:
                        layer.EraseTimeSample(path, t)

        layer.Traverse(Sdf.Path.absoluteRootPath, drop_later)

        def gone(attr_path: str) -> bool:
            return any(attr_path.startswith(p + "/") or attr_path.startswith(p + ".") for p in removed)

        # clip sets: the manifests on disk (they may name attributes first sampled after ``frame``: harmless) and the
        # topology clips up to ``frame``
        folder = top.parent
        for clip_set, meta in old_clips.items():
            manifest_path = meta.get("manifestAssetPath")
            entries: dict[str, object] = {}
            if manifest_path is not None:
                manifest = Sdf.Layer.OpenAsAnonymous(str(folder / manifest_path.path))
                if manifest is None:
                    raise ValueError(f"the manifest {manifest_path.path!r} of {str(top)!r} is missing")

                def collect(path, manifest=manifest, entries=entries):
                    if path.IsPropertyPath():
                        spec = manifest.GetAttributeAtPath(path)
                        if spec is not None:
                            entries[str(path)] = spec.typeName

                manifest.Traverse(Sdf.Path.absoluteRootPath, collect)
            kept = {p: t for p, t in entries.items() if not gone(p)}
            self._manifests[clip_set] = kept
            self._manifests_written[clip_set] = len(kept) if len(kept) == len(entries) else -1
            if clip_set != "default":
                frames = [round(float(t)) for t, _ in meta.get("active", [])]
                frames = [f for f in frames if f <= frame]
                if frames:
                    self._topology_frames[clip_set] = frames

        self._layer = layer
        self._stage = Usd.Stage.Open(layer)
        for prim in self._stage.TraverseAll():
            path = str(prim.GetPath())
            self._names.setdefault(path, set())
            self._names.setdefault(str(prim.GetPath().GetParentPath()), set()).add(prim.GetName())
        self._last_finished = frame
        self._write_top()  # the cache now ends at ``frame``, atomically
        self._remove_frames_after(frame)
        self._attach_handles(frame)

    def _remove_frames_after(self, frame: int) -> None:
        """Delete the frame and topology layers of the run folder after ``frame`` (the top-level layer no longer names
        them)."""
        for child in self.run_dir.iterdir():
            parts = child.name.split(".")
            if (
                len(parts) >= 3
                and child.is_file()
                and len(parts[-2]) == _FRAME_DIGITS
                and parts[-2].isdigit()
                and int(parts[-2]) > frame
            ):
                child.unlink()

    def _attach_handles(self, frame: int) -> None:
        """Handles for the Points, Mesh and Xform prims of a reopened cache, with the vertex and face counts of their
        geometry at ``frame``."""
        from pxr import Sdf, UsdGeom

        kinds = {str(t): k for k, t in self._types.items() if k in _PRIMVAR_KINDS}
        samples = Sdf.Layer.OpenAsAnonymous(str(self._frame_file(frame)))
        topologies = {}  # clip set -> (layer of its last clip up to ``frame``, the clip's frame)
        for clip_set, frames in self._topology_frames.items():
            layer = Sdf.Layer.OpenAsAnonymous(str(self._topology_file(clip_set, frames[-1])))
            topologies[clip_set] = (layer, frames[-1])
        mesh_set = {}
        for clip_set, manifest in self._manifests.items():
            for attr_path in manifest:
                if attr_path.endswith(".faceVertexIndices"):
                    mesh_set[attr_path[: -len(".faceVertexIndices")]] = clip_set

        def sample_length(layer, at: int, path: str, name: str) -> int:
            if layer is None:
                return 0
            value = layer.QueryTimeSample(Sdf.Path(path).AppendProperty(name), float(at))
            return 0 if value is None else len(value)

        def primvars(prim, interpolation: str) -> dict[str, str]:
            out = {}
            for pv in UsdGeom.PrimvarsAPI(prim).GetPrimvars():
                if pv.GetInterpolation() == interpolation and str(pv.GetTypeName()) in kinds:
                    out[str(pv.GetPrimvarName())] = kinds[str(pv.GetTypeName())]
            return out

        for prim in self._stage.Traverse():
            path = str(prim.GetPath())
            if prim.IsA(UsdGeom.Points):
                w = np.asarray(UsdGeom.Points(prim).GetWidthsAttr().Get() or [], dtype=np.float32)
                self._handles[path] = PointsHandle(
                    path=path,
                    point_count=int(w.shape[0]),
                    primvar_kinds=primvars(prim, UsdGeom.Tokens.vertex),
                    _cache=self,
                    _widths=w,
                )
            elif prim.IsA(UsdGeom.Mesh):
                mesh = UsdGeom.Mesh(prim)
                spec = self._layer.GetPrimAtPath(path)
                handle = MeshHandle(
                    path=path,
                    face_primvar_kinds=primvars(prim, UsdGeom.Tokens.uniform),
                    vertex_primvar_kinds=primvars(prim, UsdGeom.Tokens.vertex),
                    normals=str(mesh.GetNormalsInterpolation()) if "normals" in spec.attributes else None,
                    subsets=tuple(c.GetName() for c in prim.GetChildren() if c.IsA(UsdGeom.Subset)),
                    _cache=self,
                    _transform="xformOp:translate" in spec.attributes,
                )
                clip_set = mesh_set.get(path)
                if clip_set is not None:
                    handle.topology_set = clip_set
                    handle._has_topology = clip_set in self._topology_frames
                    handle.vertex_count = sample_length(samples, frame, path, "points")
                    handle._face_count = sample_length(*topologies.get(clip_set, (None, 0)), path, "faceVertexCounts")
                else:
                    handle.topology_set = "topology_" + path[len("/World/") :].replace("/", "_")
                    counts = mesh.GetFaceVertexCountsAttr().Get()
                    if counts is not None:  # a static mesh (set_mesh)
                        handle._has_topology = True
                        handle._face_count = len(counts)
                        handle.vertex_count = len(mesh.GetPointsAttr().Get() or [])
                        self._manifests.pop(handle.topology_set, None)
                    else:
                        self._manifests.setdefault(handle.topology_set, {})
                self._handles[path] = handle
            elif prim.IsA(UsdGeom.Xform):
                self._handles[path] = XformHandle(path=path, _cache=self)

    def existing(self, path: str):
        """The handle (PointsHandle, MeshHandle, XformHandle) of a prim of a reopened cache (``append_frame``), by prim
        path, e.g. ``/World/bar``; ValueError when the cache holds no such prim."""
        self._check_open()
        handle = self._handles.get(path)
        if handle is None:
            raise ValueError(f"the reopened cache {str(self._top_path)!r} holds no Points, Mesh or Xform prim {path!r}")
        return handle

    def _new_run_id(self) -> str:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        base = f"run-{stamp}-{os.getpid()}"
        run, k = base, 1
        while (self.frames_dir / run).exists():
            run, k = f"{base}-{k}", k + 1
        return run

    def _define_path(self, name: str, parent: XformHandle | None = None) -> str:
        from pxr import Tf

        if not isinstance(name, str) or not name:
            raise ValueError(f"prim name {name!r} must be a non-empty string")
        base = "/World" if parent is None else parent.path
        if parent is not None and (not isinstance(parent, XformHandle) or parent._cache is not self):
            raise ValueError(f"parent must be an XformHandle of this cache, got {parent!r}")
        ident = Tf.MakeValidIdentifier(name)
        names = self._names.setdefault(base, set())
        if ident in names:
            raise ValueError(f"prim name {name!r} (as USD identifier {ident!r}) is already used under {base}")
        names.add(ident)
        path = f"{base}/{ident}"
        frame = self.start_frame if self._last_finished is None else self._last_finished + 1
        if frame > self.start_frame:  # a reopened cache drops the prims defined after the frame it resumes at
            self._defined_at[path] = frame
        return path

    def add_xform(self, name: str, *, parent: XformHandle | None = None) -> XformHandle:
        """Define a ``UsdGeom.Xform`` at ``/World/<name>`` (or under ``parent``) to group prims."""
        self._check_open()
        from pxr import UsdGeom

        path = self._define_path(name, parent)
        UsdGeom.Xform.Define(self._stage, path)
        self._names[path] = set()
        return XformHandle(path=path, _cache=self)

    def add_material(self, name: str, color) -> str:
        """Define a placeholder material ``/World/Looks/<name>`` (a ``UsdPreviewSurface`` of diffuse ``color``, linear
        RGB in [0, 1]) once and return its path; :meth:`bind_material` binds it. Renderers and DCC tools show it until
        a user binds their own material to the same prims."""
        self._check_open()
        from pxr import Gf, Sdf, UsdGeom, UsdShade

        c = np.asarray(color, dtype=np.float64)
        if c.shape != (3,) or not (np.isfinite(c).all() and (c >= 0).all() and (c <= 1).all()):
            raise ValueError(f"color={color!r} must be 3 numbers in [0, 1]")
        if "/World/Looks" not in self._names:
            self._define_path("Looks")
            UsdGeom.Scope.Define(self._stage, "/World/Looks")
            self._names["/World/Looks"] = set()
        path = f"/World/Looks/{_identifier(name)}"
        if self._stage.GetPrimAtPath(path):
            return path
        self._define_path(name, XformHandle("/World/Looks", self))
        material = UsdShade.Material.Define(self._stage, path)
        shader = UsdShade.Shader.Define(self._stage, f"{path}/PreviewSurface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*c.tolist()))
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        return path

    def bind_material(self, prim_path: str, material_path: str) -> None:
        """Bind the material at ``material_path`` to the prim (mesh or face subset) at ``prim_path``."""
        self._check_open()
        from pxr import UsdShade

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
    ) -> PointsHandle:
        """Define a ``UsdGeom.Points`` prim at ``/World/<name>``.

        Args:
            name: Prim name; made into a valid USD identifier (``"body 1"`` -> ``"body_1"``).
            widths: Point diameters [stage units], shape [point_count]; written once (not time-sampled).
            primvars: ``{name: kind}`` with kind ``"float"`` (values shape [point_count]), ``"int"`` (shape
                [point_count]), ``"vector3f"`` or ``"color3f"`` (shape [point_count, 3]); vertex interpolation.
                ``displayColor`` (kind color3f) is the USD display colour.
            parent: Group to define the prim under (default ``/World``).

        Returns:
            Handle for :meth:`write_points`.
        """
        self._check_open()
        from pxr import UsdGeom, Vt

        primvars = dict(primvars or {})
        w = _check_array("widths", widths, shape=(-1,), shape_text="[point_count]")
        if (w < 0).any():
            raise ValueError("widths must be >= 0")
        self._check_primvar_kinds(primvars, "primvar")

        path = self._define_path(name, parent)
        points = UsdGeom.Points.Define(self._stage, path)
        points.CreatePointsAttr()
        points.CreateVelocitiesAttr()
        points.CreateExtentAttr()
        points.CreateWidthsAttr(Vt.FloatArray.FromNumpy(w))
        points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        api = UsdGeom.PrimvarsAPI(points)
        for pv_name, kind in primvars.items():
            api.CreatePrimvar(pv_name, self._types[kind], UsdGeom.Tokens.vertex)
        return PointsHandle(path=path, point_count=int(w.shape[0]), primvar_kinds=primvars, _cache=self, _widths=w)

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
            positions: Point positions [stage units], shape [point_count, 3]; stored as float32.
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
        from pxr import Vt

        n = handle.point_count
        shape3 = f"[point_count, 3] = [{n}, 3]"
        x = _check_array("positions", positions, shape=(n, 3), shape_text=shape3)
        samples = [("points", "points", Vt.Vec3fArray.FromNumpy(x))]
        if velocities is not None:
            v = _check_array("velocities", velocities, shape=(n, 3), shape_text=shape3)
            samples.append(("velocities", "vector3f", Vt.Vec3fArray.FromNumpy(v)))
        for pv_name, values in (primvars or {}).items():
            kind = handle.primvar_kinds.get(pv_name)
            if kind is None:
                raise ValueError(
                    f"primvar {pv_name!r} was not declared in add_points (declared: {sorted(handle.primvar_kinds)})"
                )
            a = _primvar_array(f"primvar {pv_name!r}", kind, values, n, "point_count")
            samples.append((f"primvars:{pv_name}", kind, _vt_array(kind, a)))
        if n:
            r = 0.5 * handle._widths[:, None]
            samples.append(("extent", "extent", _extent((x - r).min(axis=0), (x + r).max(axis=0))))
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

        Returns:
            Handle for :meth:`write_mesh`.
        """
        self._check_open()
        from pxr import UsdGeom

        fkinds = dict(face_primvars or {})
        vkinds = dict(vertex_primvars or {})
        self._check_primvar_kinds(fkinds, "face primvar")
        self._check_primvar_kinds(vkinds, "vertex primvar")
        if set(fkinds) & set(vkinds):
            raise ValueError(f"primvars {sorted(set(fkinds) & set(vkinds))} declared both per face and per vertex")
        if normals not in (None, "faceVarying", "vertex"):
            raise ValueError(f"normals={normals!r} must be 'faceVarying', 'vertex' or None")
        path = self._define_path(name, parent)
        self._names[path] = set()
        mesh = UsdGeom.Mesh.Define(self._stage, path)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        for create in (
            mesh.CreatePointsAttr,
            mesh.CreateVelocitiesAttr,
            mesh.CreateExtentAttr,
            mesh.CreateFaceVertexCountsAttr,
            mesh.CreateFaceVertexIndicesAttr,
        ):
            create()
        if normals is not None:
            mesh.CreateNormalsAttr()
            mesh.SetNormalsInterpolation(normals)
        api = UsdGeom.PrimvarsAPI(mesh)
        for pv, kind in fkinds.items():
            api.CreatePrimvar(pv, self._types[kind], UsdGeom.Tokens.uniform)
        for pv, kind in vkinds.items():
            api.CreatePrimvar(pv, self._types[kind], UsdGeom.Tokens.vertex)
        subsets = tuple(subsets)
        for s in subsets:
            subset_path = self._define_path(s, XformHandle(path, self))
            subset = UsdGeom.Subset.Define(self._stage, subset_path)
            subset.CreateElementTypeAttr(UsdGeom.Tokens.face)
            subset.CreateFamilyNameAttr("materialBind")
            subset.CreateIndicesAttr()
        if subsets:
            UsdGeom.Subset.SetFamilyType(mesh, "materialBind", UsdGeom.Tokens.nonOverlapping)
        if animated_transform:
            mesh.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
            mesh.AddOrientOp(UsdGeom.XformOp.PrecisionFloat)
        if topology_set is None:
            topology_set = "topology_" + path[len("/World/") :].replace("/", "_")
        elif not (isinstance(topology_set, str) and topology_set.startswith("topology_")):
            raise ValueError(f"topology_set={topology_set!r} must be a string starting with 'topology_'")
        self._manifests.setdefault(topology_set, {})
        return MeshHandle(
            path=path,
            topology_set=topology_set,
            face_primvar_kinds=fkinds,
            vertex_primvar_kinds=vkinds,
            normals=normals,
            subsets=subsets,
            _cache=self,
            _transform=animated_transform,
        )

    def _mesh_samples(self, handle: MeshHandle, points, faces, velocities, normals, face_primvars, vertex_primvars):
        """Checked per-frame samples ``[(attribute, kind, Vt value)]`` of a mesh, its topology samples
        ``[(prim path, attribute, kind, Vt value)]`` (None without faces), vertex and face counts."""
        from pxr import Vt

        x = _check_array("points", points, shape=(-1, 3), shape_text="[vertex_count, 3]")
        nv = int(x.shape[0])
        samples = [("points", "points", Vt.Vec3fArray.FromNumpy(x))]
        topology = None
        if faces is None:
            if not handle._has_topology:
                raise ValueError(f"write_mesh({handle.path!r}): the first call must pass faces")
            if nv != handle.vertex_count:
                raise ValueError(
                    f"points has shape [{nv}, 3] but the current topology has {handle.vertex_count} vertices; "
                    "pass faces when the vertex count changes"
                )
            face_kinds = {k: v for k, v in (face_primvars or {}).items() if k != "displayColor"}
            if face_kinds:
                raise ValueError("face_primvars are written with the topology: pass faces too")
            nf = handle._face_count
        else:
            f = _check_array("faces", faces, shape=(-1, 3), shape_text="[triangle_count, 3]", kind="int")
            if f.size and (f.min() < 0 or f.max() >= nv):
                raise ValueError(f"faces has vertex indices outside [0, {nv}) (vertex_count = {nv})")
            nf = int(f.shape[0])
            topology = [
                (handle.path, "faceVertexCounts", "int", Vt.IntArray.FromNumpy(np.full(nf, 3, np.int32))),
                (handle.path, "faceVertexIndices", "int", Vt.IntArray.FromNumpy(f.reshape(-1))),
            ]
        shape3 = f"[vertex_count, 3] = [{nv}, 3]"
        if velocities is not None:
            v = _check_array("velocities", velocities, shape=(nv, 3), shape_text=shape3)
            samples.append(("velocities", "vector3f", Vt.Vec3fArray.FromNumpy(v)))
        if normals is not None:
            if handle.normals is None:
                raise ValueError(f"mesh {handle.path} was declared without normals")
            n_expected = 3 * nf if handle.normals == "faceVarying" else nv
            label = "[3 x triangle_count, 3]" if handle.normals == "faceVarying" else "[vertex_count, 3]"
            nrm = _check_array("normals", normals, shape=(n_expected, 3), shape_text=f"{label} = [{n_expected}, 3]")
            samples.append(("normals", "normals", Vt.Vec3fArray.FromNumpy(nrm)))
        for pv, values in (face_primvars or {}).items():
            kind = handle.face_primvar_kinds.get(pv)
            if kind is None:
                raise ValueError(f"face primvar {pv!r} was not declared in add_mesh({handle.path!r})")
            a = _primvar_array(f"face primvar {pv!r}", kind, values, nf, "triangle_count")
            if pv == "displayColor":  # may change every frame
                samples.append((f"primvars:{pv}", kind, _vt_array(kind, a)))
            else:
                topology.append((handle.path, f"primvars:{pv}", kind, _vt_array(kind, a)))
        for pv, values in (vertex_primvars or {}).items():
            kind = handle.vertex_primvar_kinds.get(pv)
            if kind is None:
                raise ValueError(f"vertex primvar {pv!r} was not declared in add_mesh({handle.path!r})")
            a = _primvar_array(f"vertex primvar {pv!r}", kind, values, nv, "vertex_count")
            samples.append((f"primvars:{pv}", kind, _vt_array(kind, a)))
        lo, hi = (x.min(axis=0), x.max(axis=0)) if nv else (np.zeros(3), np.zeros(3))
        samples.append(("extent", "extent", _extent(lo, hi)))
        return samples, topology, nv, nf

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
            points: Vertex positions [stage units], shape [vertex_count, 3].
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
        from pxr import Vt

        samples, topology, nv, nf = self._mesh_samples(
            handle, points, faces, velocities, normals, face_primvars, vertex_primvars
        )
        if topology is not None:
            for name, idx in (subsets or {}).items():
                if name not in handle.subsets:
                    raise ValueError(f"subset {name!r} was not declared in add_mesh({handle.path!r})")
                i = _check_array(f"subset {name!r}", idx, shape=(-1,), shape_text="[k]", kind="int")
                if i.size and (i.min() < 0 or i.max() >= nf):
                    raise ValueError(f"subset {name!r} has face indices outside [0, {nf})")
                topology.append((f"{handle.path}/{name}", "indices", "int", Vt.IntArray.FromNumpy(i)))
            for name in sorted(set(handle.subsets) - set(subsets or {})):  # a subset left out is empty
                topology.append((f"{handle.path}/{name}", "indices", "int", Vt.IntArray()))
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
    ) -> None:
        """Write a static mesh (a collider's geometry) once, as default values of the top-level layer (no time
        samples). Arguments as :meth:`write_mesh`."""
        self._check_handle(handle, MeshHandle)
        if handle._has_topology:
            raise ValueError(f"mesh {handle.path} already has geometry")
        samples, topology, nv, nf = self._mesh_samples(handle, points, faces, velocities, normals, None, None)
        prim = self._stage.GetPrimAtPath(handle.path)
        for attr, _kind, value in samples:
            prim.GetAttribute(attr).Set(value)
        for _path, attr, _kind, value in topology:
            prim.GetAttribute(attr).Set(value)
        self._manifests.pop(handle.topology_set, None)
        handle._has_topology = True
        handle.vertex_count, handle._face_count = nv, nf

    def write_transform(self, handle: MeshHandle, frame: int | None, translation, orientation) -> None:
        """The prim's transform: ``translation`` [stage units] (3 numbers) and ``orientation``, a unit quaternion
        (x, y, z, w); time-sampled at ``frame``, or the static (default) value when ``frame`` is None. The mesh must
        have been declared with ``animated_transform=True``. Points p of the mesh are placed at
        ``translation + rotate(orientation, p)``."""
        self._check_handle(handle, MeshHandle)
        from pxr import Gf

        if not handle._transform:
            raise ValueError(f"mesh {handle.path} was declared without animated_transform")
        t = np.asarray(translation, dtype=np.float64)
        q = np.asarray(orientation, dtype=np.float64)
        if t.shape != (3,) or q.shape != (4,) or not (np.isfinite(t).all() and np.isfinite(q).all()):
            raise ValueError(f"translation (3 numbers) and orientation (4 numbers) must be finite, got {t!r}, {q!r}")
        norm = float(np.linalg.norm(q))
        if norm == 0.0:
            raise ValueError("orientation must be a non-zero quaternion (x, y, z, w)")
        q = q / norm
        tv = Gf.Vec3d(*t.tolist())
        qv = Gf.Quatf(float(q[3]), Gf.Vec3f(float(q[0]), float(q[1]), float(q[2])))
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
        from pxr import UsdGeom

        if int(frame) != frame or frame < self.start_frame:
            raise ValueError(f"frame={frame!r} must be an integer >= start_frame {self.start_frame}")
        attr = UsdGeom.Imageable(self._stage.GetPrimAtPath(handle.path)).CreateVisibilityAttr()
        value = UsdGeom.Tokens.inherited if visible else UsdGeom.Tokens.invisible
        if self._last_finished is not None and frame <= self._last_finished:
            attr.Set(value, float(frame))
        else:
            self._frame_layer(frame).top_samples.append((attr, value))

    def write_vector(self, handle, frame: int, name: str, value) -> None:
        """Time-sample a custom double3 attribute ``pdsim:<name>`` (e.g. ``reaction:grip``, a boundary condition's
        reaction force [N]) on the prim of ``handle`` at ``frame``."""
        self._check_open()
        layer = self._frame_layer(frame).samples
        from pxr import Gf

        v = np.asarray(value, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name!r}: a vector of 3 finite numbers, got {value!r}")
        attr_name = "pdsim:" + ":".join(_identifier(part) for part in name.split(":"))
        prim = self._stage.GetPrimAtPath(handle.path)
        if not prim.GetAttribute(attr_name):
            prim.CreateAttribute(attr_name, self._types["double3"], custom=True)
        self._sample(layer, "default", handle.path, attr_name, "double3", Gf.Vec3d(*v.tolist()))

    def _sample(self, layer: _FrameLayer, clip_set: str, prim_path: str, name: str, kind: str, value) -> None:
        type_name = self._types[kind]
        path = layer.sample(prim_path, name, type_name, value)
        manifest = self._manifests[clip_set]
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
        first = self.start_frame if self._last_finished is None else self._last_finished + 1
        for f in range(first, frame + 1):
            done = self._pending.pop(f, None) or _Frame(f, self._suffix)
            _export(done.samples.layer, self._frame_file(f))
            for clip_set, layer in done.topology.items():
                _export(layer.layer, self._topology_file(clip_set, f))
                self._topology_frames.setdefault(clip_set, []).append(f)
            for attr, value in done.top_samples:
                attr.Set(value, float(f))
        self._last_finished = frame
        self._frames_written += frame + 1 - first
        for clip_set, manifest in self._manifests.items():
            if manifest and len(manifest) != self._manifests_written.get(clip_set):
                self._write_manifest(clip_set)
        if self.save_interval_s == 0 or _monotonic() - self._last_save_end >= self.save_interval_s:
            self._write_top()

    def _frame_file(self, frame: int) -> Path:
        return self.run_dir / f"frame.{frame:0{_FRAME_DIGITS}d}{self._suffix}"

    def _topology_file(self, clip_set: str, frame: int) -> Path:
        return self.run_dir / f"{clip_set}.{frame:0{_FRAME_DIGITS}d}{self._suffix}"

    def _manifest_file(self, clip_set: str) -> Path:
        name = "manifest" if clip_set == "default" else f"{clip_set}.manifest"
        return self.run_dir / f"{name}{self._suffix}"

    def _write_manifest(self, clip_set: str) -> None:
        from pxr import Sdf

        manifest = Sdf.Layer.CreateAnonymous(f"pdsim_manifest{self._suffix}")
        for path, type_name in self._manifests[clip_set].items():
            p = Sdf.Path(path)
            prim = manifest.GetPrimAtPath(p.GetPrimPath()) or Sdf.CreatePrimInLayer(manifest, p.GetPrimPath())
            spec = Sdf.AttributeSpec(prim, p.name, type_name)
            # the value of a frame whose clip has no sample (a fragment prim before it appears): no geometry
            if p.name == "extent":  # the empty box, as UsdGeom computes it for no points
                big = float(np.finfo(np.float32).max)
                spec.default = _extent(np.full(3, big), np.full(3, -big))
            elif type_name.isArray:
                spec.default = type_name.defaultValue
        _export(manifest, self._manifest_file(clip_set))
        self._manifests_written[clip_set] = len(self._manifests[clip_set])

    def _relative(self, target: Path) -> str:
        return "./" + target.relative_to(self.path.parent).as_posix()

    def _write_top(self) -> None:
        """Export the top-level layer with the clip metadata of the finished frames (atomic replace)."""
        from pxr import Gf, Sdf, Vt

        if self._last_finished is None:
            return
        out = Sdf.Layer.CreateAnonymous(f"pdsim_top{self.path.suffix.lower()}")
        out.TransferContent(self._layer)
        template = self._relative(self.run_dir / f"frame.{'#' * _FRAME_DIGITS}{self._suffix}")
        clips = {
            "default": {
                "primPath": "/World",
                "manifestAssetPath": Sdf.AssetPath(self._relative(self._manifest_file("default"))),
                "templateAssetPath": template,
                "templateStartTime": float(self.start_frame),
                "templateEndTime": float(self._last_finished),
                "templateStride": 1.0,
            }
        }
        for clip_set, frames in self._topology_frames.items():
            clips[clip_set] = {
                "primPath": "/World",
                "manifestAssetPath": Sdf.AssetPath(self._relative(self._manifest_file(clip_set))),
                "assetPaths": Sdf.AssetPathArray([self._relative(self._topology_file(clip_set, f)) for f in frames]),
                "active": Vt.Vec2dArray([Gf.Vec2d(f, i) for i, f in enumerate(frames)]),
            }
        world = out.GetPrimAtPath("/World")
        world.SetInfo("clips", clips)
        # topology sets first: each attribute takes its values from the first clip set whose manifest names it
        world.SetInfo("clipSets", Sdf.StringListOp.CreateExplicit([*self._topology_frames, "default"]))
        out.endTimeCode = float(self._last_finished)
        info = {
            "cacheFormat": CACHE_FORMAT_VERSION,
            "run": self.run_id,
            "frames": self._relative(self.run_dir),
            "framesWritten": self._last_finished - self.start_frame + 1,
        }
        if self._defined_at:
            info["definedAt"] = dict(self._defined_at)
        info.update(self.metadata)
        out.customLayerData = {"pdsim": info}
        _export(out, self._top_path)
        self._top_written = self._last_finished
        self._last_save_end = _monotonic()

    def save(self) -> None:
        """Write the top-level layer now when it is behind the last finished frame (it is written after every frame
        unless ``save_interval_s`` > 0)."""
        self._check_open()
        if self._top_written != self._last_finished:
            self._write_top()

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
            if self._last_finished is None:
                shutil.rmtree(self.run_dir, ignore_errors=True)
                with contextlib.suppress(OSError):
                    self.frames_dir.rmdir()  # only when empty
                return
            if self._top_written != self._last_finished:
                self._write_top()
            if success:
                if self._staged:
                    os.replace(self.partial_path, self.path)
                    self._top_path = self.path
                elif self.partial_path.is_file():  # a failed run's leftover, superseded by this one
                    self.partial_path.unlink()
                self._remove_unreferenced_runs()
        finally:
            self._closed = True
            self._stage = None
            self._layer = None

    def _remove_unreferenced_runs(self) -> None:
        """Remove the run folders under the frames folder that no top-level layer beside ``path`` names."""
        from pxr import Sdf

        keep = {self.run_id}
        for suffix in _SUFFIXES:
            for candidate in (
                self.path.with_suffix(suffix),
                self.path.with_name(f"{self.path.stem}.partial{suffix}"),
            ):
                if not candidate.is_file() or candidate == self.path:
                    continue
                with contextlib.suppress(Exception):
                    layer = Sdf.Layer.OpenAsAnonymous(str(candidate), metadataOnly=True)
                    run = dict(layer.customLayerData.get("pdsim", {})).get("run")
                    if run:
                        keep.add(str(run))
        for child in self.frames_dir.iterdir():
            if child.is_dir() and child.name.startswith("run-") and child.name not in keep:
                shutil.rmtree(child, ignore_errors=True)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close(success=exc_type is None)
        if exc is not None and self._frames_written and self._staged and hasattr(exc, "add_note"):
            exc.add_note(
                f"pdsim: the earlier cache {str(self.path)!r} was kept; the frames {self.start_frame}.."
                f"{self._last_finished} finished by this run are in {str(self.partial_path)!r}"
            )
        return False

    # ------------------------------------------------------------------ checks

    @staticmethod
    def _check_primvar_kinds(kinds: dict, label: str) -> None:
        from pxr import Sdf

        for pv_name, kind in kinds.items():
            if kind not in _PRIMVAR_KINDS:
                raise ValueError(f"{label} {pv_name!r} has kind {kind!r}; allowed: {', '.join(_PRIMVAR_KINDS)}")
            if not (isinstance(pv_name, str) and Sdf.Path.IsValidNamespacedIdentifier(pv_name)):
                raise ValueError(f"{label} name {pv_name!r} is not a valid USD identifier")
            if pv_name == "displayColor" and kind != "color3f":
                raise ValueError(f"{label} displayColor must have kind 'color3f', got {kind!r}")

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
        if self._last_finished is not None and frame <= self._last_finished:
            raise ValueError(f"frame {frame} is not after the last finished frame {self._last_finished}")
        return frame

    def _frame_layer(self, frame) -> _Frame:
        frame = self._check_frame(frame)
        pending = self._pending.get(frame)
        if pending is None:
            pending = self._pending[frame] = _Frame(frame, self._suffix)
        return pending


def _monotonic() -> float:
    """time.monotonic (the module name ``time`` is shadowed by arguments of UsdCache)."""
    return time.monotonic()


def _pdsim_info(path: Path) -> dict:
    """The ``customLayerData pdsim`` dictionary of the top-level layer at ``path`` (empty when there is none)."""
    from pxr import Sdf

    layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
    if layer is None:
        raise ValueError(f"{str(path)!r} is not a USD layer")
    return dict(layer.customLayerData.get("pdsim", {}))


def cache_run(path: str | os.PathLike) -> str | None:
    """The run id (``customLayerData pdsim:run``) of the pdsim cache at ``path``; None when it names none."""
    run = _pdsim_info(Path(path)).get("run")
    return None if run is None else str(run)


def cache_files(path: str | os.PathLike) -> list[Path]:
    """Every file of the cache at ``path``: the top-level layer and the files of the run folder it names (manifest and
    frame layers); what to copy or archive to move a cache (``flatten_cache`` makes a single file instead)."""
    from pxr import Sdf

    path = Path(path)
    layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
    if layer is None:
        raise FileNotFoundError(f"no USD layer at {str(path)!r}")
    info = dict(layer.customLayerData.get("pdsim", {}))
    files = [path]
    if info.get("frames"):
        run_dir = (path.parent / info["frames"]).resolve()
        files += sorted(p for p in run_dir.iterdir() if p.is_file() and not p.name.startswith("."))
    return files


def flatten_cache(path: str | os.PathLike, out: str | os.PathLike) -> None:
    """Write the cache at ``path`` as one self-contained layer at ``out`` (value clips baked into time samples). The
    whole animation is held in memory while flattening: meant for small caches and for sending a cache as one file."""
    from pxr import Usd

    stage = Usd.Stage.Open(os.fspath(path))
    layer = stage.Flatten()
    layer.customLayerData = {}
    if not layer.Export(os.fspath(out)):
        raise OSError(f"USD could not export the flattened cache to {os.fspath(out)!r}")


def read_tet_mesh(path: str, prim_path: str | None):
    """Vertices [m] (float64 [v, 3], world space) and tetrahedra (int64 [t, 4]) of a ``UsdGeom.TetMesh`` in the
    stage at ``path`` (the prim at ``prim_path``, or the first TetMesh); GeometryError when there is none. The USD
    input reader of pdsim.fem.load_tet_mesh (this module holds every use of pxr)."""
    from pxr import Usd, UsdGeom

    from ..errors import GeometryError

    try:
        stage = Usd.Stage.Open(path)
    except Exception as exc:  # noqa: BLE001 (pxr raises Tf errors)
        raise GeometryError(f"{path}: cannot open USD stage ({exc})") from None
    if prim_path is not None:
        prim = stage.GetPrimAtPath(prim_path)
        if not prim or not prim.IsA(UsdGeom.TetMesh):
            raise GeometryError(f"{path}: no UsdGeom.TetMesh at {prim_path}")
    else:
        prim = next((p for p in stage.Traverse() if p.IsA(UsdGeom.TetMesh)), None)
        if prim is None:
            raise GeometryError(f"{path}: the stage holds no UsdGeom.TetMesh")
    tm = UsdGeom.TetMesh(prim)
    time = Usd.TimeCode.Default()
    pts = np.asarray(tm.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    idx = np.asarray(tm.GetTetVertexIndicesAttr().Get(time) or [], dtype=np.int64).reshape(-1, 4)
    xf = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time), dtype=np.float64)
    pts = pts @ xf[:3, :3] + xf[3, :3]  # USD matrices act on row vectors
    return pts, idx


def _identifier(name: str) -> str:
    """A valid USD identifier made of ``name``."""
    from pxr import Tf

    return Tf.MakeValidIdentifier(name)


def validate_usd(path: str | os.PathLike) -> list[str]:
    """Run every validator registered with ``pxr.UsdValidation`` on the stage at ``path``.

    Args:
        path: A USD file.

    Returns:
        One string per validation error of type Error (``"Error: (<validator>.<error>) <message>"``); warnings and
        infos are left out. Empty when the stage is valid.

    Raises:
        RuntimeError: ``pxr.UsdValidation`` is missing (usd-core older than 24.11) or has no validators registered.
        pxr.Tf.ErrorException: The file cannot be opened as a USD stage.
    """
    from pxr import Usd

    try:
        from pxr import UsdValidation
    except ImportError as e:
        raise RuntimeError(
            "validate_usd needs pxr.UsdValidation (usd-core >= 24.11); the installed usd-core does not provide it"
        ) from e
    missing = [
        n for n in ("ValidationRegistry", "ValidationContext", "ValidationErrorType") if not hasattr(UsdValidation, n)
    ]
    if missing:
        raise RuntimeError(f"pxr.UsdValidation lacks {', '.join(missing)}; unsupported usd-core version")

    if not Path(path).is_file():
        raise FileNotFoundError(f"no USD file at {str(path)!r}")
    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    if not validators:
        raise RuntimeError("pxr.UsdValidation has no validators registered (plugins not found)")
    context = UsdValidation.ValidationContext(validators=validators)
    errors = context.Validate(stage)
    error_type = UsdValidation.ValidationErrorType.Error
    return [e.GetErrorAsString() for e in errors if e.GetType() == error_type]
