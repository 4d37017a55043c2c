"""Loads and time curves, shared by every method with mass.

A load is declared on a body (``body.add_traction(...)`` and friends, see pdsim/bodies.py) and scaled over time by a
:class:`TimeCurve`. When the solver is built, each body turns its loads into forces on its points [N] (the method
decides how a surface load reaches its points: peridynamic particles nearest to each loaded surface triangle, FEM
vertices of each loaded boundary face); from then on the shared kernels (kernels/integration.py) add
``curve(t) * force`` to the points every step, with nothing evaluated on the host.

Kinds:

- :class:`BodyForce`: a constant acceleration field [m/s^2] (force m a on every point of a region, or of the body).
- :class:`SurfaceTraction`: a traction vector [Pa] on the part of the body's surface inside a region.
- :class:`SurfacePressure`: a pressure [Pa] on the part of the body's surface inside a region, along the inward normal.
- :class:`RegionForce`: a total force [N] spread over the points of a region in proportion to their mass.
- :class:`PointForce`: a force [N] on the point nearest to a location.
- :class:`VelocityKick`: a velocity change [m/s] given to the points of a region (or the body) at one time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .checks import check_range, check_vec3
from .errors import ParameterError
from .regions import region_mask


class TimeCurve:
    """A piecewise-linear function of time (time [s] -> dimensionless factor), constant beyond its ends.

    Build one with :meth:`constant`, :meth:`ramp` or :meth:`table`. The solver evaluates it on the device at every
    step, so it must be a table (not a Python callable)."""

    def __init__(self, times, values):
        t = np.asarray(times, dtype=np.float64).ravel()
        v = np.asarray(values, dtype=np.float64).ravel()
        if t.size == 0 or t.shape != v.shape:
            raise ParameterError("curve", (times, values), "times and values of equal, non-zero length")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            raise ParameterError("curve", (times, values), "finite times and values")
        if np.any(np.diff(t) <= 0.0):
            raise ParameterError("curve times", times, "strictly increasing times [s]")
        self.times = t
        self.values = v

    @classmethod
    def constant(cls, value: float = 1.0) -> TimeCurve:
        """The same factor at every time."""
        return cls([0.0], [check_range("value", value, None, None)])

    @classmethod
    def ramp(cls, duration: float, *, start_time: float = 0.0, start: float = 0.0, end: float = 1.0) -> TimeCurve:
        """From ``start`` at ``start_time`` [s] linearly to ``end`` at ``start_time + duration``, then held."""
        d = check_range("duration", duration, 0.0, None)
        t0 = check_range("start_time", start_time, None, None)
        return cls([t0, t0 + d], [check_range("start", start, None, None), check_range("end", end, None, None)])

    @classmethod
    def table(cls, times, values) -> TimeCurve:
        """Linear interpolation between (times [s], values); held constant before the first and after the last."""
        return cls(times, values)

    def __call__(self, t) -> np.ndarray:
        """The factor at time(s) ``t`` [s] (host-side evaluation, for checks and plots)."""
        return np.interp(t, self.times, self.values)

    def __repr__(self) -> str:
        return f"TimeCurve(times={self.times.tolist()}, values={self.values.tolist()})"


def as_curve(curve) -> TimeCurve:
    """None (constant 1), a number (constant) or a TimeCurve."""
    if curve is None:
        return TimeCurve.constant(1.0)
    if isinstance(curve, TimeCurve):
        return curve
    if isinstance(curve, int | float | np.floating | np.integer) and not isinstance(curve, bool):
        return TimeCurve.constant(float(curve))
    raise ParameterError("curve", curve, "None, a number or a pdsim.TimeCurve (constant, ramp or table)")


@dataclass
class BodyForce:
    """Acceleration field [m/s^2] on the points of ``region`` (all points when None)."""

    acceleration: np.ndarray
    region: object = None
    curve: TimeCurve = field(default_factory=TimeCurve.constant)


@dataclass
class SurfaceTraction:
    """Traction [Pa] (force per unit area of the reference surface) on the surface inside ``region``."""

    region: object
    traction: np.ndarray
    curve: TimeCurve = field(default_factory=TimeCurve.constant)


@dataclass
class SurfacePressure:
    """Pressure [Pa] on the surface inside ``region``, pushing along the inward normal (negative: suction)."""

    region: object
    pressure: float
    curve: TimeCurve = field(default_factory=TimeCurve.constant)


@dataclass
class RegionForce:
    """Total force [N] on the points of ``region``, shared in proportion to their mass."""

    region: object
    force: np.ndarray
    curve: TimeCurve = field(default_factory=TimeCurve.constant)


@dataclass
class PointForce:
    """Force [N] on the point nearest to ``location`` [m] (reference configuration)."""

    location: np.ndarray
    force: np.ndarray
    curve: TimeCurve = field(default_factory=TimeCurve.constant)


@dataclass
class VelocityKick:
    """Velocity change [m/s] given at ``time`` [s] to the points of ``region`` (all points when None)."""

    velocity: np.ndarray
    time: float = 0.0
    region: object = None


LOAD_TYPES = (BodyForce, SurfaceTraction, SurfacePressure, RegionForce, PointForce)


class PointLoads:
    """The load API of a body made of points (particles or vertices). A body class provides ``_select(region)``
    (a mask over its points), ``point_masses()`` [kg] and ``surface_point_forces(region, traction, pressure)``."""

    def _init_loads(self):
        self.loads: list = []
        self.kicks: list[VelocityKick] = []

    def add_body_force(self, acceleration, *, region=None, curve=None) -> BodyForce:
        """A constant acceleration field [m/s^2] (e.g. a per-body gravity) on the body or the points of ``region``,
        scaled by ``curve``."""
        load = BodyForce(check_vec3("acceleration", acceleration), region, as_curve(curve))
        if region is not None:
            self._select(region)
        self.loads.append(load)
        return load

    def add_traction(self, region, traction, *, curve=None) -> SurfaceTraction:
        """A traction [Pa] on the part of the body's surface inside ``region``; the total force is the traction times
        that surface's reference area."""
        load = SurfaceTraction(region, check_vec3("traction", traction), as_curve(curve))
        self.surface_point_forces(region, load.traction, 0.0)  # validates: the region must hold surface
        self.loads.append(load)
        return load

    def add_pressure(self, region, pressure: float, *, curve=None) -> SurfacePressure:
        """A pressure [Pa] on the part of the body's surface inside ``region``, along the inward normal."""
        load = SurfacePressure(region, check_range("pressure", pressure, None, None), as_curve(curve))
        self.surface_point_forces(region, np.zeros(3), load.pressure)
        self.loads.append(load)
        return load

    def add_force(self, region, force, *, curve=None) -> RegionForce:
        """A total force [N] on the points of ``region``, shared in proportion to their mass."""
        load = RegionForce(region, check_vec3("force", force), as_curve(curve))
        self._select(region)
        self.loads.append(load)
        return load

    def add_point_force(self, location, force, *, curve=None) -> PointForce:
        """A force [N] on the point nearest to ``location`` [m] (reference configuration)."""
        load = PointForce(check_vec3("location", location), check_vec3("force", force), as_curve(curve))
        self.loads.append(load)
        return load

    def add_velocity_kick(self, velocity, *, time: float = 0.0, region=None) -> VelocityKick:
        """Adds ``velocity`` [m/s] to the points of ``region`` (all points when None) at ``time`` [s] (>= 0)."""
        kick = VelocityKick(
            check_vec3("velocity", velocity), check_range("time", time, 0.0, None, lo_open=False), region
        )
        if region is not None:
            self._select(region)
        self.kicks.append(kick)
        return kick

    def resolved_loads(self, rest_positions: np.ndarray, masses: np.ndarray):
        """Each load as (point indices int64 [k], forces [N] float64 [k, 3], curve), for points at
        ``rest_positions`` [m] with ``masses`` [kg]."""
        out = []
        for load in self.loads:
            if isinstance(load, BodyForce):
                pts = np.flatnonzero(self._mask_or_all(load.region))
                out.append((pts, masses[pts, None] * load.acceleration[None, :], load.curve))
            elif isinstance(load, SurfaceTraction):
                pts, f = self.surface_point_forces(load.region, load.traction, 0.0)
                out.append((pts, f, load.curve))
            elif isinstance(load, SurfacePressure):
                pts, f = self.surface_point_forces(load.region, np.zeros(3), load.pressure)
                out.append((pts, f, load.curve))
            elif isinstance(load, RegionForce):
                pts = np.flatnonzero(self._select(load.region))
                share = masses[pts] / masses[pts].sum()
                out.append((pts, share[:, None] * load.force[None, :], load.curve))
            elif isinstance(load, PointForce):
                d = np.linalg.norm(rest_positions - load.location[None, :], axis=1)
                pts = np.array([int(np.argmin(d))])
                out.append((pts, load.force[None, :].copy(), load.curve))
        return out

    def kick_points(self, kick: VelocityKick) -> np.ndarray:
        """Indices of the points a velocity kick acts on."""
        return np.flatnonzero(self._mask_or_all(kick.region))

    def _mask_or_all(self, region) -> np.ndarray:
        if region is None:
            return np.ones(self.point_count, dtype=bool)
        return self._select(region)


def surface_forces_from_triangles(
    vertices: np.ndarray, faces: np.ndarray, region, traction: np.ndarray, pressure: float, field_name: str = "region"
):
    """Forces [N] on the triangles of a closed surface whose centroid lies in ``region``: traction times area, minus
    pressure times area times the outward unit normal. Returns (triangle indices, centroids [m], forces [N])."""
    tri = vertices[faces]
    centroids = tri.mean(axis=1)
    mask = region_mask(region, centroids, field=field_name)
    if not mask.any():
        raise ParameterError(field_name, region, "a region that contains part of the body's surface")
    idx = np.flatnonzero(mask)
    cross = np.cross(tri[idx, 1] - tri[idx, 0], tri[idx, 2] - tri[idx, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.maximum(2.0 * area, 1.0e-300)[:, None]
    forces = area[:, None] * traction[None, :] - pressure * area[:, None] * normal
    return idx, centroids[idx], forces


__all__ = [
    "LOAD_TYPES",
    "BodyForce",
    "PointForce",
    "PointLoads",
    "RegionForce",
    "SurfacePressure",
    "SurfaceTraction",
    "TimeCurve",
    "VelocityKick",
    "as_curve",
    "surface_forces_from_triangles",
]
