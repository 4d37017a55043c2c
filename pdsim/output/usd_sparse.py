"""The prims of a USD cache whose element count changes from frame to frame: the Points of crack events and the
point instancer of debris (docs/cache_format.md). :class:`SparsePrims` is a part of
:class:`pdsim.output.usd.UsdCache`; its samples go through the cache's frame layers like every other."""

from __future__ import annotations

import numpy as np
from pxr import UsdGeom

from .usd_layout import InstancerHandle, SparsePointsHandle, define_instancer, define_origin, define_sparse_points
from .usd_values import check_primvar_kinds, instancer_samples, sparse_points_samples


def _relative(positions, origin):
    """float64 ``positions`` [n, 3] relative to ``origin`` (float64 [3]), or as given when it is None."""
    return positions if origin is None else np.asarray(positions, dtype=np.float64).reshape(-1, 3) - origin


class SparsePrims:
    """UsdCache's prims of a per-frame count (see the module docstring)."""

    def add_sparse_points(
        self, name: str, *, primvars: dict[str, str] | None = None, origin=None, purpose: str | None = None
    ):
        """Define a ``UsdGeom.Points`` prim at ``/World/<name>`` whose point count changes from frame to frame (crack
        events): points, widths, normals and the vertex primvars ``{name: kind}`` are time-sampled by
        :meth:`write_sparse_points`. ``origin``: its static double-precision ``xformOp:translate`` [stage units];
        ``purpose``: ``"guide"`` (left out of renders), ``"render"``, ``"proxy"`` or None (``default``)."""
        self._check_open()
        primvars = dict(primvars or {})
        check_primvar_kinds(primvars, "primvar")
        if purpose not in (None, "guide", "render", "proxy"):
            raise ValueError(f"purpose={purpose!r} must be 'guide', 'render', 'proxy' or None")
        path = self._define_path(name)
        define_sparse_points(self._stage, path, primvars, self._types)
        if purpose is not None:
            UsdGeom.Imageable(self._stage.GetPrimAtPath(path)).CreatePurposeAttr(purpose)
        o = None if origin is None else define_origin(self._stage, path, origin)
        return SparsePointsHandle(path=path, primvar_kinds=primvars, _cache=self, origin=o)

    def write_sparse_points(self, handle, frame: int, positions, *, widths, normals, primvars=None) -> None:
        """Time-sample the points of a :meth:`add_sparse_points` prim at ``frame``: ``positions`` [stage units]
        (float64 [n, 3], any n >= 0, stored relative to the handle's origin), ``widths`` [stage units] [n], unit
        ``normals`` [n, 3] and every declared primvar ({name: [n] or [n, 3]})."""
        self._check_handle(handle, SparsePointsHandle)
        layer = self._frame_layer(frame).samples
        x = _relative(positions, handle.origin)
        for attr, kind, value in sparse_points_samples(handle, x, widths, normals, primvars):
            self._sample(layer, "default", handle.path, attr, kind, value)

    def add_instancer(self, name: str, prototype_points, prototype_faces, *, material: str | None = None, origin=None):
        """Define a ``UsdGeom.PointInstancer`` at ``/World/<name>`` with one prototype, the static triangle mesh
        ``prototype_points`` [stage units] (float [v, 3]) / ``prototype_faces`` (int [f, 3]) at
        ``/World/<name>/prototypes/chunk``, bound to ``material`` (a path from :meth:`add_material`) when given; the
        instances are time-sampled by :meth:`write_instancer`. ``origin``: its static ``xformOp:translate``."""
        self._check_open()
        path = self._define_path(name)
        self._names[path] = {"prototypes"}
        self._names[f"{path}/prototypes"] = {"chunk"}
        proto = define_instancer(self._stage, path, prototype_points, prototype_faces)
        if material is not None:
            self.bind_material(proto, material)
        o = None if origin is None else define_origin(self._stage, path, origin)
        return InstancerHandle(path=path, _cache=self, origin=o)

    def write_instancer(self, handle, frame: int, positions, *, velocities, orientations, scales, ids) -> None:
        """Time-sample the instances of a :meth:`add_instancer` prim at ``frame`` (any count n >= 0, all of the
        prototype): ``positions`` [stage units] (float64 [n, 3], stored relative to the origin), ``velocities``
        [stage units/s] [n, 3], ``orientations`` unit quaternions (x, y, z, w) [n, 4] (stored as half-precision
        ``quath``), uniform ``scales`` [n] (the prototype's factor) and stable integer ``ids`` [n]."""
        self._check_handle(handle, InstancerHandle)
        layer = self._frame_layer(frame).samples
        x = _relative(positions, handle.origin)
        for attr, kind, value in instancer_samples(x, velocities, orientations, scales, ids):
            self._sample(layer, "default", handle.path, attr, kind, value)
