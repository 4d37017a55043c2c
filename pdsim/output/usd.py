"""USD animation caches: particles as ``UsdGeom.Points`` and surfaces as ``UsdGeom.Mesh``, written frame by frame.

The stage lives in memory (an anonymous layer of the same file format as the target file); saving exports that layer
to a temporary file next to the target and ``os.replace``-s it over the target, so the file at ``path`` is at every
moment either absent or a complete, readable cache of the frames finished so far (also after a crash or Ctrl-C).

Data written by ``write_points``/``write_mesh`` for a frame is held back until ``end_frame`` finishes that frame, so
a saved cache never holds a partly written frame.

Save cost (measured on a 2-core machine without GPU, usd-core 26.11, local disk, points + velocities + one float and
one int primvar per frame): re-exporting the whole ``.usdc`` layer costs time proportional to the frames written so
far (about 0.9 ms per MB of file), so saving after every frame is O(frames^2) in total:

- 20k points x 100 frames (56 MB file): 3.6 s of saves when saving every frame (up to about 60 ms a save), against
  0.3 s to author the samples; with the default interval, one save of 0.06 s.
- 100k points x 240 frames (672 MB file): 79 s of saves when saving every frame (up to about 0.6 s a save), against
  about 2 s to author the samples; one final save takes 0.6 s.
- ``.usda`` is about 25 times slower to export than ``.usdc``; use it for small debugging caches only.

Hence saves are throttled: by default at most one every ``save_interval_s`` = 2 s, and never sooner than ten times
the duration of the previous save after it (so saving stays below about 10 % of the run time however big the cache
grows). ``save_interval_s=0`` saves after every frame regardless of cost.
"""

from __future__ import annotations

import contextlib
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from typing import Self

__all__ = ["MeshHandle", "PointsHandle", "UsdCache", "read_tet_mesh", "validate_usd"]

_SUFFIXES = (".usdc", ".usda", ".usd")
_PRIMVAR_KINDS = ("float", "int", "vector3f")
# Throttle: wait at least this many times the duration of the previous save before saving again (interval > 0 only).
_SAVE_COST_FACTOR = 10.0


@dataclass(eq=False)
class PointsHandle:
    """A ``UsdGeom.Points`` prim of a :class:`UsdCache`; returned by :meth:`UsdCache.add_points`.

    Attributes:
        path: Prim path, e.g. ``/World/particles``.
        point_count: Number of points (fixed for the whole cache).
        primvar_kinds: Declared primvars, ``{name: kind}`` with kind in ``{"float", "int", "vector3f"}``.
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
        path: Prim path, e.g. ``/World/fragments``.
        vertex_count: Number of vertices of the current topology (0 until the first ``write_mesh`` with faces).
    """

    path: str
    vertex_count: int = 0
    face_primvar_kinds: dict[str, str] = field(default_factory=dict)
    _cache: UsdCache | None = field(default=None, repr=False)
    _has_topology: bool = field(default=False, repr=False)


def _value_type(kind: str):
    """The Sdf array value type of a primvar kind ("float", "int", "vector3f")."""
    from pxr import Sdf

    return {
        "float": Sdf.ValueTypeNames.FloatArray,
        "int": Sdf.ValueTypeNames.IntArray,
        "vector3f": Sdf.ValueTypeNames.Vector3fArray,
    }[kind]


def _vt_array(kind: str, values: np.ndarray):
    """A Vt array of a primvar kind from a checked numpy array."""
    from pxr import Vt

    return {"float": Vt.FloatArray, "int": Vt.IntArray, "vector3f": Vt.Vec3fArray}[kind].FromNumpy(values)


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


def _extent(lo: np.ndarray, hi: np.ndarray):
    """Return a ``Vt.Vec3fArray`` extent ``[min, max]`` from two float arrays of shape [3]."""
    from pxr import Gf, Vt

    return Vt.Vec3fArray([Gf.Vec3f(*(float(v) for v in lo)), Gf.Vec3f(*(float(v) for v in hi))])


class UsdCache:
    """Writes a USD animation cache (``.usdc``/``.usda``/``.usd``) frame by frame, crash-safe.

    Typical use::

        with UsdCache("out/cache.usdc", fps=24.0) as cache:
            particles = cache.add_points("particles", widths=radii * 2, primvars={"damage": "float"})
            for frame in range(frame_count):
                ...  # simulate
                cache.write_points(particles, frame, positions, primvars={"damage": damage})
                cache.end_frame(frame)

    Time codes are frame numbers; ``timeCodesPerSecond = framesPerSecond = fps``. Only frames finished with
    :meth:`end_frame` reach the file; leaving the ``with`` block (normally, by an exception or by KeyboardInterrupt)
    saves them.

    Args:
        path: Output file; the extension picks the format (``.usd`` is written as binary crate).
        fps: Frames per second [1/s]; > 0.
        start_frame: First frame (``startTimeCode``); frames before it are rejected.
        up_axis: ``"Y"`` or ``"Z"``.
        meters_per_unit: Length of one stage unit [m]; > 0.
        save_interval_s: Minimum wall-clock time between saves [s]. Saves are also spaced by at least ten times the
            duration of the previous save, so that re-exporting a growing cache stays cheap. 0 saves every frame.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        *,
        fps: float,
        start_frame: int = 0,
        up_axis: str = "Z",
        meters_per_unit: float = 1.0,
        save_interval_s: float = 2.0,
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
        if int(start_frame) != start_frame:
            raise ValueError(f"start_frame={start_frame!r} must be an integer")
        if not self.path.parent.is_dir():
            raise ValueError(f"folder {str(self.path.parent)!r} of the cache does not exist")

        from pxr import Sdf, Usd, UsdGeom

        self.fps = float(fps)
        self.start_frame = int(start_frame)
        self.save_interval_s = float(save_interval_s)
        # Temporary file in the same folder (same file system, so os.replace is atomic) with the same extension, so
        # that Export picks the same file format.
        self._tmp_path = self.path.with_name(f".{self.path.name}.tmp{self.path.suffix}")

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

        self._names: set[str] = set()
        self._pending: dict[int, list[tuple[object, object]]] = {}  # frame -> [(attribute, value)]
        self._last_finished: int | None = None
        self._frames_written = 0
        self._dirty = True  # the in-memory stage differs from the file at path (or there is no file yet)
        self._last_save_end = time.monotonic()
        self._last_save_duration = 0.0
        self._closed = False

    # ------------------------------------------------------------------ properties

    @property
    def frames_written(self) -> int:
        """Number of frames finished with :meth:`end_frame` (saved to disk at the latest by :meth:`close`)."""
        return self._frames_written

    @property
    def stage(self):
        """The in-memory ``Usd.Stage`` (for inspection; author through this class)."""
        return self._stage

    # ------------------------------------------------------------------ prims

    def _define_path(self, name: str) -> str:
        from pxr import Tf

        if not isinstance(name, str) or not name:
            raise ValueError(f"prim name {name!r} must be a non-empty string")
        ident = Tf.MakeValidIdentifier(name)
        if ident in self._names:
            raise ValueError(f"prim name {name!r} (as USD identifier {ident!r}) is already used in this cache")
        self._names.add(ident)
        self._dirty = True
        return f"/World/{ident}"

    def add_points(self, name: str, *, widths: np.ndarray, primvars: dict[str, str] | None = None) -> PointsHandle:
        """Define a ``UsdGeom.Points`` prim at ``/World/<name>``.

        Args:
            name: Prim name; made into a valid USD identifier (``"body 1"`` -> ``"body_1"``).
            widths: Point diameters [stage units], shape [point_count]; written once (not time-sampled).
            primvars: ``{name: kind}`` with kind ``"float"`` (values shape [point_count]), ``"int"`` (shape
                [point_count]) or ``"vector3f"`` (shape [point_count, 3]); vertex interpolation.

        Returns:
            Handle for :meth:`write_points`.
        """
        self._check_open()
        from pxr import Sdf, UsdGeom, Vt

        primvars = dict(primvars or {})
        w = _check_array("widths", widths, shape=(-1,), shape_text="[point_count]")
        if (w < 0).any():
            raise ValueError("widths must be >= 0")
        for pv_name, kind in primvars.items():
            if kind not in _PRIMVAR_KINDS:
                raise ValueError(f"primvar {pv_name!r} has kind {kind!r}; allowed {', '.join(_PRIMVAR_KINDS)}")
            if not (isinstance(pv_name, str) and Sdf.Path.IsValidNamespacedIdentifier(pv_name)):
                raise ValueError(f"primvar name {pv_name!r} is not a valid USD identifier")

        path = self._define_path(name)
        points = UsdGeom.Points.Define(self._stage, path)
        points.CreateWidthsAttr(Vt.FloatArray.FromNumpy(w))
        points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        api = UsdGeom.PrimvarsAPI(points)
        for pv_name, kind in primvars.items():
            api.CreatePrimvar(pv_name, _value_type(kind), UsdGeom.Tokens.vertex)
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
                ``"float"``/``"int"``, [point_count, 3] for ``"vector3f"``. Primvars left out get no sample.

        Raises:
            ValueError: Wrong shape, dtype or non-finite values (the message names the array and the expected shape),
                unknown primvar, or a frame already finished.
        """
        self._check_handle(handle, PointsHandle)
        frame = self._check_frame(frame)
        from pxr import UsdGeom, Vt

        n = handle.point_count
        shape3 = f"[point_count, 3] = [{n}, 3]"
        x = _check_array("positions", positions, shape=(n, 3), shape_text=shape3)
        points = UsdGeom.Points.Get(self._stage, handle.path)
        samples = [(points.GetPointsAttr(), Vt.Vec3fArray.FromNumpy(x))]
        if velocities is not None:
            v = _check_array("velocities", velocities, shape=(n, 3), shape_text=shape3)
            samples.append((points.GetVelocitiesAttr(), Vt.Vec3fArray.FromNumpy(v)))
        api = UsdGeom.PrimvarsAPI(points)
        for pv_name, values in (primvars or {}).items():
            kind = handle.primvar_kinds.get(pv_name)
            if kind is None:
                raise ValueError(
                    f"primvar {pv_name!r} was not declared in add_points (declared: {sorted(handle.primvar_kinds)})"
                )
            label = f"primvar {pv_name!r}"
            if kind == "vector3f":
                a = _check_array(label, values, shape=(n, 3), shape_text=shape3)
            else:
                a = _check_array(label, values, shape=(n,), shape_text=f"[point_count] = [{n}]", kind=kind)
            samples.append((api.GetPrimvar(pv_name).GetAttr(), _vt_array(kind, a)))
        if n:
            r = 0.5 * handle._widths[:, None]
            samples.append((points.GetExtentAttr(), _extent((x - r).min(axis=0), (x + r).max(axis=0))))
        self._pending.setdefault(frame, []).extend(samples)

    def add_mesh(self, name: str, *, face_primvars: dict[str, str] | None = None) -> MeshHandle:
        """Define a triangle ``UsdGeom.Mesh`` (``subdivisionScheme = none``) at ``/World/<name>``.

        Args:
            name: Prim name; made into a valid USD identifier.
            face_primvars: Per-face (uniform) primvars, ``{name: kind}`` with kind in ``{"float", "int", "vector3f"}``;
                written with the topology.

        Returns:
            Handle for :meth:`write_mesh`.
        """
        self._check_open()
        from pxr import UsdGeom

        kinds = dict(face_primvars or {})
        for pv, kind in kinds.items():
            if kind not in _PRIMVAR_KINDS:
                raise ValueError(f"face primvar {pv!r} has kind {kind!r}; allowed: {', '.join(_PRIMVAR_KINDS)}")
        path = self._define_path(name)
        mesh = UsdGeom.Mesh.Define(self._stage, path)
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        api = UsdGeom.PrimvarsAPI(mesh)
        for pv, kind in kinds.items():
            api.CreatePrimvar(pv, _value_type(kind), UsdGeom.Tokens.uniform)
        return MeshHandle(path=path, face_primvar_kinds=kinds, _cache=self)

    def write_mesh(
        self,
        handle: MeshHandle,
        frame: int,
        points: np.ndarray,
        faces: np.ndarray | None = None,
        *,
        face_primvars: dict[str, np.ndarray] | None = None,
    ) -> None:
        """Time-sample mesh vertex positions and extent at ``frame``, and the topology when ``faces`` is given.

        Pass ``faces`` on the first call and on every frame where the topology (or the vertex count) changes; the
        topology of earlier samples holds otherwise.

        Args:
            handle: From :meth:`add_mesh` of this cache.
            frame: Frame number (time code); must be after the last finished frame.
            points: Vertex positions [stage units], shape [vertex_count, 3].
            faces: Triangles as vertex indices, int shape [triangle_count, 3], values in [0, vertex_count).
            face_primvars: Values of declared per-face primvars, shape [triangle_count] (or [triangle_count, 3] for
                vector3f); only together with ``faces``.

        Raises:
            ValueError: Wrong shape or values, a vertex count that changes without new faces, or missing faces on the
                first call.
        """
        self._check_handle(handle, MeshHandle)
        frame = self._check_frame(frame)
        from pxr import UsdGeom, Vt

        x = _check_array("points", points, shape=(-1, 3), shape_text="[vertex_count, 3]")
        nv = int(x.shape[0])
        mesh = UsdGeom.Mesh.Get(self._stage, handle.path)
        samples = [(mesh.GetPointsAttr(), Vt.Vec3fArray.FromNumpy(x))]
        if faces is None:
            if not handle._has_topology:
                raise ValueError(f"write_mesh({handle.path!r}): the first call must pass faces")
            if nv != handle.vertex_count:
                raise ValueError(
                    f"points has shape [{nv}, 3] but the current topology has {handle.vertex_count} vertices; "
                    "pass faces when the vertex count changes"
                )
            if face_primvars:
                raise ValueError("face_primvars are written with the topology: pass faces too")
        else:
            f = _check_array("faces", faces, shape=(-1, 3), shape_text="[triangle_count, 3]", kind="int")
            if f.size and (f.min() < 0 or f.max() >= nv):
                raise ValueError(f"faces has vertex indices outside [0, {nv}) (vertex_count = {nv})")
            samples.append((mesh.GetFaceVertexCountsAttr(), Vt.IntArray.FromNumpy(np.full(f.shape[0], 3, np.int32))))
            samples.append((mesh.GetFaceVertexIndicesAttr(), Vt.IntArray.FromNumpy(f.reshape(-1))))
            handle._has_topology = True
            handle.vertex_count = nv
            api = UsdGeom.PrimvarsAPI(mesh)
            for pv, values in (face_primvars or {}).items():
                kind = handle.face_primvar_kinds.get(pv)
                if kind is None:
                    raise ValueError(f"face primvar {pv!r} was not declared in add_mesh({handle.path!r})")
                shape = (f.shape[0], 3) if kind == "vector3f" else (f.shape[0],)
                a = _check_array(f"face primvar {pv!r}", values, shape=shape, shape_text="[triangle_count]", kind=kind)
                samples.append((api.GetPrimvar(pv).GetAttr(), _vt_array(kind, a)))
        lo, hi = (x.min(axis=0), x.max(axis=0)) if nv else (np.zeros(3), np.zeros(3))
        samples.append((mesh.GetExtentAttr(), _extent(lo, hi)))
        self._pending.setdefault(frame, []).extend(samples)

    def write_vector(self, handle, frame: int, name: str, value) -> None:
        """Time-sample a custom double3 attribute ``pdsim:<name>`` (e.g. ``reaction:grip``, a boundary condition's
        reaction force [N]) on the prim of ``handle`` at ``frame``."""
        self._check_open()
        frame = self._check_frame(frame)
        from pxr import Gf, Sdf

        v = np.asarray(value, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"{name!r}: a vector of 3 finite numbers, got {value!r}")
        prim = self._stage.GetPrimAtPath(handle.path)
        attr_name = "pdsim:" + ":".join(_identifier(part) for part in name.split(":"))
        attr = prim.GetAttribute(attr_name)
        if not attr:
            attr = prim.CreateAttribute(attr_name, Sdf.ValueTypeNames.Double3, custom=True)
        self._pending.setdefault(frame, []).append((attr, Gf.Vec3d(*v.tolist())))

    # ------------------------------------------------------------------ frames and saving

    def end_frame(self, frame: int) -> None:
        """Mark ``frame`` (and any earlier written frames) finished and save if the save interval has passed.

        Sets ``endTimeCode = frame``. Data written for later frames stays pending.

        Args:
            frame: Frame number; must be after the last finished frame.
        """
        frame = self._check_frame(frame)
        for f in sorted(k for k in self._pending if k <= frame):
            for attr, value in self._pending.pop(f):
                attr.Set(value, f)
        self._stage.SetEndTimeCode(frame)
        self._last_finished = frame
        self._dirty = True
        self._frames_written += 1
        if self.save_interval_s == 0:
            self._save()
            return
        wait = max(self.save_interval_s, _SAVE_COST_FACTOR * self._last_save_duration)
        if time.monotonic() - self._last_save_end >= wait:
            self._save()

    def save(self) -> None:
        """Save the finished frames now (atomic replace of the file at ``path``)."""
        self._check_open()
        self._save()

    def _save(self) -> None:
        t0 = time.monotonic()
        tmp = str(self._tmp_path)
        try:
            if not self._layer.Export(tmp):
                raise OSError(f"USD could not export the cache to {tmp!r}")
            os.replace(tmp, self.path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.remove(tmp)
            raise
        self._dirty = False
        self._last_save_end = time.monotonic()
        self._last_save_duration = self._last_save_end - t0

    def close(self) -> None:
        """Save the finished frames and release the stage; frames written but not finished are dropped. Idempotent."""
        if self._closed:
            return
        self._pending.clear()
        try:
            if self._dirty:
                self._save()
        finally:
            self._closed = True
            self._stage = None
            self._layer = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self.close()
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
        if self._last_finished is not None and frame <= self._last_finished:
            raise ValueError(f"frame {frame} is not after the last finished frame {self._last_finished}")
        return frame


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
