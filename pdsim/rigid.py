"""Dynamic rigid bodies: a sphere, a box or any closed mesh with mass, inertia and gravity, in two-way contact with
the particles of peridynamic bodies and the vertices of FEM bodies, the ground, static mesh colliders and each other.
kernels/rigid.py holds the integration and the body-body contact; kernels/colliders.py the contact with points.

A :class:`RigidBody` is a collider (pdsim/colliders.py) whose pose is its own state, integrated on the device: the
solvers apply it to their points after their drift with the kinematic projectiles' kernels (the same shape queries
and response), which for a dynamic body (kernels/colliders.py push_point) share one perfectly inelastic impulse
among the points it meets in the step, move a point by its velocity change over the step rather than projecting it
out (a projection would compress the point's neighbours without the body paying for it), and add the opposite of
each point's impulse, and its moment about the centre of mass, into the body's ``reaction`` (atomics; no host read).
:class:`RigidBodies` steps the scene's bodies with the solvers (pdsim.run.advance_frame): the first half kick and
drift before the solvers' steps begin (so the points see the body's pose and velocity at the end of the drift, as
their own), the second half kick with the reaction after them, then the body's contact with the ground, static
meshes and other bodies. The points' impulses and the body's are equal and opposite within the step, so the total
linear and angular momentum are conserved to round-off, and the contact only takes kinetic energy
(docs/rigid_impacts.md). A point may stay inside the body by part of the distance the body travels in a step
(measured: 0.19 particle radii at 0.86 mm a step).

Only :func:`pdsim.run.advance_frame` steps the bodies: a solver stepped on its own (``simulate``) meets them frozen.

Kinematic projectiles (SphereProjectile, BoxProjectile, MeshProjectile) stay the choice for scripted motion.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import trimesh
import warp as wp

from .checks import check_range
from .colliders import (
    Collider,
    MeshCollider,
    RigidProjectile,
    _check_name,
    _mesh_arrays,
    _MeshData,
    _quat,
    _rotate,
)
from .colliders import _vec3 as _vector
from .contact import CONTACT_OMEGA_DT, combine_friction, combine_restitution, damping_ratio_for_restitution
from .errors import FeatureNotAvailableError, ParameterError
from .kernels import colliders as kc
from .kernels import rigid as kr
from .output.views import RigidView

BOX_SAMPLES_PER_EDGE = 5  # surface samples of a box: a 5 x 5 grid on each face (corners and edges included)


@dataclass(frozen=True)
class SphereShape:
    """An analytic sphere of ``radius`` [m] for :meth:`pdsim.Scene.add_rigid_body` (centred on the body's
    position)."""

    radius: float


@dataclass(frozen=True)
class BoxShape:
    """An analytic box of edge lengths ``size`` [m] (3 numbers) for :meth:`pdsim.Scene.add_rigid_body` (centred on
    the body's position, its edges along the body frame's axes)."""

    size: tuple


def sphere_inertia(mass: float, radius: float) -> np.ndarray:
    """Inertia tensor [kg m^2] of a solid sphere about its centre: 2/5 m r^2 I."""
    return 0.4 * mass * radius * radius * np.eye(3)


def box_inertia(mass: float, size) -> np.ndarray:
    """Inertia tensor [kg m^2] of a solid box of edge lengths ``size`` [m] about its centre, in its axes:
    m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2)."""
    a2, b2, c2 = (float(x) ** 2 for x in size)
    return mass / 12.0 * np.diag([b2 + c2, a2 + c2, a2 + b2])


def _mass_from(volume: float, density, mass) -> float:
    if (density is None) == (mass is None):
        raise ParameterError("density", density, "exactly one of density [kg/m^3] and mass [kg] (> 0)")
    if mass is not None:
        return check_range("mass", mass, 0.0, None)
    return check_range("density", density, 0.0, None) * volume


class RigidBody(Collider):
    """A dynamic rigid body (see the module's docstring). Built by :meth:`pdsim.Scene.add_rigid_body`.

    Args:
        shape: SphereShape, BoxShape, or a closed triangle mesh (pdsim SolidShape, e.g. ``pdsim.load_mesh``, or
            trimesh.Trimesh) in world coordinates at time 0.
        density: [kg/m^3] (> 0), or
        mass: [kg] (> 0): give exactly one.
        position: centre of mass at time 0 [m] (analytic shapes: their centre, default the origin; meshes: default
            the mesh's centre of mass as given, which a given position moves the mesh to).
        orientation: rotation at time 0, unit quaternion (x, y, z, w), of the analytic shape's axes or of the mesh as
            given.
        velocity: of the centre of mass [m/s]; angular_velocity [rad/s] (world axes), at time 0.
        friction: Coulomb coefficient of its contacts, >= 0 (with points: combined with their material's
            contact_friction, this one alone where it has none; with the ground, a static mesh or another body: the
            geometric mean of the two sides' coefficients, pdsim/contact.py combine_friction).
        restitution: its normal restitution e in [0, 1] against the ground, static meshes and other rigid bodies,
            or None (default): the pair takes the larger of the two sides' (pdsim/contact.py combine_restitution;
            the ground's ``restitution``, None for a static mesh) and meets in the penalty form of the one contact
            law (kernels/rigid.py), whose dashpot gives e (damping_ratio_for_restitution); a pair where neither
            side brings one, or whose e is 0, meets inelastically (an impulse removes the approaching normal
            velocity). Against the points of peridynamic and FEM bodies the contact is the inelastic impulse
            whatever e is: the rebound there is the deformable body's (the elastic energy its impact stores). A body
            whose pair with the ground takes the penalty form and that starts inside the ground is lifted onto it
            before the first step, with a warning (RigidBodies).
        band: detection depth below a mesh's surface [m] (> 0; meshes only), default a tenth of its bounding radius.
        name: prim name in the cache (``/World/colliders/<name>``); None: ``RigidBody_<index>`` in the scene.

    Mass properties: mass, centre of mass and inertia tensor are analytic for the sphere and the box
    (``sphere_inertia``, ``box_inertia``) and trimesh's for a mesh (uniform density). The body frame's origin is the
    centre of mass.
    """

    def __init__(
        self,
        shape,
        *,
        density=None,
        mass=None,
        position=None,
        orientation=(0.0, 0.0, 0.0, 1.0),
        velocity=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.0),
        friction: float = 0.5,
        band: float | None = None,
        name: str | None = None,
        restitution: float | None = None,
    ):
        self.name = _check_name(name)
        self.friction = check_range("friction", friction, 0.0, None, lo_open=False)
        self.restitution = None
        if restitution is not None:
            self.restitution = check_range("restitution", restitution, 0.0, 1.0, lo_open=False, hi_open=False)
        self.orientation = _quat("orientation", orientation)
        self.velocity = _vector("velocity", velocity)
        self.angular_velocity = _vector("angular_velocity", angular_velocity)
        self.mesh_data = None
        if isinstance(shape, SphereShape):
            r = check_range("radius", shape.radius, 0.0, None)
            self.kind, self.size = kr.SHAPE_SPHERE, np.array([r, 0.0, 0.0])
            self.mass = _mass_from(4.0 / 3.0 * math.pi * r**3, density, mass)
            self.inertia = sphere_inertia(self.mass, r)
            centre = np.zeros(3)
            self.samples, self.sample_radius = np.zeros((1, 3)), np.array([r])
            m = trimesh.creation.icosphere(subdivisions=3, radius=r)
            self.body_vertices, self.body_faces = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int32)
            self.bounding_radius = r
        elif isinstance(shape, BoxShape):
            s = _vector("size", shape.size)
            if np.any(s <= 0.0):
                raise ParameterError("size", shape.size, "three edge lengths > 0")
            self.kind, self.size = kr.SHAPE_BOX, 0.5 * s
            self.mass = _mass_from(float(np.prod(s)), density, mass)
            self.inertia = box_inertia(self.mass, s)
            centre = np.zeros(3)
            g = np.linspace(-1.0, 1.0, BOX_SAMPLES_PER_EDGE)
            grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
            grid = grid[np.abs(grid).max(axis=1) == 1.0]  # the cube's surface
            self.samples, self.sample_radius = grid * self.size, np.zeros(len(grid))
            m = trimesh.creation.box(extents=s)
            self.body_vertices, self.body_faces = np.asarray(m.vertices), np.asarray(m.faces, dtype=np.int32)
            self.bounding_radius = float(np.linalg.norm(self.size))
        else:
            v, f = _mesh_arrays(shape, "shape")
            tm = trimesh.Trimesh(vertices=v, faces=f, process=False)
            if not tm.is_watertight or tm.volume <= 0.0:
                raise ParameterError("shape", shape, "a closed, outward-facing triangle mesh (positive volume)")
            self.kind, self.size = kr.SHAPE_MESH, np.zeros(3)
            self.mass = _mass_from(float(tm.volume), density, mass)
            centre = np.asarray(tm.center_mass, dtype=np.float64)
            # trimesh's inertia is for density 1 about the centre of mass, in the mesh's axes
            inertia_mesh = np.asarray(tm.moment_inertia, dtype=np.float64) * (self.mass / float(tm.volume))
            q_inv = self.orientation * np.array([-1.0, -1.0, -1.0, 1.0])
            # body frame: the mesh about its centre of mass, un-rotated by the initial orientation R0
            r0 = _rotate(self.orientation, np.eye(3)).T  # columns: the body axes in the world at time 0
            self.inertia = r0.T @ inertia_mesh @ r0
            self.body_vertices, self.body_faces = _rotate(q_inv, v - centre), f
            self.samples, self.sample_radius = self.body_vertices.copy(), np.zeros(len(v))
            self.bounding_radius = float(np.linalg.norm(self.body_vertices, axis=1).max())
            self.band = check_range("band", band, 0.0, None) if band is not None else 0.1 * self.bounding_radius
        if self.kind != kr.SHAPE_MESH:
            if band is not None:
                raise ParameterError("band", band, "None for an analytic sphere or box (a mesh's detection depth)")
            self.band = 0.0
        self.position = centre.copy() if position is None else _vector("position", position)
        self.device = None
        self.system = None
        self.gravity = np.zeros(3)  # the scene's [m/s^2] (Scene.add_rigid_body sets it)

    # -- device state -----------------------------------------------------------------------------------------------
    def setup(self, device, origin, system) -> None:
        """Allocates the device state at the initial pose, in the local frame of ``origin`` [m]."""
        self.device = wp.get_device(device)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.system = system
        d = self.device
        state = kr.RigidState()
        state.position = wp.vec3d(*(self.position - self.origin))
        state.orientation = wp.quatd(*self.orientation)
        state.velocity = wp.vec3d(*self.velocity)
        state.angular_momentum = wp.vec3d(*(self._world_inertia(self.orientation) @ self.angular_velocity))
        self.state = wp.array([state], dtype=kr.RigidState, device=d)
        self.reaction = wp.zeros(3, dtype=wp.vec3d, device=d)  # impulse, angular impulse, effective mass met
        self.motion = wp.zeros(1, dtype=kc.RigidMotion, device=d)
        self.samples_array = wp.array(self.samples.astype(np.float32), dtype=wp.vec3, device=d)
        self.radius_array = wp.array(self.sample_radius.astype(np.float32), dtype=float, device=d)
        if self.kind == kr.SHAPE_MESH:
            self.mesh_data = _MeshData(np.asarray(self.body_vertices), np.asarray(self.body_faces), d)
        shape = kr.RigidShape()
        shape.kind = int(self.kind)
        shape.size = wp.vec3(*self.size)
        shape.mesh = wp.uint64(self.mesh_data.mesh.id if self.mesh_data is not None else 0)
        shape.band = float(self.band)
        shape.inv_mass = wp.float64(1.0 / self.mass)
        shape.inv_inertia = wp.mat33d(*np.linalg.inv(self.inertia).ravel())
        self.shape = shape
        self.write_motion()

    def _world_inertia(self, q) -> np.ndarray:
        rot = _rotate(np.asarray(q, dtype=np.float64), np.eye(3)).T  # columns: the body axes in the world
        return rot @ self.inertia @ rot.T

    def write_motion(self) -> None:
        """The RigidMotion of the current state (before the first step, after a restore)."""
        kr.write_motion(state=self.state, shape=self.shape, motion=self.motion, device=self.device)

    def bind(self, origin, device=None) -> None:
        origin = np.asarray(origin, dtype=np.float64)
        if self.system is not None and not np.array_equal(origin, self.origin):
            raise ParameterError("origin", origin, f"the scene's origin {self.origin.tolist()} (rigid bodies)")
        if self.system is not None and device is not None and wp.get_device(device) != wp.get_device(self.device):
            raise ParameterError("device", str(device), f"the rigid bodies' device {self.device}")
        self.origin = origin

    # -- contact with the solvers' points ---------------------------------------------------------------------------
    def apply(self, rest, displacements, velocities, radius, kind, time: float, dt: float, mass=None, contact=None):
        """The body's collision kernel on a solver's points (kernels/colliders.py), with the opposite impulses
        accumulated into ``reaction``: the solver must pass its point masses [kg]; ``contact`` as in
        Collider.apply (the points' friction combines with the body's)."""
        if self.system is None:
            raise ParameterError(
                "rigid body", self.name, "a body added with Scene.add_rigid_body (set up by the scene)"
            )
        if mass is None:
            raise ParameterError("mass", None, "the solver's point masses [kg] (a rigid body takes the reaction)")
        arguments = {
            "rest": rest,
            "displacements": displacements,
            "velocities": velocities,
            "kind": kind,
            "radius": radius,
            "body": self.motion,
            "friction": self.point_friction(radius, contact),
            "mass": mass,
            "reaction": self.reaction,
            "device": self.device,
        }
        for phase in (0, 1):  # the mass the body meets, then the response (kernels/colliders.py push_point)
            if self.kind == kr.SHAPE_SPHERE:
                kc.push_out_of_sphere(**arguments, phase=phase, sphere_radius=float(self.size[0]))
            elif self.kind == kr.SHAPE_BOX:
                kc.push_out_of_box(**arguments, phase=phase, half_extents=self.size)
            else:
                kc.push_out_of_mesh(**arguments, phase=phase, mesh=self.mesh_data.mesh.id)

    # -- the host's view --------------------------------------------------------------------------------------------
    def state_values(self) -> dict:
        """The body's state read from the device: position (centre of mass, world [m]), orientation (x, y, z, w),
        velocity [m/s], angular_momentum [kg m^2/s] and angular_velocity [rad/s] (world axes), float64 copies that
        keep their values while the body moves on (on the CPU ``numpy()`` is a view of the live state)."""
        s = np.array(self.state.numpy(), copy=True)[0]
        q = np.asarray(s["orientation"], dtype=np.float64)
        L = np.asarray(s["angular_momentum"], dtype=np.float64)
        return {
            "position": self.origin + np.asarray(s["position"], dtype=np.float64),
            "orientation": q,
            "velocity": np.asarray(s["velocity"], dtype=np.float64),
            "angular_momentum": L,
            "angular_velocity": np.linalg.solve(self._world_inertia(q), L),
        }

    def linear_momentum(self) -> np.ndarray:
        """M v [kg m/s]."""
        return self.mass * self.state_values()["velocity"]

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """(x - origin) x M v + L [kg m^2/s]."""
        s = self.state_values()
        return (
            np.cross(s["position"] - np.asarray(origin, dtype=np.float64), self.mass * s["velocity"])
            + s["angular_momentum"]
        )

    def kinetic_energy(self) -> float:
        """1/2 M v^2 + 1/2 omega . L [J]."""
        s = self.state_values()
        return 0.5 * self.mass * float(s["velocity"] @ s["velocity"]) + 0.5 * float(
            s["angular_velocity"] @ s["angular_momentum"]
        )

    def speed_bound(self, duration: float) -> float:
        """A bound [m/s] of the speed of the body's surface over [0, ``duration``] s for the time step and the
        watchdog: its initial speed plus spin times its bounding radius plus a free fall over ``duration`` (contact
        with heavier bodies can speed it up beyond this only by giving back energy they received)."""
        g = float(np.linalg.norm(self.gravity))
        spin = float(np.linalg.norm(self.angular_velocity)) * self.bounding_radius
        return float(np.linalg.norm(self.velocity)) + spin + g * float(duration)

    def _bounding_radius(self) -> float:
        return self.bounding_radius

    def view(self, time: float, *, bounds=None):
        """The body for the output: its body-frame mesh, its current pose, velocity [m/s] and angular velocity
        [rad/s] (one read of the device)."""
        s = self.state_values()
        return RigidView(
            self.name or type(self).__name__,
            self.body_vertices,
            self.body_faces,
            s["position"],
            s["orientation"],
            static=False,
            velocity=s["velocity"],
            angular_velocity=s["angular_velocity"],
        )

    # -- checkpoints ------------------------------------------------------------------------------------------------
    def checkpoint(self) -> dict:
        """The device state, bit for bit."""
        return {"rigid_state": np.array(self.state.numpy(), copy=True)}

    def restore(self, state: dict) -> None:
        self.state.assign(np.asarray(state["rigid_state"]))
        self.write_motion()


class RigidBodies:
    """The scene's dynamic rigid bodies, stepped with the solvers (pdsim.run.advance_frame): :meth:`begin_step`
    before the solvers' steps, :meth:`end_step` after them. Built by :meth:`pdsim.Scene.build_solvers`.

    Args:
        bodies: the RigidBody instances.
        ground: the scene's GroundPlane or None.
        colliders: the scene's other colliders (static MeshColliders; kinematic projectiles raise
            FeatureNotAvailableError: a dynamic body does not collide with them).
        gravity: [m/s^2], 3 numbers.
        origin: the scene's origin [m] (the solvers' local frame).
        device: Warp device.
    """

    def __init__(self, bodies, *, ground, colliders, gravity, origin, device):
        moving = [c for c in colliders if isinstance(c, RigidProjectile)]
        if moving:
            raise FeatureNotAvailableError(
                f"dynamic rigid bodies do not collide with kinematic projectiles ('{moving[0].name or 'projectile'}'): "
                "make the projectile a rigid body too (Scene.add_rigid_body) or remove it"
            )
        self.bodies = list(bodies)
        self.ground = ground
        self.statics = [c for c in colliders if isinstance(c, MeshCollider)]
        self.gravity = np.asarray(gravity, dtype=np.float64)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.device = wp.get_device(device)
        for b in self.bodies:
            if ground is not None and not math.isnan(float(pair_damping_ratio(b.restitution, ground.restitution))):
                _place_on_ground(b, ground)
            b.setup(self.device, self.origin, self)
        self._static_shapes = []
        for c in self.statics:
            shape = kr.RigidShape()
            shape.kind = int(kr.SHAPE_MESH)
            shape.size = wp.vec3(0.0, 0.0, 0.0)
            shape.mesh = wp.uint64(c._mesh.mesh.id)
            band = c.band if c.band is not None else 0.1 * c._mesh.bounding_radius
            shape.band = float(band)
            shape.inv_mass = wp.float64(0.0)
            shape.inv_inertia = wp.mat33d()
            motion = kc.RigidMotion()
            motion.pose = wp.transform(wp.vec3(*(c.center - self.origin)), wp.quat_identity())
            motion.band = float(band)
            self._static_shapes.append((c, shape, wp.array([motion], dtype=kc.RigidMotion, device=self.device)))
        self._gravity = wp.vec3d(*self.gravity)
        self._step_start = [wp.empty_like(b.state) for b in self.bodies]  # each body's state before its drift

    def begin_step(self, dt: float) -> None:
        """First half kick and drift of every body; their motions for the solvers' collision kernels. Each body's
        state before it is kept for :meth:`undo_begin_step`."""
        for b, kept in zip(self.bodies, self._step_start):
            wp.copy(kept, b.state)
            kr.drift(
                state=b.state,
                shape=b.shape,
                gravity=self._gravity,
                dt=wp.float64(dt),
                reaction=b.reaction,
                motion=b.motion,
                device=self.device,
            )

    def undo_begin_step(self) -> None:
        """Every body back to its state before the last :meth:`begin_step` (a run stopped at the start of the
        solvers' step that followed it: the checkpoint then holds the bodies and the solvers at the same step)."""
        for b, kept in zip(self.bodies, self._step_start):
            wp.copy(b.state, kept)
            b.write_motion()

    def end_step(self, dt: float) -> None:
        """Second half kick with the points' reaction, then contact with the ground, static meshes and each other
        (each pair in the form its restitution gives: pair_damping_ratio)."""
        d = self.device
        for b in self.bodies:
            kr.kick(
                state=b.state, shape=b.shape, gravity=self._gravity, dt=wp.float64(dt), reaction=b.reaction, device=d
            )
        law = {"stiffness_rate": wp.float64((CONTACT_OMEGA_DT / float(dt)) ** 2), "dt": wp.float64(dt), "device": d}
        for b in self.bodies:
            if self.ground is not None:
                n = np.asarray(self.ground.normal, dtype=np.float64)
                n = n / np.linalg.norm(n)
                kr.plane_contact(
                    state=b.state,
                    shape=b.shape,
                    samples=b.samples_array,
                    sample_radius=b.radius_array,
                    normal=wp.vec3d(*n),
                    offset=wp.float64(float(self.ground.offset) - float(n @ self.origin)),
                    friction=wp.float64(float(combine_friction(b.friction, self.ground.friction))),
                    damping_ratio=pair_damping_ratio(b.restitution, self.ground.restitution),
                    **law,
                )
            for c, shape, motion in self._static_shapes:
                kr.mesh_contact(
                    state=b.state,
                    shape=b.shape,
                    samples=b.samples_array,
                    sample_radius=b.radius_array,
                    other=shape,
                    other_motion=motion,
                    friction=wp.float64(float(combine_friction(b.friction, c.friction))),
                    damping_ratio=pair_damping_ratio(b.restitution, None),
                    **law,
                )
        for i, a in enumerate(self.bodies):
            for b in self.bodies[i + 1 :]:
                kr.pair_contact(
                    state_a=a.state,
                    shape_a=a.shape,
                    samples_a=a.samples_array,
                    radius_a=a.radius_array,
                    state_b=b.state,
                    shape_b=b.shape,
                    samples_b=b.samples_array,
                    radius_b=b.radius_array,
                    friction=wp.float64(float(combine_friction(a.friction, b.friction))),
                    damping_ratio=pair_damping_ratio(a.restitution, b.restitution),
                    **law,
                )

    def simulate(self, dt: float, steps: int) -> None:
        """``steps`` steps of ``dt`` [s] of the bodies alone (no solver's points)."""
        for _ in range(int(steps)):
            self.begin_step(dt)
            self.end_step(dt)

    def linear_momentum(self) -> np.ndarray:
        return np.sum([b.linear_momentum() for b in self.bodies], axis=0)

    def angular_momentum(self, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        return np.sum([b.angular_momentum(origin) for b in self.bodies], axis=0)


def pair_damping_ratio(restitution_a, restitution_b) -> wp.float64:
    """The damping ratio of the penalty form for a rigid body's pair whose sides bring ``restitution_a`` and
    ``restitution_b`` (None: none): that of their combined restitution (pdsim/contact.py combine_restitution,
    damping_ratio_for_restitution), NaN (the inelastic form) where neither brings one or the pair's is 0."""
    e = float(combine_restitution(np.nan if restitution_a is None else restitution_a,
                                  np.nan if restitution_b is None else restitution_b))  # fmt: skip
    return wp.float64(math.nan if math.isnan(e) or e == 0.0 else damping_ratio_for_restitution(e))


def _place_on_ground(body: RigidBody, ground) -> None:
    """Lifts a body that starts inside the ground along its normal until its deepest surface sample touches it,
    with a warning: in the penalty form the contact's spring would throw it out at CONTACT_OMEGA_DT times its
    overlap per step (15 m/s for 1 mm at a step of 10 us). Before any step, so a resume (which restores the state)
    sees the same start."""
    n = np.asarray(ground.normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    points = body.position + _rotate(body.orientation, np.asarray(body.samples, dtype=np.float64))
    overlap = float(np.max(np.asarray(body.sample_radius) + float(ground.offset) - points @ n))
    if overlap > 0.0:
        body.position = body.position + overlap * n
        warnings.warn(
            f"rigid body {body.name!r} starts {overlap * 1e3:.3g} mm inside the ground: lifted onto it (its contact "
            "with the ground has a restitution, whose spring would throw it out)",
            stacklevel=3,
        )


def rigid_bodies_of(solvers) -> RigidBodies | None:
    """The RigidBodies the solvers' colliders belong to (one per scene), or None."""
    for s in solvers:
        for c in getattr(s, "colliders", ()):
            if isinstance(c, RigidBody) and c.system is not None:
                return c.system
    return None


def build_rigid_bodies(scene, origin, device) -> RigidBodies | None:
    """The RigidBodies of a scene's rigid bodies (Scene.add_rigid_body), set up at their initial state in the local
    frame of ``origin`` [m] on ``device``, or None without any."""
    bodies = [c for c in scene.colliders if isinstance(c, RigidBody)]
    if not bodies:
        return None
    others = [c for c in scene.colliders if not isinstance(c, RigidBody)]
    return RigidBodies(
        bodies, ground=scene.ground, colliders=others, gravity=scene.gravity, origin=origin, device=device
    )


__all__ = [
    "BoxShape",
    "RigidBodies",
    "RigidBody",
    "SphereShape",
    "box_inertia",
    "build_rigid_bodies",
    "rigid_bodies_of",
    "sphere_inertia",
]
