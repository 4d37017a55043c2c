"""Solid shapes: closed triangle meshes loaded through trimesh, and primitives (box, sphere, cylinder)."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import numpy as np
import trimesh

from .checks import check_range
from .errors import GeometryError, ParameterError

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".glb", ".gltf", ".off")


@dataclass(frozen=True)
class SolidShape:
    """A closed, consistently oriented triangle mesh bounding a solid.

    Attributes:
        vertices: vertex positions [m], shape [vertex_count, 3], float64.
        faces: triangle vertex indices, shape [face_count, 3], int32, outward-facing (counter-clockwise from outside).
        name: label used for the body in output.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "shape"

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
        """Enclosed volume [m^3] (signed-tetrahedron sum; positive for outward-facing triangles)."""
        v = self.vertices[self.faces]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def _shape_from_trimesh(mesh, name: str, source: str) -> SolidShape:
    """Validates a trimesh.Trimesh as a solid: non-empty, watertight, consistently wound, positive volume."""
    if mesh is None or len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise GeometryError(f"{source}: the mesh is empty (no triangles)")
    size = float(np.max(np.ptp(np.asarray(mesh.vertices, dtype=np.float64), axis=0)))
    mesh = mesh.copy()
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        hint = ""
        if np.isfinite(size) and size < 1.0e-5:  # vertices closer than trimesh's merge tolerance (1e-8) merge
            hint = f"; the mesh is {size:.3g} m across: is it in the wrong units? (load_mesh(..., scale=...))"
        raise GeometryError(f"{source}: the mesh is empty (all triangles are degenerate){hint}")
    if not mesh.is_watertight:
        raise GeometryError(
            f"{source}: the mesh is not watertight (it has open or non-manifold edges), so it bounds no solid; "
            "close its holes first (e.g. trimesh.repair.fill_holes or a mesh editor)"
        )
    if not mesh.is_winding_consistent:
        raise GeometryError(f"{source}: the mesh's triangles are not consistently oriented")
    if mesh.volume < 0.0:
        mesh.invert()
    if not mesh.volume > 0.0:
        raise GeometryError(f"{source}: the mesh encloses zero volume")
    return SolidShape(
        vertices=np.asarray(mesh.vertices, dtype=np.float64),
        faces=np.asarray(mesh.faces, dtype=np.int32),
        name=name,
    )


def load_mesh(path: str | os.PathLike, *, scale: float = 1.0, translate=(0.0, 0.0, 0.0), name: str | None = None):
    """Loads a closed surface mesh (OBJ, STL, PLY, GLB/glTF, OFF) as a :class:`SolidShape`.

    Args:
        path: mesh file; multi-object files (GLB scenes) are merged into one mesh.
        scale: uniform scale applied to the vertices [-], > 0.
        translate: offset added after scaling [m].
        name: body label; defaults to the file's stem.
    """
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in MESH_SUFFIXES:
        raise GeometryError(f"{path}: unknown mesh file type '{suffix}'; supported: {', '.join(MESH_SUFFIXES)}")
    if not os.path.isfile(path):
        raise GeometryError(f"{path}: no such file")
    scale = check_range("scale", scale, 0.0, None)
    translate = _vec3("translate", translate)
    if suffix == ".stl":
        _check_stl(path)
    try:
        mesh = _load_trimesh(path, suffix)
    except Exception as exc:  # noqa: BLE001 (trimesh raises many exception types for unreadable files)
        raise GeometryError(f"{path}: cannot read mesh ({exc})") from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise GeometryError(f"{path}: the file holds no triangle mesh")
    if len(mesh.faces) > 0:
        mesh.apply_scale(scale)
        mesh.apply_translation(translate)
    return _shape_from_trimesh(mesh, name or os.path.splitext(os.path.basename(path))[0], path)


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
    """trimesh.load of a mesh file. Text formats (OBJ, OFF) are decoded here: UTF-8, else Latin-1 (every byte
    sequence is valid Latin-1, and the geometry is ASCII), so a comment with one non-UTF-8 byte (a Latin-1 degree
    sign or accent from an older exporter) does not send trimesh to its optional charset detector
    (charset_normalizer, which may not be installed). Other formats go to trimesh as files."""
    if suffix not in TEXT_MESH_SUFFIXES:
        return trimesh.load(path, force="mesh", process=True)
    with open(path, "rb") as f:
        data = f.read()
    try:
        data.decode("utf-8")
    except UnicodeDecodeError:
        data = data.decode("latin-1").encode("utf-8")
    resolver = trimesh.resolvers.FilePathResolver(path)  # material libraries beside an OBJ still load
    return trimesh.load(io.BytesIO(data), file_type=suffix[1:], force="mesh", process=True, resolver=resolver)


def shape_from_arrays(vertices, faces, *, name: str = "mesh") -> SolidShape:
    """Builds a :class:`SolidShape` from vertex [n, 3] and triangle [m, 3] arrays (validated like a loaded file)."""
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
