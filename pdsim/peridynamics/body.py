"""Peridynamic bodies: a solid filled with particles on a simple-cubic lattice, its material and its boundary
conditions (the scene-facing part of the peridynamic method)."""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..geometry import SolidShape
from ..materials import Material
from ..regions import region_mask
from ..sampling import fill_solid, morton_order
from ..validate import check_range

SURFACE_CORRECTIONS = ("directional", "family", "none")


class PeridynamicBody:
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

    Particles are sorted along a Morton curve so that neighbours are close in memory.
    """

    def __init__(
        self,
        shape: SolidShape,
        material: Material,
        spacing: float,
        *,
        horizon_factor: float = 3.015,
        name: str | None = None,
        surface_correction: str = "directional",
        partial_volumes: bool = True,
        damping: float = 0.0,
        material_rotation=None,
        device: str = "cpu",
    ):
        if not isinstance(material, Material):
            raise ParameterError("material", material, "a pdsim.Material")
        if not isinstance(shape, SolidShape):
            raise ParameterError("shape", shape, "a pdsim SolidShape (pdsim.box, pdsim.load_mesh, ...)")
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
        self.material_rotation = _rotation_matrix(material_rotation)
        self.notches: list = []  # BoxRegion or SolidShape: bonds crossing them start broken
        positions, volumes = fill_solid(shape, self.spacing, device=device)
        order = morton_order(positions, self.spacing)
        self.rest_positions = positions[order]
        self.volumes = volumes[order]
        n = len(self.rest_positions)
        self.kind = np.zeros(n, dtype=np.int32)
        self.prescribed_velocity = np.zeros((n, 3), dtype=np.float64)
        self.prescribed_axes = np.ones((n, 3), dtype=np.float64)
        self.initial_velocity = np.zeros((n, 3), dtype=np.float64)
        self.unbreakable = np.zeros(n, dtype=bool)

    @property
    def particle_count(self) -> int:
        return len(self.rest_positions)

    @classmethod
    def build_solver(cls, bodies, *, device, gravity, ground, contact=None, colliders=()):
        """The scene's solver for all its peridynamic bodies."""
        from .solver import SolverPeridynamics

        return SolverPeridynamics(
            bodies, device=device, gravity=gravity, ground=ground, contact=contact, colliders=colliders
        )

    @property
    def horizon(self) -> float:
        """delta = horizon_factor * spacing [m]."""
        return self.horizon_factor * self.spacing

    def _select(self, region, field_name: str) -> np.ndarray:
        mask = region_mask(region, self.rest_positions, field=field_name)
        if not mask.any():
            raise ParameterError(field_name, region, f"a region containing at least one particle of '{self.name}'")
        return mask

    def fix(self, region) -> int:
        """Holds the particles whose reference position lies in ``region`` at rest; returns how many."""
        mask = self._select(region, "region")
        self.kind[mask] = 1
        self.prescribed_velocity[mask] = 0.0
        return int(mask.sum())

    def set_velocity(self, region, velocity, *, axes: str = "xyz") -> int:
        """Moves the particles in ``region`` at the constant ``velocity`` [m/s] (a displacement-driven boundary).
        ``axes`` names the prescribed components ("xyz" by default; "x" makes a roller grip that pulls along x and
        leaves y and z free)."""
        v = np.asarray(velocity, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ParameterError("velocity", velocity, "a sequence of 3 finite numbers [m/s]")
        if not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
            raise ParameterError("axes", axes, "a non-empty combination of 'x', 'y', 'z'")
        mask = self._select(region, "region")
        self.kind[mask] = 2
        self.prescribed_velocity[mask] = v
        self.prescribed_axes[mask] = [float(c in axes) for c in "xyz"]
        return int(mask.sum())

    def add_notch(self, cut) -> None:
        """Pre-cut: every bond whose reference segment crosses ``cut`` (a BoxRegion, e.g. a thin slab; a SolidShape's
        surface; or an open triangle surface given as (vertices, faces)) starts broken. Needs a material that breaks
        or a scene that tracks damage; any body with a notch is simulated with fracture on."""
        from ..geometry import SolidShape as _Shape
        from ..regions import BoxRegion

        if isinstance(cut, tuple) and len(cut) == 2:  # an open surface: (vertices [n, 3], triangles [m, 3])
            v = np.asarray(cut[0], dtype=np.float64)
            f = np.asarray(cut[1], dtype=np.int64)
            if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or f.size == 0:
                raise ParameterError("cut", "(vertices, faces)", "arrays of shape [n, 3] and [m, 3], m >= 1")
            cut = _Shape(vertices=v, faces=f.astype(np.int32), name="notch")
        if not isinstance(cut, BoxRegion | _Shape):
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

    def set_initial_velocity(self, velocity, region=None) -> int:
        """Initial velocity [m/s]: a vector for all particles (or those in ``region``), or an array [n, 3]."""
        v = np.asarray(velocity, dtype=np.float64)
        if v.shape == (self.particle_count, 3) and region is None:
            mask = np.ones(self.particle_count, dtype=bool)
            values = v
        elif v.shape == (3,):
            mask = np.ones(self.particle_count, dtype=bool) if region is None else self._select(region, "region")
            values = np.broadcast_to(v, (int(mask.sum()), 3))
        else:
            raise ParameterError("velocity", velocity, f"3 numbers or an array of shape ({self.particle_count}, 3)")
        if not np.all(np.isfinite(values)):
            raise ParameterError("velocity", velocity, "finite values")
        self.initial_velocity[mask] = values
        return int(mask.sum())


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
