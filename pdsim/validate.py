"""Validation helpers shared by every part of pdsim: each raises ParameterError naming the field, the value given and
what is allowed."""

from __future__ import annotations

import math

import numpy as np

from .errors import ParameterError


def check_range(field: str, value: float, lo: float | None, hi: float | None, *, lo_open=True, hi_open=True) -> float:
    """Return ``value`` as float, or raise ParameterError naming the field, value and allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(field, value, "a real number") from None
    if not math.isfinite(v):
        raise ParameterError(field, value, "a finite real number")
    below = lo is not None and (v <= lo if lo_open else v < lo)
    above = hi is not None and (v >= hi if hi_open else v > hi)
    if below or above:
        left = "-inf" if lo is None else f"{lo:g}"
        right = "inf" if hi is None else f"{hi:g}"
        lb = "(" if lo_open or lo is None else "["
        rb = ")" if hi_open or hi is None else "]"
        raise ParameterError(field, value, f"{lb}{left}, {right}{rb}")
    return v


def check_vec3(field: str, value) -> np.ndarray:
    """Three finite numbers as a float64 array of shape [3]."""
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(field, value, "a sequence of 3 finite numbers") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ParameterError(field, value, "a sequence of 3 finite numbers")
    return v


def check_axes(field: str, axes: str) -> np.ndarray:
    """A non-empty combination of 'x', 'y', 'z' as a 0/1 mask of shape [3]."""
    if not isinstance(axes, str) or not axes or any(a not in "xyz" for a in axes) or len(set(axes)) != len(axes):
        raise ParameterError(field, axes, "a non-empty combination of 'x', 'y', 'z'")
    return np.array([float(c in axes) for c in "xyz"])


def check_frames(frames) -> int:
    """Validates a frame count (an integer >= 1)."""
    if isinstance(frames, bool) or not isinstance(frames, int | np.integer) or frames < 1:
        raise ParameterError("frames", frames, "an integer >= 1")
    return int(frames)


def check_time_step(dt: float) -> float:
    """Validates a user time step [s] (> 0)."""
    return check_range("dt", dt, 0.0, None)
