"""State-based peridynamic solid: bodies, the model built from them, and the explicit solver.

The elastic model is the one derived in the peridynamics supplement of the project specification
(kernels/peridynamics/bonds.py lists the formulas). Its three parameters come from matching two reference deformations,
an isotropic expansion (theta = 3 zeta, W = 9/2 kappa zeta^2) and a shear (W = 1/2 mu zeta^2). The supplement evaluates
the family sums as integrals over a full sphere, which gives the constants

    d = 9 / (4 pi delta^4),   b = 15 mu / (2 pi delta^5),   a = kappa d / 2,   g = (5 mu / 6) d / b = delta / 4.

Particles near a free surface have truncated families and would be too soft (the surface effect).
``surface_correction`` chooses the remedy:

- ``"directional"`` (default): Madenci and Oterkus's per-axis correction. Each particle's response to a reference
  deformation along x, y and z is compared with the continuum value (dilatation: uniaxial stretch; deviatoric sum:
  uniaxial stress), and each bond is scaled by an ellipsoidal interpolation of its two particles' factors
  (kernels/peridynamics/bonds.py, compute_directional_bond_factors).
- ``"family"``: the supplement's two matching conditions applied to each particle's own discrete family instead of
  the continuum sphere, d_k = 3 / (delta sum_j V_j beta_j) and b_k = 15 mu / (2 m_k) with
  m_k = sum_j w L^2 V_j beta_j. This is exact for expansion, but it over-stiffens thin parts.
- ``"none"``: the supplement's constants.

docs/accuracy.md measures all three.

The model's elastic energy density is W_k = c0 theta_k^2 + b_k sum_j w e^2 V_j beta_j with c0 = kappa/2 - 5 mu/6.
Its derivative with respect to each bond extension is exactly the force state, so the integrator conserves energy.
The dilatation theta_k = d_k sum_j w e V_j beta_j takes no directional factor: the supplement's Lambda = n . xi / L
(the cosine of the bond's rotation, 1 to first order in the strain) made a rotated body read a wrong dilatation,
reversed past 90 degrees (tests/test_pd_large_strain.py; docs/accuracy.md). Without it the model is the linear
peridynamic solid's dilatation with the supplement's constants: the same to first order, and objective.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from ..contact import ParticleContact, material_contact_values
from ..errors import ParameterError
from ..fragment_labels import FragmentTracker
from ..fragment_surfaces import FragmentSurfaces, surface_states, with_states
from ..kernels.peridynamics import bonds as kb
from ..kernels.peridynamics import damping as pd_damping
from ..kernels.peridynamics import step as pd_step
from ..kinematics import PointKinematics
from ..output.views import DeferredView, PointsView, resolve_views
from ..solver import PointSolver, SolverContext, array_state, assign_state, register_solver
from .body import PeridynamicBody
from .events import CrackEvents
from .handoff import FragmentHandoff
from .model import PeridynamicState, build_model
from .pairs import PairPasses
from .ranges import ParticleRanges, resolve_threads


@register_solver
class SolverPeridynamics(PointSolver):
    """Explicit velocity-Verlet solver for the peridynamic bodies of a scene.

    Args:
        bodies: the peridynamic bodies (concatenated into one model).
        context: the scene's SolverContext (device, gravity, ground, contact, colliders, origin of the local frame).
        device, gravity, ground, contact, colliders, origin: override the context's fields (for scripts and tests
            that build a solver directly). ``contact``: None or False (off), True (defaults) or a dict of
            ParticleContact options (pdsim/contact.py).
        surfaces: build renderable fragment surfaces for the output views (default True).
        threads: CPU threads of the bond passes (``None``: the environment variable ``PDSIM_THREADS`` if set, else
            every core this process may run on, but at most one per 50,000 bonds). Each pass (dilatation with the
            plastic update, force with the breaking test, energy, damage) is split into that many contiguous particle
            ranges of about equal bond count, launched at once (Warp releases the GIL while a CPU kernel runs) and
            joined before the next pass; every particle is computed exactly as in one launch, so results are
            bit-identical for any thread count. The debris damping runs on the same ranges, and so do the kick and
            drift of the shared kinematics where the ranges average at least MIN_POINTS_PER_THREAD (ranges.py)
            particles. On a CUDA device each pass is one launch and ``threads`` must be None or 1.
        pairs: the form of the dilatation and force passes. ``None`` (default): on a CPU device each bond pair
            once (pdsim/peridynamics/pairs.py: the lower particle's thread scatters the other's share into
            fixed-range buffers, summed in a fixed order; with plasticity the return mapping in pair passes too),
            else the directed form (every bond k -> j gathered by k: the GPU, where the scatter would need atomics,
            and a breakable yielding body with the rigid hand-off, since the pair passes' plastic passes need every
            yielding particle outside rigid fragments; a yielding body beside brittle bodies with the hand-off runs
            the pair form). ``True`` asks for the pair form (a
            ParameterError where it is not available), ``False`` for the directed one. Both give the same forces
            and dilatation to float32 round-off (the sums run in another order) and the same broken bonds (with
            plasticity also the same plastic extensions and equivalent plastic strain to round-off); each is
            bit-identical for any thread count.

    State: displacements from the rest configuration, velocities and accelerations (pdsim/kinematics.py), so bond
    deformation is computed from displacement differences and does not depend on where the body sits. The step
    launches: conditions and kick-drift, colliders, dilatation (with the plastic update), force density (with the
    breaking test), contact, loads, kick. No allocation happens per step. ``features`` lists the optional parts that
    are live (and launched) for this scene.
    """

    method = "peridynamics"
    supported_features = PointSolver.supported_features | frozenset({"contact"})

    def __init__(
        self,
        bodies: list[PeridynamicBody],
        context: SolverContext | None = None,
        *,
        device=None,
        gravity=None,
        ground=None,
        contact=None,
        colliders=None,
        origin=None,
        surfaces: bool = True,
        threads: int | None = None,
        pairs: bool | None = None,
    ):
        if not bodies or not all(isinstance(b, PeridynamicBody) for b in bodies):
            raise ParameterError("bodies", bodies, "at least one PeridynamicBody")
        ctx = context or SolverContext()
        device = ctx.device if device is None else device
        gravity = ctx.gravity if gravity is None else gravity
        ground = ctx.ground if ground is None else ground
        contact = ctx.contact if contact is None else contact
        colliders = list(ctx.colliders if colliders is None else colliders)
        if origin is None:
            origin = ctx.origin if context is not None else _bounds_centre(bodies)
        self.origin = np.asarray(origin, dtype=np.float64)
        # yielding bodies first, so plastic state is a prefix of the particle and bond arrays (allocated only there)
        self.bodies = sorted(bodies, key=lambda b: not b.material.yields)
        self.device = wp.get_device(device)
        resolve_threads(threads, self.device)  # a bad setting fails before anything is built
        if pairs is not None and not isinstance(pairs, bool):
            raise ParameterError("pairs", pairs, "None, True or False (the pair form of the bond passes)")
        self.ground = ground
        self.model = build_model(self.bodies, self.device, self.origin)
        m = self.model
        n = m.particle_count
        d = self.device
        damping = np.concatenate([np.full(b.particle_count, b.damping) for b in self.bodies])
        self.kin = PointKinematics(
            self.bodies,
            m.body_offsets,
            m.rest_host,
            self.origin,
            m.density_host * m.volumes_host,
            m.volumes_host,
            damping,
            gravity,
            d,
            wp.float32,
        )
        self.state = PeridynamicState(
            theta=wp.zeros(n, dtype=float, device=d),
            bp=wp.zeros(n, dtype=wp.vec2, device=d),
            force_density=wp.zeros(n, dtype=wp.vec3, device=d),
            bond_ne=wp.zeros(max(m.bond_count, 1), dtype=wp.vec4, device=d),
        )
        self.force = self.state.force_density
        self.inv_mass = m.inv_density
        if m.fracture:
            self.state.bond_alive = wp.clone(m.bond_alive_initial)
            self.state.stretch_min = wp.zeros(n, dtype=float, device=d)
            self._damage = wp.zeros(n, dtype=float, device=d)
        handoff = m.fracture and any(b.rigid_handoff is not None and b.material.breaks for b in self.bodies)
        self._pairs = self._pair_passes(pairs, handoff)  # PairPasses, or None: the directed passes
        if m.plastic:  # the reverse bonds' mirror only for the directed passes (the pairs hold both directions)
            self.state.bond_plastic = wp.zeros(max(m.plastic_bond_count, 1), dtype=float, device=d)
            mirror = max(m.plastic_bond_count, 1) if self._pairs is None else 1
            self.state.bond_plastic_reverse = wp.zeros(mirror, dtype=float, device=d)
            self.state.eqps = wp.zeros(n, dtype=float, device=d)
        self._kernels = pd_step.make_step_kernels(m.fracture, m.plastic, handoff, m.damping_b is not None)
        self._offsets_host = m.family_offsets.numpy()[: n + 1].astype(np.int64)
        self._ranges = None  # ranges over every particle (energy, damage); _bond_ranges: the bond passes'
        self._all_particles = wp.array(np.arange(n, dtype=np.int32), dtype=wp.int32, device=d)
        self.handoff = None  # FragmentHandoff (pdsim/peridynamics/handoff.py) when a body has rigid_handoff on
        self.threads = threads
        if handoff:
            self.handoff = FragmentHandoff(self)
        for c in colliders:
            c.bind(self.origin, self.device)
        if ground is not None:
            ground.bind(self.origin, self.device)
        self.colliders = colliders
        self._colliders_all = ([ground] if ground is not None else []) + colliders
        self._material_contact = material_contact_values(self.bodies)  # the points' (restitution, friction), NaN: none
        self.contact = None
        if contact is not None and contact is not False:
            options = {} if contact is True else dict(contact)
            self.contact = ParticleContact.from_bodies(self.bodies, device=self.device, origin=self.origin, **options)
            if m.fracture:  # contact across a notch only where its faces close
                self.contact.track_bonds(
                    m.family_offsets, m.family_neighbors, self.state.bond_alive, m.bond_alive_initial
                )
            self._positions = wp.zeros(n, dtype=wp.vec3, device=d)  # rest + u, the contact pass's positions
        self._dummy_u8, self._dummy_f, self._dummy_i = pd_step.placeholders(d)
        self._energy_density = wp.zeros(n, dtype=float, device=d)
        self.write_surfaces = bool(surfaces)
        self._surfaces = None  # FragmentSurfaces per body, built on the first views() call
        self._surface_states = None  # their checkpoint states from restore(), put back when they are built
        self._fragments = None  # FragmentTracker, created on first use when some body can break
        live = {
            "ground_plane": ground is not None, "fracture": m.fracture, "plasticity": m.plastic,
            "anisotropy": any(b.material.anisotropy is not None for b in self.bodies),
            "contact": self.contact is not None, "colliders": bool(self.colliders),
            "internal_damping": m.damping_b is not None,
        }  # fmt: skip
        self.features = {"elastic"} | self.kin.features | {name for name, on in live.items() if on}
        self.time = 0.0
        self.step_count = 0
        self._step_dt = None  # the last step [s]: the ground's penalty form is tied to it (none before a step)
        self._stable_dt = None  # the stable step, for the watchdog's message (computed on the first check)
        self._refresh_accelerations()

    # -- CPU threads -----------------------------------------------------------------------------------------------
    @property
    def threads(self) -> int:
        """Threads the bond passes run on (1 on a CUDA device); settable (None: PDSIM_THREADS, else every core, at
        most one per MIN_BONDS_PER_THREAD bonds)."""
        return len(self._ranges.ranges)

    @threads.setter
    def threads(self, value: int | None):
        count = resolve_threads(value, self.device, self.model.bond_count)
        self._ranges = ParticleRanges(self._offsets_host, count, self.device)
        self.kin.ranges = self._ranges.point_launch()  # the kick and drift: on the ranges or one launch
        if self._pairs is not None:
            self._pairs.set_threads(count)
        self.rebalance_ranges()

    def rebalance_ranges(self) -> None:
        """The bond passes' ranges: of equal bond count over the hand-off's live list, or the particles' ranges."""
        self._bond_ranges = self._ranges
        if self.handoff is not None and self.handoff.active:
            cost = np.concatenate([[0], np.cumsum(np.diff(self._offsets_host)[self.handoff.live_host])])
            self._bond_ranges = ParticleRanges(cost.astype(np.int64), len(self._ranges.ranges), self.device)
        if self._pairs is not None:
            self._pairs.set_particles(self.handoff.live_host if self.handoff is not None else None)

    def _pair_passes(self, pairs, handoff: bool) -> PairPasses | None:
        """The pair passes for the ``pairs`` setting (see the class docstring), or None for the directed ones."""
        why = None
        if self.device.is_cuda:
            why = f"the CUDA device {self.device} (the scatter would need atomics)"
        elif handoff and any(
            b.rigid_handoff is not None and b.material.breaks and b.material.yields for b in self.bodies
        ):
            why = (
                "a yielding material with rigid_handoff (the pair passes' plastic passes need every yielding particle"
                " outside rigid fragments)"
            )
        if why is not None:
            if pairs:
                raise ParameterError("pairs", pairs, f"None or False with {why}")
            return None
        if pairs is False:
            return None
        ductile = any(b.material.failure_plastic_strain is not None for b in self.bodies)
        return PairPasses(self.model, self.model.fracture, handoff, self.device, ductile=ductile)

    @property
    def bond_passes(self) -> str:
        """The form of the dilatation and force passes: "pairs" or "directed" (the ``pairs`` setting)."""
        return "directed" if self._pairs is None else "pairs"

    def bond_cache(self):
        """The bond cache (n, e) per directed bond of the last dilatation pass (state.bond_ne), complete."""
        if self._pairs is not None:
            self._pairs.bond_cache(self.state)
        return self.state.bond_ne

    # -- time step -----------------------------------------------------------------------------------------------
    def stable_time_step(self) -> float:
        """Silling-Askari critical time step min_k sqrt(2 rho_k / sum_j V_j C_kj) [s] (no safety factor)."""
        m = self.model
        row = wp.zeros(m.particle_count, dtype=float, device=self.device)
        kb.stiffness_row_sum(
            m.particle_count,
            family_offsets=m.family_offsets,
            family_neighbors=m.family_neighbors,
            bond_wv_dil=m.bond_wv_dil,
            bond_wv_dev=m.bond_wv_dev,
            dev_b=m.dev_b,
            dil_d=m.dil_d,
            dil_c0=m.dil_c0,
            row_sum=row,
            device=self.device,
        )
        s = row.numpy().astype(np.float64)
        ok = s > 0
        if not ok.any():
            return math.inf
        dt_particle = np.sqrt(2.0 * m.density_host[ok] / s[ok])
        if m.retardation is not None:  # Material.retardation_time
            dt_particle = damped_step(dt_particle, m.retardation[ok])
        dt_bonds = float(dt_particle.min())
        return dt_bonds if self.contact is None else min(dt_bonds, self.contact.stable_time_step())

    # -- stepping ------------------------------------------------------------------------------------------------
    def _feature_arrays(self):
        """Arguments shared by the step kernels: live feature arrays or length-1 placeholders."""
        m, s = self.model, self.state
        u8, f1, i1 = self._dummy_u8, self._dummy_f, self._dummy_i
        alive = s.bond_alive if m.fracture else u8
        plastic = s.bond_plastic if m.plastic else f1
        reverse = m.bond_reverse if m.plastic else i1
        return alive, plastic, reverse

    def _mirror_plastic(self):
        """bond_plastic_reverse from bond_plastic (after a restore; the step keeps the mirror itself) for the directed
        passes (the pair form restores its own plastic extensions: PairPasses.restore_cache)."""
        m, s = self.model, self.state
        if m.plastic and m.plastic_bond_count > 0 and self._pairs is None:
            pd_step.mirror_plastic(
                m.plastic_bond_count, m.bond_reverse, s.bond_plastic, s.bond_plastic_reverse, self.device
            )

    def compute_forces(self):
        """Force density [N/m^3] at the current displacements: bonds (with plasticity and the breaking test where
        live), contact, then the loads at the end of the step being taken."""
        m, s = self.model, self.state
        alive = self._feature_arrays()[0]
        live = self.handoff.live if self.handoff is not None else self._dummy_i
        if self._pairs is not None:
            self._pairs.dilatation_and_forces(s, m, self.kin.u, self.kin.v, alive, live, self._dummy_f)
        else:
            _directed_passes(self, alive, live)
        self._other_forces(alive)

    def _other_forces(self, alive) -> None:
        """Debris damping, contact, the ground and the loads, added to the bonds' force density."""
        m, s = self.model, self.state
        if m.debris_rate is not None:  # Material.debris_damping: all particles on the ranges, or the hand-off's list
            damped = self._all_particles if self.handoff is None else self.handoff.damped
            pd_damping.debris_damping(
                self._ranges.launch if self.handoff is None else pd_step.single_launch(damped.shape[0], self.device),
                particles=damped,
                family_offsets=m.family_offsets,
                family_neighbors=m.family_neighbors,
                bond_wv=m.bond_wv,
                bond_alive=alive,
                velocities=self.kin.v,
                inv_density=m.inv_density,
                rate=m.debris_rate,
                damage_threshold=m.debris_damage,
                force_density=s.force_density,
            )
        if self.contact is not None:
            pd_step.deformed_positions(m.particle_count, m.rest_positions, self.kin.u, self._positions, self.device)
            self.contact.apply(self._positions, self.kin.u, self.kin.v, s.force_density, self.kin.point_kind)
        if self.ground is not None and self._step_dt is not None:
            self.ground.add_forces(
                m.rest_positions, self.kin.u, self.kin.v, m.radius, self.kin.point_kind, self.kin.mass,
                self.kin.force_to_newton, s.force_density, self._step_dt, contact=self._material_contact,
            )  # fmt: skip
        self.kin.add_loads(s.force_density, self._force_time)

    def begin_step(self, dt: float) -> None:
        """Kick-drift of the shared kinematics, the rigid fragments' projection over the drift (their particles
        posed on their rigid motion), then the colliders at t + dt."""
        if self.handoff is None or not self.handoff.active:
            super().begin_step(dt)
            return
        if self.watchdog is not None and self.kin.watchdog is not self.watchdog:
            self.watchdog.bind(self.kin)
        self._force_time = self.time + dt
        self.kin.begin_step(self.time, dt)
        self.handoff.project(dt)
        self.apply_colliders(self._force_time, dt)

    def end_step(self, dt: float) -> None:
        """Second half kick, then the rigid fragments' projection; advances time and the step count."""
        self.kin.end_step(self.force, self.inv_mass, dt)
        if self.handoff is not None:
            self.handoff.project(0.0)
        self.time += dt
        self.step_count += 1

    def end_frame(self) -> None:
        """The frame-end work of a run (pdsim.run.advance_checked, after the frame's steps and checks): the rigid
        hand-off's test (pdsim/peridynamics/handoff.py)."""
        if self.handoff is not None:
            self.handoff.update()

    def graph_key(self) -> tuple:
        """The shared parts (pdsim.solver.PointSolver.graph_key) and the rigid fragments' arrays."""
        key = super().graph_key()
        if self.handoff is not None:
            key += (self.handoff.live, self.handoff.damped, self.handoff.members, self._bond_ranges)
        return key

    def _refresh_accelerations(self):
        """Forces and accelerations at the current state without advancing time (after a change of state)."""
        self._force_time = self.time
        self.compute_forces()
        self.kin.end_step(self.force, self.inv_mass, 0.0)

    def apply_colliders(self, time: float, dt: float):
        """Ground plane and colliders on the free particles (spheres of radius h/2) at ``time`` [s]."""
        m = self.model
        self._step_dt = dt  # the step the force phase's ground penalty is tied to
        for c in self._colliders_all:
            c.apply(
                m.rest_positions, self.kin.u, self.kin.v, m.radius, self.kin.point_kind, time, dt, mass=self.kin.mass,
                contact=self._material_contact,
            )  # fmt: skip

    def check_state(self, speed_limit: float):
        """Raises InstabilityError if a displacement or velocity is not finite or a speed exceeds ``speed_limit``
        [m/s]; with a watchdog attached (pdsim.kinematics.Watchdog, as Scene.run does) also when the energy exceeds
        what the run started with plus the work put in, or the dilatation leaves its bounds."""
        where = f"at t={self.time:.6g} s (step {self.step_count})"
        if self._stable_dt is None:  # a bond pass: computed once, not at every check
            self._stable_dt = self.stable_time_step()
        self.bond_cache()  # the watchdog reads the bonds' stretch
        hint = (
            f"the time step is too large for this material and spacing (stable estimate "
            f"{self._stable_dt:.3g} s): use a smaller --dt or leave it automatic"
        )
        if self.watchdog is not None:
            self.watchdog.check(speed_limit, where, hint)
        else:
            self.kin.check(speed_limit, where, hint=hint)

    def checkpoint(self) -> dict:
        """The state to continue this run exactly (pdsim.solver.Solver.checkpoint): the shared kinematics, the bond
        state (live flags, plastic extensions, equivalent plastic strain, the step's dilatation and bond cache) and
        particle contact's stiffness-cap scales and exposure."""
        s = self.state
        self.bond_cache()
        out = {"kinematics": self.kinematics_checkpoint(), "bonds": {}}
        if self.handoff is not None:
            out["handoff"] = self.handoff.checkpoint()
        for name in ("theta", "bp", "force_density", "bond_ne", "bond_alive", "stretch_min"):
            out["bonds"][name] = array_state(getattr(s, name))
        out["bonds"]["bond_plastic"] = array_state(s.bond_plastic)
        out["bonds"]["eqps"] = array_state(s.eqps)
        out["surfaces"] = surface_states(self._surfaces)  # the render surfaces' last clean-up
        if self.contact is not None:
            out["contact"] = self.contact.checkpoint()
        return out

    def restore(self, state: dict) -> None:
        """Puts a :meth:`checkpoint` of a solver built from the same bodies back; fragment labels and surfaces are
        recomputed from the restored bonds at the next output."""
        if int(state["kinematics"]["point_count"]) != self.particle_count:
            raise ParameterError(
                "checkpoint", f"{state['kinematics']['point_count']} particles", f"{self.particle_count} particles"
            )
        self.kinematics_restore(state["kinematics"])
        s = self.state
        for name, values in state["bonds"].items():
            assign_state(getattr(s, name), values, name)
        self._mirror_plastic()
        if self._pairs is not None:
            self._pairs.restore_cache(s)
        if self.handoff is not None:
            self.handoff.restore(state["handoff"])
        if self.contact is not None:
            self.contact.restore(state.get("contact"))
        self._fragments = None
        self._surfaces, self._surface_states = None, state.get("surfaces")  # rebuilt at the next output

    # -- scene integration --------------------------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        return self.model.particle_count

    @property
    def bond_count(self) -> int:
        return self.model.bond_count

    def summary(self) -> str:
        return f"{self.particle_count} particles, {self.bond_count} bonds"

    def contact_energy(self) -> float:
        """Contact penalty energy [J] (0 without contact)."""
        if self.contact is None:
            return 0.0
        return self.contact.potential_energy(self._local_positions_wp())

    def speed_scale(self) -> float:
        """Largest of the bodies' P-wave speeds, initial, prescribed and kick speeds and projectile speeds [m/s]."""
        speeds = [float(np.linalg.norm(getattr(c, "velocity", np.zeros(3)))) for c in self.colliders]
        for b in self.bodies:
            speeds += [b.material.p_wave_speed, b.prescribed_speed()]
        return max(speeds)

    def point_contact_values(self):
        """The particles' own (restitution, friction), float64 [n] each: their body's material contact_restitution
        and contact_friction, NaN where it has none (pdsim/contact.py material_contact_values); the same tuple every
        call."""
        return self._material_contact

    def contact_particles(self):
        """The particles that take part in contact with bodies of other methods (all of them) and their contact
        radii h/2 [m]: (int32 [n], float32 [n]) Warp arrays (pdsim.contact.MethodContact)."""
        if getattr(self, "_contact_points", None) is None:
            n = self.model.particle_count
            self._contact_points = wp.array(np.arange(n, dtype=np.int32), dtype=wp.int32, device=self.device)
        return self._contact_points, self.model.radius

    def crack_events(self) -> CrackEvents:
        """The crack events of this solver's bodies (pdsim/peridynamics/events.py), counted from now."""
        return CrackEvents(self)

    def fragment_ids(self) -> np.ndarray:
        """Fragment id per particle (connected components of live bonds, numbered per body by the body-local index
        of the fragment's first particle, so ids stay stable over an animation); recomputed only when bonds broke
        since the last call. Zeros when no body can break."""
        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count, dtype=np.int32)
        if self._fragments is None:
            self._fragments = FragmentTracker(m.family_offsets, m.family_neighbors, m.body_offsets, compact=False)
        self._fragments.update(self.state.bond_alive)
        return self._fragments.labels

    def views(self) -> list:
        """The views of :meth:`frame_views`, the surfaces built now."""
        return resolve_views(self.frame_views())

    def frame_views(self) -> list:
        """Per body: a PointsView (positions, velocities, widths = spacing; displacement, dilatation, and damage,
        fragment and plastic_strain where those features are live) and, unless ``surfaces`` was turned off, the
        renderable surface ``<body>_surface`` (a closed shell per fragment and per particle whose damage reached the
        surfaces' threshold, pdsim/fragment_surfaces.py; vertex velocities [m/s]; face attributes fragment and
        crack; its topology changes only on frames where those regions change), as a DeferredView that holds copies
        of the state it needs (with rigid fragments, also their pieces cut from it: handoff.py, RigidPieces)."""
        x = self.positions()
        v = self.velocities()
        u = self.kin.displacements()
        values = {"displacement": u, "dilatation": self.state.theta.numpy()}
        if self.model.fracture:
            values["damage"] = self.damage()
            values["fragment"] = self.fragment_ids()
        if self.model.plastic:
            values["plastic_strain"] = self.plastic_strain()
        if self.write_surfaces and self._surfaces is None:
            self._surfaces = [_body_surfaces(b, str(self.device)) for b in self.bodies]
            with_states(self._surfaces, self._surface_states)
        reactions = self.reaction_forces()
        out = []
        for i, b in enumerate(self.bodies):
            sl = self.body_slice(i)
            out.append(
                PointsView(
                    b.name,
                    x[sl],
                    v[sl],
                    np.full(b.particle_count, b.spacing),
                    {k: a[sl] for k, a in values.items()},
                    {cond: r for (body, cond), r in reactions.items() if body == b.name},
                )
            )
            if self._surfaces is not None:
                broken = {}
                if self.model.fracture:
                    broken = {"labels": values["fragment"][sl], "damage": values["damage"][sl]}
                surface = DeferredView(f"{b.name}_surface", self._surfaces[i].deferred_view(x[sl], v[sl], **broken))
                out.append(surface if self.handoff is None else self.handoff.cut_surface(i, surface, broken["labels"]))
        return out

    # -- host-side views and diagnostics (vectorised numpy) ---------------------------------------------------------
    def _local_positions_wp(self):
        """rest + u in the local frame, as a Warp array (the contact pass's positions)."""
        out = wp.zeros(self.model.particle_count, dtype=wp.vec3, device=self.device)
        pd_step.deformed_positions(self.model.particle_count, self.model.rest_positions, self.kin.u, out, self.device)
        return out

    def _particle_vectors(self, name: str, values) -> np.ndarray:
        """``values`` as float64 [particle_count, 3]; ParameterError naming ``name`` for another shape."""
        a = np.asarray(values, dtype=np.float64)
        if a.shape != (self.model.particle_count, 3):
            raise ParameterError(name, a.shape, f"shape ({self.model.particle_count}, 3)")
        return a

    def set_positions(self, positions: np.ndarray):
        """Sets world positions [m] (shape [particle_count, 3]; the displacements become positions - rest) and
        recomputes forces, dilatation and accelerations."""
        p = self._particle_vectors("positions", positions)
        self.kin.set_displacements(p - self.model.rest_host)
        self._refresh_accelerations()

    def set_displacements(self, displacements: np.ndarray):
        """Sets displacements [m] (shape [particle_count, 3]) and recomputes forces and accelerations."""
        self.kin.set_displacements(self._particle_vectors("displacements", displacements))
        self._refresh_accelerations()

    def set_velocities(self, velocities: np.ndarray):
        """Overwrites velocities [m/s], shape [particle_count, 3] (and the accelerations where damping reads them)."""
        self.kin.set_velocities(self._particle_vectors("velocities", velocities))
        if self.model.retardation is not None or self.model.debris_rate is not None:
            self._refresh_accelerations()

    def dilatation(self) -> np.ndarray:
        """theta per particle at the current positions [-]."""
        return self.state.theta.numpy().astype(np.float64)

    def force_density(self) -> np.ndarray:
        """Internal force density per particle [N/m^3], shape [particle_count, 3]."""
        return self.state.force_density.numpy().astype(np.float64)

    def strain_energy_density(self) -> np.ndarray:
        """Elastic W_k at the current positions [J/m^3] (uses the bond geometry cached by the last force pass, which
        is always that of the current positions)."""
        m, s = self.model, self.state
        alive, plastic, _ = self._feature_arrays()
        pd_step.strain_energy_density(
            self._ranges.launch,
            self._kernels,
            family_offsets=m.family_offsets,
            bond_ne=self.bond_cache(),
            bond_wv_dev=m.bond_wv_dev,
            bond_alive=alive,
            plastic_bond_count=m.plastic_bond_count,
            bond_plastic=plastic,
            theta=s.theta,
            dev_b=m.dev_b,
            dil_c0=m.dil_c0,
            energy_density=self._energy_density,
        )
        return self._energy_density.numpy().astype(np.float64)

    def damage(self) -> np.ndarray:
        """Damage phi_k = 1 - live / all bond weight per particle [-] (zeros when no body can break)."""
        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count)
        pd_step.particle_damage(self._ranges.launch, m.family_offsets, m.bond_wv, self.state.bond_alive, self._damage)
        return self._damage.numpy().astype(np.float64)

    def plastic_strain(self) -> np.ndarray:
        """Equivalent plastic strain per particle [-] (zeros when no body yields)."""
        if not self.model.plastic:
            return np.zeros(self.model.particle_count)
        return self.state.eqps.numpy().astype(np.float64)

    def bond_alive(self) -> np.ndarray:
        """Live flag per bond (bool [bond_count]); all True when no body can break."""
        if not self.model.fracture:
            return np.ones(self.model.bond_count, dtype=bool)
        return self.state.bond_alive.numpy()[: self.model.bond_count] != 0

    def strain_energy(self) -> float:
        """Total elastic energy sum_k V_k W_k [J]."""
        return float(np.dot(self.model.volumes_host, self.strain_energy_density()))

    def slice_of(self, body: PeridynamicBody) -> slice:
        """Rows of ``body`` in the concatenated particle arrays (yielding bodies are stored first)."""
        return self.body_slice(next(i for i, b in enumerate(self.bodies) if b is body))

    def body_slice(self, index: int) -> slice:
        """Rows of the solver's body ``index`` (in ``self.bodies`` order) in the concatenated particle arrays."""
        return slice(int(self.model.body_offsets[index]), int(self.model.body_offsets[index + 1]))

    def chip_shares(self) -> dict[str, float]:
        """Per body that can break (name -> share): the share of its mass drawn as chips (:func:`_chip_shares`)."""
        return _chip_shares(self)


def _body_surfaces(body, device: str) -> FragmentSurfaces:
    """The render surfaces of a peridynamic ``body``, its particles drawn as chips from its material's chip_damage."""
    b, chip = body, body.material.chip_damage
    return FragmentSurfaces(b.shape, b.rest_positions, b.spacing, b.name, damage_threshold=chip, device=device)


def _chip_shares(solver: SolverPeridynamics) -> dict[str, float]:
    """Per body of ``solver`` that can break (name -> share): the share of its mass in particles whose damage reaches
    its material's chip_damage, the particles its render surfaces draw as chips; empty when no body can break."""
    if not solver.model.fracture:
        return {}
    damage, mass = solver.damage(), solver.masses()
    out = {}
    for i, body in enumerate(solver.bodies):
        sl = solver.body_slice(i)
        if body.fractures:
            out[body.name] = float(mass[sl][damage[sl] >= body.material.chip_damage].sum() / mass[sl].sum())
    return out


def damped_step(dt, tau):
    """The stable step [s] of central differences whose highest mode, of undamped stable step ``dt`` [s], has the
    damping ratio z = tau / dt (a Kelvin-Voigt retardation time ``tau`` [s]): dt (sqrt(1 + z^2) - z)."""
    z = tau / dt
    return dt * (np.sqrt(1.0 + z * z) - z)


def _directed_passes(solver: SolverPeridynamics, alive, live) -> None:
    """The directed dilatation (with the plastic update) and force passes of ``solver`` (kernels/peridynamics/step.py)
    over its bond ranges; ``alive`` the live flags (or a placeholder), ``live`` the hand-off's live list (or one)."""
    m, s, ks = solver.model, solver.state, solver._kernels
    f1 = solver._dummy_f
    frac = m.fracture
    _, plastic, reverse = solver._feature_arrays()
    plastic_args = (
        {
            "plastic_particle_count": m.plastic_particle_count,
            "bond_wv": m.bond_wv,
            "bond_wv_dev": m.bond_wv_dev,
            "horizon": m.horizon,
            "weighted_volume": m.weighted_volume,
            "yield_stress": m.yield_stress,
            "hardening": m.hardening,
            "psi_scale": m.psi_scale,
            "bond_plastic": plastic,
            "eqps": s.eqps,
            "bond_reverse": reverse,
            "bond_plastic_reverse": s.bond_plastic_reverse,
        }
        if m.plastic
        else pd_step.plastic_placeholders(f1, reverse)
    )
    launch = solver._bond_ranges.launch
    pd_step.dilatation(
        launch,
        ks,
        displacements=solver.kin.u,
        family_offsets=m.family_offsets,
        family_neighbors=m.family_neighbors,
        bond_geom=m.bond_geom,
        bond_wv_dil=m.bond_wv_dil,
        dil_d=m.dil_d,
        dil_coef=m.dil_coef,
        dev_b=m.dev_b,
        bond_alive=alive,
        theta=s.theta,
        bp=s.bp,
        bond_ne=s.bond_ne,
        stretch_min=s.stretch_min if frac else f1,
        live_particles=live,
        **plastic_args,
    )
    pd_step.bond_forces(
        launch,
        ks,
        family_offsets=m.family_offsets,
        family_neighbors=m.family_neighbors,
        bond_geom=m.bond_geom,
        bond_ne=s.bond_ne,
        bond_wv_dil=m.bond_wv_dil,
        bond_wv_dev=m.bond_wv_dev,
        bp=s.bp,
        bond_alive=alive,
        bond_critical_stretch=m.bond_critical_stretch if frac else f1,
        compressive_bonus=m.compressive_bonus if frac else f1,
        compressive_stretch_floor=m.compressive_stretch_floor if frac else f1,
        stretch_min=s.stretch_min if frac else f1,
        eqps=s.eqps if m.plastic else f1,
        failure_eqps=m.failure_eqps if frac else f1,
        plastic_bond_count=m.plastic_bond_count,
        bond_plastic=plastic,
        bond_plastic_reverse=s.bond_plastic_reverse if m.plastic else f1,
        live_particles=live,
        velocities=solver.kin.v,  # read only with the internal damping (Material.retardation_time)
        damping_b=m.damping_b if m.damping_b is not None else f1,
        force_density=s.force_density,
    )


def _bounds_centre(bodies) -> np.ndarray:
    """Centre of the bodies' rest bounding box [m] (the local frame's origin of a solver built without a scene)."""
    rest = np.concatenate([b.rest_positions for b in bodies])
    return 0.5 * (rest.min(axis=0) + rest.max(axis=0))
