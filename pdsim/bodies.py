"""Bodies made of points (peridynamic particles, FEM vertices): the one boundary-condition API and the kinematic kind
of a point, shared by every method with mass.

A boundary condition holds the points of a region on chosen axes: :meth:`PointBody.fix` keeps them where they are,
:meth:`PointBody.set_velocity` moves them at a prescribed velocity scaled by a time curve. Both act in a window
[start, release) of simulated time, outside which the points are free. A point takes part in at most one condition:
constraining it twice raises ParameterError naming both (combine the axes in one condition instead).
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .checks import check_axes, check_range, check_vec3
from .errors import ParameterError
from .loads import PointLoads, TimeCurve, as_curve

SURFACE_REGION = "a region that contains part of the body's surface"  # what pdsim.loads allows a surface load


class PointKind(IntEnum):
    """Kinematic kind of a point in a step (kernels/integration.py): free, fixed or moved at a prescribed velocity on
    the constrained axes of its boundary condition."""

    FREE = 0
    FIXED = 1
    PRESCRIBED = 2


@dataclass
class BoundaryCondition:
    """One boundary condition of a body: kind, constrained axes (0/1 mask [3]), velocity [m/s] scaled by ``curve``,
    active in [start, release) [s]; ``name`` labels its reaction force in outputs."""

    name: str
    kind: PointKind
    axes: np.ndarray
    velocity: np.ndarray
    curve: TimeCurve
    start: float
    release: float
    point_count: int


class PointBody(PointLoads):
    """Base of the bodies whose state lives on points with mass. A subclass sets ``self.name``, provides
    ``point_count``, ``point_rest_positions`` [m] (float64 [n, 3]) and ``_select(region)`` (bool mask [n], raising
    ParameterError for a region that holds no point), then calls ``_init_points()``."""

    method: str = ""  # "peridynamics", "fem": which solver simulates the body

    def _init_points(self):
        n = self.point_count
        self.conditions: list[BoundaryCondition] = []
        self.point_condition = np.full(n, -1, dtype=np.int32)
        self.initial_velocity = np.zeros((n, 3), dtype=np.float64)
        self._init_loads()

    # -- boundary conditions -------------------------------------------------------------------------------------------
    def fix(self, region, *, axes: str = "xyz", start: float = 0.0, release: float | None = None, name=None) -> int:
        """Holds the points in ``region`` (reference positions) where they are on ``axes`` from ``start`` [s] until
        ``release`` [s] (never released when None); returns how many points."""
        return self._add_condition(
            region, PointKind.FIXED, np.zeros(3), axes=axes, curve=None, start=start, release=release, name=name
        )

    def set_velocity(
        self,
        region,
        velocity,
        *,
        axes: str = "xyz",
        curve=None,
        start: float = 0.0,
        release: float | None = None,
        name=None,
    ) -> int:
        """Moves the points in ``region`` at ``velocity`` [m/s] times ``curve(t)`` (a TimeCurve or a number; 1 when
        None) on ``axes`` ("x" makes a roller grip that pulls along x and leaves y and z free), from ``start`` [s]
        until ``release`` [s], after which they move freely; returns how many points."""
        v = check_vec3("velocity", velocity)
        return self._add_condition(
            region, PointKind.PRESCRIBED, v, axes=axes, curve=curve, start=start, release=release, name=name
        )

    def set_initial_velocity(self, velocity, region=None) -> int:
        """Initial velocity [m/s]: a vector for all points (or those in ``region``), or an array [point_count, 3]."""
        v = np.asarray(velocity, dtype=np.float64)
        n = self.point_count
        if v.shape == (n, 3) and region is None:
            mask = np.ones(n, dtype=bool)
            values = v
        elif v.shape == (3,):
            mask = np.ones(n, dtype=bool) if region is None else self._select(region)
            values = np.broadcast_to(v, (int(mask.sum()), 3))
        else:
            raise ParameterError("velocity", velocity, f"3 numbers or an array of shape ({n}, 3)")
        if not np.all(np.isfinite(values)):
            raise ParameterError("velocity", velocity, "finite values [m/s]")
        self.initial_velocity[mask] = values
        return int(mask.sum())

    def _add_condition(self, region, kind, velocity, *, axes, curve, start, release, name) -> int:
        mask_axes = check_axes("axes", axes)
        t0 = check_range("start", start, 0.0, None, lo_open=False)
        t1 = math.inf if release is None else check_range("release", release, t0, None)
        mask = self._select(region)
        label = name or f"{'fix' if kind == PointKind.FIXED else 'velocity'}_{len(self.conditions)}"
        if any(c.name == label for c in self.conditions):
            raise ParameterError("name", label, f"a condition name not already used on '{self.name}'")
        taken = self.point_condition[mask]
        if np.any(taken >= 0):
            held, counts = np.unique(taken[taken >= 0], return_counts=True)
            others = ", ".join(f"{int(c)} by '{self.conditions[int(i)].name}'" for i, c in zip(held, counts))
            raise ParameterError(
                "region",
                region,
                f"points of '{self.name}' not already constrained: {int(counts.sum())} of the {int(mask.sum())} "
                f"points of the new condition '{label}' are already held ({others}); a point takes one condition: "
                "give one condition the axes of both, or shrink one region",
            )
        self.point_condition[mask] = len(self.conditions)
        self.conditions.append(
            BoundaryCondition(label, PointKind(kind), mask_axes, velocity, as_curve(curve), t0, t1, int(mask.sum()))
        )
        return int(mask.sum())

    # -- loads on the surface: a region that misses the surface names the body -------------------------------------
    def add_traction(self, region, traction, *, curve=None):
        """A traction [Pa] on the part of the body's surface inside ``region`` (see pdsim.loads.PointLoads)."""
        with self._surface_region_named():
            return super().add_traction(region, traction, curve=curve)

    def add_pressure(self, region, pressure: float, *, curve=None):
        """A pressure [Pa] on the part of the body's surface inside ``region`` (see pdsim.loads.PointLoads)."""
        with self._surface_region_named():
            return super().add_pressure(region, pressure, curve=curve)

    @contextmanager
    def _surface_region_named(self):
        """Re-raises the loads' 'a region that contains part of the body's surface' with the body's name and rest
        bounds, so that a region placed in the wrong units or frame shows where the body is."""
        try:
            yield
        except ParameterError as exc:
            if exc.allowed != SURFACE_REGION:
                raise
            x = np.asarray(self.point_rest_positions, dtype=np.float64)
            lo, hi = x.min(axis=0), x.max(axis=0)
            box = f"[{', '.join(f'{c:.3g}' for c in lo)}] to [{', '.join(f'{c:.3g}' for c in hi)}] m"
            raise ParameterError(
                exc.field, exc.value, f"a region that contains part of the surface of '{self.name}' (which spans {box})"
            ) from None

    @property
    def constrained(self) -> np.ndarray:
        """Bool mask of the points held by some boundary condition."""
        return self.point_condition >= 0

    def prescribed_speed(self) -> float:
        """Largest speed a boundary condition or the initial velocity gives a point [m/s]."""
        speeds = [float(np.abs(self.initial_velocity).max(initial=0.0))]
        for c in self.conditions:
            peak = float(np.abs(c.curve.values).max())
            speeds.append(float(np.linalg.norm(c.velocity * c.axes)) * peak)
        for k in self.kicks:
            speeds.append(float(np.linalg.norm(k.velocity)))
        return max(speeds)


__all__ = ["BoundaryCondition", "PointBody", "PointKind"]
