"""Contact: short-range repulsion between particles that share no bond (pdsim/colliders.py holds the colliders).

The pieces take Warp arrays and know nothing of the solver's internals. A solver step calls them as

    kick-drift, ground plane                           (positions now at time t + dt)
    collider.apply(x, v, radius, kind, t + dt, dt)     for each collider
    bond force density                                 (into force_density)
    particle_contact.apply(x, v, force_density, kind)  (adds the contact force density, then the hard floor)
    kick

Formulas and conventions are in kernels/contact.py. Nothing here loops over particles: the host work per step is a hash
grid rebuild and kernel launches for particle contact, and one pose evaluation (a few floats) per projectile.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .checks import check_range
from .errors import ParameterError
from .kernels import contact as kc
from .kernels.launch import by_name
from .solver import array_state, assign_state
from .surface_contact import SurfacePairs

CONTACT_NEIGHBOR_BUDGET = 12
"""Contact modulus calibration: C_k (2 r_k)^3 = S_k / 12, so 12 simultaneous contacts (the kissing number of equal
spheres) add one interior bond row sum S_k to a particle's Silling-Askari sum; and the cap: a particle's contact
stiffness row sum never exceeds that of 12 contacts (kernels/contact.py, stiffness cap), so the contact's stable step
is a bound whatever the number of contacts."""


GRID_CELL_FACTOR = 2.0
"""Hash grid cell size over the query radius: a query visits at most 8 cells (kernels/contact.py)."""

SHIELD_FACTOR = 2.05
SHIELD_COUNT = 32
"""A particle is shielded (interior) with at least SHIELD_COUNT particles of its body within SHIELD_FACTOR h: the
6 + 12 + 8 + 6 lattice points of a simple-cubic lattice at h, sqrt(2) h, sqrt(3) h and 2 h."""


def _per_particle(name: str, value, n: int, *, dtype=np.float64) -> np.ndarray:
    a = np.asarray(value, dtype=dtype)
    if a.ndim == 0:
        a = np.full(n, a, dtype=dtype)
    if a.shape != (n,):
        raise ParameterError(name, f"array of shape {a.shape}", f"a scalar or an array of shape ({n},)")
    if dtype is np.float64 and not np.all(np.isfinite(a)):
        raise ParameterError(name, "non-finite values", "finite values")
    return a


def bond_stiffness_row_sum(bulk_modulus, shear_modulus, horizon):
    """Continuum Silling-Askari row sum of an interior particle's bonds [N/m^4] (the sum evaluated by
    kernels/peridynamics/bonds.compute_stiffness_row_sum with the supplement's constants, integrals over the full
    sphere):
    S = (60 mu + 81/4 |kappa/2 - 5 mu/6|) / delta^2. The discrete sums of a lattice body scatter about it: below S
    for surface particles, above it at edges."""
    kappa = np.asarray(bulk_modulus, dtype=np.float64)
    mu = np.asarray(shear_modulus, dtype=np.float64)
    delta = np.asarray(horizon, dtype=np.float64)
    c0 = 0.5 * kappa - 5.0 * mu / 6.0
    return (60.0 * mu + 20.25 * np.abs(c0)) / delta**2


@dataclass
class ContactDiagnostics:
    """Per-particle contact quantities at given positions.

    Attributes:
        energy: half of the penalty energy of each of the particle's contact pairs [J], shape [n] (sums to the total).
        row_sum: contact stiffness row sum sum_j C_kj V_j [N/m^4] as the force pass uses it (capped, see
            CONTACT_NEIGHBOR_BUDGET), shape [n] (adds to the bonds' Silling-Askari sum).
        count: number of active contact pairs, int shape [n].
    """

    energy: np.ndarray
    row_sum: np.ndarray
    count: np.ndarray


class ParticleContact:
    """Short-range repulsion between particles with no live bond between them (fragments, separate bodies).

    A pair repels below the contact distance R_kj = distance_factor (r_k + r_j), or, for two particles of the same
    body, min(bonded_factor |X_j - X_k|, distance_factor (r_k + r_j)) from their reference positions X (LAMMPS PERI's
    rule): a bonded pair at rest feels nothing and a compressed one only below bonded_factor of its rest distance.
    Once the solver hands over its bonds (``track_bonds``, done for bodies that can break), two particles of one body
    across a notch repel only when the notch's faces close below bonded_factor of their rest gap measured along the
    faces' normal: faces that only slide feel nothing. The force is the linear
    penalty with a little normal damping and optional Coulomb friction (kernels/contact.py). A particle's contact
    stiffness is capped at that of 12 contacts, so ``stable_time_step()`` bounds the contact springs
    (docs/stability.md, Contact).

    Args:
        rest_positions: reference positions X [m], shape [n, 3].
        body_id: body index per particle, int shape [n].
        radius: collision radius r (h/2) [m], shape [n].
        volume: particle volume V [m^3], shape [n].
        density: mass density rho [kg/m^3], shape [n].
        bulk_modulus: kappa [Pa], shape [n] (or scalars for these material arrays).
        shear_modulus: mu [Pa], shape [n].
        horizon: delta [m], shape [n].
        device: Warp device.
        distance_factor: R / (r_k + r_j) for particles of different bodies, > 0. Default 1.35 (LAMMPS PERI's
            1.35 lattice constants): bodies at rest keep 1.35 h between particle centres (0.35 h between their cells),
            but the second particle layer then reaches the hollows between four surface particles (1.22 h away), so
            a surface no longer has holes. With 1.0 (cells touch) a lattice offset by half a spacing lets particles
            sink into the hollows and slip through at a far lower speed of approach than with 1.35 (head-on, both
            hold with the hard floor); 1.0 is cheaper (fewer hash-grid candidates).
        bonded_factor: fraction of the reference distance below which particles of the same body repel, in (0, 1];
            default 0.9 (LAMMPS, EMU).
        stiffness_scale: multiplies the contact modulus, > 0. The default (1) gives C_k (2 r_k)^3 = S_k / 12 with
            S_k the continuum bond row sum (bond_stiffness_row_sum): a facing surface particle (bond sum about
            0.94 S) with two contacts reaches about the body's largest bond sum (1.13 S), so the solver's stable step
            is practically unchanged in ordinary impacts.
        damping_ratio: normal damping as a fraction of the pair's critical damping, >= 0; default 0.02 (0.1 lost
            40 % of the energy in a collision of cubes with offset lattices, 0 gained up to 0.3 %). Give this or
            ``restitution``.
        restitution: the pair's normal restitution e in (0, 1] (sets damping_ratio: damping_ratio_for_restitution,
            the same law as every other contact pair).
        friction: Coulomb coefficient between particles, >= 0; default 0.
        floor_factor: hard floor as a fraction of the contact distance, in [0, 1); pairs closer than it are projected
            apart with their approaching velocity removed (0 disables). Default 0.6: particles of different bodies
            stay 0.6 R apart however fast they hit head-on.
        shield_interior: only particles within two lattice shells of a surface take part ("exposed": fewer than 32
            particles of their own body within 2.05 h, the two full shells of a simple-cubic lattice point); no
            foreign particle reaches the interior through two exposed layers, and skipping it makes the contact pass
            cheaper in proportion to the interior's share. Exposure is fixed at
            construction; after bonds break call ``update_exposure`` (crack faces become exposed), or leave this off
            for bodies that can break. Default True. Off, every particle takes part and, as in LAMMPS, interior
            particles of one body also repel when compressed below bonded_factor of their rest distance.
        point_restitution: each particle's side of a pair's restitution, float64 [n] in (0, 1], NaN where it brings
            none (its material's contact_restitution: material_contact_values). A pair takes the larger of its two
            sides' (combine_restitution: in the kernel, the smaller damping ratio), the one side's where the other
            brings none, and ``damping_ratio`` / ``restitution`` where neither does. None: all NaN.
        point_friction: each particle's side of a pair's Coulomb coefficient, float64 [n] >= 0, NaN where it brings
            none (its material's contact_friction). A pair takes sqrt(mu_k mu_j) (combine_friction), the one side's
            where the other brings none, and ``friction`` where neither does. None: all NaN.

    The particles' values (``point_restitution``, ``point_friction``) act between separate surfaces: particles of
    different bodies and, once ``track_bonds`` is called, particles of one body across a crack (their bond broke or a
    notch cut it; with no bond between them, either particle's damage is at least 0.25,
    kernels/contact.py CRACK_FACE_DAMAGE). Intact neighbours of one body take ``damping_ratio`` and ``friction``.
    """

    def __init__(
        self,
        rest_positions,
        body_id,
        radius,
        volume,
        density,
        bulk_modulus,
        shear_modulus,
        horizon,
        *,
        device="cpu",
        distance_factor: float = 1.35,
        bonded_factor: float = 0.9,
        stiffness_scale: float = 1.0,
        damping_ratio: float | None = None,
        restitution: float | None = None,
        friction: float = 0.0,
        floor_factor: float = 0.6,
        shield_interior: bool = True,
        point_restitution=None,
        point_friction=None,
    ):
        rest = np.asarray(rest_positions, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or len(rest) == 0:
            raise ParameterError("rest_positions", f"array of shape {rest.shape}", "an array of shape (n, 3), n >= 1")
        n = len(rest)
        ids = _per_particle("body_id", body_id, n, dtype=np.int32)
        r = _per_particle("radius", radius, n)
        vol = _per_particle("volume", volume, n)
        rho = _per_particle("density", density, n)
        kappa = _per_particle("bulk_modulus", bulk_modulus, n)
        mu = _per_particle("shear_modulus", shear_modulus, n)
        delta = _per_particle("horizon", horizon, n)
        for name, a in (("radius", r), ("volume", vol), ("density", rho), ("horizon", delta), ("shear_modulus", mu)):
            if not np.all(a > 0.0):
                raise ParameterError(name, f"min {a.min():g}", "values > 0")
        self.distance_factor = check_range("distance_factor", distance_factor, 0.0, None)
        self.bonded_factor = check_range("bonded_factor", bonded_factor, 0.0, 1.0, hi_open=False)
        self.stiffness_scale = check_range("stiffness_scale", stiffness_scale, 0.0, None)
        if damping_ratio is not None and restitution is not None:
            raise ParameterError("restitution", restitution, "either restitution or damping_ratio, not both")
        if restitution is not None:
            damping_ratio = damping_ratio_for_restitution(restitution)
        self.damping_ratio = check_range(
            "damping_ratio", 0.02 if damping_ratio is None else damping_ratio, 0.0, None, lo_open=False
        )
        self.friction = check_range("friction", friction, 0.0, None, lo_open=False)
        e_point = np.full(n, np.nan) if point_restitution is None else np.asarray(point_restitution, np.float64)
        mu_point = np.full(n, np.nan) if point_friction is None else np.asarray(point_friction, np.float64)
        for name, a, hi in (("point_restitution", e_point, 1.0), ("point_friction", mu_point, None)):
            known = a[~np.isnan(a)] if a.shape == (n,) else None
            if known is None or np.any(known <= 0.0 if hi else known < 0.0) or (hi and np.any(known > hi)):
                allowed = "values in (0, 1] or NaN" if hi else "values >= 0 or NaN"
                raise ParameterError(name, "an array" if a.shape == (n,) else f"shape {a.shape}", f"({n},) {allowed}")
        self.floor_factor = check_range("floor_factor", floor_factor, 0.0, 1.0, lo_open=False)
        self.shield_interior = bool(shield_interior)
        self.device = wp.get_device(device)
        self.particle_count = n

        modulus = (
            self.stiffness_scale * bond_stiffness_row_sum(kappa, mu, delta) / (CONTACT_NEIGHBOR_BUDGET * (2.0 * r) ** 3)
        )
        self._density_host = rho
        self._radius_host = r
        self._modulus_host = modulus
        f32 = np.float32
        d = self.device
        self.rest_positions = wp.array(rest.astype(f32), dtype=wp.vec3, device=d)
        self.body_id = wp.array(ids, dtype=wp.int32, device=d)
        self.radius = wp.array(r.astype(f32), dtype=float, device=d)
        self.volume = wp.array(vol.astype(f32), dtype=float, device=d)
        self.mass = wp.array((rho * vol).astype(f32), dtype=float, device=d)
        self.modulus = wp.array(modulus.astype(f32), dtype=float, device=d)
        # each particle's side of a pair (NaN: its material brings none): the kernel combines two sides
        self.point_damping_ratio = wp.array(damping_ratios_for_restitutions(e_point).astype(f32), device=d)
        self.point_friction = wp.array(mu_point.astype(f32), device=d)
        self.query_radius = float(self.distance_factor * 2.0 * r.max())
        dim = int(max(8, min(128, round(n ** (1.0 / 3.0)))))
        self.grid = wp.HashGrid(dim, dim, dim, device=d)
        self.exposed = wp.full(n, 1, dtype=wp.int32, device=d)  # hash-grid group: 1 takes part in contact
        if self.shield_interior:
            self._mark_exposed_at_rest(dim)
        self._all_free = wp.zeros(n, dtype=wp.int32, device=d)
        self._position_delta = wp.zeros(n, dtype=wp.vec3, device=d)
        self._velocity_delta = wp.zeros(n, dtype=wp.vec3, device=d)
        # stiffness cap's per-particle scale: the force pass reads _scale and writes _scale_out, then apply() copies
        # _scale into _scale_next (the scale just applied) and _scale_out into _scale (the next pass's). Copies, not
        # a swap of two arrays: every step launches with the same arrays, so a captured frame replays correctly
        # whatever the parity of its step count
        self._scale = wp.ones(n, dtype=float, device=d)
        self._scale_next = wp.ones(n, dtype=float, device=d)
        self._scale_out = wp.ones(n, dtype=float, device=d)
        # the dashpot cap's per-particle scale (kernels/contact.py): the force pass reads _damp and writes _damp_out,
        # copied into _damp after the pass
        self._damp = wp.ones(n, dtype=float, device=d)
        self._damp_out = wp.ones(n, dtype=float, device=d)
        self._force_buffers = {  # the force pass's scale and hard-floor buffers, by kernel parameter name
            "scale_in": self._scale,
            "damp_in": self._damp,
            "position_delta": self._position_delta,
            "velocity_delta": self._velocity_delta,
            "scale_out": self._scale_out,
            "damp_out": self._damp_out,
        }
        self._energy = wp.zeros(n, dtype=float, device=d)
        self._row_sum = wp.zeros(n, dtype=float, device=d)
        self._count = wp.zeros(n, dtype=wp.int32, device=d)
        self.cracks = False  # the bonds are known (track_bonds): contact within a body only across dead bonds
        self._bonds = {
            "family_offsets": wp.zeros(1, dtype=wp.int32, device=d),
            "family_neighbors": wp.zeros(1, dtype=wp.int32, device=d),
            "bond_alive": wp.zeros(1, dtype=wp.uint8, device=d),
            "bond_alive_initial": wp.zeros(1, dtype=wp.uint8, device=d),
        }

    def track_bonds(self, family_offsets, family_neighbors, bond_alive, bond_alive_initial):
        """Gives the contact the bonds of its particles (the solver's CSR families, int32 [n + 1] and int32
        [bond_count], live flags now, uint8 [bond_count], read in place every step, and at the start, the notches):
        from then on two particles of one body across a notch repel only when the notch's faces close, the gap
        measured along the faces' normal, so faces that slide along each other feel nothing; other pairs keep the
        distance rule (kernels/contact.py, crack_pair_geometry). Rows must match this object's."""
        self.cracks = True
        self._bonds = {
            "family_offsets": family_offsets,
            "family_neighbors": family_neighbors,
            "bond_alive": bond_alive,
            "bond_alive_initial": bond_alive_initial,
        }

    def _mark_exposed_at_rest(self, dim: int):
        grid = wp.HashGrid(dim, dim, dim, device=self.device)
        cell = float(SHIELD_FACTOR * 2.0 * self.radius.numpy().max())
        grid.build(self.rest_positions, cell)
        kc.mark_exposed_at_rest(
            grid=grid.id,
            shield_factor=SHIELD_FACTOR,
            full_count=SHIELD_COUNT,
            device=self.device,
            **by_name(self, "rest_positions", "body_id", "radius", "exposed"),
        )

    def update_exposure(self, family_offsets, family_neighbors, bond_alive):
        """Exposes (for good) every particle with fewer than 32 live bonds within 2.05 h, i.e. near a crack: call it
        after bonds break when ``shield_interior`` is on. Arguments: the solver's CSR families (int32
        [n + 1] and int32 [bond_count]) and live flags (uint8 [bond_count]); rows must match this object's. A bond
        pass (cost about one force pass over the family); a family cut at a horizon below 2.05 h exposes everything,
        which is safe."""
        if not self.shield_interior:
            return
        kc.mark_exposed_by_cracks(
            family_offsets=family_offsets,
            family_neighbors=family_neighbors,
            bond_alive=bond_alive,
            shield_factor=SHIELD_FACTOR,
            full_count=SHIELD_COUNT,
            device=self.device,
            **by_name(self, "rest_positions", "radius", "exposed"),
        )

    def exposed_mask(self) -> np.ndarray:
        """Which particles take part in contact (bool [n])."""
        return self.exposed.numpy() != 0

    def checkpoint(self) -> dict:
        """The state a resumed run needs (host copies): the stiffness-cap and dashpot-cap scales, the exposure."""
        return {
            "scale": array_state(self._scale),
            "scale_next": array_state(self._scale_next),
            "damping": array_state(self._damp),
            "exposed": array_state(self.exposed),
        }

    def restore(self, state: dict | None) -> None:
        """Puts a :meth:`checkpoint` back (ParameterError for a checkpoint without one, or of another version)."""
        if state is None:
            raise ParameterError("checkpoint", "no contact state", "a checkpoint of a scene with particle contact")
        if "damping" not in state:
            raise ParameterError("checkpoint", "no contact dashpot scale", "a checkpoint written by this version")
        assign_state(self._scale, state["scale"], "contact scale")
        assign_state(self._scale_next, state["scale_next"], "contact scale")
        assign_state(self._damp, state["damping"], "contact dashpot scale")
        assign_state(self.exposed, state["exposed"], "contact exposure")

    @classmethod
    def from_bodies(cls, bodies, *, device="cpu", origin=(0.0, 0.0, 0.0), **kwargs) -> ParticleContact:
        """Contact between the particles of ``bodies`` (PeridynamicBody list), concatenated in the given order: pass
        ``solver.bodies`` so that rows match the solver's arrays, and the solver's local-frame ``origin`` [m] (rest
        positions are stored as world - origin). ``shield_interior`` defaults to True only when no body can break
        (``body.fractures``); keyword options: see the class."""
        if not bodies:
            raise ParameterError("bodies", bodies, "at least one body")
        kwargs.setdefault("shield_interior", not any(getattr(b, "fractures", False) for b in bodies))
        counts = [b.particle_count for b in bodies]
        kwargs.setdefault("point_restitution", material_contact_values(bodies)[0])
        kwargs.setdefault("point_friction", material_contact_values(bodies)[1])

        def rep(values):
            return np.repeat(np.asarray(values, dtype=np.float64), counts)

        return cls(
            np.concatenate([b.rest_positions for b in bodies]) - np.asarray(origin, dtype=np.float64),
            np.repeat(np.arange(len(bodies), dtype=np.int32), counts),
            rep([0.5 * b.spacing for b in bodies]),
            np.concatenate([b.volumes for b in bodies]),
            rep([b.material.density for b in bodies]),
            rep([b.material.bulk_modulus for b in bodies]),
            rep([b.material.shear_modulus for b in bodies]),
            rep([b.horizon for b in bodies]),
            device=device,
            **kwargs,
        )

    # -- stepping ------------------------------------------------------------------------------------------------
    def apply(self, positions, displacements, velocities, force_density, kind=None):
        """Adds the contact force density [N/m^3] to ``force_density`` (vec3 [n]) for ``positions`` [m] (rest + u in
        the frame of this object's rest positions) and ``velocities`` [m/s] (vec3 [n]; the half-step velocities of
        velocity Verlet), then applies the hard-floor projection to ``displacements`` and ``velocities`` (free
        particles only: ``kind`` int32 [n], 0 = free; all free when None). Call it after the bond force density and
        before the kick. Rebuilds the hash grid on ``positions`` (the query, not the rebuild, dominates the call's
        cost). Updates the stiffness and dashpot caps' scales for the next call (one call of lag). No allocation."""
        self._build_grid(positions)
        kc.particle_contact_forces(
            self.shield_interior,
            self.cracks,
            positions=positions,
            velocities=velocities,
            kind=self._all_free if kind is None else kind,
            budget_count=float(CONTACT_NEIGHBOR_BUDGET),
            force_density=force_density,
            device=self.device,
            **self._force_buffers,
            **self._pair_arguments(),
            **by_name(self, "mass", "damping_ratio", "friction", "point_damping_ratio", "point_friction"),
            floor_factor=self.floor_factor,
        )
        wp.copy(self._scale_next, self._scale)
        wp.copy(self._scale, self._scale_out)
        wp.copy(self._damp, self._damp_out)
        if self.floor_factor > 0.0:
            kc.hard_floor(displacements, velocities, self._position_delta, self._velocity_delta, self.device)

    def _pair_arguments(self) -> dict:
        """The arguments the force and energy kernels share by name: the hash grid, the particles' fixed arrays and
        the contact distance's settings (the two kernels visit the same pairs)."""
        return {
            "grid": self.grid.id,
            **by_name(self, "rest_positions", "body_id", "radius", "volume", "modulus", "exposed"),
            **by_name(self, "query_radius", "distance_factor", "bonded_factor"),
            **self._bonds,
        }

    def _build_grid(self, positions):
        cell = GRID_CELL_FACTOR * self.query_radius
        if self.shield_interior:
            self.grid.build(positions, cell, groups=self.exposed)
        else:
            self.grid.build(positions, cell)

    # -- diagnostics ---------------------------------------------------------------------------------------------
    def diagnostics(self, positions) -> ContactDiagnostics:
        """Penalty energy, stiffness row sum and contact count per particle at ``positions`` (vec3 [n], [m])."""
        self._build_grid(positions)
        kc.particle_contact_energies(
            self.shield_interior,
            self.cracks,
            positions=positions,
            scale=self._scale_next,  # after apply(): the scale its force pass applied (the forces' potential)
            energy=self._energy,
            row_sum=self._row_sum,
            contact_count=self._count,
            device=self.device,
            **self._pair_arguments(),
        )
        return ContactDiagnostics(
            energy=self._energy.numpy().astype(np.float64),
            row_sum=self._row_sum.numpy().astype(np.float64),
            count=self._count.numpy(),
        )

    def potential_energy(self, positions) -> float:
        """Total penalty energy sum over pairs of 1/2 C_kj V_k V_j (R_kj - r)^2 [J] at ``positions``."""
        return float(self.diagnostics(positions).energy.sum())

    def stable_time_step(self, contact_count: int = CONTACT_NEIGHBOR_BUDGET) -> float:
        """Silling-Askari step of the contact springs alone, min_k sqrt(2 rho_k / (contact_count C_k (2 r_k)^3)) [s],
        for a particle with ``contact_count`` contacts' worth of stiffness. The default is the cap's budget (no
        particle's contact row sum exceeds it), so the result bounds the contact springs whatever their number; with
        the default calibration it equals the continuum bond estimate of the body (within the spread of the discrete
        bond sums). A solver takes the min with its own estimate: velocity Verlet then stays within the
        Gershgorin bound for bonds and contact together at safety factors up to 1/sqrt(2) = 0.707 (the Scene's 0.7),
        since dt^2 (S_bond + S_contact) <= safety^2 (2 rho + 2 rho); docs/stability.md, Contact."""
        s = contact_count * self._modulus_host * (2.0 * self._radius_host) ** 3
        return float(np.sqrt(2.0 * self._density_host / s).min())


CONTACT_OMEGA_DT = 0.15
"""The penalty pairs' stiffness tied to the step (MethodContact, the ground's penalty form): k = m_red
(CONTACT_OMEGA_DT / dt)^2, so one contact oscillates at omega dt = 0.15, far inside velocity Verlet's limit of 2 (tens
of simultaneous contacts on one point stay stable, and contact never needs a smaller step). The dashpot switches on at
full strength when a contact starts, part way through a step, so the restitution a pair gets depends on that phase
(velocity Verlet with the dashpot on the half-step velocity): over eight phases of a step, a particle thrown at the
ground's penalty form leaves at 0.070 to 0.105 for e = 0.1 and 0.584 to 0.614 for e = 0.6
(tests/test_contact_law.py, test_drop_rebounds_at_the_restitution_set_on_the_ground; omega dt = 0.25 left e = 0.1
beyond 0.05 in some phases)."""


def restitution_of_damping_ratio(damping_ratio: float) -> float:
    """Normal restitution e of the contact law (kernels/colliders.py penalty_force: a linear spring-dashpot whose
    force never pulls) at damping ratio zeta >= 0.

    A pair of reduced mass m meets at speed v0 on a spring k with a dashpot c = 2 zeta sqrt(k m); with
    omega = sqrt(k / m) its overlap is x(t) = (v0 / (omega s)) exp(-zeta omega t) sin(omega s t), s = sqrt(1 - zeta^2)
    (sinh and s = sqrt(zeta^2 - 1) above critical damping). Were the force allowed to pull, the pair would separate
    when the overlap closes, at omega s t = pi, with e = exp(-zeta pi / s), i.e. zeta = -ln e / sqrt(pi^2 + ln^2 e).
    The law's force k x + c x' never pulls, so the pair separates earlier, when k x + c x' = 0: at
    T = omega s t with tan T = 2 zeta s / (2 zeta^2 - 1) (T in (0, pi); tanh T for zeta > 1), leaving with
    e = -exp(-zeta T / s) (cos T - (zeta / s) sin T) (cosh, sinh above critical damping). That e is higher than the
    classical one (0.64 against 0.6 at zeta = 0.16, 0.25 against 0.1 at zeta = 0.59) and reaches 0 only as zeta grows
    without bound (exp(-2) = 0.135 at critical damping)."""
    zeta = check_range("damping_ratio", damping_ratio, 0.0, None, lo_open=False)
    if zeta == 1.0:
        zeta = 1.0 + 1.0e-9  # the limit, continuous from both sides
    if zeta < 1.0:
        root = np.sqrt(1.0 - zeta * zeta)
        t = np.arctan2(2.0 * zeta * root, 2.0 * zeta * zeta - 1.0)
        return float(-np.exp(-zeta * t / root) * (np.cos(t) - (zeta / root) * np.sin(t)))
    root = np.sqrt(zeta * zeta - 1.0)
    t = np.arctanh(2.0 * zeta * root / (2.0 * zeta * zeta - 1.0))
    return float(-np.exp(-zeta * t / root) * (np.cosh(t) - (zeta / root) * np.sinh(t)))


def damping_ratio_for_restitution(restitution: float) -> float:
    """Damping ratio zeta of the contact law whose normal restitution (restitution_of_damping_ratio) is
    ``restitution`` e in (0, 1]: the inverse of that decreasing function, by bisection to 1e-12 in zeta (the
    classical zeta = -ln e / sqrt(pi^2 + ln^2 e) of a dashpot allowed to pull would give a higher e here)."""
    e = check_range("restitution", restitution, 0.0, 1.0, hi_open=False)
    lo, hi = 0.0, 1.0
    while restitution_of_damping_ratio(hi) > e:
        hi *= 2.0
    while hi - lo > 1.0e-12 * max(hi, 1.0):
        mid = 0.5 * (lo + hi)
        if restitution_of_damping_ratio(mid) > e:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def combine_restitution(a, b) -> np.ndarray:
    """The restitution of a pair whose two sides bring ``a`` and ``b`` (arrays or numbers, NaN: the side brings
    none): the larger of the two (Box2D's b2MixRestitution rule, so a rubber ball bounces off a stone floor as
    rubber); where one side brings none, the other's; NaN where neither does. float64, broadcast shape. The contact
    law's damping ratio decreases with e (damping_ratio_for_restitution), so in the kernels the pair takes the smaller
    damping ratio of its two sides, the same rule."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.where(np.isnan(a), b, np.where(np.isnan(b), a, np.maximum(a, b)))


def combine_friction(a, b) -> np.ndarray:
    """The Coulomb coefficient of a pair whose two sides bring ``a`` and ``b`` (arrays or numbers, NaN: the side
    brings none): the geometric mean sqrt(a b) (Box2D's b2MixFriction rule: a side with no friction makes the pair
    frictionless); where one side brings none, the other's; NaN where neither does. float64, broadcast shape."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.where(np.isnan(a), b, np.where(np.isnan(b), a, np.sqrt(a * b)))


def damping_ratios_for_restitutions(restitution) -> np.ndarray:
    """damping_ratio_for_restitution of every value of ``restitution`` (float64 array; NaN stays NaN), solved once
    per distinct value."""
    e = np.asarray(restitution, dtype=np.float64)
    out = np.full(e.shape, np.nan)
    known = ~np.isnan(e)
    values, index = np.unique(e[known], return_inverse=True)
    out[known] = np.array([damping_ratio_for_restitution(v) for v in values])[index] if len(values) else []
    return out


def material_contact_values(bodies, *, per_body: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The per-point contact values of ``bodies`` (any bodies with ``material`` and ``particle_count``),
    concatenated in the given order: (restitution, friction), float64 [n], NaN where the body's material sets none
    (pdsim.Material contact_restitution, contact_friction); ``per_body``: one value per body instead."""
    counts = [1 if per_body else b.particle_count for b in bodies]

    def rep(values):
        return np.repeat(np.asarray([np.nan if v is None else v for v in values], dtype=np.float64), counts)

    return (
        rep([getattr(b.material, "contact_restitution", None) for b in bodies]),
        rep([getattr(b.material, "contact_friction", None) for b in bodies]),
    )


class MethodContact(SurfacePairs):
    """Contact between the bodies of mesh methods and everything else within a step: the particles of each particle
    method (the peridynamic solver's ``contact_particles()``) against the closed surface of each mesh method (the FEM
    solver's ``contact_mesh()``; kernels/contact.py, particle_mesh_contact), and the surface vertices of each mesh
    method against the faces of the other pieces of its own surface and of every other mesh method's (FEM-FEM
    contact: two bodies, or the pieces of a cracked body; kernels/surface_contact.py, vertex_face_contact). Every
    pair uses the one contact law (kernels/contact.py, penalty_force) and gives the reaction to the face's vertices:
    the pair's momentum is conserved exactly. Each side's points bring their material's restitution and friction
    (the solvers' ``point_contact_values()``), combined per pair (combine_restitution, combine_friction); the
    ``damping_ratio`` / ``restitution`` and ``friction`` given here stand where neither side brings one.

    The stiffness is tied to the step: k = m_red (CONTACT_OMEGA_DT / T)^2 (a contact oscillates at omega T = 0.15,
    far inside velocity Verlet's limit of 2), so contact never needs a smaller step. T is the run's step dt, or where
    the mesh's elements around the pair take a longer stable step, ``step_safety`` times that step (never less than
    dt): a vertex's contact is as stiff as its elements bear, the same at any step the run takes. The restitution e a
    user sets gives the dashpot's damping ratio (damping_ratio_for_restitution).

    The scene calls :meth:`apply` once per step, after every solver's ``compute_forces`` and before the kicks, and
    :meth:`end_step` after the solvers' ``end_step`` (the surface contact's hard floor). The surface mesh is rebuilt
    when its topology version changes (fracture) and refitted to the current positions once in a step that uses it (not
    while a mesh solver alone is one piece and no particle method is there). Nothing is allocated per step otherwise.

    Args:
        particle_solvers: solvers offering ``contact_particles()`` -> (point indices int32, radii float32) Warp arrays.
        mesh_solvers: solvers offering ``contact_mesh()`` -> (point indices int32 [v], triangles int32 [3 f] indexing
            those points, topology version), and ``points_in_current_numbering(version, points)`` (SolverFem).
        damping_ratio: the dashpot as a fraction of the pair's critical damping, >= 0 (default 0.1, a restitution of
            0.73); give this or ``restitution``.
        restitution: the normal restitution e in (0, 1] of a pair (sets damping_ratio).
        friction: Coulomb coefficient mu >= 0 between the surfaces (default 0).
        surfaces: contact between mesh surfaces (FEM-FEM and the pieces of a cracked FEM body); default True.
        step_safety: the fraction of a mesh vertex's stable step (its smallest element's, ``contact_steps()`` of the
            mesh solvers) the stiffness is sized on where that is longer than the run's step, in (0, 1]; default 0.7
            (Scene.time_step_safety's default: a mesh of equal elements run at the automatic step gets the stiffness
            of the run's step).
    """

    def __init__(
        self,
        particle_solvers,
        mesh_solvers,
        *,
        damping_ratio: float | None = None,
        restitution: float | None = None,
        friction: float = 0.0,
        surfaces: bool = True,
        step_safety: float = 0.7,
    ):
        self.particle_solvers = list(particle_solvers)
        self.mesh_solvers = list(mesh_solvers)
        if damping_ratio is not None and restitution is not None:
            raise ParameterError("restitution", restitution, "either restitution or damping_ratio, not both")
        if restitution is not None:
            damping_ratio = damping_ratio_for_restitution(restitution)
        self.damping_ratio = check_range(
            "damping_ratio", 0.1 if damping_ratio is None else damping_ratio, 0.0, None, lo_open=False
        )
        self.friction = check_range("friction", friction, 0.0, None, lo_open=False)
        self.surfaces = bool(surfaces)
        self.step_safety = check_range("step_safety", step_safety, 0.0, 1.0, hi_open=False)
        self._meshes = {}  # id(solver) -> [version, points, faces, positions, wp.Mesh]
        self._current = set()  # ids of the solvers whose mesh is at the current apply's positions (_mesh)
        self._to_force = {}  # id(solver) -> 1 / force_to_newton per point (Warp array)
        self._scratch = {}  # id(solver) -> work account of a solver without a watchdog
        self._sides = {}  # id(solver) -> (its point_contact_values, damping ratio, friction: Warp arrays)
        for ms in self.mesh_solvers:  # raise FeatureNotAvailableError now, before the run, for what they cannot honour
            check = getattr(ms, "check_method_contact", None)
            if check is not None:
                check()
            ms.contact_mesh()

    def _mesh(self, solver):
        """[topology version, points, faces, positions, wp.Mesh] of the solver's contact mesh at its current positions:
        rebuilt when the topology changed, else moved and refitted once per :meth:`apply` (its later calls in the same
        apply find it current)."""
        points, faces, version = solver.contact_mesh()
        entry = self._meshes.get(id(solver))
        if entry is None or entry[0] != version:
            positions = wp.zeros(points.shape[0], dtype=wp.vec3, device=points.device)
            kc.surface_positions(points, solver.kin.rest, solver.kin.u, positions)
            entry = [version, points, faces, positions, wp.Mesh(points=positions, indices=faces)]
            self._meshes[id(solver)] = entry
        elif id(solver) not in self._current:
            kc.surface_positions(points, solver.kin.rest, solver.kin.u, entry[3])
            entry[4].refit()
        self._current.add(id(solver))
        return entry

    def _side(self, solver) -> dict:
        """The solver's points' side of each pair (their material values, ``point_contact_values``) as float32
        device arrays under the kernels' names: damping ratio (damping_ratios_for_restitutions) and friction, NaN
        where a point's material brings none; rebuilt when the solver's values change (FEM fracture splits)."""
        values = solver.point_contact_values()
        entry = self._sides.get(id(solver))
        if entry is None or entry[0] is not values:
            e, mu = values
            d = solver.kin.u.device
            entry = (
                values,
                wp.array(damping_ratios_for_restitutions(e).astype(np.float32), dtype=float, device=d),
                wp.array(np.asarray(mu, dtype=np.float32), dtype=float, device=d),
            )
            self._sides[id(solver)] = entry
        return entry[1], entry[2]

    def _force_scale(self, solver):
        scale = self._to_force.get(id(solver))
        if scale is None or scale.shape[0] != solver.kin.u.shape[0]:  # FEM fracture adds vertices
            scale = wp.array(
                (1.0 / solver.kin.force_to_newton_host).astype(np.float32), dtype=float, device=solver.kin.u.device
            )
            self._to_force[id(solver)] = scale
        return scale

    def apply(self, dt: float) -> None:
        """Adds the contact forces of the current state into the solvers' force arrays (step length ``dt`` [s])."""
        rate = (CONTACT_OMEGA_DT / float(dt)) ** 2
        self._current.clear()  # no solver's contact mesh is at this apply's positions yet (_mesh)
        for ms in self.mesh_solvers if self.particle_solvers else ():
            _, m_points, m_faces, _, mesh = self._mesh(ms)
            m_work = self._work_account(ms)
            m_damping, m_friction = self._side(ms)
            for ps in self.particle_solvers:
                p_points, p_radius = ps.contact_particles()
                p_damping, p_friction = self._side(ps)
                kc.particle_mesh_forces(
                    p_points=p_points,
                    p_rest=ps.kin.rest,
                    p_u=ps.kin.u,
                    p_v=ps.kin.v,
                    p_mass=ps.kin.mass,
                    p_to_force=self._force_scale(ps),
                    p_radius=p_radius,
                    mesh=mesh.id,
                    m_points=m_points,
                    m_faces=m_faces,
                    m_v=ms.kin.v,
                    m_mass=ms.kin.mass,
                    stiffness_rate=rate,
                    damping_ratio=self.damping_ratio,
                    friction=self.friction,
                    p_damping_ratio=p_damping,
                    p_friction=p_friction,
                    m_damping_ratio=m_damping,
                    m_friction=m_friction,
                    p_force=ps.force,
                    m_force=ms.force,
                    dt=dt,
                    p_work=self._work_account(ps),
                    m_work=m_work,
                    m_step=ms.contact_steps(),
                    step_safety=self.step_safety,
                    device=ps.kin.u.device,
                )

        if self.surfaces:
            for a in self.mesh_solvers:
                for b in self.mesh_solvers:
                    self._surface_pair(a, b, rate, dt)

    def _work_account(self, solver):
        """The array the contact work done on ``solver``'s points goes to: its watchdog's work account (slot
        WATCH_COLLIDERS: work done by other bodies), or a scratch array when it has no watchdog."""
        watchdog = getattr(solver, "watchdog", None)
        if watchdog is not None:
            return watchdog.acc
        scratch = self._scratch.get(id(solver))
        if scratch is None:
            scratch = wp.zeros(4, dtype=wp.float64, device=solver.kin.u.device)
            self._scratch[id(solver)] = scratch
        return scratch


__all__ = [
    "CONTACT_OMEGA_DT",
    "ContactDiagnostics",
    "MethodContact",
    "ParticleContact",
    "bond_stiffness_row_sum",
    "combine_friction",
    "combine_restitution",
    "damping_ratio_for_restitution",
    "damping_ratios_for_restitutions",
    "material_contact_values",
    "restitution_of_damping_ratio",
]
