"""Rigid fragments of a peridynamic body (pdsim/peridynamics/handoff.py): the projection of their particles'
motion onto rigid motion, and the particles posed by it.

A rigid fragment g holds the particles members[member_offsets[g] .. member_offsets[g + 1]] (in a fixed order), each
with its offset ``body_offset`` [m] from the centre of mass in the fragment's body frame. Each step the particles move
as free points under every force and impulse of the step (contact, colliders, ground, loads, gravity, contact with
other methods and with dynamic rigid bodies); ``project_fragments`` then sums their mass, linear momentum and angular
momentum about their centre of mass in float64, one thread per fragment looping over its members in order (so the
sums do not depend on threads), and ``pose_members`` puts each particle back on the rigid motion with that centre of
mass, momentum and angular momentum. The projection conserves the fragment's linear and angular momentum exactly
(up to the float32 of the particles' state): the contact forces on the particles act on the fragment as a force and a
torque, accumulated on the device.

A static fragment (``at_rest`` 1: one held by fixed boundary conditions) is not projected (its velocity and angular
velocity stay 0), and ``pose_members`` puts each of its members back at the displacement it had when the fragment
was handed off (its ``body_offset``, bit for bit), with zero velocity.
"""

from __future__ import annotations

import warp as wp

from ..colliders import to_vec3d
from ..launch import launch
from ..rigid import rotation_quat


@wp.kernel
def project_fragments(
    member_offsets: wp.array(dtype=wp.int32),
    members: wp.array(dtype=wp.int32),
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.mat33d),
    at_rest: wp.array(dtype=wp.int32),
    rotate_dt: wp.float64,
    orientation: wp.array(dtype=wp.quatd),
    centre: wp.array(dtype=wp.vec3d),
    velocity: wp.array(dtype=wp.vec3d),
    angular_velocity: wp.array(dtype=wp.vec3d),
):
    """Fragment g: centre of mass [m] (local frame), velocity [m/s] and angular momentum about the centre of mass of
    its particles; the orientation turned by the angular velocity over ``rotate_dt`` [s] (0: kept); the angular
    velocity [rad/s] I(q)^+ L at the (new) orientation, with I^+ the body frame's pseudo-inverse inertia. A static
    fragment (at_rest[g] != 0) is left as it is (at rest)."""
    g = wp.tid()
    if at_rest[g] != 0:
        return
    m_sum = wp.float64(0.0)
    mx = wp.vec3d(wp.float64(0.0))
    mv = wp.vec3d(wp.float64(0.0))
    for i in range(member_offsets[g], member_offsets[g + 1]):
        k = members[i]
        m = wp.float64(mass[k])
        x = to_vec3d(rest[k]) + to_vec3d(displacements[k])
        mx = mx + m * x
        mv = mv + m * to_vec3d(velocities[k])
        m_sum = m_sum + m
    c = mx / m_sum
    v = mv / m_sum
    ang = wp.vec3d(wp.float64(0.0))
    for i in range(member_offsets[g], member_offsets[g + 1]):
        k = members[i]
        m = wp.float64(mass[k])
        r = to_vec3d(rest[k]) + to_vec3d(displacements[k]) - c
        ang = ang + m * wp.cross(r, to_vec3d(velocities[k]) - v)
    q = orientation[g]
    if rotate_dt > wp.float64(0.0):
        rot = wp.quat_to_matrix(q)
        w_old = rot * body_inv_inertia[g] * wp.transpose(rot) * ang
        q = wp.normalize(rotation_quat(w_old * rotate_dt) * q)
        orientation[g] = q
    rot = wp.quat_to_matrix(q)
    centre[g] = c
    velocity[g] = v
    angular_velocity[g] = rot * body_inv_inertia[g] * wp.transpose(rot) * ang


@wp.kernel
def pose_members(
    member_fragment: wp.array(dtype=wp.int32),
    members: wp.array(dtype=wp.int32),
    body_offset: wp.array(dtype=wp.vec3d),
    at_rest: wp.array(dtype=wp.int32),
    rest: wp.array(dtype=wp.vec3),
    orientation: wp.array(dtype=wp.quatd),
    centre: wp.array(dtype=wp.vec3d),
    velocity: wp.array(dtype=wp.vec3d),
    angular_velocity: wp.array(dtype=wp.vec3d),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    force_density: wp.array(dtype=wp.vec3),
):
    """Member i (particle members[i] of fragment member_fragment[i]) on its fragment's rigid motion: position
    c + R r_i (displacement from its rest position [m]) and velocity v + w x R r_i [m/s]; its force density is
    cleared [N/m^3] (the bond passes do not visit it: what the next force phase adds to it is contact, the ground,
    colliders and loads alone). A member of a static fragment: displacement ``body_offset`` [m], velocity 0."""
    i = wp.tid()
    g = member_fragment[i]
    k = members[i]
    force_density[k] = wp.vec3(0.0)
    if at_rest[g] != 0:
        held = body_offset[i]
        displacements[k] = wp.vec3(wp.float32(held[0]), wp.float32(held[1]), wp.float32(held[2]))
        velocities[k] = wp.vec3(0.0)
        return
    arm = wp.quat_to_matrix(orientation[g]) * body_offset[i]
    x = centre[g] + arm
    u = x - to_vec3d(rest[k])
    displacements[k] = wp.vec3(wp.float32(u[0]), wp.float32(u[1]), wp.float32(u[2]))
    v = velocity[g] + wp.cross(angular_velocity[g], arm)
    velocities[k] = wp.vec3(wp.float32(v[0]), wp.float32(v[1]), wp.float32(v[2]))


def project(*, fragment_count: int, member_count: int, device, record_cmd: bool = False, **arguments) -> list:
    """The rigid fragments' projection (project_fragments, one thread per fragment) and their members posed by it
    (pose_members, one thread per member); with ``record_cmd`` nothing runs and the two recorded launches are
    returned, to be replayed (``cmd.launch()``) while the arrays stay the same."""
    project_args = {k: arguments[k] for k in _PROJECT_NAMES}
    pose_args = {k: arguments[k] for k in _POSE_NAMES}
    return [
        launch(project_fragments, fragment_count, device=device, record_cmd=record_cmd, **project_args),
        launch(pose_members, member_count, device=device, record_cmd=record_cmd, **pose_args),
    ]


def pose(*, count: int, device, **arguments):
    """The rigid fragments' members posed on their rigid motion (pose_members, one thread per member)."""
    launch(pose_members, count, device=device, **arguments)


_PROJECT_NAMES = (
    "member_offsets", "members", "rest", "displacements", "velocities", "mass", "body_inv_inertia", "at_rest",
    "rotate_dt", "orientation", "centre", "velocity", "angular_velocity",
)  # fmt: skip
_POSE_NAMES = (
    "member_fragment", "members", "body_offset", "at_rest", "rest", "orientation", "centre", "velocity",
    "angular_velocity", "displacements", "velocities", "force_density",
)  # fmt: skip
