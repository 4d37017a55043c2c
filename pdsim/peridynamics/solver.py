"""State-based peridynamic solid: bodies, the model built from them, and the explicit solver.

The elastic model is the one derived in shared/seeds/pd_supplement.txt (kernels/peridynamics/bonds.py lists the formulas). Its
three parameters come from matching two reference deformations, an isotropic expansion (theta = 3 zeta,
W = 9/2 kappa zeta^2) and a shear (W = 1/2 mu zeta^2). The supplement evaluates the family sums as integrals over a
full sphere, which gives the constants

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
Its derivative with respect to each bond extension (Lambda held fixed) is exactly the supplement's force state, so
the integrator conserves energy up to the dependence of Lambda on rotation, which is negligible at small strain.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InstabilityError, ParameterError
from .body import PeridynamicBody
from .model import PeridynamicState, build_model, make_step_kernels, placeholders


class SolverPeridynamics:
    """Explicit velocity-Verlet solver for the peridynamic bodies of a scene.

    Args:
        bodies: the peridynamic bodies (concatenated into one model).
        device: Warp device ("cpu", "cuda", "cuda:0", ...).
        gravity: acceleration [m/s^2], 3 numbers.
        ground: optional ground plane collider.
        contact: short-range repulsion between particles that share no live bond (separate bodies, fragments):
            None or False (off), True (defaults) or a dict of ParticleContact options (pdsim/contact.py).
        colliders: static mesh colliders and kinematic projectiles (pdsim/contact.py).

    The step launches: kick-drift (+ ground plane), dilatation, force density, kick. No allocation happens per step.
    ``features`` lists the optional parts that are live (and launched) for this scene.
    """

    def __init__(
        self,
        bodies: list[PeridynamicBody],
        *,
        device="cpu",
        gravity=(0.0, 0.0, 0.0),
        ground=None,
        contact=None,
        colliders=(),
    ):
        import warp as wp

        if not bodies:
            raise ParameterError("bodies", bodies, "at least one PeridynamicBody")
        # yielding bodies first, so plastic state is a prefix of the particle and bond arrays (allocated only there)
        self.bodies = sorted(bodies, key=lambda b: not b.material.yields)
        self.device = wp.get_device(device)
        self.gravity = wp.vec3(*[float(g) for g in gravity])
        self.ground = ground
        self.model = build_model(self.bodies, self.device)
        n = self.model.particle_count
        d = self.device
        init_v = np.concatenate([b.initial_velocity for b in self.bodies]).astype(np.float32)
        self.state = PeridynamicState(
            positions=wp.clone(self.model.rest_positions),
            velocities=wp.array(init_v, dtype=wp.vec3, device=d),
            accelerations=wp.zeros(n, dtype=wp.vec3, device=d),
            theta=wp.zeros(n, dtype=float, device=d),
            bp=wp.zeros(n, dtype=wp.vec2, device=d),
            force_density=wp.zeros(n, dtype=wp.vec3, device=d),
            bond_ne=wp.zeros(max(self.model.bond_count, 1), dtype=wp.vec4, device=d),
            bond_lambda=wp.zeros(max(self.model.bond_count, 1), dtype=float, device=d),
        )
        m = self.model
        if m.fracture:
            self.state.bond_alive = wp.clone(m.bond_alive_initial)
            self.state.stretch_min = wp.zeros(n, dtype=float, device=d)
            self._damage = wp.zeros(n, dtype=float, device=d)
        if m.plastic:
            self.state.bond_plastic = wp.zeros(max(m.plastic_bond_count, 1), dtype=float, device=d)
            self.state.eqps = wp.zeros(n, dtype=float, device=d)
        self._kernels = make_step_kernels(fracture=m.fracture, plastic=m.plastic)
        self.colliders = list(colliders)
        self.contact = None
        if contact is not None and contact is not False:
            from ..contact import ParticleContact

            options = {} if contact is True else dict(contact)
            self.contact = ParticleContact.from_bodies(self.bodies, device=self.device, **options)
        self._dummy_u8, self._dummy_f, self._dummy_i = placeholders(d)
        self._energy_density = wp.zeros(n, dtype=float, device=d)
        self._check = wp.zeros(2, dtype=float, device=d)
        self._handles = []  # USD prims of the bodies, set by add_outputs
        self._surfaces = []  # FragmentSurfaces per body, set by add_outputs
        self._fragments = None  # FragmentTracker, created on first use when some body can break
        self.features = {"elastic"}
        if any(gi != 0.0 for gi in gravity):
            self.features.add("gravity")
        if ground is not None:
            self.features.add("ground_plane")
        if any(b.damping > 0 for b in self.bodies):
            self.features.add("damping")
        if m.fracture:
            self.features.add("fracture")
        if m.plastic:
            self.features.add("plasticity")
        if any(b.material.anisotropy is not None for b in self.bodies):
            self.features.add("anisotropy")
        if self.contact is not None:
            self.features.add("contact")
        if self.colliders:
            self.features.add("colliders")
        self.time = 0.0
        self.step_count = 0
        self._update_accelerations(0.0)

    # -- time step -----------------------------------------------------------------------------------------------
    def stable_time_step(self) -> float:
        """Silling-Askari critical time step min_k sqrt(2 rho_k / sum_j V_j C_kj) [s] (no safety factor)."""
        import warp as wp

        from ..kernels.peridynamics import bonds as kb

        m = self.model
        row = wp.zeros(m.particle_count, dtype=float, device=self.device)
        wp.launch(
            kb.compute_stiffness_row_sum,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                m.family_neighbors,
                m.bond_wv_dil,
                m.bond_wv_dev,
                m.dev_b,
                m.dil_d,
                m.dil_c0,
                row,
            ],
            device=self.device,
        )
        s = row.numpy().astype(np.float64)
        ok = s > 0
        if not ok.any():
            return math.inf
        dt_bonds = float(np.sqrt(2.0 * m.density_host[ok] / s[ok]).min())
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

    def _compute_force_density(self, positions):
        import warp as wp

        m, s, ks = self.model, self.state, self._kernels
        f1 = self._dummy_f
        alive, plastic, reverse = self._feature_arrays()
        frac = m.fracture
        wp.launch(
            ks.dilatation,
            dim=m.particle_count,
            inputs=[
                positions,
                m.family_offsets,
                m.family_neighbors,
                m.bond_geom,
                m.bond_wv_dil,
                m.dil_d,
                m.dil_coef,
                m.dev_b,
                alive,
                s.theta,
                s.bp,
                s.bond_ne,
                s.bond_lambda,
                s.stretch_min if frac else f1,
            ],
            device=self.device,
        )
        if m.plastic_particle_count > 0:
            wp.launch(
                ks.plastic_update,
                dim=m.plastic_particle_count,
                inputs=[
                    m.family_offsets,
                    m.bond_geom,
                    m.bond_wv,
                    m.bond_wv_dev,
                    alive,
                    s.bond_ne,
                    s.bond_lambda,
                    s.theta,
                    m.dev_b,
                    m.horizon,
                    m.weighted_volume,
                    m.yield_stress,
                    m.hardening,
                    m.psi_scale,
                    plastic,
                    s.eqps,
                ],
                device=self.device,
            )
        wp.launch(
            ks.force,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                m.family_neighbors,
                m.bond_geom,
                s.bond_ne,
                s.bond_lambda,
                m.bond_wv_dil,
                m.bond_wv_dev,
                s.bp,
                alive,
                m.bond_critical_stretch if frac else f1,
                m.bonus_alpha if frac else f1,
                s.stretch_min if frac else f1,
                s.eqps if m.plastic else f1,
                m.failure_eqps if frac else f1,
                m.plastic_bond_count,
                plastic,
                reverse,
                s.force_density,
            ],
            device=self.device,
        )
        if self.contact is not None:
            self.contact.apply(positions, s.velocities, s.force_density, m.kind)

    def _update_accelerations(self, dt: float):
        import warp as wp

        from ..kernels import integration as ki

        m, s = self.model, self.state
        self._compute_force_density(s.positions)
        wp.launch(
            ki.integrate_kick,
            dim=m.particle_count,
            inputs=[
                s.velocities,
                s.force_density,
                m.inv_density,
                m.kind,
                m.prescribed_axes,
                self.gravity,
                m.damping,
                dt,
                s.accelerations,
            ],
            device=self.device,
        )

    def step(self, dt: float):
        """Advances all bodies by one velocity-Verlet step of ``dt`` [s]."""
        import warp as wp

        from ..kernels import colliders as kcol
        from ..kernels import integration as ki

        m, s = self.model, self.state
        wp.launch(
            ki.integrate_kick_drift,
            dim=m.particle_count,
            inputs=[
                s.positions,
                s.velocities,
                s.accelerations,
                m.rest_positions,
                m.kind,
                m.prescribed_velocity,
                m.prescribed_axes,
                dt,
            ],
            device=self.device,
        )
        if self.ground is not None:
            g = self.ground
            wp.launch(
                kcol.collide_ground_plane,
                dim=m.particle_count,
                inputs=[
                    s.positions,
                    s.velocities,
                    m.kind,
                    m.radius,
                    wp.vec3(*g.normal),
                    float(g.offset),
                    float(g.friction),
                ],
                device=self.device,
            )
        for collider in self.colliders:
            collider.apply(s.positions, s.velocities, m.radius, m.kind, self.time + dt, dt)
        self._update_accelerations(dt)
        self.time += dt
        self.step_count += 1

    def simulate(self, dt: float, steps: int):
        """Runs ``steps`` steps of ``dt`` [s]."""
        for _ in range(int(steps)):
            self.step(dt)

    def check_state(self, speed_limit: float):
        """Raises InstabilityError if a position or velocity is not finite or a speed exceeds ``speed_limit`` [m/s]."""
        import warp as wp

        from ..kernels import integration as ki

        s = self.state
        self._check.zero_()
        wp.launch(
            ki.max_speed_and_finite,
            dim=self.model.particle_count,
            inputs=[s.positions, s.velocities, self._check],
            device=self.device,
        )
        vmax, bad = self._check.numpy()
        if bad > 0 or vmax > speed_limit:
            what = "non-finite positions or velocities" if bad > 0 else f"a particle speed of {vmax:.3g} m/s"
            raise InstabilityError(
                f"the simulation diverged at t={self.time:.6g} s (step {self.step_count}): {what}; the time step is "
                f"too large for this material and spacing (stable estimate {self.stable_time_step():.3g} s): use a "
                "smaller --dt or leave it automatic"
            )

    # -- scene integration --------------------------------------------------------------------------------------------
    @property
    def particle_count(self) -> int:
        return self.model.particle_count

    @property
    def bond_count(self) -> int:
        return self.model.bond_count

    def contact_energy(self) -> float:
        """Contact penalty energy [J] (0 without contact)."""
        return 0.0 if self.contact is None else self.contact.potential_energy(self.state.positions)

    def speed_scale(self) -> float:
        """Largest of the bodies' P-wave speeds, initial speeds, prescribed speeds and projectile speeds [m/s]."""
        speeds = [float(np.linalg.norm(getattr(c, "velocity", np.zeros(3)))) for c in self.colliders]
        for b in self.bodies:
            speeds += [
                b.material.p_wave_speed,
                float(np.abs(b.initial_velocity).max(initial=0.0)),
                float(np.abs(b.prescribed_velocity).max(initial=0.0)),
            ]
        return max(speeds)

    def _primvar_kinds(self) -> dict:
        kinds = {"displacement": "float", "dilatation": "float"}
        if self.model.fracture:
            kinds["damage"] = "float"
            kinds["fragment"] = "int"
        if self.model.plastic:
            kinds["plastic_strain"] = "float"
        return kinds

    def add_outputs(self, cache, *, surfaces: bool = True):
        """Declares one UsdGeom.Points per body, with widths = spacing and the primvars written per frame
        (displacement [m], dilatation, and damage / fragment / plastic_strain when those features are live), and,
        with ``surfaces``, the body's renderable surface ``/World/<body>_surface``: a closed triangle shell per
        fragment (pdsim/peridynamics/surfaces.py), its topology rewritten only on frames where the fragments changed."""
        from .surfaces import FragmentSurfaces

        self._handles = [
            cache.add_points(
                b.name, widths=np.full(b.particle_count, b.spacing, dtype=np.float32), primvars=self._primvar_kinds()
            )
            for b in self.bodies
        ]
        self._surfaces = []
        if surfaces:
            self._surfaces = [
                FragmentSurfaces(b.shape, b.rest_positions, b.spacing, b.name, device=str(self.device))
                for b in self.bodies
            ]
            for surf in self._surfaces:
                surf.add_outputs(cache)

    def fragment_ids(self) -> np.ndarray:
        """Fragment id per particle (connected components of live bonds, numbered per body by the body-local index
        of the fragment's first particle, so ids stay stable over an animation); recomputed only when bonds broke
        since the last call. Zeros when no body can break."""
        from ..graph import FragmentTracker

        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count, dtype=np.int32)
        if self._fragments is None:
            self._fragments = FragmentTracker(m.family_offsets, m.family_neighbors, m.body_offsets, compact=False)
        self._fragments.update(self.state.bond_alive)
        return self._fragments.labels

    def write_outputs(self, cache, frame: int):
        """Writes positions, velocities and the primvars of every body at ``frame``, and the surfaces."""
        x = self.positions()
        v = self.velocities()
        values = {
            "displacement": np.linalg.norm(x.astype(np.float64) - self.model.rest_host, axis=1).astype(np.float32),
            "dilatation": self.state.theta.numpy(),
        }
        if self.model.fracture:
            values["damage"] = self.damage().astype(np.float32)
            values["fragment"] = self.fragment_ids()
        if self.model.plastic:
            values["plastic_strain"] = self.plastic_strain().astype(np.float32)
        for i, handle in enumerate(self._handles):
            sl = self.body_slice(i)
            cache.write_points(handle, frame, x[sl], velocities=v[sl], primvars={k: a[sl] for k, a in values.items()})
        for i, surf in enumerate(self._surfaces):
            sl = self.body_slice(i)
            if self.model.fracture:
                surf.update_topology(values["fragment"][sl])
            surf.write(cache, frame, x[sl])

    # -- host-side views and diagnostics (vectorised numpy) ---------------------------------------------------------
    def positions(self) -> np.ndarray:
        """Current positions [m], shape [particle_count, 3]."""
        return self.state.positions.numpy()

    def velocities(self) -> np.ndarray:
        """Current velocities [m/s], shape [particle_count, 3]."""
        return self.state.velocities.numpy()

    def set_positions(self, positions: np.ndarray):
        """Overwrites positions [m] (shape [particle_count, 3]) and recomputes forces and dilatation."""
        import warp as wp

        p = np.asarray(positions, dtype=np.float32)
        if p.shape != (self.model.particle_count, 3):
            raise ParameterError("positions", p.shape, f"shape ({self.model.particle_count}, 3)")
        wp.copy(self.state.positions, wp.array(p, dtype=wp.vec3, device=self.device))
        self._update_accelerations(0.0)

    def set_velocities(self, velocities: np.ndarray):
        """Overwrites velocities [m/s], shape [particle_count, 3]."""
        import warp as wp

        v = np.asarray(velocities, dtype=np.float32)
        if v.shape != (self.model.particle_count, 3):
            raise ParameterError("velocities", v.shape, f"shape ({self.model.particle_count}, 3)")
        wp.copy(self.state.velocities, wp.array(v, dtype=wp.vec3, device=self.device))

    def dilatation(self) -> np.ndarray:
        """theta per particle at the current positions [-]."""
        return self.state.theta.numpy().astype(np.float64)

    def force_density(self) -> np.ndarray:
        """Internal force density per particle [N/m^3], shape [particle_count, 3]."""
        return self.state.force_density.numpy().astype(np.float64)

    def strain_energy_density(self) -> np.ndarray:
        """Elastic W_k at the current positions [J/m^3] (uses the bond geometry cached by the last force pass, which
        is always that of the current positions)."""
        import warp as wp

        m, s = self.model, self.state
        alive, plastic, _ = self._feature_arrays()
        wp.launch(
            self._kernels.energy,
            dim=m.particle_count,
            inputs=[
                m.family_offsets,
                s.bond_ne,
                m.bond_wv_dev,
                alive,
                m.plastic_bond_count,
                plastic,
                s.theta,
                m.dev_b,
                m.dil_c0,
                self._energy_density,
            ],
            device=self.device,
        )
        return self._energy_density.numpy().astype(np.float64)

    def damage(self) -> np.ndarray:
        """Damage phi_k = 1 - live / all bond weight per particle [-] (zeros when no body can break)."""
        import warp as wp

        from ..kernels.peridynamics import step as pd_step

        m = self.model
        if not m.fracture:
            return np.zeros(m.particle_count)
        wp.launch(
            pd_step.compute_damage,
            dim=m.particle_count,
            inputs=[m.family_offsets, m.bond_wv, self.state.bond_alive, self._damage],
            device=self.device,
        )
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

    def masses(self) -> np.ndarray:
        """Particle masses rho V [kg]."""
        return self.model.density_host * self.model.volumes_host

    def kinetic_energy(self) -> float:
        """1/2 sum m v^2 [J]."""
        v = self.velocities().astype(np.float64)
        return float(0.5 * np.dot(self.masses(), np.einsum("ij,ij->i", v, v)))

    def linear_momentum(self) -> np.ndarray:
        """sum m v [kg m/s]."""
        return self.masses() @ self.velocities().astype(np.float64)

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """sum m (x - origin) x v [kg m^2/s]."""
        x = self.positions().astype(np.float64) - np.asarray(origin, dtype=np.float64)
        return self.masses() @ np.cross(x, self.velocities().astype(np.float64))

    def slice_of(self, body: PeridynamicBody) -> slice:
        """Rows of ``body`` in the concatenated particle arrays (yielding bodies are stored first)."""
        return self.body_slice(next(i for i, b in enumerate(self.bodies) if b is body))

    def body_slice(self, index: int) -> slice:
        """Rows of the solver's body ``index`` (in ``self.bodies`` order) in the concatenated particle arrays."""
        return slice(int(self.model.body_offsets[index]), int(self.model.body_offsets[index + 1]))
