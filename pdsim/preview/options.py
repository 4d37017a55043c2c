"""Options of the preview that are not the camera: the output suffixes, the image size and the frame selection."""

from __future__ import annotations

import numpy as np

from ..errors import ParameterError

SUFFIXES = (".png", ".gif", ".mp4")
MAX_SIZE = 8192  # largest image side [pixels]
FIT_MODES = ("auto", "all", "selected", "first")  # what the automatic camera is fitted to (see render_cache)
FIT_REACH = 0.5  # fit="auto": how far past the rest pose the box reaches, in the rest pose's largest extent
POINTS_MODES = ("auto", "all", "none")  # which UsdGeom.Points prims are drawn (see render_cache)


def parse_size(spec: str | tuple[int, int] | None) -> tuple[int, int]:
    """``"WxH"`` (pixels, 16..8192 each) -> (W, H); None gives (640, 480)."""
    if spec is None:
        return 640, 480
    allowed = f"'WIDTHxHEIGHT' in pixels, each an integer from 16 to {MAX_SIZE} (e.g. 640x480)"
    if isinstance(spec, str):
        parts = spec.lower().split("x")
        try:
            w, h = (int(p) for p in parts)
        except ValueError:
            raise ParameterError("size", spec, allowed) from None
    else:
        w, h = spec
    if not (16 <= w <= MAX_SIZE and 16 <= h <= MAX_SIZE):
        raise ParameterError("size", spec, allowed)
    return int(w), int(h)


def parse_frames(spec: str | int | None, available: list[int], *, default: str = "all") -> list[int]:
    """Frame numbers selected by ``spec`` among the cache's consecutive frame numbers ``available``.

    ``spec``: ``"N"`` one frame; ``"A:B"`` or ``"A:B:STEP"`` frames A, A + STEP, ... before B (A inclusive, B
    exclusive, like Python slices; A defaults to the first frame, B to one past the last). Negative values count
    from the end (-1 is the last frame). None selects ``default``: ``"all"`` frames or the ``"last"`` one. A frame
    outside the cache or an empty selection raises ParameterError("frames", ...).
    """
    first, last = available[0], available[-1]
    if spec is None:
        return list(available) if default == "all" else [last]
    allowed = (
        f"a frame N or a range A:B[:STEP] with {first} <= N <= {last} and {first} <= A < B <= {last + 1} "
        "(A inclusive, B exclusive, like Python slices; negative values count from the end)"
    )

    def value(text: str) -> int:
        v = int(text)
        return v + last + 1 if v < 0 else v

    try:
        parts = [str(int(spec))] if isinstance(spec, int | np.integer) else [p.strip() for p in str(spec).split(":")]
        if len(parts) == 1:
            n = value(parts[0])
            if not first <= n <= last:
                raise ParameterError("frames", spec, allowed)
            return [n]
        if len(parts) > 3:
            raise ParameterError("frames", spec, allowed)
        a = value(parts[0]) if parts[0] else first
        b = value(parts[1]) if parts[1] else last + 1
        step = int(parts[2]) if len(parts) == 3 and parts[2] else 1
    except ValueError:
        raise ParameterError("frames", spec, allowed) from None
    if step < 1 or not (first <= a < b <= last + 1):
        raise ParameterError("frames", spec, allowed)
    return list(range(a, b, step))
