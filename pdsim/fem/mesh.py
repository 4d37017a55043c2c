"""Tetrahedral meshes for the FEM solid: meshing a closed surface (fTetWild through pytetwild), loading ready meshes
(meshio formats such as Gmsh .msh and VTK .vtk/.vtu, or a ``UsdGeom.TetMesh``), structured box meshes, and the checks
every mesh passes on its way in (orientation fixed, degenerate and inverted elements rejected).

All topology work here is vectorised numpy (sorting face keys), never a Python loop over elements.

Orientation and quality on load (:func:`tet_mesh_from_arrays`):

- indices must be integers in range, four distinct vertices per element; unreferenced vertices are dropped;
- an element whose quality q = 6 sqrt(2) |V| / l_rms^3 (1 for a regular tetrahedron, 0 for a flat one; l_rms the root
  mean square of its six edge lengths) is below ``min_quality`` is degenerate (zero or near-zero volume): error;
- every interior face must be shared by exactly two elements whose fourth vertices lie on opposite sides of it; two
  on the same side means an element is inverted (folded over its neighbour): error. Three or more elements on one face
  is a non-manifold mesh: error;
- elements with negative signed volume det(Dm) / 6 are then re-oriented (two corners swapped), so that a mesh written
  with either winding convention loads the same.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import GeometryError, ParameterError
from ..geometry import SolidShape
from ..validate import check_range

TET_MESH_SUFFIXES = (".msh", ".vtk", ".vtu", ".mesh", ".inp", ".xdmf", ".med", ".usd", ".usda", ".usdc")
DEFAULT_MIN_QUALITY = 1.0e-3

# Outward faces of a positively oriented tetrahedron (det[X1-X0, X2-X0, X3-X0] > 0); face k is opposite corner 3 - k
# for the first three and opposite corner 0 for the last: (0,2,1) opp 3, (0,1,3) opp 2, (0,3,2) opp 1, (1,2,3) opp 0.
TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
TET_FACE_OPPOSITE = np.array([3, 2, 1, 0], dtype=np.int64)
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]], dtype=np.int64)


@dataclass(frozen=True)
class TetMesh:
    """A valid, positively oriented tetrahedral mesh.

    Attributes:
        vertices: rest positions [m], shape [vertex_count, 3], float64.
        tets: element corner indices, shape [element_count, 4], int32, det[X1-X0, X2-X0, X3-X0] > 0.
        name: label used for the body in output.
    """

    vertices: np.ndarray
    tets: np.ndarray
    name: str = "tet_mesh"

    @property
    def vertex_count(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def element_count(self) -> int:
        return int(self.tets.shape[0])

    @property
    def volumes(self) -> np.ndarray:
        """Element volumes [m^3], shape [element_count]."""
        return signed_volumes(self.vertices, self.tets)

    @property
    def volume(self) -> float:
        """Total volume [m^3]."""
        return float(self.volumes.sum())

    @property
    def quality(self) -> np.ndarray:
        """Per-element quality 6 sqrt(2) V / l_rms^3 in (0, 1] (1: regular tetrahedron), shape [element_count]."""
        return element_quality(self.vertices, self.tets)

    @property
    def element_heights(self) -> np.ndarray:
        """Smallest height of each element, 3 V / (largest face area) [m], shape [element_count]."""
        return element_heights(self.vertices, self.tets)

    def boundary_faces(self) -> np.ndarray:
        """Outward-oriented boundary triangles (faces used by one element), shape [face_count, 3], int32."""
        return boundary_faces(self.tets)

    def transformed(self, *, scale: float = 1.0, translate=(0.0, 0.0, 0.0)) -> TetMesh:
        """A copy scaled by ``scale`` (> 0) and then translated by ``translate`` [m]."""
        s = check_range("scale", scale, 0.0, None)
        t = np.asarray(translate, dtype=np.float64)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ParameterError("translate", translate, "a sequence of 3 finite numbers [m]")
        return TetMesh(vertices=self.vertices * s + t, tets=self.tets.copy(), name=self.name)


def signed_volumes(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """det[X1-X0, X2-X0, X3-X0] / 6 per element [m^3]."""
    x = vertices[tets]
    d1, d2, d3 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]
    return np.einsum("ij,ij->i", d1, np.cross(d2, d3)) / 6.0


def element_quality(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed quality 6 sqrt(2) V / l_rms^3 (1 for a regular tetrahedron) per element."""
    x = vertices[tets]
    e = x[:, TET_EDGES[:, 1]] - x[:, TET_EDGES[:, 0]]
    l_rms = np.sqrt(np.einsum("ijk,ijk->i", e, e) / 6.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = 6.0 * math.sqrt(2.0) * signed_volumes(vertices, tets) / l_rms**3
    return np.nan_to_num(q, nan=0.0)


def element_heights(vertices: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """3 |V| / (largest face area) per element [m]: the smallest distance of a corner from its opposite face."""
    x = vertices[tets]
    f = x[:, TET_FACES]  # [m, 4, 3, 3]
    areas = 0.5 * np.linalg.norm(np.cross(f[:, :, 1] - f[:, :, 0], f[:, :, 2] - f[:, :, 0]), axis=2)
    return 3.0 * np.abs(signed_volumes(vertices, tets)) / areas.max(axis=1)


def _face_keys(tets: np.ndarray):
    """Faces of all elements, as (sorted vertex triples [4m, 3], element [4m], local face [4m])."""
    m = tets.shape[0]
    faces = tets[:, TET_FACES].reshape(-1, 3).astype(np.int64)
    return np.sort(faces, axis=1), np.repeat(np.arange(m), 4), np.tile(np.arange(4), m)


def _group_faces(sorted_faces: np.ndarray):
    """Order of the faces grouping equal triples (stable: by triple, then by face index), and the start flag of each
    group in that order. One packed int64 key per face when the vertex ids allow it (< 2^21), else a lexsort."""
    n = int(sorted_faces.max()) + 1 if len(sorted_faces) else 1
    if n < (1 << 21):
        key = (sorted_faces[:, 0] * n + sorted_faces[:, 1]) * n + sorted_faces[:, 2]
        order = np.argsort(key, kind="stable")
    else:
        order = np.lexsort((sorted_faces[:, 2], sorted_faces[:, 1], sorted_faces[:, 0]))
    s = sorted_faces[order]
    new = np.ones(len(s), dtype=bool)
    if len(s) > 1:
        new[1:] = np.any(s[1:] != s[:-1], axis=1)
    return order, new


def boundary_faces(tets: np.ndarray, *, return_elements: bool = False, return_face_ids: bool = False):
    """Faces used by exactly one element, wound outward for positively oriented elements, shape [k, 3], int32; with
    ``return_elements`` also the element of each face, shape [k]; with ``return_face_ids`` instead the face id
    4 e + k of each (element e, local face k of TET_FACES), int64 [k] (stable while elements keep their index)."""
    tets = np.asarray(tets, dtype=np.int64)
    if tets.shape[0] == 0:
        empty = np.zeros((0, 3), dtype=np.int32)
        return (empty, np.zeros(0, dtype=np.int64)) if (return_elements or return_face_ids) else empty
    sorted_faces, elem, local = _face_keys(tets)
    order, new = _group_faces(sorted_faces)
    group = np.cumsum(new) - 1
    counts = np.bincount(group)
    single = counts[group] == 1
    idx = np.sort(order[single])
    faces = tets[elem[idx]][np.arange(len(idx))[:, None], TET_FACES[local[idx]]].astype(np.int32)
    if return_face_ids:
        return faces, idx.astype(np.int64)  # faces are numbered 4 e + k by _face_keys
    return (faces, elem[idx]) if return_elements else faces


def interior_face_pairs(tets: np.ndarray):
    """Pairs of (face index 4 e + k) that share a triple, shape [p, 2]; raises if a face has three or more elements."""
    sorted_faces, _, _ = _face_keys(np.asarray(tets, dtype=np.int64))
    order, new = _group_faces(sorted_faces)
    group = np.cumsum(new) - 1
    counts = np.bincount(group)
    if counts.size and counts.max() > 2:
        bad = int(order[np.flatnonzero(counts[group] > 2)[0]] // 4)
        raise GeometryError(
            f"the tetrahedral mesh is not manifold: a face of element {bad} is shared by {int(counts.max())} elements "
            "(at most 2 allowed)"
        )
    starts = np.flatnonzero(new)
    pair_groups = counts == 2
    first = starts[pair_groups]
    return np.stack([order[first], order[first + 1]], axis=1)


def tet_mesh_from_arrays(vertices, tets, *, name: str = "tet_mesh", min_quality: float = DEFAULT_MIN_QUALITY):
    """Validates and orients a tetrahedral mesh given as arrays.

    Args:
        vertices: rest positions [m], shape [n, 3].
        tets: corner indices, shape [m, 4] (any winding; elements are re-oriented to positive volume).
        name: label of the mesh.
        min_quality: smallest allowed element quality 6 sqrt(2) |V| / l_rms^3, in [0, 1); default 1e-3.

    Raises:
        GeometryError: empty mesh, non-finite vertices, bad indices, degenerate (zero or near-zero volume), inverted
            (folded) or non-manifold elements; the message names the first offending element.
    """
    min_quality = check_range("min_quality", min_quality, 0.0, 1.0, lo_open=False)
    try:
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        t_raw = np.asarray(tets, dtype=np.float64).reshape(-1, 4)
        t = t_raw.astype(np.int64)
    except (TypeError, ValueError):
        raise GeometryError(
            f"{name}: vertices must be an [n, 3] array of numbers and tets an [m, 4] array of vertex indices"
        ) from None
    if t.shape[0] == 0 or v.shape[0] == 0:
        raise GeometryError(f"{name}: the tetrahedral mesh is empty (no elements)")
    if not np.all(np.isfinite(v)):
        raise GeometryError(f"{name}: the vertices contain non-finite values (NaN or inf)")
    if not np.array_equal(t, t_raw) or t.min() < 0 or t.max() >= len(v):
        raise GeometryError(f"{name}: tets must hold integer vertex indices in [0, {len(v)})")
    st = np.sort(t, axis=1)
    repeated = np.flatnonzero(np.any(st[:, 1:] == st[:, :-1], axis=1))
    if repeated.size:
        raise GeometryError(
            f"{name}: element {int(repeated[0])} has a repeated vertex {t[repeated[0]].tolist()} (zero volume); "
            f"{repeated.size} such element(s)"
        )
    used = np.zeros(len(v), dtype=bool)
    used[t.ravel()] = True
    if not used.all():
        remap = np.cumsum(used) - 1
        v = v[used]
        t = remap[t]
    q = element_quality(v, t)
    bad = np.flatnonzero(np.abs(q) < min_quality)
    if bad.size:
        vol = signed_volumes(v, t)
        raise GeometryError(
            f"{name}: element {int(bad[0])} is degenerate (volume {abs(vol[bad[0]]):.3g} m^3, quality "
            f"{abs(q[bad[0]]):.3g} < min_quality={min_quality:g}; 1 is a regular tetrahedron); {bad.size} such "
            "element(s): remesh or lower min_quality"
        )
    pairs = interior_face_pairs(t)
    if pairs.size:
        # signed volume of (face triple in sorted order, opposite vertex) for both elements of each interior face
        sf = np.sort(t[:, TET_FACES].reshape(-1, 3), axis=1)
        opp = t[:, TET_FACE_OPPOSITE].reshape(-1)
        face_xyz = v[sf[pairs[:, 0]]]
        n = np.cross(face_xyz[:, 1] - face_xyz[:, 0], face_xyz[:, 2] - face_xyz[:, 0])
        s0 = np.einsum("ij,ij->i", n, v[opp[pairs[:, 0]]] - face_xyz[:, 0])
        s1 = np.einsum("ij,ij->i", n, v[opp[pairs[:, 1]]] - face_xyz[:, 0])
        folded = np.flatnonzero(s0 * s1 >= 0.0)
        if folded.size:
            e0, e1 = int(pairs[folded[0], 0] // 4), int(pairs[folded[0], 1] // 4)
            raise GeometryError(
                f"{name}: elements {e0} and {e1} lie on the same side of their shared face: an element is inverted "
                f"(folded over its neighbour); {folded.size} such face(s)"
            )
    neg = signed_volumes(v, t) < 0.0
    t = t.copy()
    t[neg] = t[neg][:, [0, 1, 3, 2]]
    return TetMesh(vertices=v, tets=t.astype(np.int32), name=name)


def tetrahedralize(
    shape: SolidShape,
    *,
    edge_length: float | None = None,
    epsilon: float = 1.0e-3,
    optimize: bool = True,
    min_quality: float = DEFAULT_MIN_QUALITY,
    threads: int = 0,
    name: str | None = None,
    cache_dir: str | os.PathLike | None = None,
) -> TetMesh:
    """Fills a closed surface with a quality tetrahedral mesh using fTetWild (pytetwild, MPL-2.0).

    fTetWild's output differs from run to run (measured on one input: 2,078 to 3,463 vertices, also with one thread).
    For reproducible simulations pass ``cache_dir``: the first mesh made for a given surface and parameters is saved
    there (.vtu, keyed by a SHA-1 of the inputs) and loaded by later calls.

    Args:
        shape: a closed, consistently oriented surface (``pdsim.load_mesh``, ``pdsim.box``, ...; an open surface is
            rejected when the shape is built).
        edge_length: target edge length [m], > 0; default 1/20 of the bounding-box diagonal.
        epsilon: envelope size: largest distance of the output boundary from the input surface, relative to the
            bounding-box diagonal, in (0, 0.1].
        optimize: run fTetWild's quality optimisation (default True).
        min_quality: quality check on the result (see :func:`tet_mesh_from_arrays`).
        threads: mesher threads (0: all cores).
        name: mesh label; defaults to the shape's name.
        cache_dir: folder of cached meshes (created if missing), or None.
    """
    if not isinstance(shape, SolidShape):
        raise ParameterError("shape", shape, "a pdsim SolidShape (pdsim.box, pdsim.load_mesh, ...)")
    diag = float(np.linalg.norm(shape.extent))
    if edge_length is None:
        edge_length = diag / 20.0
    edge_length = check_range("edge_length", edge_length, 0.0, diag, hi_open=False)
    epsilon = check_range("epsilon", epsilon, 0.0, 0.1, hi_open=False)
    if int(threads) != threads or threads < 0:
        raise ParameterError("threads", threads, "an integer >= 0")
    label = name or shape.name
    cached = None
    if cache_dir is not None:
        import hashlib

        h = hashlib.sha1()
        h.update(np.ascontiguousarray(shape.vertices, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(shape.faces, dtype=np.int64).tobytes())
        h.update(repr((float(edge_length), float(epsilon), bool(optimize))).encode())
        os.makedirs(cache_dir, exist_ok=True)
        cached = os.path.join(os.fspath(cache_dir), f"{label}-{h.hexdigest()[:20]}.vtu")
        if os.path.isfile(cached):
            return load_tet_mesh(cached, name=label, min_quality=min_quality)
    wrapper = _ftetwild()
    with _scratch_directory():  # fTetWild writes a scratch __tracked_surface.stl into the working directory
        v, t = _run_ftetwild(wrapper, shape, edge_length, epsilon, optimize, threads)
    if len(t) == 0:
        raise GeometryError(f"{shape.name}: fTetWild produced no elements (is the surface too thin for edge_length?)")
    mesh = tet_mesh_from_arrays(v, t, name=label, min_quality=min_quality)
    if cached is not None:
        tmp = cached + ".tmp.vtu"
        write_tet_mesh(mesh, tmp)
        os.replace(tmp, cached)
    return mesh


class _scratch_directory:
    """Runs a block in a fresh temporary working directory (removed afterwards), then returns to the old one."""

    def __enter__(self):
        import tempfile

        self._old = os.getcwd()
        self._tmp = tempfile.TemporaryDirectory(prefix="pdsim-ftetwild-")
        os.chdir(self._tmp.name)
        return self

    def __exit__(self, *exc):
        os.chdir(self._old)
        self._tmp.cleanup()
        return False


def _run_ftetwild(wrapper, shape, edge_length, epsilon, optimize, threads):
    """Calls fTetWild's tetrahedralize_mesh; returns (vertices [n, 3], tets [m, 4])."""
    return wrapper.tetrahedralize_mesh(
        np.ascontiguousarray(shape.vertices, dtype=np.float64),
        np.ascontiguousarray(shape.faces, dtype=np.uint32),
        bool(optimize),
        False,  # skip_simplify
        0.05,  # relative edge length (unused when the absolute one is > 0)
        float(edge_length),
        float(epsilon),
        10.0,  # stop_energy
        False,  # coarsen
        int(threads),
        80,  # optimisation iterations
        6,  # log level
        True,  # quiet
        False,  # vtk ordering
        False,  # disable filtering
        np.empty((0, 3), dtype=np.float64),
        np.empty((0, 4), dtype=np.int32),
        np.empty(0, dtype=np.float64),
    )


def _ftetwild():
    """The compiled fTetWild wrapper of pytetwild. pytetwild 0.4.2's package ``__init__`` imports pyvista (an
    undeclared, heavy dependency used only for its PyVista accessor); when pyvista is missing the extension module is
    loaded directly, which needs nothing but numpy."""
    try:
        from pytetwild import PyfTetWildWrapper

        return PyfTetWildWrapper
    except ModuleNotFoundError as exc:
        if exc.name == "pytetwild":
            raise GeometryError("meshing a surface needs pytetwild (pip install pytetwild)") from None
    import importlib.machinery
    import importlib.util
    import sys

    key = "pytetwild.PyfTetWildWrapper"
    if key in sys.modules:
        return sys.modules[key]
    spec = importlib.util.find_spec("pytetwild")
    folder = spec.submodule_search_locations[0]
    files = [f for f in os.listdir(folder) if f.startswith("PyfTetWildWrapper") and f.endswith((".so", ".pyd"))]
    if not files:
        raise GeometryError(f"pytetwild is installed in {folder} but its compiled fTetWild module is missing")
    path = os.path.join(folder, files[0])
    loader = importlib.machinery.ExtensionFileLoader(key, path)
    module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(key, path, loader=loader))
    loader.exec_module(module)
    sys.modules[key] = module
    return module


def load_tet_mesh(
    path: str | os.PathLike,
    *,
    scale: float = 1.0,
    translate=(0.0, 0.0, 0.0),
    name: str | None = None,
    prim_path: str | None = None,
    min_quality: float = DEFAULT_MIN_QUALITY,
) -> TetMesh:
    """Loads a ready tetrahedral mesh: Gmsh .msh, VTK .vtk/.vtu, Medit .mesh, Abaqus .inp, ... through meshio, or a
    ``UsdGeom.TetMesh`` from .usd/.usda/.usdc (the first one, or the prim at ``prim_path``; its points are taken in
    world space). Only the tetrahedra of the file are used. Checked as :func:`tet_mesh_from_arrays`.

    Args:
        path: mesh file.
        scale: uniform scale [-], > 0, applied before ``translate`` [m].
        name: label; defaults to the file's stem.
        prim_path: USD only: the TetMesh prim to load.
        min_quality: smallest allowed element quality.
    """
    path = os.fspath(path)
    label = name or os.path.splitext(os.path.basename(path))[0]
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in TET_MESH_SUFFIXES:
        raise GeometryError(
            f"{path}: unknown tetrahedral mesh type '{suffix}'; supported: {', '.join(TET_MESH_SUFFIXES)}"
        )
    if not os.path.isfile(path):
        raise GeometryError(f"{path}: no such file")
    if suffix in (".usd", ".usda", ".usdc"):
        from ..output.usd import read_tet_mesh

        v, t = read_tet_mesh(path, prim_path)
    else:
        try:
            import meshio
        except ModuleNotFoundError:
            raise GeometryError(f"{path}: reading {suffix} files needs meshio (pip install meshio)") from None
        try:
            m = meshio.read(path)
        except Exception as exc:  # noqa: BLE001 (meshio raises many exception types for unreadable files)
            raise GeometryError(f"{path}: cannot read mesh ({exc})") from None
        blocks = [c.data for c in m.cells if c.type == "tetra"]
        if not blocks:
            kinds = sorted({c.type for c in m.cells})
            raise GeometryError(f"{path}: the file holds no tetrahedra (cell types: {', '.join(kinds) or 'none'})")
        v, t = np.asarray(m.points, dtype=np.float64), np.concatenate(blocks)
        if v.shape[1] == 2:
            raise GeometryError(f"{path}: the file holds 2D points; a tetrahedral mesh needs 3D points")
    mesh = tet_mesh_from_arrays(v, t, name=label, min_quality=min_quality)
    return mesh.transformed(scale=scale, translate=translate)


def box_tet_mesh(size, cells, *, center=(0.0, 0.0, 0.0), name: str = "box", jitter: float = 0.0, seed: int = 0):
    """A structured tetrahedral mesh of an axis-aligned box: ``cells`` = (nx, ny, nz) hexahedra, each cut into six
    tetrahedra around its main diagonal (Kuhn subdivision: conforming across cells).

    Args:
        size: edge lengths [m], each > 0.
        cells: cells per axis, integers >= 1.
        center: box centre [m].
        jitter: random displacement of interior vertices as a fraction of the smallest cell size, in [0, 0.3)
            (irregular meshes for tests); boundary vertices stay on the faces of the box.
        seed: random seed of the jitter.
    """
    s = np.asarray(size, dtype=np.float64)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ParameterError("size", size, "three edge lengths > 0 [m]")
    c = np.asarray(cells)
    if c.shape != (3,) or not np.all(c == np.round(c)) or np.any(c < 1):
        raise ParameterError("cells", cells, "three integers >= 1")
    jitter = check_range("jitter", jitter, 0.0, 0.3, lo_open=False)
    nx, ny, nz = (int(k) for k in c)
    gx, gy, gz = (np.linspace(-0.5 * s[i], 0.5 * s[i], int(c[i]) + 1) for i in range(3))
    xs, ys, zs = np.meshgrid(gx, gy, gz, indexing="ij")
    verts = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)

    def vid(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    corner = np.stack([vid(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1)) for b in range(8)], axis=1)
    # six tetrahedra sharing the diagonal 0-7, one per permutation of the axis order
    kuhn = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])
    tets = corner[:, kuhn].reshape(-1, 4)
    if jitter > 0:
        rng = np.random.default_rng(seed)
        h = float((s / c).min())
        lo, hi = -0.5 * s, 0.5 * s
        interior = np.all((verts > lo + 1e-12) & (verts < hi - 1e-12), axis=1)
        verts[interior] += rng.uniform(-jitter * h, jitter * h, size=(int(interior.sum()), 3))
    verts += np.asarray(center, dtype=np.float64)
    return tet_mesh_from_arrays(verts, tets, name=name)


def write_tet_mesh(mesh: TetMesh, path: str | os.PathLike) -> None:
    """Writes a tetrahedral mesh with meshio (format from the suffix: .msh, .vtk, .vtu, ...)."""
    import meshio

    meshio.write(os.fspath(path), meshio.Mesh(mesh.vertices, [("tetra", mesh.tets)]))


__all__ = [
    "TetMesh",
    "boundary_faces",
    "box_tet_mesh",
    "element_heights",
    "element_quality",
    "load_tet_mesh",
    "signed_volumes",
    "tet_mesh_from_arrays",
    "tetrahedralize",
    "write_tet_mesh",
]
