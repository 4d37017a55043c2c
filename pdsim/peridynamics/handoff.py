"""Rigid hand-off: a fragment of a breakable peridynamic body that has stopped deforming becomes a rigid body.

A fragment (a connected set of particles over live bonds, pdsim/fragment_labels.py) is handed off when, at the end of
``frames`` consecutive frames, the equivalent strain of its vibration

    eps = sqrt(4 K_int / (M c_p^2))

stays below ``strain`` [-]. K_int [J] is the kinetic energy of its particles not in rigid motion (K - 1/2 M v^2 -
1/2 w . L, with v the velocity of the centre of mass, L the angular momentum about it and w = I^+ L), M [kg] its
mass and c_p [m/s] its material's P-wave speed: a plane wave of strain eps carries a kinetic and an elastic energy
density of 1/2 rho c_p^2 eps^2 each, so a vibration of root-mean-square strain eps has, over a period, the mean
kinetic energy 1/4 M c_p^2 eps^2. The test reads the motion only: a fragment at rest that holds a static strain (its
own weight on a few contact points, a crack jammed shut inside it) is quiet, and one that vibrates shows it at every
frame end but at the turning points, which ``frames`` consecutive frames do not all meet. Its elastic energy E_el
[J] is measured for the books (``released``). A free fragment must also have settled: the fastest point of its rigid
motion, v_max = max |v + w x (x_i - c)| [m/s], stays below ``strain`` c_p, so that no impact at its own speed (whose
strain is about v / c_p) could strain it past the same threshold. A piece in flight, which would break again where it
lands, therefore stays deformable until it rests (``RigidHandoff(in_flight=True)`` drops this test: pieces flying
through empty space go rigid too). Only fragments of a body with the setting on, in a body that has
broken into more than one fragment, are handed off: fragments of free particles only (no boundary condition) as
rigid fragments, and (with ``RigidHandoff(fixed=True)``; off by default) fragments held by fixed boundary conditions
as static fragments.

A static fragment is one whose constrained particles are all held by ``fix`` on all three axes, from a start already
passed and never released, and none of whose particles carries a load or a velocity kick still to come (a prescribed
velocity, a fix on some axes only, a release, a load or a kick keep the fragment deformable); a clamped rim is the
case it is for. Its eps counts its whole kinetic energy K (the constraint leaves it no free rigid motion). From its
hand-off on it sleeps: its particles stay where they are (their displacements kept bit for bit) at zero velocity,
its bonds are no longer visited, and its particles stay in particle contact as static collision proxies (forces on
them are discarded, as on the fixed rim itself). Its momentum is zero by the constraint; its energy K + E_el is
dropped (``released``). What it gives up: it no longer breaks, vibrates or responds to a hit (a projectile or a
fragment that reaches it later meets a fixed obstacle, and a kinematic projectile passes through it). A body that has
not broken never sleeps (it would before the hit that breaks it).

From the hand-off on (kernels/peridynamics/handoff.py):

- the fragment's particles stay as collision proxies: every step they move as free points under every force and
  impulse (particle contact, colliders, the ground, dynamic rigid bodies, contact with other methods, loads, gravity),
  then their motion is projected onto the rigid motion of the same linear and angular momentum, and they are posed
  on it (after the drift and after the second half kick);
- its bonds are no longer visited: the dilatation and force passes run over the compacted list of the particles
  outside rigid fragments (``live``, rebuilt at each hand-off; kernels/peridynamics/step.py), split into CPU
  threads' ranges of equal bond count over that list, so their cost drops with the rigid share of the bonds; the
  debris-damping pass (Material.debris_damping) runs over those and the fragment's particles whose damage is above
  the material's threshold (``damped``: the drag still acts on them, as without the hand-off, and is projected with
  the other forces);
- its rigid motion is updated on the device every step (two launches, no host round trip);
- its render surface is cut out of the body's surface mesh at the first frame it is rigid and written from then on as
  a rigid piece: that surface as a static mesh in the fragment's body frame, under the transform of its rigid
  motion, with its velocity and angular velocity (``RigidPieces``; docs/cache_format.md); a static fragment's
  transform stays at its centre of mass at the hand-off, unrotated, with zero velocities.

At the hand-off a free fragment keeps its linear and angular momentum exactly; the energy K_int + E_el is dropped
(``released``: ``internal_kinetic``, at most 1/4 M c_p^2 strain^2, which holds a static fragment's whole K, and
``elastic``, the strain it holds: its shape at the hand-off is kept). The fragment no longer breaks further, and its
internal vibration is gone (docs/fracture.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from ..bodies import PointKind
from ..checks import check_range
from ..errors import ParameterError
from ..kernels.peridynamics import handoff as kh
from ..output.views import DeferredView, MeshView, RigidView

DEFAULT_STRAIN_FRACTION = 0.1  # default threshold: this fraction of the material's critical stretch
# the rigid fragments' state in a checkpoint, in the order of FragmentHandoff._host_state
CHECKPOINT_NAMES = (
    "offsets", "members", "body_offset", "inv_inertia", "orientation", "centre", "velocity", "angular", "static",
)  # fmt: skip


@dataclass(frozen=True)
class RigidHandoff:
    """The rigid hand-off setting of a peridynamic body (``PeridynamicBody(rigid_handoff=...)``).

    Args:
        strain: threshold of the equivalent strain of the vibration eps (module docstring) [-], > 0; None:
            DEFAULT_STRAIN_FRACTION times the material's critical stretch at the body's horizon.
        frames: consecutive frames a fragment must stay below it, integer >= 1.
        fixed: also hand off the fragments held by fixed boundary conditions, as static fragments (module
            docstring); False (default): only fragments of free particles. Off by default because a static fragment
            no longer responds to hits (module docstring) and nothing wakes it.
        in_flight: also hand off free fragments that move: True drops the test that the fastest point of the
            fragment's rigid motion stays below ``strain`` times its P-wave speed (module docstring); False
            (default): only fragments that have settled, which no impact at their own speed could break.
    """

    strain: float | None = None
    frames: int = 3
    fixed: bool = False
    in_flight: bool = False

    def __post_init__(self):
        if self.strain is not None:
            object.__setattr__(self, "strain", check_range("strain", self.strain, 0.0, None))
        if isinstance(self.frames, bool) or int(self.frames) != self.frames or self.frames < 1:
            raise ParameterError("frames", self.frames, "an integer >= 1 (consecutive frames below the threshold)")
        if not isinstance(self.fixed, bool):
            raise ParameterError("fixed", self.fixed, "True or False (static hand-off of fragments held by fix)")
        if not isinstance(self.in_flight, bool):
            raise ParameterError("in_flight", self.in_flight, "True or False (hand-off of fragments that move)")


def handoff_setting(value) -> RigidHandoff | None:
    """A body's ``rigid_handoff`` argument as a RigidHandoff (True: the defaults) or None (None or False: off)."""
    if value is None or value is False:
        return None
    if value is True:
        return RigidHandoff()
    if isinstance(value, RigidHandoff):
        return value
    raise ParameterError("rigid_handoff", value, "None, False, True or a pdsim.RigidHandoff")


class FragmentHandoff:
    """The rigid fragments of one peridynamic solver: per-particle quiet-frame counters on the host, the fragments'
    state on the device (module docstring). Built by the solver when a body has ``rigid_handoff`` on."""

    def __init__(self, solver):
        self.solver = solver
        m = solver.model
        n = m.particle_count
        body_of = np.repeat(np.arange(len(solver.bodies)), np.diff(np.asarray(m.body_offsets)))
        self.body_of = body_of
        self.body_start = np.asarray(m.body_offsets)[body_of]
        threshold, speed, enabled = [], [], []
        for b in solver.bodies:
            setting = b.rigid_handoff
            enabled.append(setting is not None and b.material.breaks)
            strain = None if setting is None else setting.strain
            if strain is None:
                sc = b.material.critical_stretch_for(b.horizon) if b.material.breaks else 0.0
                strain = DEFAULT_STRAIN_FRACTION * sc
            threshold.append(strain)
            speed.append(b.material.p_wave_speed)
        self.frames_needed = np.array([b.rigid_handoff.frames if b.rigid_handoff else 0 for b in solver.bodies])
        self.fixed = np.array([bool(b.rigid_handoff and b.rigid_handoff.fixed) for b in solver.bodies])[body_of]
        self.in_flight = np.array([bool(b.rigid_handoff and b.rigid_handoff.in_flight) for b in solver.bodies])[body_of]
        # per boundary condition (in the kinematics' order): a fix on all three axes never released; its window [s]
        anchor, window = [], []
        for b in solver.bodies:
            for c in b.conditions:
                anchor.append(c.kind == PointKind.FIXED and bool(np.all(c.axes != 0)) and c.release == np.inf)
                window.append((c.start, c.release))
        self.anchor_condition = np.asarray(anchor, dtype=bool)
        self.condition_window = np.asarray(window, dtype=np.float64).reshape(-1, 2)
        self.enabled = np.asarray(enabled, dtype=bool)[body_of]
        self.threshold = np.asarray(threshold, dtype=np.float64)[body_of]
        self.wave_speed = np.asarray(speed, dtype=np.float64)[body_of]
        self.quiet = np.zeros(n, dtype=np.int64)  # consecutive frames each particle's fragment stayed quiet
        self.fragment_of = np.full(n, -1, dtype=np.int32)  # rigid fragment per particle, -1: deformable
        self.released = {"internal_kinetic": 0.0, "elastic": 0.0}  # dropped at hand-offs [J] (module docstring)
        self._pieces = None  # RigidPieces per body (the rigid fragments in the output), made by the first views
        self._set_state(
            np.zeros(1, dtype=np.int32), np.zeros(0, dtype=np.int32), np.zeros((0, 3)), np.zeros((0, 3, 3)),
            np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int32),
        )  # fmt: skip

    # -- device state ---------------------------------------------------------------------------------------------
    def _set_state(self, offsets, members, body_offset, inv_inertia, orientation, centre, velocity, angular, static):
        d = self.solver.device
        self.fragment_count = len(offsets) - 1
        self.member_count = len(members)
        self.member_offsets = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=d)
        self.members = wp.array(members.astype(np.int32), dtype=wp.int32, device=d)
        fragment = np.repeat(np.arange(self.fragment_count, dtype=np.int32), np.diff(offsets))
        self.member_fragment = wp.array(fragment, dtype=wp.int32, device=d)
        self.body_offset = wp.array(body_offset, dtype=wp.vec3d, device=d)
        self.body_inv_inertia = wp.array(inv_inertia, dtype=wp.mat33d, device=d)
        self.orientation = wp.array(orientation, dtype=wp.quatd, device=d)
        self.centre = wp.array(centre, dtype=wp.vec3d, device=d)
        self.velocity = wp.array(velocity, dtype=wp.vec3d, device=d)
        self.angular_velocity = wp.array(angular, dtype=wp.vec3d, device=d)
        self.static = wp.array(np.asarray(static, dtype=np.int32), dtype=wp.int32, device=d)
        self.fragment_of = np.full(self.solver.model.particle_count, -1, dtype=np.int32)
        self.fragment_of[members] = fragment
        self.live_host = np.flatnonzero(self.fragment_of < 0).astype(np.int32)
        self.live = wp.array(self.live_host, dtype=wp.int32, device=d)
        self.static_particle = np.zeros(len(self.fragment_of), dtype=bool)  # members of static fragments
        self.static_particle[members] = np.asarray(static, dtype=np.int32)[fragment] != 0
        damped = self.fragment_of < 0  # the debris-damping pass: the live particles and the rigid ones it acts on
        m = self.solver.model
        if m.debris_rate is not None and len(members):  # a rigid particle's damage no longer changes
            damaged = (m.debris_rate.numpy() > 0.0) & (self.solver.damage() > m.debris_damage.numpy())
            damped |= damaged & ~self.static_particle  # a static fragment is at rest: no drag
        self.damped = wp.array(np.flatnonzero(damped).astype(np.int32), dtype=wp.int32, device=d)
        self._commands = {}  # (rotate_dt, ids of u and v) -> the recorded launches of project

    def _host_state(self) -> list:
        return [
            self.member_offsets.numpy().astype(np.int32), self.members.numpy().astype(np.int32),
            self.body_offset.numpy().astype(np.float64), self.body_inv_inertia.numpy().astype(np.float64),
            self.orientation.numpy().astype(np.float64), self.centre.numpy().astype(np.float64),
            self.velocity.numpy().astype(np.float64), self.angular_velocity.numpy().astype(np.float64),
            self.static.numpy().astype(np.int32),
        ]  # fmt: skip

    @property
    def active(self) -> bool:
        """True once a fragment is rigid."""
        return self.fragment_count > 0

    def rigid_particles(self) -> np.ndarray:
        """bool [particle_count]: the particles of rigid fragments."""
        return self.fragment_of >= 0

    def live_bond_rows(self) -> int:
        """Bond rows the dilatation and force passes visit per pass: those of particles not in a rigid fragment."""
        sizes = np.diff(self.solver._offsets_host)
        return int(sizes[self.fragment_of < 0].sum())

    def pieces(self, body: int, labels: np.ndarray) -> dict:
        """The rigid fragments of the solver's body ``body`` now, for the output (copies): ``label``, each one's
        fragment id (its particles' entry of ``labels``, the body's fragment ids), ``centre`` [m] (world),
        ``orientation`` (unit quaternion x, y, z, w), ``velocity`` [m/s] and ``angular_velocity`` [rad/s], float64."""
        offsets, members, _, _, orientation, centre, velocity, angular, _ = self._host_state()
        first = members[offsets[:-1]] if len(members) else np.zeros(0, dtype=np.int64)
        mine = self.body_of[first] == body
        start = int(self.solver.model.body_offsets[body])
        return {
            "label": np.asarray(labels)[first[mine] - start].astype(np.int64),
            "centre": centre[mine] + self.solver.origin,
            "orientation": orientation[mine],
            "velocity": velocity[mine],
            "angular_velocity": angular[mine],
        }

    def cut_surface(self, body: int, surface: DeferredView, labels: np.ndarray) -> DeferredView:
        """The solver's body ``body``'s ``surface`` view (labels: the body's fragment ids now), with its rigid pieces
        cut from it once a fragment is rigid (RigidPieces)."""
        if not self.active:
            return surface
        if self._pieces is None:
            self._pieces = [RigidPieces(b.name) for b in self.solver.bodies]
        return self._pieces[body].deferred(surface, self.pieces(body, labels))

    # -- the step ---------------------------------------------------------------------------------------------------
    def project(self, rotate_dt: float) -> None:
        """Projects the rigid fragments' particles onto rigid motion and poses them (kernels/peridynamics/handoff.py);
        ``rotate_dt`` [s]: the time over which the orientation turns (the step after the drift, 0 after the kick)."""
        if self.fragment_count == 0:
            return
        s = self.solver
        key = (float(rotate_dt), id(s.kin.u), id(s.kin.v))
        commands = self._commands.get(key)
        if commands is None:  # recorded once per configuration: a replay skips wp.launch's argument packing
            commands = kh.project(
                fragment_count=self.fragment_count,
                member_count=self.member_count,
                device=s.device,
                record_cmd=True,
                member_offsets=self.member_offsets,
                members=self.members,
                member_fragment=self.member_fragment,
                body_offset=self.body_offset,
                rest=s.model.rest_positions,
                displacements=s.kin.u,
                velocities=s.kin.v,
                mass=s.kin.mass,
                body_inv_inertia=self.body_inv_inertia,
                at_rest=self.static,
                rotate_dt=float(rotate_dt),
                orientation=self.orientation,
                centre=self.centre,
                velocity=self.velocity,
                angular_velocity=self.angular_velocity,
                force_density=s.state.force_density,
            )
            self._commands[key] = (commands, s.kin.u, s.kin.v)  # the arrays kept alive: their ids stay theirs
        else:
            commands = commands[0]
        for cmd in commands:
            cmd.launch()

    # -- the frame-end test -------------------------------------------------------------------------------------------
    def update(self) -> int:
        """The frame-end test (module docstring): counts the quiet frames of the deformable fragments and hands off
        those that reached their body's ``frames``; returns the number of fragments handed off."""
        s = self.solver
        labels = s.fragment_ids().astype(np.int64) + self.body_start  # global id: first particle of the fragment
        n = len(labels)
        free, anchor = self._points()
        candidate = self.enabled & (self.fragment_of < 0)
        bad = np.zeros(n, dtype=bool)  # per fragment id: holds a particle that cannot be handed off
        np.logical_or.at(bad, labels, ~(candidate & (free | anchor)))
        anchored = np.zeros(n, dtype=bool)  # per fragment id: holds a fixed particle (a static fragment)
        np.logical_or.at(anchored, labels, anchor)
        np.logical_or.at(bad, labels, anchored[labels] & (self._loaded() | ~self.fixed))
        pieces = np.zeros(len(s.bodies), dtype=np.int64)  # fragments per body
        firsts = np.unique(labels)
        np.add.at(pieces, self.body_of[firsts], 1)
        bad |= pieces[self.body_of] <= 1  # an unbroken body is not a fragment
        eligible = ~bad[labels]
        if not eligible.any():
            self.quiet[:] = 0
            return 0
        idx, inverse, props, e_el, eps, limit, x = self._strains(eligible, labels, anchor)
        count = len(eps)
        quiet_fragment = (eps < limit) & (props["impact_strain"] < limit)
        quiet = np.zeros(n, dtype=np.int64)
        quiet[idx] = np.where(quiet_fragment[inverse], self.quiet[idx] + 1, 0)
        self.quiet = quiet
        need = np.zeros(count, dtype=np.int64)
        need[inverse] = self.frames_needed[self.body_of[idx]]
        ready_count = np.full(count, np.iinfo(np.int64).max)
        np.minimum.at(ready_count, inverse, quiet[idx])
        ready = ready_count >= need
        if not ready.any():
            return 0
        static = np.zeros(count, dtype=bool)
        np.logical_or.at(static, inverse, anchor[idx])
        self._hand_off(idx, inverse, ready, static, props, x)
        dropped = np.where(static, props["kinetic"], props["internal_kinetic"])  # a static fragment's motion: all
        self.released["internal_kinetic"] += float(dropped[ready].sum())
        self.released["elastic"] += float(e_el[ready].sum())
        return int(ready.sum())

    def _points(self) -> tuple[np.ndarray, np.ndarray]:
        """bool per particle: (free: under no boundary condition, or under one already released; anchor: held by a
        fix on all three axes that has started and is never released, the particles that make a fragment static)."""
        s = self.solver
        cond = s.kin.point_condition_host
        free = cond < 0
        anchor = np.zeros(len(cond), dtype=bool)
        some = ~free
        start, release = self.condition_window[cond[some]].T
        free[some] = release <= s.time
        anchor[some] = self.anchor_condition[cond[some]] & (start <= s.time)
        return free, anchor

    def _loaded(self) -> np.ndarray:
        """bool per particle: carries a load or a velocity kick still to come (a static fragment cannot honour it)."""
        kin = self.solver.kin
        out = np.zeros(kin.point_count, dtype=bool)
        if kin.load_count:
            out[kin.load_point.numpy()] = True
        for _, points, _ in kin.kicks[kin.next_kick :]:
            out[points.numpy()] = True
        return out

    def _strains(self, mask: np.ndarray, labels: np.ndarray, anchor: np.ndarray) -> tuple:
        """The equivalent strain eps (module docstring) of the fragments of the particles ``mask`` (grouped by their
        global fragment id ``labels``; a fragment with an ``anchor`` particle counts its whole kinetic energy): (the
        particles' indices idx, their fragment 0..g-1 ``inverse``, the fragments' rigid_properties (with
        ``counted_kinetic``, the kinetic energy in eps [J]), elastic energy
        [J], eps [-], threshold [-], positions x [m] of every particle)."""
        s = self.solver
        x = s.model.rest_positions.numpy().astype(np.float64) + s.kin.u.numpy().astype(np.float64)
        v = s.kin.velocities()
        mass = np.asarray(s.kin.mass_host, dtype=np.float64)
        energy = s.model.volumes_host * s.strain_energy_density()
        ids, inverse = np.unique(labels[mask], return_inverse=True)
        props = rigid_properties(x[mask], v[mask], mass[mask], inverse, len(ids))
        e_el = np.bincount(inverse, weights=energy[mask], minlength=len(ids))
        idx = np.flatnonzero(mask)
        c2 = np.zeros(len(ids))
        limit = np.zeros(len(ids))
        c2[inverse] = self.wave_speed[idx] ** 2
        limit[inverse] = self.threshold[idx]
        anchored = np.zeros(len(ids), dtype=bool)
        np.logical_or.at(anchored, inverse, anchor[idx])
        props["counted_kinetic"] = np.where(anchored, props["kinetic"], props["internal_kinetic"])  # the K in eps
        eps = np.sqrt(4.0 * np.maximum(props["counted_kinetic"], 0.0) / (props["mass"] * c2))
        # the settling test: the fastest point of the rigid motion over c_p (0 for static and in-flight fragments)
        arm = x[idx] - props["centre"][inverse]
        point_speed = np.linalg.norm(
            props["velocity"][inverse] + np.cross(props["angular_velocity"][inverse], arm), axis=1
        )
        speed = np.zeros(len(ids))
        np.maximum.at(speed, inverse, point_speed)
        exempt = anchored.copy()
        np.logical_or.at(exempt, inverse, self.in_flight[idx])
        props["impact_strain"] = np.where(exempt, 0.0, speed / np.sqrt(c2))
        return idx, inverse, props, e_el, eps, limit, x

    def fragment_strains(self) -> dict:
        """The deformable fragments of the bodies with the hand-off on, now (for measurements): per fragment its
        ``body`` (index in the solver), ``size`` (particles), ``eps`` [-] and ``threshold`` [-] (module docstring),
        ``constrained`` (particles under a boundary condition), the ``kinetic`` energy in eps and the ``elastic``
        energy [J], ``elastic_strain`` sqrt(2 E_el / (M c_p^2)) [-] (the strain of the elastic energy, which eps does
        not count), ``impact_strain`` v_max / c_p [-] (the settling test; 0 where it does not apply);
        ``labels``: the global fragment id per particle
        (its body's fragment id plus the body's first particle), ``ids``: each fragment's."""
        s = self.solver
        labels = s.fragment_ids().astype(np.int64) + self.body_start
        mask = self.enabled & (self.fragment_of < 0)
        idx, inverse, props, e_el, eps, limit, _ = self._strains(mask, labels, self._points()[1])
        count = len(eps)
        c2 = np.zeros(count)
        c2[inverse] = self.wave_speed[idx] ** 2
        constrained = s.kin.point_condition_host[idx] >= 0
        body = np.zeros(count, dtype=np.int64)
        body[inverse] = self.body_of[idx]
        ids = np.zeros(count, dtype=np.int64)
        ids[inverse] = labels[idx]
        return {
            "labels": labels,
            "ids": ids,
            "body": body,
            "size": np.bincount(inverse, minlength=count),
            "eps": eps,
            "threshold": limit,
            "constrained": np.bincount(inverse, weights=constrained, minlength=count).astype(np.int64),
            "kinetic": props["counted_kinetic"],
            "elastic": e_el,
            "elastic_strain": np.sqrt(2.0 * np.maximum(e_el, 0.0) / (props["mass"] * c2)),
            "impact_strain": props["impact_strain"],
        }

    def _hand_off(self, idx, inverse, ready, static, props, x) -> None:
        """Appends the fragments ``ready`` (of the eligible particles ``idx`` grouped by ``inverse``) to the rigid
        fragments and poses their particles on their rigid motion; those ``static`` at rest where they are (their
        particles' body offsets: their displacements now, kept bit for bit; velocity and angular velocity 0)."""
        take = ready[inverse]
        new_members = idx[take]
        group = inverse[take]
        order = np.argsort(group, kind="stable")
        new_members, group = new_members[order], group[order]
        kept = np.flatnonzero(ready)
        renumber = np.full(len(ready), -1, dtype=np.int64)
        renumber[kept] = np.arange(len(kept))
        group = renumber[group]
        counts = np.bincount(group, minlength=len(kept))
        offsets, members, body_offset, inv_inertia, orientation, centre, velocity, angular, fixed = self._host_state()
        start = int(offsets[-1])
        rests = static[kept]
        at_rest = rests[:, None]
        centre_new = props["centre"][kept]
        u = self.solver.kin.u.numpy()[new_members].astype(np.float64)
        new = [
            np.concatenate([offsets, start + np.cumsum(counts)]).astype(np.int32),
            np.concatenate([members, new_members]).astype(np.int32),
            np.concatenate([body_offset, np.where(at_rest[group], u, x[new_members] - centre_new[group])]),
            np.concatenate([inv_inertia, np.where(at_rest[:, :, None], 0.0, props["inv_inertia"][kept])]),
            np.concatenate([orientation, np.tile([0.0, 0.0, 0.0, 1.0], (len(kept), 1))]),
            np.concatenate([centre, centre_new]),
            np.concatenate([velocity, np.where(at_rest, 0.0, props["velocity"][kept])]),
            np.concatenate([angular, np.where(at_rest, 0.0, props["angular_velocity"][kept])]),
            np.concatenate([fixed, rests.astype(np.int32)]),
        ]
        self._set_state(*new)
        s = self.solver
        kh.pose(
            member_fragment=self.member_fragment, members=self.members, body_offset=self.body_offset,
            at_rest=self.static, rest=s.model.rest_positions, orientation=self.orientation, centre=self.centre,
            velocity=self.velocity, angular_velocity=self.angular_velocity, displacements=s.kin.u, velocities=s.kin.v,
            force_density=s.state.force_density, count=self.member_count, device=s.device,
        )  # fmt: skip
        self.quiet[new_members] = 0
        s.rebalance_ranges()

    # -- checkpoints ------------------------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        out = {k: np.array(a, copy=True) for k, a in zip(CHECKPOINT_NAMES, self._host_state())}
        out["quiet"] = np.array(self.quiet, copy=True)
        out["released"] = np.array([self.released["internal_kinetic"], self.released["elastic"]])
        return out

    def restore(self, state: dict) -> None:
        self._set_state(*[np.asarray(state[k]) for k in CHECKPOINT_NAMES])
        self.quiet = np.array(state["quiet"], dtype=np.int64, copy=True)
        released = np.asarray(state["released"], dtype=np.float64)
        self.released = {"internal_kinetic": float(released[0]), "elastic": float(released[1])}
        self._pieces = None  # their meshes are cut again from the restored surface
        self.solver.rebalance_ranges()


class RigidPieces:
    """The rigid pieces of one peridynamic body in the output: the render surface of each rigid fragment, cut out of
    the body's surface mesh (its faces whose ``fragment`` is the fragment's id, chips included) at the first frame the
    fragment is rigid, kept as a static mesh in the fragment's body frame (R^T (x - c) at that frame), and written from
    then on as a RigidView ``piece_<id>`` (with the faces' attributes: crack, fragment) under ``<body>_pieces``
    posed by the fragment's rigid motion; the body's
    surface loses those faces (and the vertices only they use). A fragment whose surface has no face yet stays in
    no piece until it has. After a restart the meshes are cut again from the restored surface (the writer keeps the
    pieces it wrote and only adds their poses)."""

    def __init__(self, body_name: str):
        self.body_name = body_name
        self.group = f"{body_name}_pieces"
        self.rest = {}  # fragment id -> (points [v, 3] in the body frame [m], faces [f, 3])
        self._version = None  # (surface topology version, ids cut) of the last surface built
        self._count = 0  # minus the cut surface's topology version (negative: apart from the uncut surface's)

    def deferred(self, surface: DeferredView, pieces: dict) -> DeferredView:
        """The body's ``surface`` (a DeferredView of its MeshView) and its rigid pieces now (``pieces``: from
        FragmentHandoff.pieces), built together, in that order, on the thread that builds the surface."""

        def build():
            return self.views(surface.build(), pieces)

        return DeferredView(surface.name, build)

    def views(self, mesh: MeshView, pieces: dict) -> list:
        """[the surface ``mesh`` without the rigid pieces' faces, one RigidView per piece with a surface]."""
        labels = pieces["label"]
        frag = mesh.face_attributes.get("fragment")
        if frag is None or len(labels) == 0:
            return [mesh]
        frag = np.asarray(frag, dtype=np.int64)
        faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
        points = np.asarray(mesh.points, dtype=np.float64)
        for i in np.flatnonzero(~np.isin(labels, list(self.rest))):  # new pieces (a loop over fragments)
            rows = frag == labels[i]
            if not rows.any():
                continue
            verts, local = np.unique(faces[rows], return_inverse=True)
            rot = quat_matrix(pieces["orientation"][i])
            body_points = (points[verts] - pieces["centre"][i]) @ rot  # R^T (x - c), row by row
            attributes = {k: np.asarray(a)[rows] for k, a in mesh.face_attributes.items()}
            self.rest[int(labels[i])] = (body_points, local.reshape(-1, 3), attributes)
        cut = np.array(sorted(set(labels.tolist()) & set(self.rest)), dtype=np.int64)
        keep = ~np.isin(frag, cut)
        used = np.zeros(len(points), dtype=bool)
        used[faces[keep].ravel()] = True
        renumber = np.cumsum(used) - 1
        key = (mesh.topology_version, tuple(cut.tolist()))
        if key != self._version:
            self._version = key
            self._count += 1
        surface = MeshView(
            mesh.name,
            points[used],
            None if mesh.velocities is None else np.asarray(mesh.velocities)[used],
            -self._count,
            renumber[faces[keep]],
            {k: np.asarray(a)[keep] for k, a in mesh.face_attributes.items()},
            {k: np.asarray(a)[used] for k, a in mesh.vertex_attributes.items()},
        )
        out = [surface]
        for i in np.flatnonzero(np.isin(labels, cut)):
            body_points, local, attributes = self.rest[int(labels[i])]
            out.append(
                RigidView(
                    f"piece_{int(labels[i])}", body_points, local, pieces["centre"][i], pieces["orientation"][i],
                    group=self.group, velocity=pieces["velocity"][i], angular_velocity=pieces["angular_velocity"][i],
                    face_attributes=attributes,
                )
            )  # fmt: skip
        return out


def quat_matrix(q) -> np.ndarray:
    """The rotation matrix [3, 3] of a unit quaternion (x, y, z, w), float64."""
    x, y, z, w = (float(c) for c in q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid_properties(x, v, mass, group, count: int) -> dict:
    """Per group of points (``group`` [n] in 0..count-1) of positions x [m], velocities v [m/s] and masses [kg]:
    mass, centre (of mass), velocity (of the centre of mass), angular momentum L about the centre, inertia tensor I
    (points) and its pseudo-inverse, angular velocity w = I^+ L, kinetic energy and internal kinetic energy
    K - 1/2 M v^2 - 1/2 w . L [J]. Vectorised (numpy), float64."""
    m_tot = np.bincount(group, weights=mass, minlength=count)

    def gsum(values):
        values = values.reshape(len(group), int(np.prod(values.shape[1:])))  # also for no points
        return np.stack([np.bincount(group, weights=values[:, i], minlength=count) for i in range(values.shape[1])], 1)

    centre = gsum(mass[:, None] * x) / m_tot[:, None]
    velocity = gsum(mass[:, None] * v) / m_tot[:, None]
    r = x - centre[group]
    vr = v - velocity[group]
    ang = gsum(mass[:, None] * np.cross(r, vr))
    rr = gsum(mass[:, None, None] * (np.einsum("ni,nj->nij", r, r))).reshape(count, 3, 3)
    inertia = np.trace(rr, axis1=1, axis2=2)[:, None, None] * np.eye(3) - rr
    scale = np.maximum(np.abs(inertia).max(axis=(1, 2)), np.finfo(np.float64).tiny)
    inv_inertia = np.linalg.pinv(inertia / scale[:, None, None], rcond=1e-9, hermitian=True) / scale[:, None, None]
    omega = np.einsum("gij,gj->gi", inv_inertia, ang)
    kinetic = 0.5 * np.bincount(group, weights=mass * np.einsum("ni,ni->n", v, v), minlength=count)
    rigid = 0.5 * m_tot * np.einsum("gi,gi->g", velocity, velocity) + 0.5 * np.einsum("gi,gi->g", omega, ang)
    return {
        "mass": m_tot,
        "centre": centre,
        "velocity": velocity,
        "angular_momentum": ang,
        "inertia": inertia,
        "inv_inertia": inv_inertia,
        "angular_velocity": omega,
        "kinetic": kinetic,
        "internal_kinetic": kinetic - rigid,
    }
