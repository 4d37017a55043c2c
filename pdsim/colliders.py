"""Colliders: the ground plane, static triangle meshes and kinematic rigid projectiles (sphere, box, mesh, moving
ballistically or along a scripted path). They act on every method that has mass; kernels/colliders.py holds the
formulas."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh
import warp as wp

from .checks import check_range
from .contact import CONTACT_OMEGA_DT, combine_friction, combine_restitution, damping_ratios_for_restitutions
from .errors import ParameterError
from .kernels import colliders as kc
from .output.views import RigidView


def _points(rest, displacements, velocities, radius, kind) -> dict:
    """The solver's point arrays (the arguments of Collider.apply) under the collision kernels' parameter names."""
    return {"rest": rest, "displacements": displacements, "velocities": velocities, "kind": kind, "radius": radius}


_EMPTY: dict = {}  # device name -> (empty point masses, empty reaction): a kinematic collider takes no reaction


def kinematic(device) -> dict:
    """The collision kernels' ``mass``, ``reaction`` and ``phase`` arguments of a kinematic collider (empty arrays,
    the response phase: the kernels take no reaction)."""
    key = str(device)
    if key not in _EMPTY:
        _EMPTY[key] = (wp.zeros(0, dtype=float, device=device), wp.zeros(0, dtype=wp.vec3d, device=device))
    mass, reaction = _EMPTY[key]
    return {"mass": mass, "reaction": reaction, "phase": 1}


class Collider:
    """A collider pushes penetrating free points out of its volume (see kernels/colliders.py).

    ``apply(rest, displacements, velocities, radius, kind, time, dt)`` is called after the drift with the solver's
    points in its local frame: rest positions [m], displacements [m] and velocities [m/s] (vec3 [n]), collision radii
    [m] (float [n], zero for FEM vertices), kinematic kinds (int32 [n], 0 = free), ``time`` [s] the time of the
    positions (the end of the step) and ``dt`` [s] the step that led there. The scene first calls
    ``bind(origin, device)``: world = origin + local, on the solvers' device."""

    friction: float = 0.0
    origin: np.ndarray = np.zeros(3)
    name: str | None = None  # prim name in the cache; None: the scene names it <class name>_<index>

    def view(self, time: float, *, bounds=None):
        """The collider for the output: a pdsim.output.views.RigidView (mesh in the body frame [m] and the pose at
        ``time`` [s]). ``bounds`` ((lo, hi) world corners [m] of the scene) sizes unbounded colliders (the ground
        plane)."""
        raise NotImplementedError

    def bind(self, origin, device=None) -> None:
        """Sets the origin [m] of the solvers' local frame (world = origin + local) and the Warp device they run on
        (None: unchanged); the collider's own device arrays are rebuilt on a new device."""
        self.origin = np.asarray(origin, dtype=np.float64)
        if device is not None and getattr(self, "device", None) != wp.get_device(device):
            self.device = wp.get_device(device)
            self._on_device()

    def _on_device(self) -> None:
        """Rebuilds the collider's device arrays on ``self.device`` (a collider without any has nothing to do)."""

    def apply(self, rest, displacements, velocities, radius, kind, time: float, dt: float, mass=None, contact=None):
        """Pushes the solver's free points out of the collider at ``time`` [s] (step ``dt`` [s]); ``contact``: the
        points' own (restitution, friction), float64 [n] each, NaN where a point's material brings none
        (pdsim/contact.py material_contact_values); None: none brings any."""
        raise NotImplementedError

    def point_friction(self, radius, contact):
        """The Coulomb coefficient of each point's pair with this collider: its ``friction`` combined with the
        point's material's (pdsim/contact.py combine_friction), float32 [n] on ``radius``'s device, computed once per
        solver (the points' ``radius`` array and their ``contact`` values)."""
        key = (str(radius.device), id(radius), radius.shape[0], id(contact))
        cache = self.__dict__.setdefault("_point_friction", {})
        if key not in cache:
            mu_point = np.full(radius.shape[0], np.nan) if contact is None else contact[1]
            mu = combine_friction(mu_point, self.friction).astype(np.float32)
            cache[key] = (contact, wp.array(mu, dtype=float, device=radius.device))  # holds contact: its id stays
        return cache[key][1]


@dataclass
class GroundPlane(Collider):
    """A static plane n . x = offset (world) that free points cannot cross.

    Two forms of the same contact, chosen per point by the restitution of the point's pair with the plane (the plane's
    ``restitution`` combined with the point's material's contact_restitution, pdsim/contact.py combine_restitution;
    the pair's friction likewise combines ``friction`` with the material's contact_friction):

    - None (default): inelastic projection with Coulomb friction after the drift (``apply``, kernels/colliders.py
      collide_ground_plane): the point's approaching normal velocity is removed.
    - a restitution e in (0, 1]: the plane is a contact pair of the one law (kernels/colliders.py penalty_force,
      ground_plane_force) in the force phase (``add_forces``): stiffness k = m (CONTACT_OMEGA_DT / dt)^2 per point
      (pdsim/contact.py: tied to the step, so it never needs a smaller step), the dashpot's damping ratio of
      restitution e (pdsim/contact.py damping_ratio_for_restitution) and Coulomb ``friction``.
      A body whose lowest vibration is well above the contact's frequency then rebounds at e times its impact speed;
      the projection stays as a floor one point radius below the surface (a point pushed that deep is projected back
      to it). A point that starts overlapping the plane meets it from that overlap (``_pair_values``), so a body
      placed inside the contact band rests there without gaining energy. Points with zero radius (FEM vertices)
      cannot take it (pdsim/fem/solver.py refuses it).
    """

    normal: tuple = (0.0, 0.0, 1.0)
    offset: float = 0.0
    friction: float = 0.5
    name: str | None = "ground"
    restitution: float | None = None

    def view(self, time: float = 0.0, *, bounds=None):
        """The plane for the output: a square of the plane centred under the scene, 10 x the half-diagonal of
        ``bounds`` ((lo, hi) world corners [m]; default a 2 m square at the origin's foot), as the static RigidView
        ``ground`` directly under /World; its faces look along ``normal``."""
        n = np.asarray(self.normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        if bounds is None:
            centre, half = np.zeros(3), 1.0
        else:
            lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
            centre = 0.5 * (lo + hi)
            half = 5.0 * max(0.5 * float(np.linalg.norm(hi - lo)), 1.0e-3)
        centre = centre - (n @ centre - float(self.offset)) * n  # its foot on the plane
        t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)  # t1 x t2 = n: counter-clockwise seen from the side n points to
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * half
        points = corners[:, :1] * t1 + corners[:, 1:] * t2
        faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
        name = self.name or "ground"
        return RigidView(name, points, faces, centre, np.array([0.0, 0.0, 0.0, 1.0]), static=True, group=None)

    @property
    def impulse(self) -> np.ndarray:
        """Total impulse the plane has given the points it stopped [N s], float64 [3] (summed over the solvers that
        passed their point masses)."""
        arrays = getattr(self, "_impulse", {})
        return np.sum([a.numpy()[0] for a in arrays.values()], axis=0) if arrays else np.zeros(3)

    def apply(self, rest, displacements, velocities, radius, kind, time: float, dt: float, mass=None, contact=None):
        """The projection (both forms) on the free points; ``contact``: the points' own (restitution, friction),
        float64 [n] each, NaN where a point's material brings none (pdsim/contact.py material_contact_values); None:
        none brings any."""
        if not hasattr(self, "_impulse"):
            self._impulse = {}
        key = (str(rest.device), id(rest))
        if key not in self._impulse:
            self._impulse[key] = wp.zeros(1, dtype=wp.vec3d, device=rest.device)
        if mass is None:
            if key not in getattr(self, "_no_mass", {}):
                self._no_mass = {**getattr(self, "_no_mass", {}), key: wp.zeros(0, dtype=float, device=rest.device)}
            mass = self._no_mass[key]
        pair = self._pair_values(rest, radius, contact)
        kc.push_out_of_plane(
            **_points(rest, displacements, velocities, radius, kind),
            normal=np.asarray(self.normal, dtype=np.float64),
            offset=pair["offset"],
            friction=pair["friction"],
            mass=mass,
            impulse=self._impulse[key],
            device=rest.device,
        )

    def _pair_values(self, rest, radius, contact) -> dict:
        """The plane's pair with each point, computed once per solver (``key``): the restitution and friction the
        pair takes (pdsim/contact.py combine_restitution, combine_friction: the plane's own ``restitution`` and
        ``friction`` against the point's material values), as float32 device arrays: ``damping_ratio`` of the
        penalty form (NaN where the pair has no restitution: projection only), ``friction``, the projection's
        ``offset`` [m] (local frame; one point radius below the surface, the largest of the solver, where the
        penalty form acts) and the penalty form's ``penalty_offset`` [m] (local frame); ``penalty``: whether any point
        takes the penalty form.

        Where the penalty form acts, a point whose reference position (``rest``, its place at the start) overlaps
        the plane by d > 0 meets the plane d lower, its floor too: the spring starts from the overlap the point
        starts with, so a body placed inside the contact band rests where it was placed instead of being thrown out
        by the springs' stored energy 1/2 k d^2 (k = m (CONTACT_OMEGA_DT / dt)^2 makes that a speed of
        CONTACT_OMEGA_DT d / dt: 67 m/s for d = 4.5 mm at dt = 10 us). Computed from the reference positions, it is
        the same after a resume."""
        if not hasattr(self, "_pairs"):
            self._pairs = {}
        key = (str(radius.device), id(radius), radius.shape[0], id(contact))
        if key not in self._pairs:
            n_points = radius.shape[0]
            e_point, mu_point = (np.full(n_points, np.nan),) * 2 if contact is None else contact
            e = combine_restitution(e_point, np.nan if self.restitution is None else self.restitution)
            mu = combine_friction(mu_point, self.friction)
            penalty = ~np.isnan(e)
            r = radius.numpy().astype(np.float64)
            floor = float(r.max()) if n_points and penalty.any() else 0.0
            n = np.asarray(self.normal, dtype=np.float64)
            plane = self.offset - n @ self.origin
            start = np.where(penalty, np.maximum(r + plane - rest.numpy().astype(np.float64) @ n, 0.0), 0.0)
            offset = np.where(penalty, plane - floor - start, plane)
            d = radius.device
            self._pairs[key] = {
                "damping_ratio": wp.array(damping_ratios_for_restitutions(e).astype(np.float32), device=d),
                "friction": wp.array(mu.astype(np.float32), device=d),
                "offset": wp.array(offset.astype(np.float32), device=d),
                "penalty_offset": wp.array((plane - start).astype(np.float32), device=d),
                "penalty": bool(penalty.any()),
                "contact": contact,  # held, so that its id stays its own
            }
        return self._pairs[key]

    def add_forces(
        self, rest, displacements, velocities, radius, kind, mass, force_to_newton, force, dt: float, contact=None
    ):
        """The penalty form's forces on the free points whose pair with the plane has a restitution (the plane's
        ``restitution`` or the point's material's; nothing for the others), added to ``force`` in the solver's unit
        (force [N] / ``force_to_newton``), for the step ``dt`` [s]; the arrays as in ``apply``, with the points'
        masses [kg]. Call it in the force phase, after the internal forces."""
        pair = self._pair_values(rest, radius, contact)
        if not pair["penalty"]:
            return
        n = np.asarray(self.normal, dtype=np.float64)
        kc.ground_forces(
            **_points(rest, displacements, velocities, radius, kind),
            mass=mass,
            force_to_newton=force_to_newton,
            normal=n,
            offset=pair["penalty_offset"],
            stiffness_rate=(CONTACT_OMEGA_DT / float(dt)) ** 2,
            damping_ratio=pair["damping_ratio"],
            friction=pair["friction"],
            force=force,
            device=rest.device,
        )


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


def rotation_between(q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Rotation vector [rad] (world axes) that turns the orientation q0 into q1 (unit quaternions (x, y, z, w))."""
    return _rotation_vector(_quat_mul(q1, q0 * np.array([-1.0, -1.0, -1.0, 1.0])))


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


def _check_name(name):
    """A collider name: None (the scene names it) or a non-empty string."""
    if name is not None and not (isinstance(name, str) and name.strip()):
        raise ParameterError("name", name, "a non-empty string or None")
    return name


def collider_names(colliders) -> list[str]:
    """The output names of a scene's colliders: each one's ``name``, or ``<class name>_<index in the list>``;
    ParameterError when two are the same (the cache makes them prims /World/colliders/<name>)."""
    names = []
    for i, c in enumerate(colliders):
        name = getattr(c, "name", None) or f"{type(c).__name__}_{i}"
        if name in names:
            raise ParameterError("name", name, "a collider name not already used in this scene")
        names.append(name)
    return names


def _mesh_arrays(shape, name: str):
    """Vertices [m] (float64 [v, 3]) and triangles (int32 [f, 3]) of a SolidShape or trimesh.Trimesh."""
    v = np.asarray(getattr(shape, "vertices", None), dtype=np.float64)
    f = np.asarray(getattr(shape, "faces", None))
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise ParameterError(name, shape, "a closed triangle mesh (pdsim SolidShape or trimesh.Trimesh)")
    return v, f.astype(np.int32)


class _MotionBuffer:
    """RigidMotion rows in a device array, written from the host in one copy: a static mesh's single row, or a
    projectile's table of the frame's steps (``rows`` entries plus a last scratch row for a step outside a frame
    program); the kernels read them, so no launch argument changes between steps. On CUDA the staging array is
    pageable host memory, not pinned: a copy from pageable memory has read its source when it returns, so the next
    frame's rows can be written at once, while a pinned source could still be waiting in the stream behind the
    frames in flight."""

    def __init__(self, device, rows: int = 1):
        self.device = device
        self.rows = int(rows)
        self.array = wp.zeros(self.rows, dtype=kc.RigidMotion, device=device)
        self._staging = self.array if device.is_cpu else wp.zeros(self.rows, dtype=kc.RigidMotion, device="cpu")
        self._view = self._staging.numpy()  # zero-copy structured view of the host array

    def set_row(self, row: int, position, rotation, linear_velocity, angular_velocity, band: float = 0.0):
        """Fills row ``row`` of the host staging array (``upload`` sends it)."""
        v = self._view
        v["pose"][row, :3] = position
        v["pose"][row, 3:] = rotation
        v["linear_velocity"][row] = linear_velocity
        v["angular_velocity"][row] = angular_velocity
        v["band"][row] = band

    def upload(self, row: int | None = None):
        """Copies the staging rows (all, or one) to the device; never during a graph capture (a captured copy would
        replay the staging buffer's contents of replay time)."""
        if self._staging is self.array:
            return
        if self.device.is_capturing:
            raise RuntimeError("a collider pose was written from the host during a graph capture")
        if row is None:
            wp.copy(self.array, self._staging)
        else:
            wp.copy(self.array, self._staging, dest_offset=row, src_offset=row, count=1)

    def write(self, position, rotation, linear_velocity, angular_velocity, band: float = 0.0):
        self.set_row(0, position, rotation, linear_velocity, angular_velocity, band)
        self.upload(0)


class _MeshData:
    """A wp.Mesh with its arrays kept alive, and the mesh's bounding radius about the local origin [m]."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, device):
        self.points = wp.array(vertices.astype(np.float32), dtype=wp.vec3, device=device)
        self.indices = wp.array(faces.ravel(), dtype=wp.int32, device=device)
        self.mesh = wp.Mesh(points=self.points, indices=self.indices)
        self.bounding_radius = float(np.linalg.norm(vertices, axis=1).max())


class _RadiusBound:
    """Largest collision radius [m] of a Warp array, read from the device once per array (per solver: a collider
    shared by several solvers reads each one's radii once, not at every call)."""

    def __init__(self):
        self._values = {}  # id(array) -> (array, value); the array is kept so that its id stays unique

    def __call__(self, radius) -> float:
        entry = self._values.get(id(radius))
        if entry is None or entry[0] is not radius:
            entry = (radius, float(radius.numpy().max()) if radius.shape[0] else 0.0)
            self._values[id(radius)] = entry
        return entry[1]


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
        device: Warp device of its arrays until a solver binds it to the device the run uses.
        name: prim name in the cache (``/World/colliders/<name>``); None: ``<class name>_<index>`` in the scene.
    """

    def __init__(self, shape, *, friction: float = 0.5, band: float | None = None, device="cpu", name=None):
        self.name = _check_name(name)
        self.friction = check_range("friction", friction, 0.0, None, lo_open=False)
        self.band = None if band is None else check_range("band", band, 0.0, None)
        self.device = wp.get_device(device)
        self.vertices, self.faces = _mesh_arrays(shape, "shape")
        # the mesh's frame: centred on its bounding box, so float32 vertices keep their precision anywhere
        self.center = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
        self._mesh = _MeshData(self.vertices - self.center, self.faces, self.device)
        self._motions = {}  # band [m] -> its _MotionBuffer (written once: the mesh is static)
        self._radius_bound = _RadiusBound()

    def bind(self, origin, device=None) -> None:
        super().bind(origin, device)
        self._motions = {}

    def _on_device(self) -> None:
        self._mesh = _MeshData(self.vertices - self.center, self.faces, self.device)
        self._motions = {}

    def view(self, time: float = 0.0, *, bounds=None):
        """The static mesh for the output: vertices relative to the centre of its bounding box, placed at it."""
        return RigidView(
            self.name or type(self).__name__,
            self.vertices - self.center,
            self.faces,
            self.center.copy(),
            IDENTITY_ROTATION.copy(),
            static=True,
        )

    def apply(self, rest, displacements, velocities, radius, kind, time: float, dt: float, mass=None, contact=None):
        band = _mesh_band(self.band, self._radius_bound, radius)
        motion = self._motions.get(band)
        if motion is None:  # static: the pose is written once per band (per solver's radii)
            motion = _MotionBuffer(self.device)
            motion.write(self.center - self.origin, IDENTITY_ROTATION, np.zeros(3), np.zeros(3), band)
            self._motions[band] = motion
        kc.push_out_of_mesh(
            **_points(rest, displacements, velocities, radius, kind),
            mesh=self._mesh.mesh.id,
            body=motion.array,
            friction=self.point_friction(radius, contact),
            device=self.device,
            **kinematic(self.device),
        )


class RigidProjectile(Collider):
    """A kinematic rigid body: it pushes particles and is not pushed back.

    Its motion is either ballistic (``velocity`` [m/s], ``angular_velocity`` [rad/s, world axes] and ``gravity``
    [m/s^2] from the initial pose at time 0) or scripted: ``path(t)`` returns the position [m] of the body's origin at
    time t [s], or a pair (position, rotation quaternion (x, y, z, w)). The poses of a frame's steps are evaluated on
    the host before the frame (:meth:`begin_frame`) and written to a device table in one copy; each step copies its
    row on the device (a step outside a frame program evaluates and writes its own); the surface velocity used in
    the contact response is the rigid motion over the step, (p(t) - p(t - dt)) / dt plus the rotation between the
    two poses.

    Args:
        center: initial position of the body's origin [m].
        rotation: initial rotation quaternion (x, y, z, w).
        velocity, angular_velocity, gravity: ballistic motion (ignored with a path).
        path: callable t -> position or (position, quaternion), or None.
        friction: Coulomb coefficient between the body and particles, >= 0.
        device: Warp device of its arrays until a solver binds it to the device the run uses.
        name: prim name in the cache (``/World/colliders/<name>``); None: ``<class name>_<index>`` in the scene.
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
        name: str | None = None,
    ):
        self.name = _check_name(name)
        if path is not None and not callable(path):
            raise ParameterError("path", path, "a callable t -> position or (position, quaternion)")
        self.center = _vec3("center", center)
        self.rotation = _quat("rotation", rotation)
        self.velocity = _vec3("velocity", velocity)
        self.angular_velocity = _vec3("angular_velocity", angular_velocity)
        self.gravity = _vec3("gravity", gravity)
        self.path = path
        self.friction = check_range("friction", friction, 0.0, None, lo_open=False)
        self.device = wp.get_device(device)
        self._motion = _MotionBuffer(self.device)  # the step's motion, copied from the table's row
        self._table = _MotionBuffer(self.device, 1)  # the frame's steps, then a scratch row
        self._slots: dict = {}  # (end time [s], dt [s]) of each step of the frame -> its row
        self._last: tuple | None = None  # (time, position, quaternion) of the last evaluated pose

    def _on_device(self) -> None:
        self._motion = _MotionBuffer(self.device)
        self._table = _MotionBuffer(self.device, 1)
        self._slots = {}
        self.__dict__.pop("_frame", None)  # the frame's table is written again on the new device

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

    def body_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The body's surface in its body frame: vertices [m] (float64 [v, 3]) and triangles (int32 [f, 3])."""
        raise NotImplementedError

    def view(self, time: float, *, bounds=None):
        """The projectile for the output at ``time`` [s]: its body-frame mesh and ``pose(time)``."""
        if not hasattr(self, "_body_mesh_cache"):
            self._body_mesh_cache = self.body_mesh()
        points, faces = self._body_mesh_cache
        p, q = self.pose(time)
        return RigidView(self.name or type(self).__name__, points, faces, p, q, static=False)

    def begin_frame(self, time: float, dt: float, steps: int) -> None:
        """Evaluates the motion of the ``steps`` steps of ``dt`` [s] from ``time`` [s] (the end times accumulated as
        the solvers accumulate theirs) and writes them to the device table in one copy; :meth:`apply` then copies the
        step's row on the device. A second call for the same steps (another solver of the scene) does nothing."""
        frame = (float(time), float(dt), int(steps), tuple(np.asarray(self.origin, dtype=np.float64).tolist()))
        if frame == getattr(self, "_frame", None):
            return
        self._frame = frame
        rows, ends, t = [], [], float(time)
        for _ in range(int(steps)):
            t = t + float(dt)
            ends.append(t)
            rows.append(self._motion_over(t, dt))
        if self._table.rows != len(rows) + 1:
            self._table = _MotionBuffer(self.device, len(rows) + 1)
        for k, row in enumerate(rows):
            self._table.set_row(k, *row)
        self._table.upload()
        self._slots = {(x, float(dt)): k for k, x in enumerate(ends)}

    def _update_motion(self, time: float, dt: float, band: float = 0.0):
        """The step's motion into ``self._motion``: its row of the frame's table (:meth:`begin_frame`), or, for a
        step outside a frame program, the motion evaluated now into the scratch row; ``band`` [m] (meshes) is added
        to the distance the surface sweeps in the step."""
        slot = self._slots.get((float(time), float(dt)))
        if slot is None:
            if self.device.is_capturing:
                raise RuntimeError(
                    f"the pose of {type(self).__name__} at t={time!r} s is not in the frame's table "
                    "(RigidProjectile.begin_frame) during a graph capture"
                )
            slot = self._table.rows - 1
            self._table.set_row(slot, *self._motion_over(time, dt))
            self._table.upload(slot)
        kc.select_step_motion(self._table.array, slot, band, self._motion.array, self.device)

    def _motion_over(self, time: float, dt: float) -> tuple:
        """(position, rotation, linear velocity, angular velocity, swept distance) in the local frame of the rigid
        motion over [time - dt, time]; the pose at the start of the step is the one evaluated by the previous call
        when it matches (to round-off of the time)."""
        t0 = float(time) - float(dt)
        if self._last is not None and math.isclose(self._last[0], t0, rel_tol=1.0e-9, abs_tol=1.0e-6 * float(dt)):
            p0, q0 = self._last[1], self._last[2]
        else:
            p0, q0 = self.pose(t0)
        p1, q1 = self.pose(time)
        self._last = (float(time), p1, q1)
        if dt > 0.0:
            v = (p1 - p0) / dt
            w = rotation_between(q0, q1) / dt
        else:
            v = w = np.zeros(3)
        sweep = float(np.linalg.norm(p1 - p0) + np.linalg.norm(w) * dt * self._bounding_radius())
        return p1 - self.origin, q1, v, w, sweep

    def _bounding_radius(self) -> float:
        return 0.0

    def apply(self, rest, displacements, velocities, radius, kind, time: float, dt: float, mass=None, contact=None):
        self._update_motion(time, dt, band=self._band(radius))
        self._push(
            _points(rest, displacements, velocities, radius, kind)
            | {"body": self._motion.array, "friction": self.point_friction(radius, contact), "device": self.device}
            | kinematic(self.device)
        )

    def _band(self, radius) -> float:
        """Detection depth below the surface [m] (meshes; 0 for the analytic shapes), given the solver's radii."""
        return 0.0

    def _push(self, arguments: dict) -> None:
        """Launches the shape's collision kernel with ``arguments``, those its kernels share by parameter name: the
        solver's arrays (rest, displacements, velocities, kind, radius), the step's motion (``body``), the friction
        coefficient and the device."""
        raise NotImplementedError


class SphereProjectile(RigidProjectile):
    """A kinematic sphere of ``radius`` [m] centred at ``center`` [m] (see RigidProjectile for the motion)."""

    def __init__(self, radius: float, center=(0.0, 0.0, 0.0), **kwargs):
        super().__init__(center, **kwargs)
        self.sphere_radius = check_range("radius", radius, 0.0, None)

    def _bounding_radius(self) -> float:
        return self.sphere_radius

    def body_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """An icosphere of 1280 triangles (3 subdivisions) of the sphere's radius."""
        m = trimesh.creation.icosphere(subdivisions=3, radius=self.sphere_radius)
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int32)

    def _push(self, arguments: dict) -> None:
        kc.push_out_of_sphere(**arguments, sphere_radius=self.sphere_radius)


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

    def body_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The box's 8 corners and 12 triangles."""
        m = trimesh.creation.box(extents=2.0 * self.half_extents)
        return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int32)

    def _push(self, arguments: dict) -> None:
        kc.push_out_of_box(**arguments, half_extents=self.half_extents)


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
        self.band = None if band is None else check_range("band", band, 0.0, None)
        # body frame: vertices relative to the origin, un-rotated by the initial rotation
        q_inv = self.rotation * np.array([-1.0, -1.0, -1.0, 1.0])
        self._body = (_rotate(q_inv, v - c), f)
        self._mesh = _MeshData(self._body[0], f, self.device)
        self._radius_bound = _RadiusBound()

    def _on_device(self) -> None:
        super()._on_device()
        self._mesh = _MeshData(self._body[0], self._body[1], self.device)

    def _bounding_radius(self) -> float:
        return self._mesh.bounding_radius

    def body_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh in its body frame (relative to ``center``, un-rotated by the initial rotation)."""
        return self._body

    def _band(self, radius) -> float:
        return _mesh_band(self.band, self._radius_bound, radius)

    def _push(self, arguments: dict) -> None:
        kc.push_out_of_mesh(**arguments, mesh=self._mesh.mesh.id)


def _rotate(q: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Rotates points [n, 3] by the unit quaternion q (x, y, z, w)."""
    u = q[:3]
    t = 2.0 * np.cross(u, points)
    return points + q[3] * t + np.cross(u, t)


__all__ = [
    "BoxProjectile",
    "Collider",
    "GroundPlane",
    "MeshCollider",
    "MeshProjectile",
    "RigidProjectile",
    "SphereProjectile",
    "collider_names",
]
