"""Tetrahedral meshes for the FEM solid: meshing a closed surface (fTetWild through pytetwild), loading ready meshes
(meshio formats such as Gmsh .msh and VTK .vtk/.vtu, or a ``UsdGeom.TetMesh``), structured box meshes, and the checks
every mesh passes on its way in (orientation fixed, degenerate and inverted elements rejected).

All topology work here is vectorised numpy (sorting face keys), never a Python loop over elements.

Orientation and quality on load (:func:`tet_mesh_from_arrays`):

- indices must be integers in range, four distinct vertices per element; unreferenced vertices are dropped;
- an element whose quality q = 6 sqrt(2) |V| / l_rms^3 (1 for a regular tetrahedron, 0 for a flat one; l_rms the root
  mean square of its six edge lengths) is below ``min_quality`` (default 0.02) is degenerate: error naming the worst
  elements, their quality and the stable time step each forces against the median element's (a sliver of quality
  3e-3 cut an explicit run's step 400x and cracked falsely);
- every interior face must be shared by exactly two elements whose fourth vertices lie on opposite sides of it; two
  on the same side means an element is inverted (folded over its neighbour): error. Three or more elements on one face
  is a non-manifold mesh: error;
- elements with negative signed volume det(Dm) / 6 are then re-oriented (two corners swapped), so that a mesh written
  with either winding convention loads the same.
"""

from __future__ import annotations

import hashlib
import importlib.util
import math
import os
import signal
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field

import meshio
import numpy as np

from ..checks import check_range, unit_hint
from ..errors import GeometryError, ParameterError
from ..geometry import SolidShape

TET_MESH_SUFFIXES = (".msh", ".vtk", ".vtu", ".mesh", ".inp", ".xdmf", ".med", ".usd", ".usda", ".usdc")

DEFAULT_MIN_QUALITY = 0.02
# fTetWild's meshes measure 0.26 to 0.36 at worst (box, sphere, cylinder); a sliver of quality 3e-3 cut the stable step
# 400x below the median element's and cracked falsely. 0.02 keeps the worst element's step within about 40x.
MAX_MESH_ELEMENTS = 20_000_000  # estimated elements above which tetrahedralize refuses (fTetWild's memory and time)

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
    min_quality: float = DEFAULT_MIN_QUALITY  # the quality its elements were checked against (pre-flight rechecks
    # meshes built directly, ``checked`` False)
    checked: bool = field(default=False, repr=False, compare=False)

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
        return TetMesh(
            vertices=self.vertices * s + t,
            tets=self.tets.copy(),
            name=self.name,
            min_quality=self.min_quality,
            checked=self.checked,  # a uniform scale keeps every element's quality
        )


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


def quality_problem(vertices: np.ndarray, tets: np.ndarray, min_quality: float, name: str, *, show: int = 3):
    """The one-line message of a mesh whose elements fall below ``min_quality`` (None when none does): the worst
    ``show`` elements with their quality and the stable time step each forces, as a fraction of the median element's
    (an explicit step is proportional to an element's smallest height). All numpy, no loop over elements."""
    q = np.abs(element_quality(vertices, tets))
    bad = np.flatnonzero(q < min_quality)
    if not bad.size:
        return None
    heights = element_heights(vertices, tets)
    median = float(np.median(heights))
    worst = bad[np.argsort(q[bad], kind="stable")[:show]]

    def entry(e) -> str:
        hgt = float(heights[e])
        if not hgt > 0.0:
            return f"element {int(e)} (quality {q[e]:.3g}: flat, no stable time step)"
        return f"element {int(e)} (quality {q[e]:.3g}: stable time step 1/{median / hgt:.3g} of the median element's)"

    vol = abs(float(signed_volumes(vertices, tets[worst[:1]])[0]))
    return (
        f"{name}: element {int(worst[0])} is degenerate (quality {q[worst[0]]:.3g} < min_quality={min_quality:g}; "
        f"1 is a regular tetrahedron; volume {vol:.3g} m^3); {bad.size} such element(s) of {len(tets)}, worst "
        f"{', '.join(entry(e) for e in worst)}; slivers cut an explicit run's time step and crack falsely: remesh "
        "(tetrahedralize with optimize=True, or better mesher settings) or lower min_quality to accept them"
    )


def stable_order(keys: np.ndarray) -> np.ndarray:
    """The order that sorts non-negative integer ``keys`` [n] stably (equal keys in index order): the same as
    ``np.argsort(keys, kind="stable")``. Where key * n + index fits in int64 those unique keys are sorted instead, by
    numpy's default (introsort) sort, several times faster than its stable sort on int64 keys."""
    keys = np.asarray(keys, dtype=np.int64)
    n = len(keys)
    if n == 0 or int(keys.max()) >= np.iinfo(np.int64).max // max(n, 1) - 1 or int(keys.min()) < 0:
        return np.argsort(keys, kind="stable")
    return np.argsort(keys * n + np.arange(n, dtype=np.int64))


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
        order = stable_order(key)
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
    problem = quality_problem(v, t, min_quality, name)
    if problem:
        raise GeometryError(problem)
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
    return TetMesh(vertices=v, tets=t.astype(np.int32), name=name, min_quality=min_quality, checked=True)


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

    fTetWild's output differs from run to run (in its vertex count too, also with one thread).
    For reproducible simulations pass ``cache_dir``: the first mesh made for a given surface and parameters is saved
    there (.vtu, keyed by a SHA-1 of the inputs) and loaded by later calls.

    fTetWild runs in a child Python process (``sys.executable``, loading only numpy and the compiled wrapper; about
    0.1 s of start-up against 0.5 s and more of meshing): a native crash of the mesher (it segfaults on some thin
    parts) raises GeometryError naming the mesh instead of ending the caller. A surface whose estimated element
    count exceeds MAX_MESH_ELEMENTS is refused before meshing (ParameterError, with a unit hint).

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
        h = hashlib.sha1()
        h.update(np.ascontiguousarray(shape.vertices, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(shape.faces, dtype=np.int64).tobytes())
        h.update(repr((float(edge_length), float(epsilon), bool(optimize))).encode())
        os.makedirs(cache_dir, exist_ok=True)
        cached = os.path.join(os.fspath(cache_dir), f"{label}-{h.hexdigest()[:20]}.vtu")
        if os.path.isfile(cached):
            return tet_mesh_from_arrays(*read_meshio_tets(cached), name=label, min_quality=min_quality)
    check_mesh_size(shape, edge_length)
    v, t = _mesh_in_child(shape, label, edge_length, epsilon, optimize, threads)
    if len(t) == 0:
        raise GeometryError(
            f"{label}: fTetWild produced no elements: the surface is too thin for edge_length={edge_length:.3g} m "
            f"(its thinnest bounding-box side is {float(np.min(shape.extent)):.3g} m); thicken the part or lower "
            "edge_length"
        )
    mesh = tet_mesh_from_arrays(v, t, name=label, min_quality=min_quality)
    if cached is not None:
        tmp = cached + ".tmp.vtu"
        write_tet_mesh(mesh, tmp)
        os.replace(tmp, cached)
    return mesh


def check_mesh_size(shape: SolidShape, edge_length: float) -> float:
    """The number of elements fTetWild makes for ``shape`` at ``edge_length`` [m], estimated as the volume over a
    regular tetrahedron's (edge^3 / (6 sqrt 2); fTetWild makes more on curved surfaces, which it refines);
    ParameterError with a unit hint above MAX_MESH_ELEMENTS."""
    estimate = abs(shape.volume) / (edge_length**3 / (6.0 * math.sqrt(2.0)))
    if estimate > MAX_MESH_ELEMENTS:
        raise ParameterError(
            "edge_length",
            edge_length,
            f"a length giving at most {MAX_MESH_ELEMENTS:.0e} elements for '{shape.name}' (this gives about "
            f"{estimate:.3g}: edge_length >= {edge_length * (estimate / MAX_MESH_ELEMENTS) ** (1.0 / 3.0):.3g} m fits)"
            + unit_hint(float(np.max(shape.extent)), edge_length, what="edge_length", count=estimate),
        )
    return estimate


# The child process that runs fTetWild: a native crash (fTetWild segfaults on some thin parts, and on a second call
# in a process after an earlier call failed) ends the child, not the caller. It loads only numpy and the compiled
# wrapper (not pdsim, not pyvista): about 0.1 s of start-up. Its working directory is a scratch folder, where fTetWild
# writes its __tracked_surface.stl. Arguments: wrapper path, input .npz, output .npz.
_CHILD = r"""
import importlib.machinery, importlib.util, sys
import numpy as np
{hook}
path, inp, outp = sys.argv[1:4]
key = "pytetwild.PyfTetWildWrapper"
loader = importlib.machinery.ExtensionFileLoader(key, path)
module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(key, path, loader=loader))
loader.exec_module(module)
a = np.load(inp)
v, t = module.tetrahedralize_mesh(
    a["vertices"], a["faces"], bool(a["optimize"]), False, 0.05, float(a["edge_length"]), float(a["epsilon"]), 10.0,
    False, int(a["threads"]), 80, 6, True, False, False,
    np.empty((0, 3), dtype=np.float64), np.empty((0, 4), dtype=np.int32), np.empty(0, dtype=np.float64),
)
np.savez(outp, vertices=np.asarray(v, dtype=np.float64), tets=np.asarray(t, dtype=np.int64))
"""
_CHILD_TEST_HOOK = ""  # Python run in the child before meshing (tests: "import os; os.abort()" to test a crash)


def _mesh_in_child(shape: SolidShape, label: str, edge_length, epsilon, optimize, threads):
    """Runs fTetWild on ``shape`` in a child Python process; returns (vertices [n, 3], tets [m, 4]). A crash of the
    mesher (a signal, or an exception) becomes a GeometryError naming the mesh, how it ended and what to change."""
    wrapper = _ftetwild_path()
    with tempfile.TemporaryDirectory(prefix="pdsim-ftetwild-") as tmp:
        inp, outp = os.path.join(tmp, "surface.npz"), os.path.join(tmp, "tets.npz")
        np.savez(
            inp,
            vertices=np.ascontiguousarray(shape.vertices, dtype=np.float64),
            faces=np.ascontiguousarray(shape.faces, dtype=np.uint32),
            optimize=bool(optimize),
            edge_length=float(edge_length),
            epsilon=float(epsilon),
            threads=int(threads),
        )
        code = _CHILD.replace("{hook}", _CHILD_TEST_HOOK)
        proc = subprocess.run(
            [sys.executable, "-c", code, wrapper, inp, outp], cwd=tmp, capture_output=True, text=True, check=False
        )
        if proc.returncode == 0 and os.path.isfile(outp):
            with np.load(outp) as r:
                return r["vertices"], r["tets"]
    if proc.returncode < 0:
        try:
            how = f"crashed ({signal.Signals(-proc.returncode).name})"
        except ValueError:
            how = f"crashed (signal {-proc.returncode})"
    else:
        last = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
        how = f"failed (exit status {proc.returncode}{': ' + last[-1] if last else ''})"
    ext = shape.extent
    raise GeometryError(
        f"{label}: fTetWild {how} meshing the surface ({len(shape.faces)} triangles, {ext[0]:.3g} x {ext[1]:.3g} x "
        f"{ext[2]:.3g} m, edge_length={edge_length:.3g} m); thin parts crash the mesher: thicken the part (its "
        f"thinnest bounding-box side is {float(np.min(ext)):.3g} m) or lower edge_length, or mesh it elsewhere and "
        "load it with load_tet_mesh"
    )


def _ftetwild_path() -> str:
    """Path of pytetwild's compiled fTetWild wrapper, found without importing the package (whose ``__init__`` imports
    pyvista, an undeclared heavy dependency)."""
    try:
        spec = importlib.util.find_spec("pytetwild")
    except (ImportError, ValueError):
        spec = None
    if spec is None or not spec.submodule_search_locations:
        raise GeometryError("meshing a surface needs pytetwild (pip install pytetwild)")
    folder = spec.submodule_search_locations[0]
    files = [f for f in os.listdir(folder) if f.startswith("PyfTetWildWrapper") and f.endswith((".so", ".pyd"))]
    if not files:
        raise GeometryError(f"pytetwild is installed in {folder} but its compiled fTetWild module is missing")
    return os.path.join(folder, files[0])


def read_meshio_tets(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(vertices [m], tetrahedra) of a mesh file meshio reads (.msh, .vtk, .vtu, .mesh, .inp, ...): its tetrahedral
    cells only; GeometryError for an unreadable file, one without tetrahedra, or 2D points."""
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
    return v, t


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
    meshio.write(os.fspath(path), meshio.Mesh(mesh.vertices, [("tetra", mesh.tets)]))


__all__ = [
    "TetMesh",
    "boundary_faces",
    "box_tet_mesh",
    "element_heights",
    "element_quality",
    "signed_volumes",
    "stable_order",
    "tet_mesh_from_arrays",
    "tetrahedralize",
]
