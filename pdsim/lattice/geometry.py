"""Geometry of the position-based particle lattice (dell'Erba 2018): the Bravais
lattices (``LatticeType``, ``Lattice``) and the Lagrangian neighbourhoods of their points (``LatticeNeighbourhood``).
Lengths are in metres; integer lattice coordinates c give the points origin + sum_i c_i a_i."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..checks import check_range
from ..errors import ParameterError

MAX_OFFSETS = 255  # per-link offset ids are uint8
_TOL = 1.0e-6  # relative tolerance for lattice-vector comparisons


class LatticeType(str, Enum):
    """The five plane Bravais lattices and three cubic lattices."""

    SQUARE = "square"
    HEXAGONAL = "hexagonal"
    RECTANGULAR = "rectangular"
    CENTRED_RECTANGULAR = "centred_rectangular"
    OBLIQUE = "oblique"
    SIMPLE_CUBIC = "simple_cubic"
    BODY_CENTRED_CUBIC = "body_centred_cubic"
    FACE_CENTRED_CUBIC = "face_centred_cubic"


# ------------------------------------------------------------------------------------------------------------ lattices
@dataclass(frozen=True, eq=False)
class Lattice:
    """A Bravais lattice: points origin + sum_i c_i a_i for integer c.

    Attributes:
        type: which lattice.
        basis: primitive vectors a_i [m], shape [dim, 3] (2D lattices lie in the z = 0 plane).
        spacing: nearest-neighbour distance h [m].
    """

    type: LatticeType
    basis: np.ndarray
    spacing: float

    @property
    def dim(self) -> int:
        """2 for the plane lattices, 3 for the cubic ones."""
        return int(self.basis.shape[0])

    @property
    def basis_matrix(self) -> np.ndarray:
        """The basis restricted to its dimension, shape [dim, dim] [m] (rows are the vectors)."""
        return self.basis[:, : self.dim]

    # -- constructors -----------------------------------------------------------------------------------------------
    @classmethod
    def square(cls, spacing: float) -> Lattice:
        """Square lattice of side ``spacing`` [m] (coordination number 4)."""
        h = check_range("spacing", spacing, 0.0, None)
        return cls(LatticeType.SQUARE, np.array([[h, 0.0, 0.0], [0.0, h, 0.0]]), h)

    @classmethod
    def hexagonal(cls, spacing: float) -> Lattice:
        """Hexagonal (triangular) lattice, nearest-neighbour distance ``spacing`` [m], rows along x (coordination 6)."""
        h = check_range("spacing", spacing, 0.0, None)
        return cls(LatticeType.HEXAGONAL, np.array([[h, 0.0, 0.0], [0.5 * h, 0.5 * math.sqrt(3.0) * h, 0.0]]), h)

    @classmethod
    def rectangular(cls, spacing: float, *, aspect: float = 1.5) -> Lattice:
        """Rectangular lattice: ``spacing`` [m] along x, ``aspect`` x ``spacing`` along y; aspect in [0.25, 4]."""
        h = check_range("spacing", spacing, 0.0, None)
        r = check_range("aspect", aspect, 0.25, 4.0, lo_open=False, hi_open=False)
        return cls(LatticeType.RECTANGULAR, np.array([[h, 0.0, 0.0], [0.0, r * h, 0.0]]), h * min(1.0, r))

    @classmethod
    def centred_rectangular(cls, spacing: float, *, aspect: float = 1.5) -> Lattice:
        """Centred rectangular lattice: a rectangular cell ``spacing`` x ``aspect`` ``spacing`` [m] with a point at its
        centre (primitive vectors (a, 0) and (a/2, b/2)); aspect in [0.25, 4], != sqrt(3) (that is hexagonal)."""
        h = check_range("spacing", spacing, 0.0, None)
        r = check_range("aspect", aspect, 0.25, 4.0, lo_open=False, hi_open=False)
        if abs(r - math.sqrt(3.0)) < 1.0e-9:
            raise ParameterError("aspect", aspect, "[0.25, 4] except sqrt(3) (use Lattice.hexagonal)")
        basis = np.array([[h, 0.0, 0.0], [0.5 * h, 0.5 * r * h, 0.0]])
        return cls(LatticeType.CENTRED_RECTANGULAR, basis, float(min(h, np.linalg.norm(basis[1]))))

    @classmethod
    def oblique(cls, spacing: float, *, ratio: float = 1.2, angle: float = 75.0) -> Lattice:
        """Oblique lattice: a1 = (spacing, 0), a2 of length ``ratio`` x ``spacing`` at ``angle`` degrees from a1;
        ratio in [0.5, 2], angle in [30, 150]."""
        h = check_range("spacing", spacing, 0.0, None)
        r = check_range("ratio", ratio, 0.5, 2.0, lo_open=False, hi_open=False)
        g = math.radians(check_range("angle", angle, 30.0, 150.0, lo_open=False, hi_open=False))
        basis = np.array([[h, 0.0, 0.0], [r * h * math.cos(g), r * h * math.sin(g), 0.0]])
        return cls(LatticeType.OBLIQUE, basis, h * min(1.0, r))

    @classmethod
    def simple_cubic(cls, spacing: float) -> Lattice:
        """Simple cubic lattice of side ``spacing`` [m] (coordination number 6)."""
        h = check_range("spacing", spacing, 0.0, None)
        return cls(LatticeType.SIMPLE_CUBIC, np.eye(3) * h, h)

    @classmethod
    def body_centred_cubic(cls, spacing: float) -> Lattice:
        """Body-centred cubic lattice of cube side ``spacing`` [m] (nearest neighbours at sqrt(3)/2 spacing)."""
        h = check_range("spacing", spacing, 0.0, None)
        basis = np.array([[h, 0.0, 0.0], [0.0, h, 0.0], [0.5 * h, 0.5 * h, 0.5 * h]])
        return cls(LatticeType.BODY_CENTRED_CUBIC, basis, 0.5 * math.sqrt(3.0) * h)

    @classmethod
    def face_centred_cubic(cls, spacing: float) -> Lattice:
        """Face-centred cubic lattice of cube side ``spacing`` [m] (nearest neighbours at spacing / sqrt(2))."""
        h = check_range("spacing", spacing, 0.0, None)
        basis = 0.5 * h * np.array([[0.0, 1.0, 1.0], [1.0, 0.0, 1.0], [1.0, 1.0, 0.0]])
        return cls(LatticeType.FACE_CENTRED_CUBIC, basis, h / math.sqrt(2.0))

    # -- geometry ---------------------------------------------------------------------------------------------------
    def vectors(self, coords: np.ndarray) -> np.ndarray:
        """Cartesian vectors [m], shape [n, 3], of integer lattice coordinates ``coords`` [n, dim]."""
        return np.asarray(coords, dtype=np.float64) @ self.basis

    def candidate_offsets(self, length: float) -> np.ndarray:
        """Every nonzero integer offset whose lattice vector is at most ``length`` [m] long, shape [m, dim]."""
        inv = np.linalg.inv(self.basis_matrix)
        r = math.ceil(length * np.abs(inv).sum(axis=0).max()) + 1
        axes = [np.arange(-r, r + 1)] * self.dim
        c = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
        c = c[np.any(c != 0, axis=1)]
        v = self.vectors(c)
        return c[np.linalg.norm(v, axis=1) <= length * (1.0 + _TOL)]

    def coordination_offsets(self) -> np.ndarray:
        """Integer offsets to the lattice's Voronoi-relevant neighbours (the faces of the Wigner-Seitz cell): square 4,
        rectangular 4, hexagonal 6, centred rectangular 6, oblique 6, simple cubic 6, BCC 14, FCC 12. A vector v is
        relevant when v/2 is strictly closer to 0 and v than to any other lattice point."""
        longest = float(np.linalg.norm(self.basis, axis=1).max())
        c = self.candidate_offsets(2.0 * longest * math.sqrt(self.dim))
        v = self.vectors(c)
        n2 = np.einsum("ij,ij->i", v, v)
        # relevant iff |w|^2 - v.w > 0 for every w != v (w = 0 excluded already)
        gap = n2[None, :] - v @ v.T
        np.fill_diagonal(gap, np.inf)
        relevant = np.all(gap > _TOL * self.spacing**2, axis=1)
        return c[relevant]


# ------------------------------------------------------------------------------------------------------ neighbourhoods
NEIGHBOURHOOD_METRICS = ("coordination", "chebyshev", "euclidean")


@dataclass(frozen=True, kw_only=True)
class LatticeNeighbourhood:
    """Which lattice points are a particle's Lagrangian neighbours (fixed at t0).

    Args:
        metric: "coordination" (shell 1 = the lattice's coordination neighbours, the faces of its Wigner-Seitz cell;
            shell 2 = their neighbours, i.e. graph distance 2), "chebyshev" (shell n = points at Chebyshev distance
            max_a |dx_a| / s_a in ((n - 1) c, n c], c the largest Chebyshev norm of a coordination neighbour: the
            paper's Figure 3 for the square lattice) or "euclidean" (shell n = points at weighted Euclidean distance
            |dx / s| in ((n - 1) r, n r]).
        gradient: 1 (first gradient: one shell) or 2 (second gradient: two shells).
        radius: r [m] of the "euclidean" metric; default the coordination shell's longest vector.
        metric_scale: per-axis scales s (x, y, z) of the chebyshev and euclidean metrics, each > 0: an anisotropic
            metric reaching s_a times farther along axis a. Default isotropic.
        shell_weights: static weight of the neighbours of each shell in the rules (w1, w2), each > 0.
    """

    metric: str = "coordination"
    gradient: int = 1
    radius: float | None = None
    metric_scale: tuple = (1.0, 1.0, 1.0)
    shell_weights: tuple = (1.0, 1.0)

    def __post_init__(self):
        if self.metric not in NEIGHBOURHOOD_METRICS:
            raise ParameterError("metric", self.metric, " or ".join(map(repr, NEIGHBOURHOOD_METRICS)))
        if isinstance(self.gradient, bool) or self.gradient not in (1, 2):
            raise ParameterError("gradient", self.gradient, "1 (first gradient) or 2 (second gradient)")
        if self.radius is not None:
            check_range("radius", self.radius, 0.0, None)
        s = np.asarray(self.metric_scale, dtype=np.float64)
        if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ParameterError("metric_scale", self.metric_scale, "3 finite numbers > 0")
        w = np.asarray(self.shell_weights, dtype=np.float64)
        if w.shape != (2,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ParameterError("shell_weights", self.shell_weights, "2 finite numbers > 0 (shell 1, shell 2)")

    def offsets(self, lattice: Lattice) -> tuple[np.ndarray, np.ndarray]:
        """Neighbour offsets of ``lattice``: integer offsets [m, dim] and their shell (0 or 1) [m], sorted by shell
        and length, each offset o directly followed by -o."""
        coord = lattice.coordination_offsets()
        dim = lattice.dim
        if self.metric == "coordination":
            shells = [coord]
            if self.gradient == 2:
                s2 = (coord[:, None, :] + coord[None, :, :]).reshape(-1, dim)
                s2 = np.unique(s2, axis=0)
                known = {tuple(c) for c in coord}
                keep = np.array([np.any(c != 0) and tuple(c) not in known for c in s2], dtype=bool)
                shells.append(s2[keep])
        else:
            scale = np.asarray(self.metric_scale, dtype=np.float64)[:dim]
            if self.metric == "chebyshev":
                unit = float(np.abs(lattice.vectors(coord)[:, :dim] / scale).max(axis=1).max())

                def norm(v):
                    return np.abs(v / scale).max(axis=1)

            else:
                unit = (
                    float(self.radius)
                    if self.radius is not None
                    else float(np.linalg.norm(lattice.vectors(coord), axis=1).max())
                )

                def norm(v):
                    return np.linalg.norm(v / scale, axis=1)

            reach = self.gradient * unit * float(scale.max()) * math.sqrt(dim)
            cand = lattice.candidate_offsets(reach)
            rho = norm(lattice.vectors(cand)[:, :dim]) / unit
            shells = [cand[rho <= 1.0 + _TOL]]
            if self.gradient == 2:
                shells.append(cand[(rho > 1.0 + _TOL) & (rho <= 2.0 + _TOL)])
        offs, shell = [], []
        for s, c in enumerate(shells):
            if len(c) == 0:
                raise ParameterError("radius", self.radius, "a radius that gives every shell at least one neighbour")
            pairs = _paired(lattice, c)
            offs.append(pairs)
            shell.append(np.full(len(pairs), s, dtype=np.int32))
        offs = np.concatenate(offs)
        if len(offs) > MAX_OFFSETS:
            raise ParameterError("neighbourhood", self, f"at most {MAX_OFFSETS} neighbours (this gives {len(offs)})")
        return offs.astype(np.int64), np.concatenate(shell)


def _paired(lattice: Lattice, c: np.ndarray) -> np.ndarray:
    """The offsets ``c`` (a set closed under negation) sorted by length then lexicographically, as pairs (o, -o)."""
    first = c[np.arange(len(c)), np.argmax(c != 0, axis=1)]
    rep = c[first > 0]
    length = np.round(np.linalg.norm(lattice.vectors(rep), axis=1) / lattice.spacing, 9)
    order = np.lexsort((*(rep[:, a] for a in reversed(range(rep.shape[1]))), length))
    rep = rep[order]
    out = np.empty((2 * len(rep), c.shape[1]), dtype=np.int64)
    out[0::2] = rep
    out[1::2] = -rep
    return out
