"""Contact: short-range repulsion between particles that share no bond, and colliders (static triangle meshes and
kinematic rigid projectiles: sphere, box, mesh, moving ballistically or along a scripted path).

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

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError
from .materials import _check_range

CONTACT_NEIGHBOR_BUDGET = 12
"""Contact modulus calibration: C_k V = S_k / 12, so 12 simultaneous contacts (the kissing number of equal spheres)
add at most one interior bond row sum S_k to a particle's Silling-Askari sum."""


GRID_CELL_FACTOR = 2.0
"""Hash grid cell size over the query radius (see kernels/contact.py for the measurement behind it)."""

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
    kernels/pd_bonds.compute_stiffness_row_sum with the supplement's constants, integrals over the full sphere):
    S = (60 mu + 81/4 |kappa/2 - 5 mu/6|) / delta^2. Measured on a 0.3 m cube (h = 0.02 m, nu = 0 to 0.45): the
    discrete sums lie between 0.65 S (surface particles) and 1.24 S (edges), interior particles at 0.90 S."""
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
        row_sum: contact stiffness row sum sum_j C_kj V_j [N/m^4], shape [n] (adds to the bonds' Silling-Askari sum).
        count: number of active contact pairs, int shape [n].
    """

    energy: np.ndarray
    row_sum: np.ndarray
    count: np.ndarray


class ParticleContact:
    """Short-range repulsion between particles with no live bond between them (fragments, separate bodies).

    A pair repels below the contact distance R_kj = distance_factor (r_k + r_j), or, for two particles of the same
    body, min(bonded_factor |X_j - X_k|, distance_factor (r_k + r_j)) from their reference positions X (LAMMPS PERI's
    rule): a bonded pair at rest feels nothing and a compressed one only below bonded_factor of its rest distance, so
    bonds need no look-up and broken ones need no bookkeeping. The force is a linear penalty with a little normal
    damping and optional Coulomb friction (kernels/contact.py).

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
            sink into the hollows and slip through at 0.17 of the P-wave speed of approach (measured on two cubes:
            1.35 holds to 0.40; head-on, both hold with the hard floor). 1.0 is 1.6x cheaper (fewer hash-grid
            candidates).
        bonded_factor: fraction of the reference distance below which particles of the same body repel, in (0, 1];
            default 0.9 (LAMMPS, EMU).
        stiffness_scale: multiplies the contact modulus, > 0. The default (1) gives C_k (2 r_k)^3 = S_k / 12 with
            S_k the continuum bond row sum (bond_stiffness_row_sum): a facing surface particle (bond sum about
            0.94 S) with two contacts reaches about the body's largest bond sum (1.13 S), so the solver's stable step
            is practically unchanged in ordinary impacts (see the tests for measured figures).
        damping_ratio: normal damping as a fraction of the pair's critical damping, >= 0; default 0.02 (0.1 lost
            40 % of the energy in a collision of cubes with offset lattices, 0 gained up to 0.3 %).
        friction: Coulomb coefficient between particles, >= 0; default 0.
        floor_factor: hard floor as a fraction of the contact distance, in [0, 1); pairs closer than it are projected
            apart with their approaching velocity removed (0 disables). Default 0.6: particles of different bodies
            stay 0.6 R apart however fast they hit head-on.
        shield_interior: only particles within two lattice shells of a surface take part ("exposed": fewer than 32
            particles of their own body within 2.05 h, the two full shells of a simple-cubic lattice point); no
            foreign particle reaches the interior through two exposed layers, and skipping it made the contact pass
            2x faster on two 27 x 27 x 14 slabs (48 % exposed), 3.5x on a 27^3 cube (38 %). Exposure is fixed at
            construction; after bonds break call ``update_exposure`` (crack faces become exposed), or leave this off
            for bodies that can break. Default True. Off, every particle takes part and, as in LAMMPS, interior
            particles of one body also repel when compressed below bonded_factor of their rest distance.
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
        damping_ratio: float = 0.02,
        friction: float = 0.0,
        floor_factor: float = 0.6,
        shield_interior: bool = True,
    ):
        import warp as wp

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
        self.distance_factor = _check_range("distance_factor", distance_factor, 0.0, None)
        self.bonded_factor = _check_range("bonded_factor", bonded_factor, 0.0, 1.0, hi_open=False)
        self.stiffness_scale = _check_range("stiffness_scale", stiffness_scale, 0.0, None)
        self.damping_ratio = _check_range("damping_ratio", damping_ratio, 0.0, None, lo_open=False)
        self.friction = _check_range("friction", friction, 0.0, None, lo_open=False)
        self.floor_factor = _check_range("floor_factor", floor_factor, 0.0, 1.0, lo_open=False)
        self.shield_interior = bool(shield_interior)
        self.device = wp.get_device(device)
        self.particle_count = n

        modulus = (
            self.stiffness_scale * bond_stiffness_row_sum(kappa, mu, delta) / (CONTACT_NEIGHBOR_BUDGET * (2.0 * r) ** 3)
        )
        self._density_host = rho
        self._volume_host = vol
        self._modulus_host = modulus
        f32 = np.float32
        d = self.device
        self.rest_positions = wp.array(rest.astype(f32), dtype=wp.vec3, device=d)
        self.body_id = wp.array(ids, dtype=wp.int32, device=d)
        self.radius = wp.array(r.astype(f32), dtype=float, device=d)
        self.volume = wp.array(vol.astype(f32), dtype=float, device=d)
        self.mass = wp.array((rho * vol).astype(f32), dtype=float, device=d)
        self.modulus = wp.array(modulus.astype(f32), dtype=float, device=d)
        self.query_radius = float(self.distance_factor * 2.0 * r.max())
        dim = int(max(8, min(128, round(n ** (1.0 / 3.0)))))
        self.grid = wp.HashGrid(dim, dim, dim, device=d)
        self.exposed = wp.full(n, 1, dtype=wp.int32, device=d)  # hash-grid group: 1 takes part in contact
        if self.shield_interior:
            self._mark_exposed_at_rest(dim)
        self._all_free = wp.zeros(n, dtype=wp.int32, device=d)
        self._position_delta = wp.zeros(n, dtype=wp.vec3, device=d)
        self._velocity_delta = wp.zeros(n, dtype=wp.vec3, device=d)
        self._energy = wp.zeros(n, dtype=float, device=d)
        self._row_sum = wp.zeros(n, dtype=float, device=d)
        self._count = wp.zeros(n, dtype=wp.int32, device=d)

    def _mark_exposed_at_rest(self, dim: int):
        import warp as wp

        from .kernels import contact as kc

        grid = wp.HashGrid(dim, dim, dim, device=self.device)
        cell = float(SHIELD_FACTOR * 2.0 * self.radius.numpy().max())
        grid.build(self.rest_positions, cell)
        wp.launch(
            kc.count_lattice_neighbors,
            dim=self.particle_count,
            inputs=[grid.id, self.rest_positions, self.body_id, self.radius, SHIELD_FACTOR, SHIELD_COUNT, self.exposed],
            device=self.device,
        )

    def update_exposure(self, family_offsets, family_neighbors, bond_alive):
        """Exposes (for good) every particle with fewer than 32 live bonds within 2.05 h, i.e. near a crack: call it
        after bonds break when ``shield_interior`` is on. Arguments: the solver's CSR families (int32
        [n + 1] and int32 [bond_count]) and live flags (uint8 [bond_count]); rows must match this object's. A bond
        pass (cost about one force pass over the family); a family cut at a horizon below 2.05 h exposes everything,
        which is safe."""
        import warp as wp

        from .kernels import contact as kc

        if not self.shield_interior:
            return
        wp.launch(
            kc.count_live_lattice_bonds,
            dim=self.particle_count,
            inputs=[
                family_offsets,
                family_neighbors,
                bond_alive,
                self.rest_positions,
                self.radius,
                SHIELD_FACTOR,
                SHIELD_COUNT,
                self.exposed,
            ],
            device=self.device,
        )

    def exposed_mask(self) -> np.ndarray:
        """Which particles take part in contact (bool [n])."""
        return self.exposed.numpy() != 0

    @classmethod
    def from_bodies(cls, bodies, *, device="cpu", **kwargs) -> ParticleContact:
        """Contact between the particles of ``bodies`` (PeridynamicBody list), concatenated in the given order: pass
        ``solver.bodies`` so that rows match the solver's arrays. ``shield_interior`` defaults to True only when no
        body can break (``body.fractures``); keyword options: see the class."""
        if not bodies:
            raise ParameterError("bodies", bodies, "at least one body")
        kwargs.setdefault("shield_interior", not any(getattr(b, "fractures", False) for b in bodies))
        counts = [b.particle_count for b in bodies]

        def rep(values):
            return np.repeat(np.asarray(values, dtype=np.float64), counts)

        return cls(
            np.concatenate([b.rest_positions for b in bodies]),
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
    def apply(self, positions, velocities, force_density, kind=None):
        """Adds the contact force density [N/m^3] to ``force_density`` (vec3 [n]) for ``positions`` [m] and
        ``velocities`` [m/s] (vec3 [n]; the half-step velocities of velocity Verlet), then applies the hard-floor
        projection to ``positions`` and ``velocities`` (free particles only: ``kind`` int32 [n], 0 = free; all free
        when None). Call it after the bond force density and before the kick. Rebuilds the hash grid on
        ``positions`` (measured: the rebuild is about 5 % of the call; the query dominates). No allocation."""
        import warp as wp

        from .kernels import contact as kc

        force_kernel, _ = kc.make_particle_contact_kernels(self.shield_interior)
        self._build_grid(positions)
        wp.launch(
            force_kernel,
            dim=self.particle_count,
            inputs=[
                self.grid.id,
                positions,
                velocities,
                self.rest_positions,
                self.body_id,
                self.radius,
                self.volume,
                self.mass,
                self.modulus,
                self._all_free if kind is None else kind,
                self.exposed,
                self.query_radius,
                self.distance_factor,
                self.bonded_factor,
                self.damping_ratio,
                self.friction,
                self.floor_factor,
                force_density,
                self._position_delta,
                self._velocity_delta,
            ],
            device=self.device,
        )
        if self.floor_factor > 0.0:
            wp.launch(
                kc.apply_contact_projection,
                dim=self.particle_count,
                inputs=[positions, velocities, self._position_delta, self._velocity_delta],
                device=self.device,
            )

    def _build_grid(self, positions):
        cell = GRID_CELL_FACTOR * self.query_radius
        if self.shield_interior:
            self.grid.build(positions, cell, groups=self.exposed)
        else:
            self.grid.build(positions, cell)

    # -- diagnostics ---------------------------------------------------------------------------------------------
    def diagnostics(self, positions) -> ContactDiagnostics:
        """Penalty energy, stiffness row sum and contact count per particle at ``positions`` (vec3 [n], [m])."""
        import warp as wp

        from .kernels import contact as kc

        _, energy_kernel = kc.make_particle_contact_kernels(self.shield_interior)
        self._build_grid(positions)
        wp.launch(
            energy_kernel,
            dim=self.particle_count,
            inputs=[
                self.grid.id,
                positions,
                self.rest_positions,
                self.body_id,
                self.radius,
                self.volume,
                self.modulus,
                self.exposed,
                self.query_radius,
                self.distance_factor,
                self.bonded_factor,
                self._energy,
                self._row_sum,
                self._count,
            ],
            device=self.device,
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
        """Silling-Askari step of the contact springs alone, min_k sqrt(2 rho_k / (contact_count C_k V_k)) [s], for
        a particle with ``contact_count`` simultaneous contacts. With the default calibration and 12 contacts this
        equals the continuum bond estimate of the body; a solver can take the min with its own estimate."""
        s = contact_count * self._modulus_host * self._volume_host
        return float(np.sqrt(2.0 * self._density_host / s).min())


# -- colliders ---------------------------------------------------------------------------------------------------------
def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


def _quat_from_rotation_vector(w: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(w))
    if angle == 0.0:
        return np.array([0.0, 0.0, 0.0, 1.0])
    s = math.sin(0.5 * angle) / angle
    return np.array([w[0] * s, w[1] * s, w[2] * s, math.cos(0.5 * angle)])


def _rotation_vector(q: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, angle in [0, pi]) of a unit quaternion (x, y, z, w)."""
    if q[3] < 0.0:
        q = -q
    s = float(np.linalg.norm(q[:3]))
    if s == 0.0:
        return np.zeros(3)
    return q[:3] * (2.0 * math.atan2(s, q[3]) / s)


def _vec3(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ParameterError(name, value, "3 finite numbers")
    return a


def _quat(name: str, value) -> np.ndarray:
    q = np.asarray(value, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)) or np.linalg.norm(q) == 0.0:
        raise ParameterError(name, value, "a non-zero quaternion (x, y, z, w)")
    return q / np.linalg.norm(q)


def _mesh_arrays(shape, name: str):
    """Vertices [m] (float64 [v, 3]) and triangles (int32 [f, 3]) of a SolidShape or trimesh.Trimesh."""
    v = np.asarray(getattr(shape, "vertices", None), dtype=np.float64)
    f = np.asarray(getattr(shape, "faces", None))
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ParameterError(name, shape, "a closed triangle mesh (pdsim SolidShape or trimesh.Trimesh)")
    return v, f.astype(np.int32)


class Collider:
    """A collider pushes penetrating free particles out of its volume (see kernels/contact.py).

    ``apply(positions, velocities, radius, kind, time, dt)`` is called after the drift, with positions [m] and
    velocities [m/s] (vec3 [n]), collision radii [m] (float [n]), particle kinds (int32 [n], 0 = free), ``time`` [s]
    the time of the positions (the end of the step) and ``dt`` [s] the step that led there."""

    friction: float = 0.0

    def apply(self, positions, velocities, radius, kind, time: float, dt: float):
        raise NotImplementedError


class _MotionBuffer:
    """The collider's RigidMotion in a one-element device array, rewritten from the host once per step (through a
    pinned staging copy on CUDA); the kernels read it, so no launch argument changes between steps."""

    def __init__(self, device):
        import warp as wp

        from .kernels import contact as kc

        self.device = device
        self.array = wp.zeros(1, dtype=kc.RigidMotion, device=device)
        self._staging = self.array if device.is_cpu else wp.zeros(1, dtype=kc.RigidMotion, device="cpu", pinned=True)
        self._view = self._staging.numpy()  # zero-copy structured view of the host array

    def write(self, position, rotation, linear_velocity, angular_velocity, band: float = 0.0):
        import warp as wp

        v = self._view
        v["pose"][0, :3] = position
        v["pose"][0, 3:] = rotation
        v["linear_velocity"][0] = linear_velocity
        v["angular_velocity"][0] = angular_velocity
        v["band"][0] = band
        if self._staging is not self.array:
            wp.copy(self.array, self._staging)


class _MeshData:
    """A wp.Mesh with its arrays kept alive, and the mesh's bounding radius about the local origin [m]."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, device):
        import warp as wp

        self.points = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=device)
        self.indices = wp.array(faces.ravel(), dtype=wp.int32, device=device)
        self.mesh = wp.Mesh(points=self.points, indices=self.indices)
        self.bounding_radius = float(np.linalg.norm(vertices, axis=1).max())


class _RadiusBound:
    """Largest collision radius [m] of a Warp array, read from the device once per array."""

    def __init__(self):
        self._array = None
        self._value = 0.0

    def __call__(self, radius) -> float:
        if radius is not self._array:
            self._array = radius
            self._value = float(radius.numpy().max())
        return self._value


def _mesh_band(band: float | None, radius_bound: _RadiusBound, radius) -> float:
    """Detection depth below a mesh surface [m]: the given band, or twice the largest particle radius."""
    return band if band is not None else 2.0 * radius_bound(radius)


IDENTITY_ROTATION = np.array([0.0, 0.0, 0.0, 1.0])


class MeshCollider(Collider):
    """A static closed triangle mesh (pdsim SolidShape or trimesh.Trimesh, world coordinates [m]).

    Particles closer to the surface than their radius, or inside the mesh, are pushed out along the normal; a
    particle is found while its centre lies within radius + ``band`` of the surface (default band: 2 x the largest
    particle radius, far more than a particle moves in one stable step).

    Args:
        shape: the mesh.
        friction: Coulomb coefficient, >= 0.
        band: detection depth below the surface [m] (> 0) or None.
        device: Warp device.
    """

    def __init__(self, shape, *, friction: float = 0.5, band: float | None = None, device="cpu"):
        import warp as wp

        self.friction = _check_range("friction", friction, 0.0, None, lo_open=False)
        self.band = None if band is None else _check_range("band", band, 0.0, None)
        self.device = wp.get_device(device)
        v, f = _mesh_arrays(shape, "shape")
        self._mesh = _MeshData(v, f, self.device)
        self._motion = _MotionBuffer(self.device)
        self._radius_bound = _RadiusBound()
        self._band_written = None

    def apply(self, positions, velocities, radius, kind, time: float, dt: float):
        import warp as wp

        from .kernels import contact as kc

        band = _mesh_band(self.band, self._radius_bound, radius)
        if band != self._band_written:  # static: the pose is written once (again only if the radii change)
            self._motion.write(np.zeros(3), IDENTITY_ROTATION, np.zeros(3), np.zeros(3), band)
            self._band_written = band
        wp.launch(
            kc.collide_mesh,
            dim=positions.shape[0],
            inputs=[positions, velocities, kind, radius, self._mesh.mesh.id, self._motion.array, self.friction],
            device=self.device,
        )


class RigidProjectile(Collider):
    """A kinematic rigid body: it pushes particles and is not pushed back.

    Its motion is either ballistic (``velocity`` [m/s], ``angular_velocity`` [rad/s, world axes] and ``gravity``
    [m/s^2] from the initial pose at time 0) or scripted: ``path(t)`` returns the position [m] of the body's origin at
    time t [s], or a pair (position, rotation quaternion (x, y, z, w)). The pose is evaluated once per step on the
    host and written to a one-element device array; the surface velocity used in the contact response is the rigid
    motion over the step, (p(t) - p(t - dt)) / dt plus the rotation between the two poses.

    Args:
        center: initial position of the body's origin [m].
        rotation: initial rotation quaternion (x, y, z, w).
        velocity, angular_velocity, gravity: ballistic motion (ignored with a path).
        path: callable t -> position or (position, quaternion), or None.
        friction: Coulomb coefficient between the body and particles, >= 0.
        device: Warp device.
    """

    def __init__(
        self,
        center=(0.0, 0.0, 0.0),
        *,
        rotation=(0.0, 0.0, 0.0, 1.0),
        velocity=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        gravity=(0.0, 0.0, 0.0),
        path: Callable | None = None,
        friction: float = 0.0,
        device="cpu",
    ):
        import warp as wp

        if path is not None and not callable(path):
            raise ParameterError("path", path, "a callable t -> position or (position, quaternion)")
        self.center = _vec3("center", center)
        self.rotation = _quat("rotation", rotation)
        self.velocity = _vec3("velocity", velocity)
        self.angular_velocity = _vec3("angular_velocity", angular_velocity)
        self.gravity = _vec3("gravity", gravity)
        self.path = path
        self.friction = _check_range("friction", friction, 0.0, None, lo_open=False)
        self.device = wp.get_device(device)
        self._motion = _MotionBuffer(self.device)
        self._last: tuple | None = None  # (time, position, quaternion) of the last evaluated pose

    def pose(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """Position of the origin [m] (shape [3]) and rotation quaternion (x, y, z, w) at ``time`` [s]."""
        t = float(time)
        if self.path is None:
            p = self.center + self.velocity * t + 0.5 * self.gravity * t * t
            q = _quat_mul(_quat_from_rotation_vector(self.angular_velocity * t), self.rotation)
            return p, q
        value = self.path(t)
        if isinstance(value, tuple) and len(value) == 2:
            return _vec3("path(t) position", value[0]), _quat("path(t) rotation", value[1])
        return _vec3("path(t)", value), IDENTITY_ROTATION.copy()

    def _update_motion(self, time: float, dt: float, band: float = 0.0):
        """Writes the pose at ``time`` and the rigid motion over [time - dt, time] to the device; the pose at the
        start of the step is the one evaluated by the previous call when it matches (to round-off of the time).
        ``band`` [m] is widened by the distance the surface sweeps in the step (meshes)."""
        t0 = float(time) - float(dt)
        if self._last is not None and math.isclose(self._last[0], t0, rel_tol=1.0e-9, abs_tol=1.0e-6 * float(dt)):
            p0, q0 = self._last[1], self._last[2]
        else:
            p0, q0 = self.pose(t0)
        p1, q1 = self.pose(time)
        self._last = (float(time), p1, q1)
        if dt > 0.0:
            v = (p1 - p0) / dt
            w = _rotation_vector(_quat_mul(q1, q0 * np.array([-1.0, -1.0, -1.0, 1.0]))) / dt
        else:
            v = w = np.zeros(3)
        sweep = float(np.linalg.norm(p1 - p0) + np.linalg.norm(w) * dt * self._bounding_radius())
        self._motion.write(p1, q1, v, w, band + sweep)

    def _bounding_radius(self) -> float:
        return 0.0


class SphereProjectile(RigidProjectile):
    """A kinematic sphere of ``radius`` [m] centred at ``center`` [m] (see RigidProjectile for the motion)."""

    def __init__(self, radius: float, center=(0.0, 0.0, 0.0), **kwargs):
        super().__init__(center, **kwargs)
        self.sphere_radius = _check_range("radius", radius, 0.0, None)

    def _bounding_radius(self) -> float:
        return self.sphere_radius

    def apply(self, positions, velocities, radius, kind, time: float, dt: float):
        import warp as wp

        from .kernels import contact as kc

        self._update_motion(time, dt)
        wp.launch(
            kc.collide_sphere,
            dim=positions.shape[0],
            inputs=[positions, velocities, kind, radius, self._motion.array, self.sphere_radius, self.friction],
            device=self.device,
        )


class BoxProjectile(RigidProjectile):
    """A kinematic box of edge lengths ``size`` [m] centred at ``center`` [m], turned by ``rotation`` (see
    RigidProjectile for the motion)."""

    def __init__(self, size, center=(0.0, 0.0, 0.0), **kwargs):
        super().__init__(center, **kwargs)
        s = _vec3("size", size)
        if np.any(s <= 0.0):
            raise ParameterError("size", size, "three edge lengths > 0")
        self.half_extents = 0.5 * s

    def _bounding_radius(self) -> float:
        return float(np.linalg.norm(self.half_extents))

    def apply(self, positions, velocities, radius, kind, time: float, dt: float):
        import warp as wp

        from .kernels import contact as kc

        self._update_motion(time, dt)
        wp.launch(
            kc.collide_box,
            dim=positions.shape[0],
            inputs=[
                positions,
                velocities,
                kind,
                radius,
                self._motion.array,
                wp.vec3(*self.half_extents),
                self.friction,
            ],
            device=self.device,
        )


class MeshProjectile(RigidProjectile):
    """A kinematic closed triangle mesh (SolidShape or trimesh.Trimesh, vertices in world coordinates at time 0).

    Its origin (the point whose motion ``velocity`` / ``path`` describe) is ``center`` [m], by default the centre of
    the mesh's bounding box; ``rotation`` is the rotation at time 0 relative to the mesh as given. The detection band
    below the surface is ``band`` [m] (default 2 x the largest particle radius) plus the distance the surface sweeps
    in the step.
    """

    def __init__(self, shape, center=None, *, band: float | None = None, **kwargs):
        v, f = _mesh_arrays(shape, "shape")
        c = 0.5 * (v.min(axis=0) + v.max(axis=0)) if center is None else _vec3("center", center)
        super().__init__(c, **kwargs)
        self.band = None if band is None else _check_range("band", band, 0.0, None)
        # body frame: vertices relative to the origin, un-rotated by the initial rotation
        q_inv = self.rotation * np.array([-1.0, -1.0, -1.0, 1.0])
        self._mesh = _MeshData(_rotate(q_inv, v - c), f, self.device)
        self._radius_bound = _RadiusBound()

    def _bounding_radius(self) -> float:
        return self._mesh.bounding_radius

    def apply(self, positions, velocities, radius, kind, time: float, dt: float):
        import warp as wp

        from .kernels import contact as kc

        self._update_motion(time, dt, band=_mesh_band(self.band, self._radius_bound, radius))
        wp.launch(
            kc.collide_mesh,
            dim=positions.shape[0],
            inputs=[positions, velocities, kind, radius, self._mesh.mesh.id, self._motion.array, self.friction],
            device=self.device,
        )


def _rotate(q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Rotates points [n, 3] by the unit quaternion q (x, y, z, w)."""
    u = q[:3]
    t = 2.0 * np.cross(u, points)
    return points + q[3] * t + np.cross(u, t)


__all__ = [
    "BoxProjectile",
    "Collider",
    "ContactDiagnostics",
    "MeshCollider",
    "MeshProjectile",
    "ParticleContact",
    "RigidProjectile",
    "SphereProjectile",
    "bond_stiffness_row_sum",
]
