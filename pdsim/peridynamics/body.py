"""Peridynamic bodies: a solid filled with particles on a simple-cubic lattice, its material and its boundary
conditions (the scene-facing part of the peridynamic method)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..bodies import PointBody
from ..checks import check_range
from ..errors import ParameterError
from ..geometry import SolidShape
from ..loads import surface_forces_from_triangles
from ..materials import Material
from ..regions import BoxRegion, region_mask
from ..sampling import fill_solid, jitter_points, morton_order
from .handoff import handoff_setting

DEFAULT_HORIZON_FACTOR = 3.015  # horizon over spacing of a PeridynamicBody unless it sets its own

SURFACE_CORRECTIONS = ("directional", "family", "none")
SAMPLINGS = ("lattice", "jittered")


class PeridynamicBody(PointBody):
    """A solid discretised into particles on a simple-cubic lattice, simulated with state-based peridynamics.

    Args:
        shape: the solid to fill (see pdsim.geometry).
        material: elastic constants and density.
        spacing: lattice spacing h [m], > 0 and at most the shape's smallest extent.
        horizon_factor: horizon delta = horizon_factor * h, in [1.5, 8]; default 3.015 (about 3 spacings, ties avoided).
        name: label of the body in the USD cache; defaults to the shape's name.
        surface_correction: "directional" (Madenci-Oterkus per-direction factors, default), "family" (per-particle
            calibration of d and b on the isotropic reference deformations) or "none" (the supplement's constants).
        partial_volumes: count neighbours near the horizon by the fraction of their cell inside it (default True).
        damping: mass-proportional viscous damping coefficient c [1/s], >= 0 (a = f / rho - c v).
        material_rotation: 3x3 rotation from the material frame (where ``material.anisotropy.axis`` is given) to world
            space; identity by default. Turning a body and its material_rotation together gives the same result.
        device: Warp device used to sample the shape ("cpu" by default; sampling is a one-off).
        sampling: "lattice" (particles on the simple-cubic lattice) or "jittered" (each lattice point moved
            at random inside its own cell, volume h^3 kept, pdsim.sampling.jitter_points): the particle
            arrangement then has no lattice planes for cracks to follow (docs/fracture.md). None (default):
            "jittered" with the material's ``sampling_jitter`` where it has one, else "lattice".
        jitter: largest offset of a jittered particle along each axis, as a fraction of h, in (0, 1] (the offsets are
            uniform in [-jitter h / 2, jitter h / 2)); when None (default) the material's ``sampling_jitter``, or
            0.5. Only with sampling="jittered".
        sampling_seed: seed of the jitter, an integer in [0, 2^31 - 1] (default 0): the same seed gives the same
            particles, wherever the body sits.
        rigid_handoff: False (off), True (the defaults) or a pdsim.RigidHandoff: fragments of the body that stop
            deforming and settle become rigid bodies, and (``RigidHandoff(fixed=True)``) those held by a fixed rim
            static ones (pdsim/peridynamics/handoff.py; only for a material that breaks). None (default): the
            material's ``rigid_handoff`` (on for the brittle presets, else off).

    Particles are sorted along a Morton curve so that neighbours are close in memory.
    """

    def __init__(
        self,
        shape: SolidShape,
        material: Material,
        spacing: float,
        *,
        horizon_factor: float = DEFAULT_HORIZON_FACTOR,
        name: str | None = None,
        surface_correction: str = "directional",
        partial_volumes: bool = True,
        damping: float = 0.0,
        material_rotation=None,
        device: str = "cpu",
        sampling: str | None = None,
        jitter: float | None = None,
        sampling_seed: int = 0,
        rigid_handoff=None,
    ):
        if not isinstance(material, Material):
            raise ParameterError("material", material, "a pdsim.Material")
        if not isinstance(shape, SolidShape):
            raise ParameterError("shape", shape, "a pdsim SolidShape (pdsim.box, pdsim.load_mesh, ...)")
        if sampling is None:
            sampling = "lattice" if material.sampling_jitter is None else "jittered"
        if sampling not in SAMPLINGS:
            raise ParameterError("sampling", sampling, " or ".join(map(repr, SAMPLINGS)))
        if sampling == "lattice" and jitter is not None:
            raise ParameterError("jitter", jitter, "None (the default) unless sampling='jittered'")
        if jitter is None:
            jitter = 0.5 if material.sampling_jitter is None else material.sampling_jitter
        jitter = check_range("jitter", jitter, 0.0, 1.0, hi_open=False)
        if isinstance(sampling_seed, bool) or not isinstance(sampling_seed, int | np.integer):
            raise ParameterError("sampling_seed", sampling_seed, "an integer in [0, 2147483647]")
        if not 0 <= int(sampling_seed) <= 2**31 - 1:
            raise ParameterError("sampling_seed", sampling_seed, "an integer in [0, 2147483647]")
        if surface_correction not in SURFACE_CORRECTIONS:
            raise ParameterError("surface_correction", surface_correction, " or ".join(map(repr, SURFACE_CORRECTIONS)))
        self.shape = shape
        self.material = material
        self.spacing = check_range("spacing", spacing, 0.0, None)
        self.horizon_factor = check_range("horizon_factor", horizon_factor, 1.5, 8.0, lo_open=False, hi_open=False)
        self.name = name or shape.name
        self.surface_correction = surface_correction
        self.partial_volumes = bool(partial_volumes)
        self.damping = check_range("damping", damping, 0.0, None, lo_open=False)
        self.rigid_handoff = handoff_setting(material.rigid_handoff if rigid_handoff is None else rigid_handoff)
        self.material_rotation = _rotation_matrix(material_rotation)
        self.notches: list = []  # BoxRegion or SolidShape: bonds crossing them start broken
        positions, volumes = fill_solid(shape, self.spacing, device=device)
        order = morton_order(positions, self.spacing)
        self.rest_positions = positions[order]
        self.sampling, self.jitter, self.sampling_seed = sampling, jitter, int(sampling_seed)
        if sampling == "jittered":
            self.rest_positions = jitter_points(
                shape, self.rest_positions, self.spacing, jitter, self.sampling_seed, device=device
            )
        self.volumes = volumes[order]
        n = len(self.rest_positions)
        self.unbreakable = np.zeros(n, dtype=bool)
        self._init_points()

    @property
    def particle_count(self) -> int:
        return len(self.rest_positions)

    method = "peridynamics"

    @property
    def point_count(self) -> int:
        return len(self.rest_positions)

    @property
    def point_rest_positions(self) -> np.ndarray:
        """Rest positions of the particles [m] (world), float64 [particle_count, 3]."""
        return self.rest_positions

    @property
    def horizon(self) -> float:
        """delta = horizon_factor * spacing [m]."""
        return self.horizon_factor * self.spacing

    def add_notch(self, cut) -> None:
        """Pre-cut: every bond whose reference segment crosses ``cut`` (a BoxRegion, e.g. a thin slab; a SolidShape's
        surface; or an open triangle surface given as (vertices, faces)) starts broken. Needs a material that breaks
        or a scene that tracks damage; any body with a notch is simulated with fracture on."""
        if isinstance(cut, tuple) and len(cut) == 2:  # an open surface: (vertices [n, 3], triangles [m, 3])
            v = np.asarray(cut[0], dtype=np.float64)
            f = np.asarray(cut[1], dtype=np.int64)
            if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or f.size == 0:
                raise ParameterError("cut", "(vertices, faces)", "arrays of shape [n, 3] and [m, 3], m >= 1")
            cut = SolidShape(vertices=v, faces=f.astype(np.int32), name="notch")
        if not isinstance(cut, BoxRegion | SolidShape):
            raise ParameterError("cut", cut, "a BoxRegion, a SolidShape or a (vertices, faces) surface")
        self.notches.append(cut)

    def set_unbreakable(self, region) -> int:
        """Bonds touching a particle in ``region`` never break (e.g. grips, supports); returns the particle count."""
        mask = self._select(region, "region")
        self.unbreakable[mask] = True
        return int(mask.sum())

    @property
    def fractures(self) -> bool:
        """True when this body's bonds can break or start broken."""
        return self.material.breaks or bool(self.notches)

    def _select(self, region, field_name: str = "region") -> np.ndarray:
        mask = region_mask(region, self.rest_positions, field=field_name)
        if not mask.any():
            raise ParameterError(field_name, region, f"a region containing at least one particle of '{self.name}'")
        return mask

    def surface_point_forces(self, region, traction, pressure: float):
        """Forces [N] of a surface load on the particles. Each triangle of the body's input surface is split into
        congruent pieces no longer than a quarter of the spacing (a box face is two triangles, which would otherwise
        put the whole load on two particles); each piece whose centroid lies in ``region`` carries its share of
        traction x area (minus pressure x area x outward normal) and gives it to the particle nearest to its
        centroid, so a uniform traction on a flat face reaches each face particle in proportion to the area it is
        nearest to (within about 10 %). Returns (particle indices int64 [k], forces float64 [k, 3])."""

        def every(p):  # all triangles: their pieces are selected below
            return np.ones(len(p), dtype=bool)

        _, _, tri_forces = surface_forces_from_triangles(
            self.shape.vertices, self.shape.faces, every, np.asarray(traction, dtype=np.float64), float(pressure)
        )
        tree = cKDTree(self.rest_positions)
        total = np.zeros((self.particle_count, 3))
        hit = False
        for centroids, parent, share in _surface_pieces(self.shape.vertices, self.shape.faces, 0.25 * self.spacing):
            inside = region_mask(region, centroids)
            if inside.any():
                hit = True
                _, nearest = tree.query(centroids[inside])
                f = tri_forces[parent[inside]] * share
                for axis in range(3):
                    total[:, axis] += np.bincount(nearest, f[:, axis], minlength=self.particle_count)
        if not hit:
            raise ParameterError("region", region, "a region that contains part of the body's surface")
        points = np.flatnonzero(np.any(total != 0.0, axis=1))
        return points.astype(np.int64), total[points]

    def point_masses(self) -> np.ndarray:
        """rho V per particle [kg]."""
        return self.material.density * self.volumes


def _surface_pieces(vertices: np.ndarray, faces: np.ndarray, size: float, chunk: int = 1 << 20):
    """Splits each triangle into s^2 congruent pieces, s = ceil(longest edge / ``size``), and yields them in chunks
    of about ``chunk`` pieces as (piece centroids [p, 3], parent triangle index [p], the share 1 / s^2 of the
    parent's area each piece holds)."""
    tri = vertices[faces]
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    splits = np.maximum(np.ceil(edges / size - 1.0e-9), 1).astype(np.int64)
    for s in np.unique(splits):
        i, j = (g.ravel() for g in np.meshgrid(np.arange(s), np.arange(s), indexing="ij"))
        up, down = i + j <= s - 1, i + j <= s - 2  # pieces pointing like the triangle, and the flipped ones
        bary = np.concatenate([np.c_[i, j][up] + 1.0 / 3.0, np.c_[i, j][down] + 2.0 / 3.0]) / float(s)  # [s^2, 2]
        parents = np.flatnonzero(splits == s)
        step = max(1, chunk // len(bary))
        for lo in range(0, len(parents), step):
            p = parents[lo : lo + step]
            o, a, b = tri[p, 0], tri[p, 1] - tri[p, 0], tri[p, 2] - tri[p, 0]
            c = o[:, None] + bary[None, :, :1] * a[:, None] + bary[None, :, 1:] * b[:, None]
            yield c.reshape(-1, 3), np.repeat(p, len(bary)), 1.0 / float(s * s)


def _rotation_matrix(value) -> np.ndarray:
    """Validates a 3x3 rotation matrix (orthonormal, det +1); None gives the identity."""
    if value is None:
        return np.eye(3)
    R = np.asarray(value, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1.0e-6):
        raise ParameterError("material_rotation", value, "a 3x3 rotation matrix (orthonormal)")
    if np.linalg.det(R) < 0.0:
        raise ParameterError("material_rotation", value, "a proper rotation (determinant +1)")
    return R
