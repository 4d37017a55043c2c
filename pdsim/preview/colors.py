"""Colours of the preview: the base colours, the viridis ramp and the categorical palette, and how primvar values
become colours (``Coloring``). Colours are sRGB in [0, 1]; :func:`linear` converts them for shading (an authored
``displayColor`` is linear RGB already)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NEUTRAL = (0.74, 0.72, 0.68)
CRACK = (0.86, 0.36, 0.16)
BACKGROUND = (0.95, 0.96, 0.97)
AMBIENT = 0.3  # share of the ambient (sky) term in the shading of a surface facing up
MISSING = (0.55, 0.55, 0.55)  # a value that is not finite under a ramp
# Viridis at 9 evenly spaced stops (sRGB).
_RAMP = np.array(
    [
        [0.267, 0.005, 0.329],
        [0.283, 0.141, 0.458],
        [0.254, 0.265, 0.530],
        [0.207, 0.372, 0.553],
        [0.164, 0.471, 0.558],
        [0.128, 0.567, 0.551],
        [0.135, 0.659, 0.518],
        [0.267, 0.749, 0.441],
        [0.478, 0.821, 0.318],
        [0.741, 0.873, 0.150],
        [0.993, 0.906, 0.144],
    ]
)
# A categorical palette of 20 colours (Tableau 20, sRGB) for integer primvars.
_PALETTE = (
    np.array(
        [
            [31, 119, 180],
            [255, 127, 14],
            [44, 160, 44],
            [214, 39, 40],
            [148, 103, 189],
            [140, 86, 75],
            [227, 119, 194],
            [127, 127, 127],
            [188, 189, 34],
            [23, 190, 207],
            [174, 199, 232],
            [255, 187, 120],
            [152, 223, 138],
            [255, 152, 150],
            [197, 176, 213],
            [196, 156, 148],
            [247, 182, 210],
            [199, 199, 199],
            [219, 219, 141],
            [158, 218, 229],
        ]
    )
    / 255.0
)


def linear(srgb) -> np.ndarray:
    """sRGB [0, 1] -> linear (gamma 2.2), float32 of the same shape."""
    return np.power(np.clip(np.asarray(srgb, dtype=np.float32), 0.0, 1.0), 2.2).astype(np.float32)


def ramp_colors(t: np.ndarray) -> np.ndarray:
    """Viridis sRGB colours [..., 3] of values ``t`` in [0, 1] (clipped; NaN gives grey)."""
    t = np.asarray(t, dtype=np.float64)
    bad = ~np.isfinite(t)
    x = np.clip(np.where(bad, 0.0, t), 0.0, 1.0) * (len(_RAMP) - 1)
    k = np.minimum(x.astype(np.int64), len(_RAMP) - 2)
    f = (x - k)[..., None]
    out = (1.0 - f) * _RAMP[k] + f * _RAMP[k + 1]
    out[bad] = MISSING
    return out


def palette_colors(ids: np.ndarray) -> np.ndarray:
    """Categorical sRGB colours [..., 3] of integer ids (cycling through 20 colours)."""
    ids = np.asarray(ids)
    return _PALETTE[np.mod(np.rint(np.nan_to_num(ids)).astype(np.int64), len(_PALETTE))]


@dataclass
class Coloring:
    """How values become colours: a ramp over [lo, hi] for floats, a palette for integers."""

    name: str | None = None
    categorical: bool = False
    lo: float = 0.0
    hi: float = 1.0

    def map(self, values: np.ndarray) -> np.ndarray:
        """sRGB colours [..., 3] of scalar values [...]."""
        if self.categorical:
            return palette_colors(values)
        span = self.hi - self.lo
        t = (np.asarray(values, np.float64) - self.lo) / span if span > 0 else np.full(np.shape(values), 0.5)
        return ramp_colors(t)
