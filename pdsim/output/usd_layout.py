"""The prims of a USD cache: the handles :class:`pdsim.output.usd.UsdCache` returns for them, the stage metadata and
``/World``, the definitions of Points and Mesh prims and of placeholder materials, and the handles of the prims of a
reopened cache."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

from .usd_values import PRIMVAR_KINDS


@dataclass(eq=False)
class XformHandle:
    """A ``UsdGeom.Xform`` prim that groups other prims (``/World/colliders``, the fragment prims of a surface)."""

    path: str
    _cache: object = field(default=None, repr=False)  # the UsdCache that made it


@dataclass(eq=False)
class PointsHandle:
    """A ``UsdGeom.Points`` prim of a :class:`UsdCache`; returned by :meth:`UsdCache.add_points`.

    Attributes:
        path: Prim path, e.g. ``/World/particles``.
        point_count: Number of points (fixed for the whole cache).
        primvar_kinds: Declared primvars, ``{name: kind}`` with kind in ``{"float", "int", "vector3f", "color3f"}``.
        origin: The prim's static ``xformOp:translate`` [stage units] (float64 [3]) the points are written relative
            to, or None (points in world space).
    """

    path: str
    point_count: int
    primvar_kinds: dict[str, str]
    _cache: object = field(repr=False)  # the UsdCache that made it
    _widths: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, np.float32))
    origin: np.ndarray | None = None


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
        origin: The prim's static ``xformOp:translate`` [stage units] (float64 [3]) the vertices are written relative
            to, or None.
    """

    path: str
    vertex_count: int = 0
    face_primvar_kinds: dict[str, str] = field(default_factory=dict)
    vertex_primvar_kinds: dict[str, str] = field(default_factory=dict)
    normals: str | None = None
    subsets: tuple[str, ...] = ()
    _cache: object = field(default=None, repr=False)  # the UsdCache that made it
    topology_set: str = ""  # name of the value-clip set that holds its topology
    _has_topology: bool = field(default=False, repr=False)
    _face_count: int = field(default=0, repr=False)
    _transform: bool = field(default=False, repr=False)  # xformOps declared (animated transform)
    origin: np.ndarray | None = None


@dataclass(eq=False)
class SparsePointsHandle:
    """A ``UsdGeom.Points`` prim whose point count changes from frame to frame (crack events); returned by
    :meth:`UsdCache.add_sparse_points`. ``primvar_kinds``: its vertex primvars ``{name: kind}``; ``origin``: its
    static ``xformOp:translate`` [stage units] (float64 [3])."""

    path: str
    primvar_kinds: dict[str, str]
    _cache: object = field(repr=False)
    origin: np.ndarray | None = None


@dataclass(eq=False)
class InstancerHandle:
    """A ``UsdGeom.PointInstancer`` with one prototype (debris); returned by :meth:`UsdCache.add_instancer`.
    ``origin``: its static ``xformOp:translate`` [stage units] (float64 [3])."""

    path: str
    _cache: object = field(repr=False)
    origin: np.ndarray | None = None


def define_sparse_points(stage: Usd.Stage, path: str, primvars: dict, types: dict) -> None:
    """A ``UsdGeom.Points`` prim at ``path`` whose points, widths, normals and vertex primvars ``{name: kind}`` are all
    time-sampled (their count changes from frame to frame)."""
    points = UsdGeom.Points.Define(stage, path)
    for create in (points.CreatePointsAttr, points.CreateExtentAttr, points.CreateWidthsAttr, points.CreateNormalsAttr):
        create()
    points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    points.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    api = UsdGeom.PrimvarsAPI(points)
    for pv_name, kind in primvars.items():
        api.CreatePrimvar(pv_name, types[kind], UsdGeom.Tokens.vertex)


def define_instancer(stage: Usd.Stage, path: str, prototype_points: np.ndarray, prototype_faces: np.ndarray):
    """A ``UsdGeom.PointInstancer`` at ``path`` with the one prototype ``<path>/prototypes/chunk`` (a static triangle
    mesh of ``prototype_points`` [stage units], float [v, 3], and ``prototype_faces``, int [f, 3]); its per-instance
    attributes (positions, velocities, orientations, scales, protoIndices, ids) are declared for time samples.
    Returns the prototype's path."""
    instancer = UsdGeom.PointInstancer.Define(stage, path)
    for create in (
        instancer.CreatePositionsAttr,
        instancer.CreateVelocitiesAttr,
        instancer.CreateOrientationsAttr,
        instancer.CreateScalesAttr,
        instancer.CreateProtoIndicesAttr,
        instancer.CreateIdsAttr,
        instancer.CreateExtentAttr,
    ):
        create()
    UsdGeom.Scope.Define(stage, f"{path}/prototypes")
    proto = f"{path}/prototypes/chunk"
    mesh = UsdGeom.Mesh.Define(stage, proto)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    pts = np.ascontiguousarray(prototype_points, dtype=np.float32)
    faces = np.ascontiguousarray(prototype_faces, dtype=np.int32)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pts))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.reshape(-1)))
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*pts.min(axis=0).tolist()), Gf.Vec3f(*pts.max(axis=0).tolist())]))
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path(proto)])
    return proto


def define_origin(stage: Usd.Stage, path: str, origin) -> np.ndarray:
    """Give the prim at ``path`` a static double-precision ``xformOp:translate`` of ``origin`` [stage units] (3 finite
    numbers); returns it as float64 [3]. Points written relative to it keep float32's relative precision around the
    body instead of around the world origin (a body at 1e6 m keeps sub-millimetre positions)."""
    o = np.asarray(origin, dtype=np.float64)
    if o.shape != (3,) or not np.isfinite(o).all():
        raise ValueError(f"origin={origin!r} must be 3 finite numbers")
    op = UsdGeom.Xformable(stage.GetPrimAtPath(path)).AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
    op.Set(Gf.Vec3d(*o.tolist()))
    return o


def _static_origin(spec) -> np.ndarray | None:
    """The static ``xformOp:translate`` of a prim spec without an animated pose (no ``xformOp:orient``), or None."""
    if spec is None or "xformOp:translate" not in spec.attributes or "xformOp:orient" in spec.attributes:
        return None
    value = spec.attributes["xformOp:translate"].default
    return None if value is None else np.array(value, dtype=np.float64)


def _sampled_widths(spec) -> bool:
    """Whether the Points prim spec has no default ``widths`` (they are time-sampled: a SparsePointsHandle's)."""
    return spec is None or "widths" not in spec.attributes or spec.attributes["widths"].default is None


def default_topology_set(path: str) -> str:
    """The value-clip set of its own that holds the topology of the mesh at ``path``: ``topology_<path under /World>``
    with ``/`` as ``_``."""
    return "topology_" + path[len("/World/") :].replace("/", "_")


def define_world(stage: Usd.Stage, fps: float, start_frame: int, up_axis: str, meters_per_unit: float) -> None:
    """Stage metadata (time codes per second and frames per second ``fps``, start and end at ``start_frame``, up axis,
    metres per unit) and the default prim ``/World`` (an Xform) with its ``pdsim:time`` attribute."""
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(start_frame)
    stage.SetEndTimeCode(start_frame)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    time_attr = world.GetPrim().CreateAttribute("pdsim:time", Sdf.ValueTypeNames.Double, custom=True)
    time_attr.SetDocumentation("simulated time of the frame [s]")


def define_points(stage: Usd.Stage, path: str, widths: np.ndarray, primvars: dict, types: dict) -> None:
    """A ``UsdGeom.Points`` prim at ``path`` with its (static) ``widths`` and vertex primvars ``{name: kind}``."""
    points = UsdGeom.Points.Define(stage, path)
    points.CreatePointsAttr()
    points.CreateVelocitiesAttr()
    points.CreateExtentAttr()
    points.CreateWidthsAttr(Vt.FloatArray.FromNumpy(widths))
    points.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    api = UsdGeom.PrimvarsAPI(points)
    for pv_name, kind in primvars.items():
        api.CreatePrimvar(pv_name, types[kind], UsdGeom.Tokens.vertex)


def define_mesh(stage: Usd.Stage, path: str, fkinds: dict, vkinds: dict, normals: str | None, types: dict):
    """A triangle ``UsdGeom.Mesh`` (``subdivisionScheme = none``) at ``path`` with its geometry attributes, normals of
    interpolation ``normals`` (None: no normals), per-face primvars ``fkinds`` and per-vertex ones ``vkinds``; returns
    the ``UsdGeom.Mesh``."""
    mesh = UsdGeom.Mesh.Define(stage, path)
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
        api.CreatePrimvar(pv, types[kind], UsdGeom.Tokens.uniform)
    for pv, kind in vkinds.items():
        api.CreatePrimvar(pv, types[kind], UsdGeom.Tokens.vertex)
    return mesh


def define_face_subset(stage: Usd.Stage, path: str) -> None:
    """A ``UsdGeom.Subset`` of faces at ``path`` (family ``materialBind``; its indices are written with the
    topology)."""
    subset = UsdGeom.Subset.Define(stage, path)
    subset.CreateElementTypeAttr(UsdGeom.Tokens.face)
    subset.CreateFamilyNameAttr("materialBind")
    subset.CreateIndicesAttr()


def define_material(stage: Usd.Stage, path: str, color: np.ndarray) -> None:
    """A ``UsdShade.Material`` at ``path`` whose ``UsdPreviewSurface`` has the diffuse ``color`` (linear RGB, float
    [3]) and roughness 0.6."""
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color.tolist()))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")


def reopened_handles(cache, stream, frame: int) -> dict:
    """``{prim path: handle}`` for the Points, Mesh and Xform prims of the stage of a reopened ``cache``, with the
    vertex and face counts of their geometry at ``frame`` (read from the frame and topology layers of ``stream``). A
    mesh without topology clips gets its own, empty, manifest; a static mesh (``set_mesh``) none."""
    handles = {}
    kinds = {str(t): k for k, t in cache._types.items() if k in PRIMVAR_KINDS}
    samples = Sdf.Layer.OpenAsAnonymous(str(stream.frame_file(frame)))
    topologies = {}  # clip set -> (layer of its last clip up to ``frame``, the clip's frame)
    for clip_set, frames in stream.topology_frames.items():
        layer = Sdf.Layer.OpenAsAnonymous(str(stream.topology_file(clip_set, frames[-1])))
        topologies[clip_set] = (layer, frames[-1])
    mesh_set = {}
    for clip_set, manifest in stream.manifests.items():
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

    for prim in cache._stage.Traverse():
        path = str(prim.GetPath())
        spec = cache._layer.GetPrimAtPath(path)
        if prim.IsA(UsdGeom.PointInstancer):
            handles[path] = InstancerHandle(path=path, _cache=cache, origin=_static_origin(spec))
        elif prim.IsA(UsdGeom.Points) and _sampled_widths(spec):
            handles[path] = SparsePointsHandle(
                path=path,
                primvar_kinds=primvars(prim, UsdGeom.Tokens.vertex),
                _cache=cache,
                origin=_static_origin(spec),
            )
        elif prim.IsA(UsdGeom.Points):
            w = np.asarray(UsdGeom.Points(prim).GetWidthsAttr().Get() or [], dtype=np.float32)
            handles[path] = PointsHandle(
                path=path,
                point_count=int(w.shape[0]),
                primvar_kinds=primvars(prim, UsdGeom.Tokens.vertex),
                _cache=cache,
                _widths=w,
                origin=_static_origin(cache._layer.GetPrimAtPath(path)),
            )
        elif prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            spec = cache._layer.GetPrimAtPath(path)
            handle = MeshHandle(
                path=path,
                face_primvar_kinds=primvars(prim, UsdGeom.Tokens.uniform),
                vertex_primvar_kinds=primvars(prim, UsdGeom.Tokens.vertex),
                normals=str(mesh.GetNormalsInterpolation()) if "normals" in spec.attributes else None,
                subsets=tuple(c.GetName() for c in prim.GetChildren() if c.IsA(UsdGeom.Subset)),
                _cache=cache,
                _transform="xformOp:orient" in spec.attributes,
                origin=_static_origin(spec),
            )
            clip_set = mesh_set.get(path)
            if clip_set is not None:
                handle.topology_set = clip_set
                handle._has_topology = clip_set in stream.topology_frames
                handle.vertex_count = sample_length(samples, frame, path, "points")
                handle._face_count = sample_length(*topologies.get(clip_set, (None, 0)), path, "faceVertexCounts")
            else:
                handle.topology_set = default_topology_set(path)
                counts = mesh.GetFaceVertexCountsAttr().Get()
                if counts is not None:  # a static mesh (set_mesh)
                    handle._has_topology = True
                    handle._face_count = len(counts)
                    handle.vertex_count = len(mesh.GetPointsAttr().Get() or [])
                    stream.manifests.pop(handle.topology_set, None)
                else:
                    stream.manifests.setdefault(handle.topology_set, {})
            handles[path] = handle
        elif prim.IsA(UsdGeom.Xform):
            handles[path] = XformHandle(path=path, _cache=cache)
    return handles
