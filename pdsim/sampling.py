"""Filling solids with particles on a regular lattice, with an exact inside test against the surface mesh."""

from __future__ import annotations

import numpy as np
import warp as wp

from . import memory
from .checks import check_range, format_bytes, unit_hint
from .errors import GeometryError, ParameterError
from .geometry import SolidShape
from .kernels import sampling as ks

MAX_LATTICE_POINTS = 200_000_000


SAMPLING_BYTES_PER_CANDIDATE = 100  # peak host memory of fill_solid per lattice point of the bounding box (60-65 B
# measured with tools/preflight_calibration.py, plus the body's Morton sort)


def lattice_counts(shape: SolidShape, spacing: float) -> np.ndarray:
    """Points per axis of the simple-cubic lattice of ``spacing`` [m] over the shape's bounding box, as float64 [3]
    (floats, so that a spacing far too small for the shape gives a large number, not an integer overflow)."""
    extent = np.asarray(shape.extent, dtype=np.float64)
    # Tolerance of 1e-3 cells: a box of edge n h stored in float32 (STL, PLY, GLB) measures n h (1 +- 1e-7) and must
    # still get n points, not n + 1 with the outer layer on its faces (where the inside test is ambiguous).
    with np.errstate(over="ignore"):
        return np.maximum(np.ceil(extent / float(spacing) - 1.0e-3), 1.0)


def check_lattice_size(shape: SolidShape, spacing: float, *, free_bytes: float | None = None) -> int:
    """The number of candidate lattice points of ``fill_solid(shape, spacing)``, or ParameterError (naming the
    spacing, the count, the memory it needs and a unit hint) when it exceeds MAX_LATTICE_POINTS or the free host
    memory (``free_bytes``; measured when None)."""
    counts = lattice_counts(shape, spacing)
    total = float(np.prod(counts))
    size = float(np.max(shape.extent))
    if total > MAX_LATTICE_POINTS:
        raise ParameterError(
            "spacing",
            spacing,
            f"a value giving at most {MAX_LATTICE_POINTS:.0e} lattice points for '{shape.name}' (this gives "
            f"{' x '.join(f'{c:.3g}' for c in counts)} = {total:.3g})" + unit_hint(size, spacing, count=total),
        )
    need = total * SAMPLING_BYTES_PER_CANDIDATE
    if free_bytes is None:
        free_bytes = memory.free_host_memory()
    if free_bytes is not None and need > free_bytes:
        raise ParameterError(
            "spacing",
            spacing,
            f"a value whose particle sampling of '{shape.name}' fits in the {format_bytes(free_bytes)} of free host "
            f"memory (this needs about {format_bytes(need)} for {total:.3g} lattice points; spacing >= "
            f"{spacing * (need / free_bytes) ** (1.0 / 3.0):.3g} m fits)" + unit_hint(size, spacing, count=total),
        )
    return int(total)


def simple_cubic_lattice(shape: SolidShape, spacing: float) -> np.ndarray:
    """Candidate simple-cubic lattice points [m], shape [n, 3], covering the shape's bounding box and centred on it
    (a box of edge n h gets exactly n points along that edge, h/2 from its faces)."""
    lo, hi = shape.bounds
    check_lattice_size(shape, spacing)
    counts = lattice_counts(shape, spacing).astype(np.int64)
    start = 0.5 * (lo + hi) - 0.5 * (counts - 1) * spacing
    axes = [start[a] + spacing * np.arange(counts[a]) for a in range(3)]
    g = np.meshgrid(*axes, indexing="ij")
    return np.stack([c.ravel() for c in g], axis=1)


def points_inside(shape: SolidShape, points: np.ndarray, *, device: str = "cpu") -> np.ndarray:
    """Exact inside test (generalised winding number against the closed mesh, a Warp mesh query): bool mask [n].
    Mesh and points are taken relative to the shape's centre before they become float32, so the test is as exact
    anywhere in the world as at the origin."""
    centre = 0.5 * (shape.bounds[0] + shape.bounds[1])
    with wp.ScopedDevice(device):
        mesh = wp.Mesh(
            points=wp.array((shape.vertices - centre).astype(np.float32), dtype=wp.vec3),
            indices=wp.array(shape.faces.astype(np.int32).ravel(), dtype=wp.int32),
            support_winding_number=True,
        )
        pts = wp.array((points - centre).astype(np.float32), dtype=wp.vec3)
        max_dist = float(np.linalg.norm(shape.extent)) * 2.0 + 1.0
        return ks.points_inside_mesh(mesh, pts, max_dist).numpy().astype(bool)


def fill_solid(shape: SolidShape, spacing: float, *, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Fills ``shape`` with particles on a simple-cubic lattice of ``spacing`` h [m].

    Returns:
        positions: particle reference positions [m], shape [n, 3], float64.
        volumes: particle volumes h^3 [m^3], shape [n].
    """
    h = check_range("spacing", spacing, 0.0, None)
    smallest = float(np.min(shape.extent))
    if h > smallest * (1.0 + 1.0e-9):  # an extent equal to the spacing, up to the round-off of the vertices, is fine
        raise ParameterError(
            "spacing",
            spacing,
            f"(0, {smallest:g}] for '{shape.name}' (its smallest extent)" + unit_hint(float(np.max(shape.extent)), h),
        )
    candidates = simple_cubic_lattice(shape, h)
    positions = candidates[points_inside(shape, candidates, device=device)]
    if len(positions) == 0:
        raise GeometryError(
            f"'{shape.name}': no lattice point of spacing {h:g} lies inside the shape; use a smaller spacing"
        )
    return positions, np.full(len(positions), h**3)


def jitter_points(
    shape: SolidShape, points: np.ndarray, spacing: float, fraction: float, seed: int, *, device: str = "cpu"
) -> np.ndarray:
    """Jittered sampling: each lattice point of ``points`` [n, 3] (cell centres of a simple-cubic lattice of
    ``spacing`` h) moves by an independent uniform offset in [-fraction h / 2, fraction h / 2)^3, so it stays inside
    its own cell (the cells still partition the shape: every particle keeps the volume h^3). A point whose moved
    position falls outside the shape keeps its lattice position. The offsets come from numpy's PCG64 generator seeded
    with ``seed`` and are drawn in the order of ``points`` (give them in Morton order, which does not depend on where
    the shape lies, and the jitter is the same anywhere in the world). Returns the moved points [n, 3]."""
    rng = np.random.default_rng(int(seed))
    moved = points + (fraction * spacing) * (rng.random(points.shape) - 0.5)
    keep = points_inside(shape, moved, device=device)
    return np.where(keep[:, None], moved, points)


def morton_order(points: np.ndarray, cell: float) -> np.ndarray:
    """Permutation that sorts points [n, 3] along a Morton (Z-order) curve of cells of size ``cell`` [m]. Lattice
    points (spaced ``cell`` apart) sit on cell centres, so their cell does not depend on round-off: the order is the
    same wherever the lattice lies in the world."""
    q = np.floor((points - points.min(axis=0)) / cell + 0.5).astype(np.uint64)
    q = np.minimum(q, np.uint64(2**21 - 1))

    def spread(v):
        v = v & np.uint64(0x1FFFFF)
        v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
        v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
        v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
        v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
        v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
        return v

    code = spread(q[:, 0]) | (spread(q[:, 1]) << np.uint64(1)) | (spread(q[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")
