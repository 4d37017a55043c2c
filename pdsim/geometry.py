"""Solid shapes: surface meshes loaded through trimesh, repaired and placed in metres, and primitives (box, sphere,
cylinder)."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import numpy as np
import trimesh

from .checks import check_range
from .errors import GeometryError, ParameterError
from .mesh_repair import count_polygons, repair_surface

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")


@dataclass(frozen=True)
class SolidShape:
    """A closed, consistently oriented triangle mesh bounding a solid.

    Attributes:
        vertices: vertex positions [m], shape [vertex_count, 3], float64.
        faces: triangle vertex indices, shape [face_count, 3], int32, outward-facing (counter-clockwise from outside).
        name: label used for the body in output.
        repairs: the line saying what loading repaired ('' when nothing was).
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "shape"
    repairs: str = ""

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounds [[xmin, ymin, zmin], [xmax, ymax, zmax]] [m]."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def extent(self) -> np.ndarray:
        """Size of the axis-aligned bounding box [m], shape [3]."""
        b = self.bounds
        return b[1] - b[0]

    @property
    def volume(self) -> float:
        """Enclosed volume [m^3] (signed-tetrahedron sum about the bounding-box centre, so that it keeps its digits
        far from the origin; positive for outward-facing triangles)."""
        v = (self.vertices - 0.5 * (self.bounds[0] + self.bounds[1]))[self.faces]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def _shape_from_trimesh(mesh, name: str, source: str, triangulated: int = -1) -> SolidShape:
    """A :class:`SolidShape` of a trimesh.Trimesh, repaired into a closed solid by
    :func:`pdsim.mesh_repair.repair_surface` (welding, hole capping, parts); GeometryError when it is empty or
    encloses no volume."""
    if mesh is None or len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise GeometryError(f"{source}: the mesh is empty (no triangles)")
    v = np.asarray(mesh.vertices, dtype=np.float64)
    size = float(np.max(np.ptp(v, axis=0)))
    try:
        vertices, faces, report = repair_surface(v, np.asarray(mesh.faces, dtype=np.int64), source, triangulated)
    except GeometryError as exc:
        if "empty" in str(exc) and np.isfinite(size) and size < 1.0e-5:  # welded to a point at the 1e-8 m floor
            raise GeometryError(
                f"{exc}; the mesh is {size:.3g} m across: is it in the wrong units? (load_mesh(..., scale=...))"
            ) from None
        raise
    return SolidShape(vertices=vertices, faces=faces, name=name, repairs=report.line(name))


UP_AXES = ("Y", "Z")
MIN_MESH_SIZE = 1.0e-7  # a placed mesh smaller than this [m] across is taken for a mesh in the wrong units


def _rotation_matrix(rotation) -> np.ndarray:
    """3x3 rotation of ``rotation``: Euler angles (rx, ry, rz) [degrees] about the world x, then y, then z axis
    (R = Rz Ry Rx), or a 3x3 rotation matrix (orthonormal to 1e-6, determinant +1)."""
    a = np.asarray(rotation, dtype=np.float64)
    allowed = "3 Euler angles in degrees (about x, then y, then z) or a 3x3 rotation matrix"
    if a.shape == (3,) and np.all(np.isfinite(a)):
        cx, cy, cz = np.cos(np.radians(a))
        sx, sy, sz = np.sin(np.radians(a))
        rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]])
        ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
        rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
        return rz @ ry @ rx
    orthonormal = a.shape == (3, 3) and np.all(np.isfinite(a)) and np.abs(a @ a.T - np.eye(3)).max() <= 1.0e-6
    if orthonormal and np.linalg.det(a) > 0.0:
        return a
    raise ParameterError("rotation", a.tolist(), allowed)


def _up_matrix(up_axis: str, world_up: str) -> np.ndarray:
    """Rotation taking a file's up axis to the world's: identity, or +-90 degrees about x (Y-up to Z-up:
    (x, y, z) -> (x, -z, y))."""
    for field, value in (("up_axis", up_axis), ("world_up", world_up)):
        if not isinstance(value, str) or value.upper() not in UP_AXES:
            raise ParameterError(field, value, "'Y' or 'Z'")
    up_axis, world_up = up_axis.upper(), world_up.upper()
    if up_axis == world_up:
        return np.eye(3)
    y_to_z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return y_to_z if up_axis == "Y" else y_to_z.T


def load_mesh(
    path: str | os.PathLike,
    *,
    scale: float | None = None,
    fit_size: float | None = None,
    rotation=None,
    up_axis: str = "Z",
    world_up: str = "Z",
    position=None,
    name: str | None = None,
) -> SolidShape:
    """Loads a surface mesh (OBJ, STL, PLY, GLB/glTF, OFF) as a :class:`SolidShape` placed in metres.

    The mesh is repaired as needed (:mod:`pdsim.mesh_repair`: coincident vertices welded by position, holes capped,
    parts united, parts that cannot be capped rebuilt from their winding number) and one line saying what was
    repaired is printed (also kept as ``shape.repairs``). Quads and n-gons are triangulated on reading. A mesh is
    refused (GeometryError naming the file) only when it encloses no volume.

    The placement, in this order:
        1. ``up_axis`` ('Y' or 'Z', default 'Z'): the file's up axis, turned onto ``world_up`` ('Y' or 'Z', the
           scene's up axis, default 'Z'): a Y-up file (glTF, most OBJ exports) in a Z-up scene takes
           (x, y, z) -> (x, -z, y).
        2. ``rotation``: Euler angles (rx, ry, rz) [degrees] about the world x, then y, then z axis, or a 3x3
           rotation matrix; about the file's origin.
        3. ``scale`` [-] (> 0: file units to metres, e.g. 0.01 for centimetres) or ``fit_size`` [m] (> 0: the
           largest bounding-box extent after steps 1-2 becomes ``fit_size``); at most one of the two. Neither: 1.
        4. ``position`` [m]: where the centre of the bounding box's bottom face (lowest along ``world_up``) goes, so
           that ``position=(0, 0, 0)`` stands the object on a ground at height 0, centred over the origin. None:
           the file's coordinates are kept (after steps 1-3, about the file's origin).

    Args:
        path: mesh file; multi-object files (GLB scenes) are merged into one mesh.
        name: body label; defaults to the file's stem.
    """
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in MESH_SUFFIXES:
        raise GeometryError(f"{path}: unknown mesh file type '{suffix}'; supported: {', '.join(MESH_SUFFIXES)}")
    if not os.path.isfile(path):
        raise GeometryError(f"{path}: no such file")
    if scale is not None and fit_size is not None:
        raise ParameterError("fit_size", fit_size, "None when scale is given (scale and fit_size both set the size)")
    scale = 1.0 if scale is None else check_range("scale", scale, 0.0, None)
    fit_size = None if fit_size is None else check_range("fit_size", fit_size, 0.0, None)
    turn = _up_matrix(up_axis, world_up)
    if rotation is not None:
        turn = _rotation_matrix(rotation) @ turn
    position = None if position is None else _vec3("position", position)
    if suffix == ".stl":
        _check_stl(path)
    try:
        mesh, triangulated = _load_trimesh(path, suffix)
    except Exception as exc:  # noqa: BLE001 (trimesh raises many exception types for unreadable files)
        raise GeometryError(f"{path}: cannot read mesh ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise GeometryError(f"{path}: the file holds no triangle mesh")
    name = name or os.path.splitext(os.path.basename(path))[0]
    shape = _shape_from_trimesh(mesh, name, path, triangulated)
    v = shape.vertices @ turn.T
    if fit_size is not None:
        scale = fit_size / float(np.ptp(v, axis=0).max())
    v = v * scale
    if position is not None:
        up = np.eye(3)[2 if world_up.upper() == "Z" else 1]
        lo, hi = v.min(axis=0), v.max(axis=0)
        bottom = 0.5 * (lo + hi) - ((0.5 * (lo + hi) - lo) @ up) * up
        v = v + (position - bottom)
    size = float(np.ptp(v, axis=0).max())
    if not size >= MIN_MESH_SIZE:
        raise GeometryError(
            f"{path}: the placed mesh is {size:.3g} m across (under {MIN_MESH_SIZE:g} m): is it in the wrong units? "
            "(load_mesh(..., scale=...) turns file units into metres; fit_size=... sets the size in metres)"
        )
    if shape.repairs:
        print(shape.repairs)
    return SolidShape(vertices=v, faces=shape.faces, name=name, repairs=shape.repairs)


def _check_stl(path: str) -> None:
    """GeometryError unless ``path`` holds an STL: a binary STL (an 80-byte header, a triangle count N, then exactly
    50 bytes per triangle: 84 + 50 N bytes) or ASCII STL text ('solid' ... 'facet normal' ... 'endsolid'). An OBJ or
    OFF file named .stl is named as such."""
    with open(path, "rb") as f:
        data = f.read()
    if len(data) >= 84 and len(data) == 84 + 50 * int.from_bytes(data[80:84], "little"):
        return  # binary STL
    text = data[:65536].decode("latin-1")
    if text.lstrip().startswith("solid") and ("facet" in text or "endsolid" in text):
        return  # ASCII STL
    lines = [ln.split(None, 1)[0] for ln in text.splitlines() if ln.strip()]
    if lines and any(w == "v" for w in lines) and any(w == "f" for w in lines):
        raise GeometryError(f"{path}: the file holds OBJ text ('v' and 'f' lines), not STL; rename it to .obj")
    if lines and lines[0] == "OFF":
        raise GeometryError(f"{path}: the file holds OFF text, not STL; rename it to .off")
    raise GeometryError(
        f"{path}: not a readable STL file ({len(data)} bytes): neither ASCII STL text ('solid' ... 'endsolid') nor a "
        "binary STL (84 + 50 x N bytes for N triangles); export it again as STL"
    )


TEXT_MESH_SUFFIXES = (".obj", ".off")  # always text: read here, so that their encoding never matters to trimesh


def _load_trimesh(path: str, suffix: str):
    """(trimesh.load of a mesh file, polygons of more than 3 corners it triangulated (counted in OBJ and OFF text;
    -1 for the other formats)). Vertices are not merged here (the repair welds them by position). Text formats (OBJ,
    OFF) are decoded here: UTF-8, else Latin-1 (every byte sequence is valid Latin-1, and the geometry is ASCII), so
    a comment with one non-UTF-8 byte (a Latin-1 degree sign or accent from an older exporter) does not send trimesh
    to its optional charset detector (charset_normalizer, which may not be installed). Other formats go to trimesh
    as files."""
    if suffix not in TEXT_MESH_SUFFIXES:
        return trimesh.load(path, force="mesh", process=False), -1
    with open(path, "rb") as f:
        data = f.read()
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
        data = text.encode("utf-8")
    resolver = trimesh.resolvers.FilePathResolver(path)  # material libraries beside an OBJ still load
    mesh = trimesh.load(io.BytesIO(data), file_type=suffix[1:], force="mesh", process=False, resolver=resolver)
    return mesh, count_polygons(text)


def shape_from_arrays(vertices, faces, *, name: str = "mesh") -> SolidShape:
    """Builds a :class:`SolidShape` from vertex [n, 3] [m] and triangle [m, 3] arrays (repaired like a loaded file;
    the repair line is kept as ``shape.repairs``, not printed)."""
    try:
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        f_raw = np.asarray(faces, dtype=np.float64).reshape(-1, 3)
        f = f_raw.astype(np.int64)
    except (TypeError, ValueError):
        raise GeometryError(
            f"{name}: vertices must be an [n, 3] array of numbers and faces an [m, 3] array of vertex indices"
        ) from None
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{name}: the vertices contain non-finite values (NaN or inf)")
    if f.size and (not np.array_equal(f, f_raw) or f.min() < 0 or f.max() >= len(v)):
        raise GeometryError(f"{name}: faces must hold integer vertex indices in [0, {len(v)})")
    return _shape_from_trimesh(trimesh.Trimesh(vertices=v, faces=f, process=False), name, name)


def _vec3(field: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError(field, value, "a sequence of 3 finite numbers")
    return a


def box(size, *, center=(0.0, 0.0, 0.0), name: str = "box") -> SolidShape:
    """An axis-aligned box with edge lengths ``size`` [m] (each > 0) centred at ``center`` [m]."""
    s = _vec3("size", size)
    if np.any(s <= 0.0):
        raise ParameterError("size", tuple(size), "three edge lengths > 0")
    m = trimesh.creation.box(extents=s)
    m.apply_translation(_vec3("center", center))
    return _shape_from_trimesh(m, name, name)


def sphere(radius: float, *, center=(0.0, 0.0, 0.0), subdivisions: int = 4, name: str = "sphere") -> SolidShape:
    """A sphere of ``radius`` [m] (> 0), an icosphere with ``subdivisions`` levels (1..7)."""
    r = check_range("radius", radius, 0.0, None)
    if int(subdivisions) != subdivisions or not 1 <= subdivisions <= 7:
        raise ParameterError("subdivisions", subdivisions, "an integer in [1, 7]")
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=r)
    m.apply_translation(_vec3("center", center))
    return _shape_from_trimesh(m, name, name)


def cylinder(
    radius: float, height: float, *, center=(0.0, 0.0, 0.0), axis: str = "z", sections: int = 64, name="cylinder"
) -> SolidShape:
    """A cylinder of ``radius`` and ``height`` [m] (both > 0) along ``axis`` ('x', 'y' or 'z')."""
    r = check_range("radius", radius, 0.0, None)
    h = check_range("height", height, 0.0, None)
    if axis not in ("x", "y", "z"):
        raise ParameterError("axis", axis, "'x', 'y' or 'z'")
    if int(sections) != sections or sections < 8:
        raise ParameterError("sections", sections, "an integer >= 8")
    m = trimesh.creation.cylinder(radius=r, height=h, sections=int(sections))
    if axis == "x":
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    elif axis == "y":
        m.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    m.apply_translation(_vec3("center", center))
    return _shape_from_trimesh(m, name, name)
