"""Writes method-neutral views (pdsim/output/views.py) into a USD cache (pdsim/output/usd.py), frame by frame.

The first views of a name declare its prim: ``UsdGeom.Points`` at ``/World/<body>`` for a PointsView, a
``UsdGeom.Mesh`` at ``/World/<name>`` for a MeshView, with the primvars of the attributes it carries. A mesh's
topology and face attributes are written on its first frame and on every frame whose topology version changed.
"""

from __future__ import annotations

import numpy as np

from .views import MeshView, PointsView, attribute_kind


class ViewWriter:
    """Turns each frame's views into time samples of ``cache`` (a UsdCache)."""

    def __init__(self, cache):
        self.cache = cache
        self._points = {}  # name -> PointsHandle
        self._meshes = {}  # name -> (MeshHandle, last written topology version)

    def write(self, frame: int, views) -> None:
        for view in views:
            if isinstance(view, PointsView):
                self._write_points(frame, view)
            elif isinstance(view, MeshView):
                self._write_mesh(frame, view)
            else:
                raise TypeError(f"not an output view: {view!r}")

    def _write_points(self, frame: int, view: PointsView) -> None:
        handle = self._points.get(view.name)
        if handle is None:
            kinds = {k: attribute_kind(k) for k in view.attributes}
            widths = np.broadcast_to(np.asarray(view.widths, dtype=np.float32), (len(view.positions),))
            handle = self.cache.add_points(view.name, widths=np.ascontiguousarray(widths), primvars=kinds)
            self._points[view.name] = handle
        values = {}
        for k, a in view.attributes.items():
            kind = handle.primvar_kinds[k]
            values[k] = np.asarray(a, dtype=np.int32 if kind == "int" else np.float32)
        self.cache.write_points(
            handle,
            frame,
            np.asarray(view.positions, dtype=np.float32),
            velocities=None if view.velocities is None else np.asarray(view.velocities, dtype=np.float32),
            primvars=values,
        )
        for name, force in view.reactions.items():
            self.cache.write_vector(handle, frame, f"reaction:{name}", force)

    def _write_mesh(self, frame: int, view: MeshView) -> None:
        entry = self._meshes.get(view.name)
        if entry is None:
            kinds = {k: attribute_kind(k) for k in view.face_attributes}
            entry = [self.cache.add_mesh(view.name, face_primvars=kinds), None]
            self._meshes[view.name] = entry
        handle, version = entry
        points = np.asarray(view.points, dtype=np.float32)
        if version != view.topology_version:
            prim = {
                k: np.asarray(a, dtype=np.int32 if handle.face_primvar_kinds[k] == "int" else np.float32)
                for k, a in view.face_attributes.items()
            }
            self.cache.write_mesh(handle, frame, points, np.asarray(view.faces), face_primvars=prim)
            entry[1] = view.topology_version
        else:
            self.cache.write_mesh(handle, frame, points)


__all__ = ["ViewWriter"]
