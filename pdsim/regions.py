"""Regions that select particles by their reference position (for boundary conditions).

A region is any object with ``contains(points) -> bool mask`` evaluated on reference positions [m], shape [n, 3]; plain
callables with that signature are accepted too. Evaluation is vectorised numpy over all particles of a body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ParameterError


@dataclass(frozen=True)
class BoxRegion:
    """Axis-aligned box [lo, hi] [m] (inclusive)."""

    lo: tuple
    hi: tuple

    def contains(self, points: np.ndarray) -> np.ndarray:
        lo = np.asarray(self.lo, dtype=np.float64)
        hi = np.asarray(self.hi, dtype=np.float64)
        return np.all((points >= lo) & (points <= hi), axis=1)


@dataclass(frozen=True)
class SphereRegion:
    """Ball of ``radius`` [m] around ``center`` [m] (inclusive)."""

    center: tuple
    radius: float

    def contains(self, points: np.ndarray) -> np.ndarray:
        return np.linalg.norm(points - np.asarray(self.center, dtype=np.float64), axis=1) <= self.radius


@dataclass(frozen=True)
class HalfSpace:
    """Points with (x - point) . normal >= 0, i.e. on the side the normal points to."""

    point: tuple
    normal: tuple

    def contains(self, points: np.ndarray) -> np.ndarray:
        n = np.asarray(self.normal, dtype=np.float64)
        return (points - np.asarray(self.point, dtype=np.float64)) @ n >= 0.0


def region_mask(region, points: np.ndarray, *, field: str = "region") -> np.ndarray:
    """Evaluates a region (object with ``contains`` or a callable) on points [n, 3]; returns a bool mask [n]."""
    fn = getattr(region, "contains", region)
    if not callable(fn):
        raise ParameterError(
            field, region, "a region (BoxRegion, SphereRegion, HalfSpace) or a callable points -> mask"
        )
    mask = np.asarray(fn(points))
    if mask.shape != (len(points),) or mask.dtype != np.bool_:
        raise ParameterError(field, region, f"a region whose mask is a bool array of shape ({len(points)},)")
    return mask
