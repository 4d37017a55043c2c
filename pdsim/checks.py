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


def format_bytes(n: float) -> str:
    """A byte count for messages: '512 B', '3.4 MB', '18.2 GB' (decimal units)."""
    n = float(n)
    for unit, size in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def unit_hint(size: float, length: float, *, what: str = "spacing", count: float | None = None) -> str:
    """A hint for a body whose ``size`` [m] (largest extent) and discretisation ``length`` [m] (particle spacing or
    element edge) look 1000x off, as a sentence starting with '; ' to append to a message, or '' when they do not.

    Two slips give such numbers: a mesh modelled in millimetres read as metres (1000x too large: far too many
    points) and a spacing given in millimetres (1000x too large: larger than the body). ``count`` is the number of
    points or elements this gives, for the message."""
    size, length = float(size), float(length)
    if not (size > 0.0 and length > 0.0 and math.isfinite(size) and math.isfinite(length)):
        return ""
    per_axis = size / length
    counted = "" if count is None else f": {count:.3g} {'particles' if what == 'spacing' else 'elements'}"
    if 3.0e3 <= per_axis <= 1.0e7:
        return (
            f"; the mesh is {size:.3g} m across with {what} {length:.3g} m{counted}; did you mean millimetres? "
            f"(a mesh modelled in millimetres is 1000x too large read as metres: load_mesh(..., scale=0.001))"
        )
    if per_axis < 0.2 and 3.0 <= per_axis * 1.0e3 <= 2.0e3:
        return (
            f"; the mesh is {size:.3g} m across with {what} {length:.3g} m; did you mean millimetres? "
            f"({what}={length / 1.0e3:.3g} m; or, for a mesh 1000x too small, load_mesh(..., scale=1000))"
        )
    return ""
