"""The solver of the position-based particle lattice: steps, diagnostics (PE1, PE2, trajectories, fragments) and output
views for the lattice bodies of a scene (pdsim/lattice/body.py describes the model, kernels/lattice/rules.py the step).

Scene protocol (pdsim/solver.py): a lattice is step-based and has no time step of its own, so ``stable_time_step()``
is ``math.inf`` (it never limits the other bodies of a scene) and every ``simulate(dt, steps)`` call, which the scene
makes once per frame, advances each body by its ``steps_per_frame`` lattice steps whatever ``dt`` and ``steps`` are.
A lattice is massless and position-based: it cannot honour gravity, a ground plane, colliders, contact or loads
(``check_features`` refuses them). Rest positions are kept relative to the context's origin (world = origin + local),
so a body far from the world origin steps exactly as one at it.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from ..errors import InstabilityError, ParameterError
from ..fragment_labels import fragment_labels
from ..kernels.lattice import rules as kl
from ..output.views import PointsView
from ..solver import Solver, SolverContext, array_state, assign_state, register_solver
from .body import LatticeBody, LatticeKind

__all__ = ["SolverLattice"]

_TRACK_CHUNK = 256


class _LatticeRuntime:
    """Device arrays and the step sequence of one lattice body (all launches are per body).

    ``origin`` [m], float64 [3]: the solver's local frame. The kernels see rest positions and rule origins relative
    to it (float32), so their rounding does not grow with the body's distance from the world origin."""

    def __init__(self, body: LatticeBody, device, origin: np.ndarray):
        self.body = body
        self.device = device
        n = body.particle_count
        self.n = n
        f32 = np.float32

        def vec3(a):
            return wp.array(np.asarray(a, dtype=f32).reshape(-1, 3), dtype=wp.vec3, device=device)

        def i32(a):
            return wp.array(np.asarray(a, dtype=np.int32), dtype=wp.int32, device=device)

        def flt(a):
            return wp.array(np.asarray(a, dtype=f32), dtype=float, device=device)

        self.origin = origin
        self.rest_world = body.rest_positions  # X [m], float64 [n, 3] (world)
        self.rest_local = body.rest_positions - origin  # X - origin [m], float64 [n, 3]
        self.rest = vec3(self.rest_local)
        self.kind = i32(body.kind)
        self.group = i32(body.leader_group)
        paths = body.leader_paths
        if paths:
            self.key_offsets = i32(np.concatenate([[0], np.cumsum([len(p.steps) for p in paths])]))
            self.key_step = i32(np.concatenate([p.steps for p in paths]))
            self.key_disp = vec3(np.concatenate([p.displacements for p in paths]))
            self.group_velocity = vec3(np.stack([p.velocity_after for p in paths]))
        else:
            self.key_offsets, self.key_step = i32([0, 1]), i32([0])
            self.key_disp, self.group_velocity = vec3(np.zeros(3)), vec3(np.zeros(3))
        self.kind_host = body.kind.copy()  # mirror of ``kind`` (changes only at category-change events)
        self.events: dict[int, list] = {}
        for c in body.kind_changes:
            self.events.setdefault(c.step, []).append((i32(c.indices), c.kind, c.group, c.indices))
        self._update_leader_ids()

        self.row_offsets = i32(body.row_offsets)
        self.link_neighbor = i32(body.link_neighbor if body.link_count else [0])
        self.link_offset = wp.array(
            body.link_offset if body.link_count else np.zeros(1, np.uint8), dtype=wp.uint8, device=device
        )
        self.fracture = body.fracture is not None
        self.link_alive = wp.array(
            np.ones(max(body.link_count, 1) if self.fracture else 1, dtype=np.uint8), dtype=wp.uint8, device=device
        )
        self.offset_delta = vec3(body.offset_delta)
        self.offset_weight = flt(body.offset_weight)
        self.offset_shell = i32(body.offset_shell)
        self.offset_length = flt(body.offset_length)
        if self.fracture:
            d1, d2 = body.fracture.thresholds()
            self.offset_threshold = flt(np.where(body.offset_shell == 0, d1, d2))
            s = body.fracture.fictitious_distance
            self.fictitious_scale = 1.0 if s is None else float(s)
            ghosts = s is not None
        else:
            self.offset_threshold = flt(np.zeros(len(body.offset_delta)))
            self.fictitious_scale = 1.0
            ghosts = False
        self.frame_offsets = i32(body.frame_offsets)
        self.frame_sources = i32(body.frame_sources if len(body.frame_sources) else [0])
        self.has_frame = body.frame_count > 0
        self.frame_lag = body.frame_update == "previous"

        weight_fn, update_fn = body.rule.warp_functions()
        self.follow_kernel = kl.make_follow_kernel(weight_fn, update_fn, self.fracture, ghosts)
        scalars, axis, origin = body.rule.parameters(body)
        p = kl.LatticeRuleParams()
        p.scalars = wp.vec4(*[float(v) for v in scalars])
        p.axis = wp.vec3(*[float(v) for v in axis])
        p.origin = wp.vec3(*[float(v) for v in np.asarray(origin, dtype=np.float64) - self.origin])  # local frame
        self.params = p

        self.u_cur = wp.zeros(n, dtype=wp.vec3, device=device)
        self.u_next = wp.zeros(n, dtype=wp.vec3, device=device)
        self.u_prev = wp.zeros(n, dtype=wp.vec3, device=device)
        self.broken_total = wp.zeros(1, dtype=wp.int32, device=device)
        # the step index on the device (the leaders' paths read it), advanced by a kernel each step; the host keeps
        # a mirror (never read back), so that a frame's launches do not change from frame to frame
        self.step_clock = wp.zeros(1, dtype=wp.int32, device=device)
        self._clock_host = 0
        self.pe1 = wp.zeros(n, dtype=float, device=device)
        self.pe1_intact = wp.zeros(n, dtype=float, device=device)
        self.broken = wp.zeros(n, dtype=wp.int32, device=device)
        self._check = wp.zeros(2, dtype=float, device=device)
        self._fragments = None  # (live links broken so far, labels) of the last fragment labelling
        self._solid_links = None  # links joining two non-frame particles, bool [link_count] (built on first use)

        self.tracked = np.asarray(body.tracked, dtype=np.int64)
        t = len(self.tracked)
        self.track_ids = i32(self.tracked if t else [0])
        self.track_u = wp.zeros((_TRACK_CHUNK, max(t, 1)), dtype=wp.vec3, device=device)
        self.track_pe1 = wp.zeros((_TRACK_CHUNK, max(t, 1)), dtype=float, device=device)
        self.track_slot = 0
        self.track_host_u: list[np.ndarray] = []
        self.track_host_pe1: list[np.ndarray] = []
        self.step_count = 0
        self._record_tracks()

    # -- stepping --------------------------------------------------------------------------------------------------
    def step(self):
        t = self.step_count + 1
        d = self.device
        if self._clock_host != self.step_count:  # a restore or a state set from the host
            if d.is_capturing:
                raise RuntimeError("the lattice step clock was set from the host during a graph capture")
            self.step_clock.assign(np.array([self.step_count], dtype=np.int32))
        kl.advance_step_clock(self.step_clock, d)
        self._clock_host = t
        events = self.events.get(t, ())
        for ids, kind, group, host_ids in events:
            kl.set_kind(len(host_ids), ids, kind, group, self.kind, self.group, d)
            self.kind_host[host_ids] = kind
        if events:
            self._update_leader_ids()
        if self.leader_count:
            kl.move_leaders(
                self.leader_count,
                step_clock=self.step_clock,
                leader_ids=self.leader_ids,
                group=self.group,
                key_offsets=self.key_offsets,
                key_step=self.key_step,
                key_disp=self.key_disp,
                group_velocity=self.group_velocity,
                u_cur=self.u_cur,
                u_next=self.u_next,
                device=d,
            )
        kl.follow(
            self.follow_kernel,
            self.n,
            rest=self.rest,
            kind=self.kind,
            row_offsets=self.row_offsets,
            link_neighbor=self.link_neighbor,
            link_offset=self.link_offset,
            link_alive=self.link_alive,
            offset_delta=self.offset_delta,
            offset_weight=self.offset_weight,
            offset_shell=self.offset_shell,
            fictitious_scale=self.fictitious_scale,
            params=self.params,
            u_cur=self.u_cur,
            u_next=self.u_next,
            device=d,
        )
        if self.has_frame:
            kl.copy_frame(
                self.body.body_count,
                self.body.frame_count,
                self.frame_offsets,
                self.frame_sources,
                self.u_cur if self.frame_lag else self.u_next,
                self.u_next,
                d,
            )
        if self.fracture:
            kl.break_links(
                self.n,
                body_count=self.body.body_count,
                row_offsets=self.row_offsets,
                link_neighbor=self.link_neighbor,
                link_offset=self.link_offset,
                offset_delta=self.offset_delta,
                offset_threshold=self.offset_threshold,
                u=self.u_next,
                link_alive=self.link_alive,
                broken_total=self.broken_total,
                device=d,
            )
        self.u_cur, self.u_next = self.u_next, self.u_cur
        self.step_count = t
        self._record_tracks()

    # -- frames replayed as graphs (pdsim/capture.py) ----------------------------------------------------------
    def capture_blocker(self) -> str | None:
        """Why this body's steps cannot be replayed as a graph, or None: tracked particles are recorded into a slot
        that is a launch argument and flushed to the host every few thousand steps."""
        if len(self.tracked):
            return f"the tracked particles of lattice body '{self.body.name}' (recorded into host-chosen slots)"
        return None

    def events_due(self, steps: int) -> bool:
        """True when a category change falls in the next ``steps`` steps (a launch of that step only)."""
        return any(self.step_count < s <= self.step_count + steps for s in self.events)

    def graph_key(self) -> tuple:
        """What the captured launches of a frame depend on: the buffers in their current roles, the leaders."""
        return (self.u_cur, self.u_next, self.u_prev, self.leader_ids, self.leader_count)

    def after_replay(self, steps: int) -> None:
        """The host bookkeeping of ``steps`` replayed steps: step count, clock mirror, the buffers' roles."""
        self.step_count += int(steps)
        self._clock_host = self.step_count
        if steps % 2:
            self.u_cur, self.u_next = self.u_next, self.u_cur

    def _update_leader_ids(self):
        ids = np.nonzero(self.kind_host == int(LatticeKind.LEADER))[0].astype(np.int32)
        self.leader_count = len(ids)
        self.leader_ids = wp.array(ids if len(ids) else np.zeros(1, np.int32), dtype=wp.int32, device=self.device)

    def run(self, steps: int):
        for i in range(steps):
            if i == steps - 1:
                wp.copy(self.u_prev, self.u_cur)
            self.step()

    def _record_tracks(self):
        if len(self.tracked) == 0:
            return
        if self.track_slot == _TRACK_CHUNK:
            self._flush_tracks()
        kl.record_tracks(
            len(self.tracked),
            ids=self.track_ids,
            row_offsets=self.row_offsets,
            link_neighbor=self.link_neighbor,
            link_offset=self.link_offset,
            offset_delta=self.offset_delta,
            offset_length=self.offset_length,
            u=self.u_cur,
            slot=self.track_slot,
            track_u=self.track_u,
            track_pe1=self.track_pe1,
            device=self.device,
        )
        self.track_slot += 1

    def _flush_tracks(self):
        k = self.track_slot
        if k:
            self.track_host_u.append(self.track_u.numpy()[:k].astype(np.float64))
            self.track_host_pe1.append(self.track_pe1.numpy()[:k].astype(np.float64))
        self.track_slot = 0

    # -- diagnostics -----------------------------------------------------------------------------------------------
    def displacements(self) -> np.ndarray:
        return self.u_cur.numpy().astype(np.float64)

    def pseudo_energy(self):
        kl.pseudo_energy(
            self.n,
            row_offsets=self.row_offsets,
            link_neighbor=self.link_neighbor,
            link_offset=self.link_offset,
            link_alive=self.link_alive,
            use_alive=int(self.fracture),
            offset_delta=self.offset_delta,
            offset_length=self.offset_length,
            u=self.u_cur,
            pe1=self.pe1,
            pe1_intact=self.pe1_intact,
            broken=self.broken,
            device=self.device,
        )
        return (
            self.pe1.numpy().astype(np.float64),
            self.pe1_intact.numpy().astype(np.float64),
            self.broken.numpy().astype(np.int64),
        )

    def fragments(self) -> np.ndarray:
        """Fragment id per particle, int64 [n]: connected components of the leaders and followers over intact links
        (pdsim.fragment_labels, the one labeller), numbered 0, 1, ... in the order of their smallest particle index; -1
        for frame points. Relabelled only when links broke since the last call (one 4-byte read otherwise)."""
        broken = int(self.broken_total.numpy()[0]) if self.fracture else 0
        if self._fragments is not None and self._fragments[0] == broken:
            return self._fragments[1].copy()  # nothing broke since the last labelling
        b = self.body
        # frame points stay frame points (category changes swap leaders and followers only): a static mask
        solid = self.kind_host != int(LatticeKind.FRAME)
        if self._solid_links is None:
            owner_solid = np.repeat(solid, np.diff(b.row_offsets))
            self._solid_links = owner_solid & solid[b.link_neighbor]
        live = self._solid_links
        if self.fracture:
            live = live & (self.link_alive.numpy()[: b.link_count] != 0)
        labels = fragment_labels(b.row_offsets, b.link_neighbor, live)  # frame points: singletons
        out = np.full(self.n, -1, dtype=np.int64)
        out[solid] = np.unique(labels[solid], return_inverse=True)[1]  # order kept: ranks by smallest index
        self._fragments = (broken, out)
        return out.copy()

    def check(self) -> tuple[float, bool]:
        self._check.zero_()
        kl.check_finite(self.n, self.u_cur, self._check, self.device)
        umax, bad = self._check.numpy()
        return float(umax), bool(bad > 0)


_INSTEAD = {
    "gravity": "leave the scene's gravity at its default (it does not act on lattices) or put the body under gravity "
    "as a peridynamic or FEM body",
    "ground_plane": "remove the ground plane or make the body a peridynamic or FEM body",
    "colliders": "remove the colliders or make the body a peridynamic or FEM body",
    "contact": "leave contact automatic (Scene.enable_contact not called) or make the body a peridynamic or FEM body",
}


@register_solver
class SolverLattice(Solver):
    """Steps the lattice bodies of a scene and gives their output views.

    Args:
        bodies: the LatticeBody objects (each keeps its own arrays; they never interact).
        context: the scene's SolverContext; its ``origin`` [m] is the local frame of the rest positions (world =
            origin + local). None: a default context on ``device`` with the origin at the centre of the bodies' rest
            bounding box.
        device: Warp device ("cpu", "cuda", ...); overrides the context's.

    All bodies of one solver must have the same ``steps_per_frame``. Raises FeatureNotAvailableError when the context
    asks for what a lattice cannot honour (see :meth:`requested_features`).
    """

    method = "lattice"
    supported_features = frozenset({"fracture", "frame"})

    def __init__(self, bodies: list[LatticeBody], context: SolverContext | None = None, *, device=None):
        if not bodies or not all(isinstance(b, LatticeBody) for b in bodies):
            raise ParameterError("bodies", bodies, "at least one LatticeBody")
        spf = {b.steps_per_frame for b in bodies}
        if len(spf) != 1:
            raise ParameterError("steps_per_frame", sorted(spf), "the same value for every lattice body of a scene")
        if context is None:
            context = SolverContext(device="cpu" if device is None else device, origin=_bounds_centre(bodies))
        self.check_features(bodies, context)
        self.context = context
        self.bodies = list(bodies)
        self.steps_per_frame = spf.pop()
        self.device = wp.get_device(context.device if device is None else device)
        self.origin = np.asarray(context.origin, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(self.origin)):
            raise ParameterError("origin", context.origin, "3 finite numbers [m]")
        self._runtimes = [_LatticeRuntime(b, self.device, self.origin) for b in self.bodies]
        self.time = 0.0
        self.features = {"lattice"}
        if any(b.fracture is not None for b in self.bodies):
            self.features.add("fracture")
        if any(b.frame_count for b in self.bodies):
            self.features.add("frame")

    # -- features --------------------------------------------------------------------------------------------------
    @classmethod
    def requested_features(cls, bodies, context: SolverContext) -> dict:
        """{feature: who asks for it}: a ground plane, colliders, contact switched on explicitly (True or an options
        dict; None is the scene's automatic setting and asks nothing) and a gravity the scene was given explicitly and
        that is not zero (``context.gravity_is_default`` False; the scene's default gravity asks nothing)."""
        asked = {}
        if context.ground is not None:
            asked["ground_plane"] = "the scene's ground plane (Scene.add_ground_plane)"
        if context.colliders:
            asked["colliders"] = "the scene's colliders (Scene.add_collider)"
            if any(getattr(c, "mass", None) is not None for c in context.colliders):  # a two-way contact has no force
                asked["colliders"] = "the scene's rigid bodies (Scene.add_rigid_body: no force to exchange)"
        if context.contact:
            asked["contact"] = "the scene's particle contact (Scene.enable_contact)"
        explicit = not getattr(context, "gravity_is_default", True)
        if explicit and any(float(g) != 0.0 for g in context.gravity):
            asked["gravity"] = "the scene's gravity (Scene(gravity=...))"
        return asked

    @classmethod
    def instead(cls, feature: str) -> str:
        return (
            "a lattice body is massless and position-based: its motion comes from its leaders "
            "(LatticeBody.add_leaders, clamp, change_kind), while gravity, ground planes, colliders and contact act on "
            f"peridynamic and FEM bodies; {_INSTEAD.get(feature, 'remove the setting')}"
        )

    # -- stepping --------------------------------------------------------------------------------------------------
    @property
    def step_count(self) -> int:
        """Lattice steps done so far."""
        return self._runtimes[0].step_count

    def step(self):
        """One lattice step of every body."""
        for r in self._runtimes:
            r.step()

    def run_steps(self, steps: int):
        """``steps`` lattice steps of every body (PE2 then compares the last two configurations)."""
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise ParameterError("steps", steps, "an integer >= 0")
        for r in self._runtimes:
            r.run(int(steps))

    def simulate(self, dt: float, steps: int):
        """One frame of a scene: ``steps_per_frame`` lattice steps (``dt`` and ``steps`` only advance ``time`` [s] by
        dt x steps: a lattice is step-based)."""
        self.run_steps(self.steps_per_frame)
        self.time += float(dt) * int(steps)

    # -- frames replayed as graphs (pdsim/capture.py) ----------------------------------------------------------
    def graph_capture_blocker(self, dt: float) -> str | None:
        """Why a frame cannot be replayed as a graph (tracked particles), or None."""
        for r in self._runtimes:
            reason = r.capture_blocker()
            if reason:
                return reason
        return None

    def frame_needs_direct(self, dt: float, steps: int) -> bool:
        """True when a category change falls in the next frame."""
        return any(r.events_due(self.steps_per_frame) for r in self._runtimes)

    def graph_key(self) -> tuple:
        return tuple(k for r in self._runtimes for k in r.graph_key())

    def begin_frame(self, dt: float, steps: int) -> None:
        """Nothing to write before a lattice frame (its step index lives on the device)."""

    def after_replay(self, dt: float, steps: int) -> None:
        """The host bookkeeping of a replayed frame (:meth:`simulate`'s)."""
        for r in self._runtimes:
            r.after_replay(self.steps_per_frame)
        self.time += float(dt) * int(steps)

    def stable_time_step(self) -> float:
        """math.inf: a lattice step has no stability limit and does not constrain the scene's time step."""
        return math.inf

    def speed_scale(self) -> float:
        """0 m/s: lattice particles have no velocity (see check_state)."""
        return 0.0

    def check_state(self, speed_limit: float):
        """Raises InstabilityError when a displacement is not finite or exceeds 1000 times the body's size (possible
        with a large mixed-coordinate K or relaxation near 2). ``speed_limit`` is not used (no velocities)."""
        for r in self._runtimes:
            umax, bad = r.check()
            ext = r.rest_local.max(axis=0) - r.rest_local.min(axis=0)
            size = float(np.linalg.norm(ext)) + r.body.spacing
            if bad or umax > 1.0e3 * size:
                what = "non-finite displacements" if bad else f"a displacement of {umax:.3g} m"
                cause = _leader_cause(r.body.leader_paths, int(r.step_count), 1.0e3 * size)
                raise InstabilityError(
                    f"lattice body '{r.body.name}' diverged at step {r.step_count}: {what}; "
                    + (cause or "lower the rule's k or relaxation")
                )

    def checkpoint(self) -> dict:
        """The state to continue this run exactly (pdsim.solver.Solver.checkpoint), per body: the current, next and
        previous configurations, categories and leader groups, live links and the broken-link count, the step count
        and the tracked particles' history; and the solver's time."""
        bodies = {}
        for i, r in enumerate(self._runtimes):
            r._flush_tracks()
            bodies[str(i)] = {
                "name": r.body.name,
                "step_count": int(r.step_count),
                "u_cur": array_state(r.u_cur),
                "u_next": array_state(r.u_next),
                "u_prev": array_state(r.u_prev),
                "kind": array_state(r.kind),
                "group": array_state(r.group),
                "kind_host": np.array(r.kind_host, copy=True),
                "link_alive": array_state(r.link_alive),
                "broken_total": array_state(r.broken_total),
                "track_u": np.concatenate(r.track_host_u) if r.track_host_u else None,
                "track_pe1": np.concatenate(r.track_host_pe1) if r.track_host_pe1 else None,
            }
        return {"time": float(self.time), "bodies": bodies}

    def restore(self, state: dict) -> None:
        """Puts a :meth:`checkpoint` of a solver built from the same bodies back."""
        bodies = state["bodies"]
        if len(bodies) != len(self._runtimes):
            raise ParameterError(
                "checkpoint", f"{len(bodies)} lattice bodies", f"{len(self._runtimes)} (the same scene)"
            )
        for i, r in enumerate(self._runtimes):
            b = bodies[str(i)]
            if b["name"] != r.body.name:
                raise ParameterError("checkpoint", f"lattice body {b['name']!r}", f"body {r.body.name!r}")
            for name in ("u_cur", "u_next", "u_prev", "kind", "group", "link_alive", "broken_total"):
                assign_state(getattr(r, name), b[name], name)
            r.kind_host = np.asarray(b["kind_host"]).copy()
            r._update_leader_ids()
            r.step_count = int(b["step_count"])
            r._fragments = None
            r.track_slot = 0
            r.track_host_u = [] if b["track_u"] is None else [np.asarray(b["track_u"], dtype=np.float64)]
            r.track_host_pe1 = [] if b["track_pe1"] is None else [np.asarray(b["track_pe1"], dtype=np.float64)]
        self.time = float(state["time"])

    # -- scene integration -----------------------------------------------------------------------------------------
    @property
    def point_count(self) -> int:
        """All points of all bodies (frame points included)."""
        return sum(b.particle_count for b in self.bodies)

    @property
    def particle_count(self) -> int:
        """Same as point_count."""
        return self.point_count

    @property
    def bond_count(self) -> int:
        """Directed neighbour links of all bodies."""
        return sum(b.link_count for b in self.bodies)

    def summary(self) -> str:
        frame = sum(b.frame_count for b in self.bodies)
        return f"{self.point_count} lattice points ({frame} frame), {self.bond_count} links"

    def views(self) -> list:
        """One PointsView per body: name = body name, positions = world positions [m] (float64 [n, 3]),
        velocities = zeros (float64 [n, 3]: a lattice has steps, not time, so its particles have no velocity),
        widths = the body's point_width [m] ([n]), and the shared attributes ``displacement`` (u [m], float64 [n, 3]),
        ``kind`` (LatticeKind values: 0 follower, 1 leader, 2 frame), ``pe1`` and ``pe1_intact`` [m^2], ``pe2`` [m],
        ``broken_links`` (lost body links per particle; links between two frame points never break) and, for bodies
        with fracture, ``fragment`` (connected pieces over intact links, 0, 1, ... by smallest particle index; -1 for
        frame points)."""
        out = []
        for r in self._runtimes:
            u = r.displacements()
            pe1, pe1_intact, broken = r.pseudo_energy()
            attributes = {
                "displacement": u,
                "kind": r.kind_host.astype(np.int32),
                "pe1": pe1,
                "pe1_intact": pe1_intact,
                "pe2": np.linalg.norm(u - r.u_prev.numpy().astype(np.float64), axis=1),
                "broken_links": broken,
            }
            if r.fracture:
                attributes["fragment"] = r.fragments()
            out.append(
                PointsView(
                    name=r.body.name,
                    positions=r.rest_world + u,
                    velocities=np.zeros((r.n, 3), dtype=np.float64),
                    widths=np.full(r.n, r.body.point_width, dtype=np.float64),
                    attributes=attributes,
                )
            )
        return out

    # -- host views ------------------------------------------------------------------------------------------------
    def _rt(self, body) -> _LatticeRuntime:
        if isinstance(body, LatticeBody):
            for r in self._runtimes:
                if r.body is body:
                    return r
            raise ParameterError("body", body.name, "a body of this solver")
        if isinstance(body, bool) or not isinstance(body, (int, np.integer)) or not 0 <= body < len(self._runtimes):
            raise ParameterError("body", body, f"a LatticeBody of this solver or an index in [0, {len(self.bodies)})")
        return self._runtimes[int(body)]

    def positions(self, body=0) -> np.ndarray:
        """Current world positions X + u [m], shape [particle_count, 3], float64."""
        r = self._rt(body)
        return r.rest_world + r.displacements()

    def displacements(self, body=0) -> np.ndarray:
        """Current displacements u [m], shape [particle_count, 3]."""
        return self._rt(body).displacements()

    def set_displacements(self, displacements, body=0):
        """Overwrites the current displacements u [m] of a body (shape [particle_count, 3]); the previous
        configuration (PE2) becomes the old current one. For diagnostics and tests: the rules apply from the next
        step."""
        r = self._rt(body)
        u = np.asarray(displacements, dtype=np.float64)
        if u.shape != (r.n, 3) or not np.all(np.isfinite(u)):
            raise ParameterError("displacements", u.shape, f"finite values of shape ({r.n}, 3) [m]")
        wp.copy(r.u_prev, r.u_cur)
        r.u_cur.assign(wp.array(u.astype(np.float32), dtype=wp.vec3, device=self.device))

    def kinds(self, body=0) -> np.ndarray:
        """Current category of every particle (LatticeKind values), shape [particle_count]."""
        return self._rt(body).kind.numpy().astype(np.int32)

    def pe1(self, body=0, *, intact_only: bool = False) -> np.ndarray:
        """PE1 per particle [m^2] at the current step: sum over the Lagrangian neighbours of (dis - dis0)^2; with
        ``intact_only`` only over links not lost to fracture."""
        pe1, pe1_intact, _ = self._rt(body).pseudo_energy()
        return pe1_intact if intact_only else pe1

    def pe2(self, body=0) -> np.ndarray:
        """PE2 per particle [m]: |C_t - C_{t-1}|, the distance moved in the last step of the last run_steps/simulate
        call."""
        r = self._rt(body)
        return np.linalg.norm(r.displacements() - r.u_prev.numpy().astype(np.float64), axis=1)

    def broken_links(self, body=0) -> np.ndarray:
        """Links lost per particle, shape [particle_count] (directed: a lost pair counts at both ends). Body links
        only: a link with at least one leader or follower end (a frame point counts its lost links to body points);
        links between two frame points are never used and never break."""
        return self._rt(body).pseudo_energy()[2]

    def link_alive(self, body=0) -> np.ndarray:
        """Alive flag per directed link (the body's CSR order), bool [link_count]."""
        r = self._rt(body)
        if not r.fracture:
            return np.ones(r.body.link_count, dtype=bool)
        return r.link_alive.numpy()[: r.body.link_count].astype(bool)

    def fragments(self, body=0) -> np.ndarray:
        """Connected pieces of leaders and followers over intact links: an id per particle (0, 1, ... in order of
        their smallest particle index), -1 for frame points."""
        return self._rt(body).fragments()

    def fictitious_points(self, body=0) -> tuple[np.ndarray, np.ndarray]:
        """The fictitious points of the current step: (owner particle index [m], position [m, 3] [m]), one for each
        link a body point (leader or follower) has lost: x_j + s (X_k - X_j). Frame points own none (they copy, they
        apply no rule). Empty without fracture or fictitious points."""
        r = self._rt(body)
        b = r.body
        if not r.fracture or b.fracture.fictitious_distance is None:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
        owner = np.repeat(np.arange(b.particle_count), np.diff(b.row_offsets))
        dead = ~self.link_alive(body) & (owner < b.body_count)
        owner = owner[dead]
        x = self.positions(body)
        return owner, x[owner] + b.fracture.fictitious_distance * b.offset_delta[b.link_offset[dead]]

    def trajectories(self, body=0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """History of the tracked particles (LatticeBody.track) at steps 0..step_count: (indices [T], positions
        [steps + 1, T, 3] [m], PE1 [steps + 1, T] [m^2])."""
        r = self._rt(body)
        if len(r.tracked) == 0:
            raise ParameterError(
                "body", r.body.name, "a body with tracked particles (LatticeBody.track before solving)"
            )
        r._flush_tracks()
        u = np.concatenate(r.track_host_u)
        pe1 = np.concatenate(r.track_host_pe1)
        r.track_host_u, r.track_host_pe1 = [u], [pe1]
        return r.tracked.copy(), r.rest_world[r.tracked][None] + u, pe1


def _bounds_centre(bodies) -> np.ndarray:
    """Centre of the rest bounding box of all points of ``bodies`` [m], float64 [3]."""
    lo = np.min([b.rest_positions.min(axis=0) for b in bodies], axis=0)
    hi = np.max([b.rest_positions.max(axis=0) for b in bodies], axis=0)
    return 0.5 * (lo + hi)


def _leader_cause(paths, step: int, limit: float) -> str | None:
    """The likely cause of a diverged lattice body when it is a leader path: the first path whose displacement at
    ``step`` (float64 on the host) is not finite in float32, the precision of the device, or exceeds ``limit`` [m];
    None when every path stays within it (then the rule diverged)."""
    for p in paths:
        if step >= p.steps[-1]:
            u = p.displacements[-1] + p.velocity_after * float(step - p.steps[-1])
        else:
            u = np.array([np.interp(step, p.steps, p.displacements[:, a]) for a in range(3)])
        size = float(np.max(np.abs(u)))
        if not size < np.finfo(np.float32).max or size > limit:
            how = (
                f"velocity ({', '.join(f'{c:.3g}' for c in p.velocity_after)}) m/step"
                if len(p.steps) == 1
                else f"a path of {len(p.steps)} keyframes"
            )
            beyond = "the float32 range" if not size < np.finfo(np.float32).max else f"{limit:.3g} m"
            return (
                f"the leaders added with {how} move {size:.3g} m by step {step}, beyond "
                f"{beyond}; give add_leaders' velocity in metres per step and path displacements in metres"
            )
    return None
