"""Bodies of the position-based particle lattice (dell'Erba 2018): particle kinds, the
body's points, frame, neighbour links, leaders and category changes. The lattices and neighbourhoods are in
pdsim/lattice/geometry.py, the rules and fracture in pdsim/lattice/rules.py, the solver in pdsim/lattice/solver.py,
the kernels in kernels/lattice/rules.py, the choices made where the paper is open in docs/lattice.md.

A body is a set of lattice points filling a shape (the leaders and followers) surrounded by a frame (a shell of lattice
points one or two layers deep that copies the displacement of its assigned body points). Its motion is step-based: at
every step the leaders move along their scripted paths, each follower moves to a position given by a rule over its
Lagrangian neighbours (fixed at t0) as they were at the previous step, and the frame copies. No forces, masses or time
step are involved; lengths are in metres ("units" in the paper) and leader speeds in metres per step.

Particles are numbered as in the paper: body points first, from left to right, then bottom to top (then back to
front in 3D), then the frame points in the same order. Particle index j is the paper's point number j + 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from ..checks import check_range
from ..errors import GeometryError, ParameterError
from ..geometry import SolidShape
from ..regions import BoxRegion, SphereRegion, region_mask
from ..sampling import points_inside
from .geometry import Lattice, LatticeNeighbourhood, LatticeType
from .rules import LatticeFracture, LatticeRule, LatticeRuleCentroid

MAX_LATTICE_POINTS = 20_000_000


class LatticeKind(IntEnum):
    """Particle categories (the paper's four kinds). Fictitious points are not particles: one exists per broken link."""

    FOLLOWER = 0
    LEADER = 1
    FRAME = 2
    FICTITIOUS = 3


# -------------------------------------------------------------------------------------------------------------- bodies
FRAME_RULES = ("average", "single")
FRAME_UPDATES = ("previous", "current")


@dataclass
class _LeaderPath:
    steps: np.ndarray  # keyframe steps, int, increasing
    displacements: np.ndarray  # [k, 3] [m]
    velocity_after: np.ndarray  # [3] [m/step] after the last keyframe


@dataclass
class _KindChange:
    step: int
    indices: np.ndarray
    kind: int
    group: int


class LatticeBody:
    """A body of the position-based particle lattice.

    Give either ``shape`` or ``counts``:

    - ``shape``: a ``pdsim.SolidShape`` (closed mesh: filled with a 3D lattice, or cut by the z = 0 plane for a 2D
      lattice), a ``BoxRegion`` or ``SphereRegion``, or a polygon (array [m, 2] of x, y vertices [m], 2D lattices).
      The lattice is anchored at ``origin`` (default the centre of the shape's bounds; z = 0 for 2D lattices).
    - ``counts``: a block of (nx, ny) points (2D lattices: rows along x, alternate rows of sheared lattices shifted
      back so the block is a rectangle) or (nx, ny, nz) (simple cubic), first point at ``origin`` (default 0).

    Args:
        lattice: the Bravais lattice.
        neighbourhood: Lagrangian neighbours (default: coordination number, first gradient).
        rule: follower rule (default the centroid rule).
        frame_layers: depth of the frame in shell-1 steps from the body; None (default) = exactly the points needed
            to complete every body point's neighbourhood (one layer for first gradient, two for second); 0 = no frame.
        frame_rule: "average" (a frame point takes the mean displacement of all its nearest body points) or "single"
            (only the first of them, by particle number).
        frame_update: "current" (default): after the followers, the frame copies its sources' new displacement (the
            paper's step: leaders, then followers, then frame). "previous": the frame rule reads the same
            intermediate lattice as the followers (its sources' previous displacement), so frame points lag one step:
            a stronger edge delay (near-frame rows lag and detach first), at the price of a period-2 ripple after a
            release (docs/lattice.md).
        fracture: link-loss thresholds and fictitious points; None (default) = no fracture.
        steps_per_frame: lattice steps per frame of a scene (each solver ``simulate`` call), integer >= 1.
        name: label in the USD cache (the name of the body's output view).
        point_width: point diameter written to the cache [m]; default half the spacing.

    Attributes (built at construction; n = particle_count = body_count + frame_count, m = link_count):
        rest_positions: X [m], shape [n, 3], float64; body points first (paper numbering), then the frame.
        coords: integer lattice coordinates, shape [n, dim].
        kind: initial category (LatticeKind values), int32 [n]; leader_group: leader path index or -1, int32 [n].
        row_offsets, link_neighbor, link_offset: neighbour rows (CSR): int32 [n + 1], int32 [m], uint8 [m] (index into
            the offset table).
        offsets, offset_shell, offset_delta, offset_length, offset_weight: the offset table: integer offsets
            [M, dim], shell (0, 1) [M], rest offset [M, 3] [m], its length [M] [m], static weight [M].
        frame_offsets, frame_sources: the frame points' source particles (CSR over all n rows; empty for body points).
        tracked: particle indices whose history the solver records.
    """

    method = "lattice"  # simulated by SolverLattice (pdsim/lattice/solver.py)

    def __init__(
        self,
        lattice: Lattice,
        shape=None,
        *,
        counts=None,
        origin=None,
        neighbourhood: LatticeNeighbourhood | None = None,
        rule: LatticeRule | None = None,
        frame_layers: int | None = None,
        frame_rule: str = "average",
        frame_update: str = "current",
        fracture: LatticeFracture | None = None,
        steps_per_frame: int = 1,
        name: str = "lattice",
        point_width: float | None = None,
    ):
        if not isinstance(lattice, Lattice):
            raise ParameterError("lattice", lattice, "a pdsim.Lattice (Lattice.square(...), ...)")
        self.lattice = lattice
        self.neighbourhood = neighbourhood if neighbourhood is not None else LatticeNeighbourhood()
        if not isinstance(self.neighbourhood, LatticeNeighbourhood):
            raise ParameterError("neighbourhood", neighbourhood, "a LatticeNeighbourhood")
        self.rule = rule if rule is not None else LatticeRuleCentroid()
        if not isinstance(self.rule, LatticeRule):
            raise ParameterError("rule", rule, "a LatticeRule (LatticeRuleCentroid, ...)")
        if frame_layers is not None and (
            isinstance(frame_layers, bool)
            or not isinstance(frame_layers, (int, np.integer))
            or not 0 <= frame_layers <= 4
        ):
            raise ParameterError("frame_layers", frame_layers, "None or an integer in [0, 4]")
        if frame_rule not in FRAME_RULES:
            raise ParameterError("frame_rule", frame_rule, " or ".join(map(repr, FRAME_RULES)))
        if frame_update not in FRAME_UPDATES:
            raise ParameterError("frame_update", frame_update, " or ".join(map(repr, FRAME_UPDATES)))
        if fracture is not None and not isinstance(fracture, LatticeFracture):
            raise ParameterError("fracture", fracture, "None or a LatticeFracture")
        if (
            isinstance(steps_per_frame, bool)
            or not isinstance(steps_per_frame, (int, np.integer))
            or steps_per_frame < 1
        ):
            raise ParameterError("steps_per_frame", steps_per_frame, "an integer >= 1")
        if not isinstance(name, str) or not name:
            raise ParameterError("name", name, "a non-empty string")
        self.frame_layers = frame_layers
        self.frame_rule = frame_rule
        self.frame_update = frame_update
        self.fracture = fracture
        self.steps_per_frame = int(steps_per_frame)
        self.name = name
        self.point_width = (
            0.5 * lattice.spacing if point_width is None else check_range("point_width", point_width, 0.0, None)
        )

        if (shape is None) == (counts is None):
            raise ParameterError("shape", shape, "exactly one of shape and counts")
        body_coords, self.origin = (
            _block_coords(lattice, counts, origin) if counts is not None else _shape_coords(lattice, shape, origin)
        )
        self.offsets, self.offset_shell = self.neighbourhood.offsets(lattice)
        self._build(body_coords)
        if fracture is not None:
            d1, d2 = fracture.thresholds()
            longest = self.offset_length_by_shell()
            for s, (d, lmax) in enumerate(zip((d1, d2), longest, strict=False)):
                if lmax > 0 and d <= lmax:
                    raise ParameterError(
                        "distances", fracture.distances, f"a shell-{s + 1} threshold > its longest rest link {lmax:g} m"
                    )
        n = self.particle_count
        self.kind = np.full(n, int(LatticeKind.FOLLOWER), dtype=np.int32)
        self.kind[self.body_count :] = int(LatticeKind.FRAME)
        self.leader_group = np.full(n, -1, dtype=np.int32)
        self.leader_paths: list[_LeaderPath] = []
        self.kind_changes: list[_KindChange] = []
        self.tracked = np.zeros(0, dtype=np.int64)

    # -- construction ----------------------------------------------------------------------------------------------
    @classmethod
    def block(cls, lattice: Lattice, counts, **kwargs) -> LatticeBody:
        """A block of ``counts`` = (nx, ny) or (nx, ny, nz) points (keyword options: see LatticeBody)."""
        return cls(lattice, counts=counts, **kwargs)

    def _build(self, body_coords: np.ndarray):
        lat = self.lattice
        dim = lat.dim
        offs = self.offsets
        body_coords = _paper_order(lat, self.origin, body_coords)
        nb = len(body_coords)
        # frame: lattice points outside the body within frame_layers shell-1 steps (or completing neighbourhoods)
        depth = int(np.abs(offs).max())
        layers = self.frame_layers
        margin = depth * (2 if layers is None else max(layers, 1))
        cmin = body_coords.min(axis=0) - margin
        shape = tuple(int(s) for s in body_coords.max(axis=0) - cmin + margin + 1)
        if int(np.prod(shape, dtype=np.int64)) > 8 * MAX_LATTICE_POINTS:
            raise ParameterError("counts", shape, "a body whose index box holds fewer lattice points")
        body_mask = np.zeros(shape, dtype=bool)
        body_mask[tuple((body_coords - cmin).T)] = True
        if layers is None:
            reach = _dilate(body_mask, offs) & ~body_mask
        else:
            shell1 = offs[self.offset_shell == 0]
            reach = body_mask.copy()
            for _ in range(layers):
                reach |= _dilate(reach, shell1)
            reach &= ~body_mask
        frame_coords = np.argwhere(reach) + cmin if layers != 0 else np.zeros((0, dim), dtype=np.int64)
        frame_coords = _paper_order(lat, self.origin, frame_coords)
        coords = np.concatenate([body_coords, frame_coords]).astype(np.int64)
        n = len(coords)
        self.coords = coords
        self.body_count = nb
        self.frame_count = n - nb
        self.rest_positions = self.origin + lat.vectors(coords)
        index = np.full(shape, -1, dtype=np.int32)
        index[tuple((coords - cmin).T)] = np.arange(n, dtype=np.int32)
        self._index, self._index_min = index, cmin

        # neighbour rows (CSR), one column per offset, in offset order
        table = np.stack([self._lookup(coords + o) for o in offs], axis=1)
        valid = table >= 0
        self.row_offsets = np.concatenate([[0], np.cumsum(valid.sum(axis=1))]).astype(np.int32)
        self.link_neighbor = table[valid].astype(np.int32)
        self.link_offset = np.broadcast_to(np.arange(len(offs), dtype=np.uint8), table.shape)[valid].copy()
        self.offset_delta = lat.vectors(offs)
        self.offset_length = np.linalg.norm(self.offset_delta, axis=1)
        w = np.asarray(self.neighbourhood.shell_weights, dtype=np.float64)
        self.offset_weight = w[self.offset_shell]

        # frame sources: the nearest body points (Euclidean), ties kept (average rule) or the first (single rule)
        self.frame_offsets, self.frame_sources = self._frame_sources(coords[nb:], nb)

    def _lookup(self, coords: np.ndarray) -> np.ndarray:
        """Particle index of integer lattice coordinates [m, dim], -1 where there is none."""
        rel = coords - self._index_min
        inside = np.all((rel >= 0) & (rel < np.asarray(self._index.shape)), axis=1)
        out = np.full(len(coords), -1, dtype=np.int32)
        out[inside] = self._index[tuple(rel[inside].T)]
        return out

    def _frame_sources(self, frame_coords: np.ndarray, nb: int):
        n = nb + len(frame_coords)
        offsets = np.zeros(n + 1, dtype=np.int32)
        if len(frame_coords) == 0:
            return offsets, np.zeros(0, dtype=np.int32)
        lat = self.lattice
        steps = int(np.abs(self.offsets).max()) * max(1, self.frame_layers or 2) + 2
        reach = steps * float(np.linalg.norm(lat.basis, axis=1).max())
        cand = lat.candidate_offsets(reach)
        length = np.linalg.norm(lat.vectors(cand), axis=1)
        key = np.round(length / lat.spacing, 6)
        pairs_f, pairs_s = [], []
        todo = np.ones(len(frame_coords), dtype=bool)
        for lv in np.unique(key):
            if not todo.any():
                break
            hit_f, hit_s = [], []
            for o in cand[key == lv]:
                idx = np.nonzero(todo)[0]
                src = self._lookup(frame_coords[idx] + o)
                ok = (src >= 0) & (src < nb)
                hit_f.append(idx[ok])
                hit_s.append(src[ok])
            hf = np.concatenate(hit_f)
            if len(hf):
                pairs_f.append(hf)
                pairs_s.append(np.concatenate(hit_s))
                todo[hf] = False
        if todo.any():
            raise GeometryError(f"'{self.name}': {int(todo.sum())} frame points found no body point to follow")
        f = np.concatenate(pairs_f)
        s = np.concatenate(pairs_s)
        order = np.lexsort((s, f))
        f, s = f[order], s[order]
        if self.frame_rule == "single":
            first = np.ones(len(f), dtype=bool)
            first[1:] = f[1:] != f[:-1]
            f, s = f[first], s[first]
        counts = np.bincount(f + nb, minlength=n)
        offsets[1:] = np.cumsum(counts)
        return offsets, s.astype(np.int32)

    # -- properties ------------------------------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        """Body points plus frame points."""
        return len(self.coords)

    @property
    def link_count(self) -> int:
        """Directed neighbour links (each pair counted from both ends)."""
        return len(self.link_neighbor)

    @property
    def spacing(self) -> float:
        """Nearest-neighbour distance of the lattice [m]."""
        return self.lattice.spacing

    def offset_length_by_shell(self) -> tuple[float, float]:
        """Longest rest link [m] of shell 1 and shell 2 (0 when the shell is empty)."""
        out = []
        for s in (0, 1):
            m = self.offset_shell == s
            out.append(float(self.offset_length[m].max()) if m.any() else 0.0)
        return out[0], out[1]

    def particle_index(self, coords) -> int:
        """Particle index of the integer lattice coordinates ``coords`` (dim integers), or -1."""
        c = np.asarray(coords, dtype=np.int64).reshape(1, -1)
        if c.shape[1] != self.lattice.dim:
            raise ParameterError("coords", coords, f"{self.lattice.dim} integers")
        return int(self._lookup(c)[0])

    def nearest_particle(self, point, *, frame: bool = False) -> int:
        """Index of the body point (or any point with ``frame=True``) whose rest position is nearest ``point`` [m]."""
        p = np.asarray(point, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ParameterError("point", point, "3 finite numbers [m]")
        x = self.rest_positions if frame else self.rest_positions[: self.body_count]
        return int(np.argmin(np.linalg.norm(x - p, axis=1)))

    # -- particle selection and categories -----------------------------------------------------------------------
    def select(self, region, field_name: str = "region") -> np.ndarray:
        """Indices of the body points selected by ``region``: a region object or callable evaluated on rest
        positions (frame points excluded), an index or a sequence of indices, or a bool mask over body points."""
        nb = self.body_count
        if isinstance(region, (int, np.integer)) and not isinstance(region, bool):
            idx = np.array([int(region)])
        elif isinstance(region, (list, tuple, np.ndarray)):
            a = np.asarray(region)
            if a.dtype == np.bool_ and a.shape == (nb,):
                idx = np.nonzero(a)[0]
            elif a.ndim == 1 and (a.size == 0 or np.issubdtype(a.dtype, np.integer)):
                idx = a.astype(np.int64)
            else:
                raise ParameterError(field_name, region, f"indices in [0, {nb}) or a bool mask of shape ({nb},)")
        else:
            idx = np.nonzero(region_mask(region, self.rest_positions[:nb], field=field_name))[0]
        if idx.size == 0:
            raise ParameterError(field_name, region, f"a selection of at least one body point of '{self.name}'")
        if idx.min() < 0 or idx.max() >= nb:
            raise ParameterError(field_name, region, f"body point indices in [0, {nb})")
        return np.unique(idx)

    def add_leaders(
        self,
        region,
        *,
        velocity=(0.0, 0.0, 0.0),
        start_step: int = 0,
        stop_step: int | None = None,
        release_step: int | None = None,
        path=None,
    ) -> np.ndarray:
        """Makes the selected body points leaders (scripted motion); returns their indices.

        The motion is ``velocity`` [m/step] from ``start_step`` to ``stop_step`` (then holding; None: for ever), or
        ``path``: keyframes [(step, (ux, uy, uz)), ...] of displacement [m], linear in between, held after the last.
        At ``release_step`` the leaders become followers (None: never); they move at step t to their path's value at t.
        """
        idx = self.select(region)
        if path is not None:
            try:
                steps = np.array([int(s) for s, _ in path], dtype=np.int64)
                disp = np.array([np.asarray(u, dtype=np.float64).reshape(3) for _, u in path])
            except (TypeError, ValueError):
                raise ParameterError("path", path, "keyframes [(step, (ux, uy, uz)), ...]") from None
            if len(steps) == 0 or np.any(np.diff(steps) <= 0) or steps[0] < 0 or not np.all(np.isfinite(disp)):
                raise ParameterError("path", path, "keyframes with steps >= 0, strictly increasing, finite values")
            lp = _LeaderPath(steps, disp, np.zeros(3))
        else:
            v = np.asarray(velocity, dtype=np.float64)
            if v.shape != (3,) or not np.all(np.isfinite(v)):
                raise ParameterError("velocity", velocity, "3 finite numbers [m/step]")
            s0 = _check_step("start_step", start_step)
            if stop_step is None:
                lp = _LeaderPath(np.array([s0]), np.zeros((1, 3)), v)
            else:
                s1 = _check_step("stop_step", stop_step)
                if s1 <= s0:
                    raise ParameterError("stop_step", stop_step, f"a step > start_step = {s0}")
                lp = _LeaderPath(np.array([s0, s1]), np.stack([np.zeros(3), v * (s1 - s0)]), np.zeros(3))
        self.leader_paths.append(lp)
        group = len(self.leader_paths) - 1
        self.kind[idx] = int(LatticeKind.LEADER)
        self.leader_group[idx] = group
        if release_step is not None:
            r = _check_step("release_step", release_step)
            if r < 1:
                raise ParameterError("release_step", release_step, "a step >= 1")
            self.kind_changes.append(_KindChange(r, idx, int(LatticeKind.FOLLOWER), -1))
        return idx

    def clamp(self, region) -> np.ndarray:
        """Makes the selected body points leaders held at their rest positions; returns their indices."""
        return self.add_leaders(region)

    def change_kind(self, region, kind: LatticeKind, *, at_step: int) -> np.ndarray:
        """Category change at step ``at_step`` (>= 1): the selected body points become followers, or leaders holding
        their displacement of that moment."""
        idx = self.select(region)
        if kind not in (LatticeKind.FOLLOWER, LatticeKind.LEADER):
            raise ParameterError("kind", kind, "LatticeKind.FOLLOWER or LatticeKind.LEADER")
        s = _check_step("at_step", at_step)
        if s < 1:
            raise ParameterError("at_step", at_step, "a step >= 1")
        self.kind_changes.append(_KindChange(s, idx, int(kind), -1))
        return idx

    def track(self, region) -> np.ndarray:
        """Records the displacement and PE1 of the selected points at every step (see
        SolverLattice.trajectories); returns their indices. Frame points may be given by index."""
        as_array = isinstance(region, (list, tuple, np.ndarray)) and np.asarray(region).dtype != np.bool_
        if as_array or (isinstance(region, (int, np.integer)) and not isinstance(region, bool)):
            idx = np.atleast_1d(np.asarray(region)).astype(np.int64)
            if idx.size == 0 or idx.min() < 0 or idx.max() >= self.particle_count:
                raise ParameterError("region", region, f"particle indices in [0, {self.particle_count})")
            idx = np.unique(idx)
        else:
            idx = self.select(region)
        self.tracked = np.unique(np.concatenate([self.tracked, idx]))
        return idx


# --------------------------------------------------------------------------------------------------------- helpers
def _check_step(field_name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise ParameterError(field_name, value, "an integer step >= 0")
    return int(value)


def _dilate(mask: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """mask shifted by every offset, OR-ed (cells shifted outside the array are dropped)."""
    out = np.zeros_like(mask)
    for o in offsets:
        src = tuple(slice(max(0, -int(d)), mask.shape[a] - max(0, int(d))) for a, d in enumerate(o))
        dst = tuple(slice(max(0, int(d)), mask.shape[a] - max(0, -int(d))) for a, d in enumerate(o))
        out[dst] |= mask[src]
    return out


def _paper_order(lattice: Lattice, origin: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """Sorts integer coordinates as the paper numbers points: left to right, bottom to top, then back to front."""
    if len(coords) == 0:
        return coords.reshape(0, lattice.dim).astype(np.int64)
    x = np.round(lattice.vectors(coords) / lattice.spacing, 6)
    return coords[np.lexsort((x[:, 0], x[:, 1], x[:, 2]))].astype(np.int64)


def _block_coords(lattice: Lattice, counts, origin):
    c = np.asarray(counts)
    if c.shape != (lattice.dim,) or not np.issubdtype(c.dtype, np.integer) or np.any(c < 1):
        raise ParameterError("counts", counts, f"{lattice.dim} integers >= 1 (points along each axis)")
    if lattice.dim == 3 and lattice.type != LatticeType.SIMPLE_CUBIC:
        raise ParameterError("counts", counts, "a 2D or simple cubic lattice (fill a box shape for BCC and FCC)")
    if int(np.prod(c, dtype=np.int64)) > MAX_LATTICE_POINTS:
        raise ParameterError("counts", counts, f"at most {MAX_LATTICE_POINTS:.0e} points")
    o = np.zeros(3) if origin is None else _vec3("origin", origin)
    if lattice.dim == 2:
        o[2] = 0.0
    axes = [np.arange(int(n)) for n in c]
    g = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1).astype(np.int64)
    if lattice.dim == 2:
        shear = lattice.basis[1, 0] / lattice.basis[0, 0]
        g[:, 0] -= np.floor(g[:, 1] * shear + 1.0e-9).astype(np.int64)
    return g, o


def _shape_coords(lattice: Lattice, shape, origin):
    dim = lattice.dim
    if isinstance(shape, SolidShape):
        lo, hi = shape.bounds

        def inside(p):
            return _inside_mesh(shape, p)

    elif isinstance(shape, BoxRegion):
        lo, hi = np.asarray(shape.lo, dtype=np.float64), np.asarray(shape.hi, dtype=np.float64)
        inside = shape.contains
    elif isinstance(shape, SphereRegion):
        c, r = np.asarray(shape.center, dtype=np.float64), float(shape.radius)
        lo, hi = c - r, c + r
        inside = shape.contains
    else:
        poly = np.asarray(shape, dtype=np.float64) if isinstance(shape, (list, tuple, np.ndarray)) else None
        if poly is None or poly.ndim != 2 or poly.shape[1] != 2 or len(poly) < 3 or not np.all(np.isfinite(poly)):
            raise ParameterError(
                "shape", shape, "a SolidShape, BoxRegion, SphereRegion or polygon array [m, 2] (x, y vertices [m])"
            )
        if dim != 2:
            raise ParameterError("shape", "polygon", "a polygon only for 2D lattices (a SolidShape for 3D)")
        lo = np.array([*poly.min(axis=0), 0.0])
        hi = np.array([*poly.max(axis=0), 0.0])

        def inside(p):
            return _inside_polygon(p[:, :2], poly)

    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    o = 0.5 * (lo + hi) if origin is None else _vec3("origin", origin)
    if dim == 2:
        o = o.copy()
        o[2] = 0.0
        if not lo[2] <= 0.0 <= hi[2]:
            raise GeometryError("the shape does not reach the z = 0 plane that holds a 2D lattice")
    # integer ranges covering the bounds (corners mapped through the inverse basis)
    corners = np.array(np.meshgrid(*[[lo[a], hi[a]] for a in range(dim)], indexing="ij")).reshape(dim, -1).T
    c = (corners - o[:dim]) @ np.linalg.inv(lattice.basis_matrix)
    cmin = np.floor(c.min(axis=0)).astype(np.int64) - 1
    cmax = np.ceil(c.max(axis=0)).astype(np.int64) + 1
    if int(np.prod(cmax - cmin + 1, dtype=np.int64)) > 4 * MAX_LATTICE_POINTS:
        raise ParameterError("spacing", lattice.spacing, "a spacing giving fewer lattice points in the shape")
    axes = [np.arange(cmin[a], cmax[a] + 1) for a in range(dim)]
    g = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    p = o + lattice.vectors(g)
    box = np.all((p[:, :dim] >= lo[:dim] - 1e-12) & (p[:, :dim] <= hi[:dim] + 1e-12), axis=1)
    g, p = g[box], p[box]
    keep = np.asarray(inside(p), dtype=bool)
    if not keep.any():
        raise GeometryError(f"no lattice point of spacing {lattice.spacing:g} lies inside the shape")
    return g[keep].astype(np.int64), o


def _inside_mesh(shape, points: np.ndarray) -> np.ndarray:
    """Winding-number inside test of points [n, 3] [m] against a closed SolidShape (pdsim.sampling.points_inside)."""
    return points_inside(shape, points, device="cpu")


def _inside_polygon(p: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd test of points p [n, 2] against a closed polygon [m, 2] (a loop over the polygon's edges)."""
    x, y = p[:, 0], p[:, 1]
    inside = np.zeros(len(p), dtype=bool)
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        if y0 == y1:
            continue
        cross = (y0 > y) != (y1 > y)
        xs = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (x < xs)
    return inside


def _vec3(field_name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError(field_name, value, "3 finite numbers [m]")
    return a.copy()
