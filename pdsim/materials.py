"""Material definitions: elastic constants now, with room for yield and fracture fields."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ParameterError


def _check_range(field: str, value: float, lo: float | None, hi: float | None, *, lo_open=True, hi_open=True) -> float:
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


@dataclass(frozen=True)
class Material:
    """An isotropic linear-elastic solid.

    Args:
        density: mass density rho [kg/m^3], > 0.
        youngs_modulus: Young's modulus E [Pa], > 0.
        poisson_ratio: Poisson's ratio nu [-], in (-1, 0.5).
        name: optional label used in output.

    Yield and fracture parameters are added by the plasticity and fracture features; a material without them is purely
    elastic and the solver allocates and launches nothing for those features.
    """

    density: float
    youngs_modulus: float
    poisson_ratio: float
    name: str = "material"

    def __post_init__(self):
        object.__setattr__(self, "density", _check_range("density", self.density, 0.0, None))
        object.__setattr__(self, "youngs_modulus", _check_range("youngs_modulus", self.youngs_modulus, 0.0, None))
        object.__setattr__(self, "poisson_ratio", _check_range("poisson_ratio", self.poisson_ratio, -1.0, 0.5))

    @property
    def bulk_modulus(self) -> float:
        """kappa = E / (3 (1 - 2 nu)) [Pa]."""
        return self.youngs_modulus / (3.0 * (1.0 - 2.0 * self.poisson_ratio))

    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) [Pa]."""
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))

    @property
    def lame_lambda(self) -> float:
        """lambda = kappa - 2 mu / 3 [Pa]."""
        return self.bulk_modulus - 2.0 * self.shear_modulus / 3.0

    @property
    def p_wave_modulus(self) -> float:
        """M = kappa + 4 mu / 3 = lambda + 2 mu [Pa]."""
        return self.bulk_modulus + 4.0 * self.shear_modulus / 3.0

    @property
    def p_wave_speed(self) -> float:
        """Dilatational (P) wave speed sqrt(M / rho) [m/s]."""
        return math.sqrt(self.p_wave_modulus / self.density)

    @property
    def bar_wave_speed(self) -> float:
        """Thin-bar (one-dimensional stress) wave speed sqrt(E / rho) [m/s]."""
        return math.sqrt(self.youngs_modulus / self.density)

    @property
    def shear_wave_speed(self) -> float:
        """Shear (S) wave speed sqrt(mu / rho) [m/s]."""
        return math.sqrt(self.shear_modulus / self.density)


# A few presets with round numbers; soft enough that animation time steps stay affordable.
RUBBER = Material(density=1100.0, youngs_modulus=5.0e6, poisson_ratio=0.45, name="rubber")
SOFT_SOLID = Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, name="soft_solid")
