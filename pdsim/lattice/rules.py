"""Follower rules (``LatticeRule`` and its subclasses: which Warp functions of kernels/lattice/rules.py a body's
follower kernel is built from, and their parameter block) and link fracture (``LatticeFracture``) of the
position-based particle lattice."""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass

import numpy as np

from ..checks import check_range
from ..errors import ParameterError
from ..kernels.lattice import rules as kl


# ------------------------------------------------------------------------------------------------------------- rules
@dataclass(frozen=True, kw_only=True)
class LatticeRule:
    """A follower rule: u_j <- update(c, u_j, X_j) with c the weighted centroid of j's neighbours (relative to X_j).

    Subclasses name two Warp functions (``warp_functions``) with the signatures of ``lattice_weight_uniform``
    (delta, rest_delta, shell, params) -> weight and ``lattice_update_centroid`` (centroid, u_old, rest, params) ->
    new displacement in kernels/lattice/rules.py, and fill the parameter block (``parameters``); a custom rule is a
    subclass with its own ``@wp.func`` pair. The solver compiles one follower kernel per pair.

    Args:
        relaxation: omega in (0, 2): u_new = u_old + omega (target - u_old). 1 (default) places the follower on its
            target as in the paper; > 1 overshoots (the paper's suggested route to oscillation), < 1 lags.
    """

    relaxation: float = 1.0

    def __post_init__(self):
        check_range("relaxation", self.relaxation, 0.0, 2.0)

    def warp_functions(self):
        """(weight function, update function) as Warp ``@wp.func`` objects."""
        return kl.lattice_weight_uniform, kl.lattice_update_centroid

    def parameters(self, body) -> tuple:
        """(scalars[4], axis[3], origin[3]) of the parameter block for ``body`` (a LatticeBody)."""
        return (self.relaxation, 0.0, 1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)


@dataclass(frozen=True, kw_only=True)
class LatticeRuleCentroid(LatticeRule):
    """x_j(t) = sum_k w_k x_k(t - 1) / sum_k w_k: the centre of gravity of the neighbours (w_k = shell weight)."""


@dataclass(frozen=True, kw_only=True)
class LatticeRuleDistanceWeighted(LatticeRule):
    """x_j(t) = sum_k w_k dis(k, j)^p x_k / sum_k w_k dis(k, j)^p with dis the current distance [m]: farther
    neighbours pull harder (the paper's Hooke-like rule has p = 1).

    Args:
        exponent: p in [0, 4], one value for every shell or (p1, p2) per shell (p = 0: no distance weighting in
            that shell).
    """

    exponent: float | tuple = 1.0

    def __post_init__(self):
        super().__post_init__()
        p = np.atleast_1d(np.asarray(self.exponent, dtype=np.float64))
        if p.ndim != 1 or len(p) not in (1, 2) or not np.all(np.isfinite(p)) or np.any((p < 0) | (p > 4)):
            raise ParameterError("exponent", self.exponent, "1 or 2 numbers in [0, 4] (per shell)")

    def warp_functions(self):
        return kl.lattice_weight_distance, kl.lattice_update_centroid

    def parameters(self, body):
        p = np.atleast_1d(np.asarray(self.exponent, dtype=np.float64))
        return (self.relaxation, 0.0, float(p[0]), float(p[-1])), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)


@dataclass(frozen=True, kw_only=True)
class LatticeRuleMixedCoordinate(LatticeRule):
    """The mixed-coordinate (Poisson) rule: the axial coordinate is the centroid's; each lateral coordinate is the
    centroid's minus k (u_j . a) d_j, with u_j . a the follower's new axial displacement [m] and d_j its rest offset
    from the axis, perpendicular to it [m] (the paper's y_j = K (x_j(t) - x_j(t0)) da + mean y; k > 0 contracts a body
    stretched along the axis).

    Args:
        k: K [1/m], a finite number; 0 is the centroid rule.
        axis: direction of the axis (normalised), default x.
        origin: a point of the axis [m]; default the centre of the body's rest bounding box.
    """

    k: float = 0.01
    axis: tuple = (1.0, 0.0, 0.0)
    origin: tuple | None = None

    def __post_init__(self):
        super().__post_init__()
        check_range("k", self.k, None, None)
        a = np.asarray(self.axis, dtype=np.float64)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
            raise ParameterError("axis", self.axis, "3 finite numbers, not all zero")
        if self.origin is not None:
            o = np.asarray(self.origin, dtype=np.float64)
            if o.shape != (3,) or not np.all(np.isfinite(o)):
                raise ParameterError("origin", self.origin, "3 finite numbers [m] or None")

    def warp_functions(self):
        return kl.lattice_weight_uniform, kl.lattice_update_mixed_coordinate

    def parameters(self, body):
        a = np.asarray(self.axis, dtype=np.float64)
        a = a / np.linalg.norm(a)
        if self.origin is None:
            x = body.rest_positions[: body.body_count]
            o = 0.5 * (x.min(axis=0) + x.max(axis=0))
        else:
            o = np.asarray(self.origin, dtype=np.float64)
        return (self.relaxation, self.k, 1.0, 0.0), tuple(a), tuple(o)


# ------------------------------------------------------------------------------------------------------------ fracture
@dataclass(frozen=True)
class LatticeFracture:
    """Links are lost when their current length exceeds a threshold; fictitious points then balance the rule.

    Args:
        distances: threshold length [m] per shell, (d1,) or (d1, d2); a single number applies to every shell. Each
            must exceed the longest rest link of its shell.
        fictitious_distance: s > 0: a broken link k of particle j is replaced in j's rule by a fictitious point at
            x_j + s (X_k - X_j), the original lattice offset scaled by s (it moves with j). s = 1 (default) gives
            elastic-like fracture edges (a detached piece recovers its shape), s != 1 plastic-like ones (the edge
            layer stays contracted, s < 1, or loosened, s > 1). None: no fictitious points, the link simply drops
            out of the rule (edges then collapse inwards, as the paper's frame is meant to prevent).
    """

    distances: tuple | float
    _: KW_ONLY
    fictitious_distance: float | None = 1.0

    def __post_init__(self):
        d = np.atleast_1d(np.asarray(self.distances, dtype=np.float64))
        if d.ndim != 1 or len(d) not in (1, 2) or not np.all(np.isfinite(d)) or np.any(d <= 0):
            raise ParameterError("distances", self.distances, "1 or 2 finite lengths > 0 [m] (per shell)")
        if self.fictitious_distance is not None:
            check_range("fictitious_distance", self.fictitious_distance, 0.0, 4.0)

    def thresholds(self) -> tuple[float, float]:
        """(d1, d2) [m]."""
        d = np.atleast_1d(np.asarray(self.distances, dtype=np.float64))
        return float(d[0]), float(d[-1])
