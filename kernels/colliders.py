"""Collider kernels: the ground plane, static triangle meshes and kinematic rigid projectiles (sphere, box, mesh).

Points are at rest + displacement in the solver's local frame (kernels/integration.py); poses are given in that
frame too. Colliders push a penetrating free point (a sphere of its collision radius) back to the surface along the
outward normal, remove its approaching normal velocity relative to the collider's surface velocity and reduce the
relative tangential velocity by Coulomb friction (the convention of ``collide_ground_plane``). A kinematic collider is
not pushed back; the push moves the point's displacement. A dynamic rigid body (pdsim/rigid.py) uses the same
kernels with the points' masses and takes the opposite impulses (``push_point``). Friction (and the ground's damping
ratio) come per point: the Coulomb coefficient of each point's pair with the collider (pdsim/contact.py
combine_friction of the collider's and the point's material's).
"""

import warp as wp

from .integration import PARTICLE_FREE
from .launch import launch

# share of a point's remaining penetration of a dynamic rigid body removed per step beyond what its velocity change
# moves it (push_point): without it a body resting on points sinks at a steady rate
PUSH_OUT_RATE = wp.constant(0.1)


@wp.kernel
def collide_ground_plane(
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    normal: wp.vec3,
    offset: wp.array(dtype=float),
    friction: wp.array(dtype=float),
    mass: wp.array(dtype=float),
    impulse: wp.array(dtype=wp.vec3d),
):
    """Keeps free points (spheres of the given radius, at rest + displacement in the solver's local frame) above the
    plane n . x = offset[i] (local frame, per point [m]): a penetrating point is projected back onto the plane, its
    approaching normal velocity removed (inelastic) and its tangential velocity reduced by Coulomb friction
    (friction[i] * removed normal speed, never reversing it). The impulse the plane gives, m (v_new - v_old) [N s],
    is added to ``impulse[0]`` (points of mass ``mass`` [kg]; pass an empty ``mass`` to skip it)."""
    i = wp.tid()
    if kind[i] != PARTICLE_FREE:
        return
    x = rest[i] + displacements[i]
    depth = radius[i] + offset[i] - wp.dot(normal, x)
    if depth > 0.0:
        displacements[i] = displacements[i] + depth * normal
        v = velocities[i]
        vn = wp.dot(v, normal)
        if vn < 0.0:
            vt = v - vn * normal
            vt_len = wp.length(vt)
            scale = float(0.0)
            if vt_len > 0.0:
                scale = wp.max(0.0, 1.0 - friction[i] * (-vn) / vt_len)
            v_new = vt * scale
            velocities[i] = v_new
            if mass.shape[0] > 0:
                dp = mass[i] * (v_new - v)
                wp.atomic_add(impulse, 0, wp.vec3d(wp.float64(dp[0]), wp.float64(dp[1]), wp.float64(dp[2])))


@wp.func
def face_point_mass(wa: float, wb: float, wc: float, ma: float, mb: float, mc: float):
    """Effective mass [kg] of the point of a triangle with barycentric weights (wa, wb, wc) whose vertices weigh ma,
    mb, mc [kg] (> 0): a force F at the point pushes vertex j with w_j F, which accelerates the point by
    F sum_j w_j^2 / m_j, so its mass is 1 / sum_j w_j^2 / m_j. The barycentric average sum_j w_j m_j overstates it
    near a light vertex (a small element's corner beside large ones), and a penalty tied to that average is too
    stiff for the light vertex at the step."""
    return 1.0 / (wa * wa / ma + wb * wb / mb + wc * wc / mc)


@wp.func
def contact_step_factor(dt: float, step: float):
    """(dt / max(dt, step))^2: the factor that turns a penalty rate (omega / dt)^2 tied to the run's step dt [s] into
    one tied to the longer ``step`` [s] of the elements around a contact (never stiffer than dt allows)."""
    r = dt / wp.max(dt, step)
    return r * r


@wp.func
def penalty_force(
    n: wp.vec3, depth: float, v_rel: wp.vec3, k: float, m_red: float, damping_ratio: float, friction: float
):
    """The contact law of every penalty pair (particle-mesh, vertex-face, ground) [N]: a linear spring-dashpot along
    the unit normal n (pointing from the other side to this one), F_n = max(k depth - c v_n, 0) (never pulling),
    c = 2 damping_ratio sqrt(k m_red), v_n = v_rel . n (v_rel: this side's velocity minus the other's [m/s]), plus
    regularised Coulomb friction on the tangential relative velocity v_t: |F_t| = min(friction F_n, c_t |v_t|)
    opposing v_t, c_t = 2 sqrt(k m_red) (critically damped). depth [m] > 0 is the overlap, k [N/m] the penalty,
    m_red [kg] the pair's reduced mass. The restitution of a damping ratio, and the damping ratio of a restitution a
    user sets: pdsim/contact.py, restitution_of_damping_ratio and damping_ratio_for_restitution."""
    damper = 2.0 * damping_ratio * wp.sqrt(k * m_red)
    vn = wp.dot(v_rel, n)
    fn = wp.max(k * depth - damper * vn, 0.0)
    f = fn * n
    if friction > 0.0:
        vt = v_rel - vn * n
        vt_len = wp.length(vt)
        if vt_len > 0.0:
            ft = wp.min(friction * fn, 2.0 * wp.sqrt(k * m_red) * vt_len)
            f -= (ft / vt_len) * vt
    return f


@wp.func
def pair_damping_ratio(zeta_k: float, zeta_j: float, scene: float):
    """Damping ratio of a pair whose sides bring zeta_k and zeta_j (NaN: none): the smaller (the larger restitution,
    pdsim/contact.py combine_restitution), the one side's where the other brings none, ``scene`` where neither does."""
    if wp.isnan(zeta_k):
        if wp.isnan(zeta_j):
            return scene
        return zeta_j
    if wp.isnan(zeta_j):
        return zeta_k
    return wp.min(zeta_k, zeta_j)


@wp.func
def pair_friction(mu_k: float, mu_j: float, scene: float):
    """Coulomb coefficient of a pair whose sides bring mu_k and mu_j (NaN: none): sqrt(mu_k mu_j) (pdsim/contact.py
    combine_friction), the one side's where the other brings none, ``scene`` where neither does."""
    if wp.isnan(mu_k):
        if wp.isnan(mu_j):
            return scene
        return mu_j
    if wp.isnan(mu_j):
        return mu_k
    return wp.sqrt(mu_k * mu_j)


@wp.func
def collider_response(
    x: wp.vec3,
    v: wp.vec3,
    sdf: float,
    n: wp.vec3,
    r: float,
    v_surface: wp.vec3,
    friction: float,
):
    """Projection and velocity response of a particle of radius r at signed distance sdf [m] (outward normal n) from a
    collider surface moving at v_surface [m/s]. Returns (new position, new velocity)."""
    x_new = x + (r - sdf) * n
    v_rel = v - v_surface
    vn = wp.dot(v_rel, n)
    v_new = v
    if vn < 0.0:
        vt = v_rel - vn * n
        vt_len = wp.length(vt)
        scale = float(0.0)
        if vt_len > 0.0:
            scale = wp.max(0.0, 1.0 - friction * (-vn) / vt_len)
        v_new = v_surface + vt * scale
    return x_new, v_new


@wp.struct
class RigidMotion:
    """Pose and velocity of a collider over the current step, stored in a one-element device array (a static mesh:
    written once; a projectile: copied by ``select_motion`` from the frame's table each step, so a captured graph
    replays with the new poses).

    pose: body frame to world; linear_velocity [m/s] of the frame origin; angular_velocity [rad/s] (world axes);
    band: detection depth below a mesh surface [m] (meshes only); inv_mass [1/kg] and inv_inertia [1/(kg m^2)] (world
    axes, about the frame origin) and step [s], the length of the step: a dynamic rigid body's (pdsim/rigid.py), zero
    for a kinematic collider."""

    pose: wp.transform
    linear_velocity: wp.vec3
    angular_velocity: wp.vec3
    band: float
    inv_mass: float
    inv_inertia: wp.mat33
    step: float


@wp.kernel
def select_motion(table: wp.array(dtype=RigidMotion), slot: int, band: float, motion: wp.array(dtype=RigidMotion)):
    """motion[0] <- table[slot] with ``band`` [m] added to its band: the step's row of a table of the frame's
    motions, written by the host before the frame (the slot is the step's place in the frame, the same in every
    frame, so a captured frame replays with the new frame's poses)."""
    m = table[slot]
    m.band = m.band + band
    motion[0] = m


@wp.func
def rigid_point_velocity(x: wp.vec3, motion: RigidMotion):
    """Velocity [m/s] of the material point of a rigid body at world position x: v + omega x (x - origin)."""
    return motion.linear_velocity + wp.cross(motion.angular_velocity, x - wp.transform_get_translation(motion.pose))


@wp.func
def to_vec3d(v: wp.vec3):
    """v in float64."""
    return wp.vec3d(wp.float64(v[0]), wp.float64(v[1]), wp.float64(v[2]))


@wp.func
def push_point(
    i: int,
    x: wp.vec3,
    sdf: float,
    n: wp.vec3,
    r: float,
    motion: RigidMotion,
    friction: float,
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    mass: wp.array(dtype=float),
    reaction: wp.array(dtype=wp.vec3d),
    phase: int,
):
    """The response of point i at x [m] (rest + displacement), signed distance sdf [m] and outward normal n from the
    surface of a rigid collider moving with ``motion`` (collider_response), written to its displacement and velocity.

    A dynamic collider (non-empty ``mass``: point masses [kg]) is met in two launches. Phase 0 only adds
    m k to reaction[2][0], k = 1/M + (a x n) . I^-1 (a x n) the body's inverse effective mass at the point (a = x - c,
    c the pose's translation, the body's centre of mass): the mass the body meets this step. Phase 1 scales the
    point's velocity change by 1 / (1 + sum m k), the perfectly inelastic impulse between the body and the points it
    touches together (without it, a light body meeting more mass than its own in one step would rebound with energy
    it never had); the point moves along n by its normal velocity change times the step (motion.step [s]), or by
    PUSH_OUT_RATE of its penetration if that is more, at most out of the body, instead of a full projection (which
    would compress its neighbours without the body paying for it: the pair would gain energy); and the body takes
    the opposite impulse: reaction[0] -= m dv [N s] and reaction[1] -= (x_new - c) x m dv + (x_new - x) x m v_old
    [N m s] (the second term: the moment of the point's momentum moved with it, so that the pair conserves angular
    momentum as it conserves momentum). A kinematic collider (empty ``mass``) runs phase 1 alone: unscaled, with the
    full projection."""
    dynamic = mass.shape[0] > 0
    centre = wp.transform_get_translation(motion.pose)
    if phase == 0:
        if dynamic:
            an = wp.cross(x - centre, n)
            k = motion.inv_mass + wp.dot(an, motion.inv_inertia * an)
            wp.atomic_add(reaction, 2, wp.vec3d(wp.float64(mass[i] * k), wp.float64(0.0), wp.float64(0.0)))
        return
    v_old = velocities[i]
    vs = rigid_point_velocity(x, motion)
    x_new, v_new = collider_response(x, v_old, sdf, n, r, vs, friction)
    if dynamic:
        share = wp.float32(wp.float64(1.0) / (wp.float64(1.0) + reaction[2][0]))
        v_new = v_old + share * (v_new - v_old)
        # the position follows the velocity change over the step (as if the impulse came before the drift), at most
        # out of the body
        x_new = x + wp.min(wp.max(wp.dot(v_new - v_old, n) * motion.step, PUSH_OUT_RATE * (r - sdf)), r - sdf) * n
    displacements[i] = displacements[i] + (x_new - x)
    velocities[i] = v_new
    if dynamic:
        dp = mass[i] * (v_new - v_old)
        arm = x_new - centre
        dpd = to_vec3d(dp)
        armd = to_vec3d(arm)
        wp.atomic_sub(reaction, 0, dpd)
        moved = (x_new - x) * mass[i]
        moment = wp.cross(armd, dpd) + to_vec3d(wp.cross(moved, v_old))
        wp.atomic_sub(reaction, 1, moment)


@wp.func
def mesh_contact_point(mesh: wp.uint64, p: wp.vec3, r: float, max_dist: float):
    """The closest point of a closed triangle mesh to a sphere of radius r [m] centred at p, searched within
    ``max_dist`` [m] of the surface: (touch, sdf, n, face, u, v). touch is 1 when the signed distance sdf [m] < r
    (the sign from the angle-weighted pseudo-normal, negative inside), else 0 and the rest is not to be used; n is the
    outward unit normal (along p - closest point, or the face normal when p lies within 1e-6 r of the surface);
    face, u, v locate the closest point (barycentric weights u, v, 1 - u - v of the face's vertices)."""
    hit = wp.mesh_query_point_sign_normal(mesh, p, max_dist)
    if not hit.result:
        return 0, float(0.0), wp.vec3(0.0), int(-1), float(0.0), float(0.0)
    closest = wp.mesh_eval_position(mesh, hit.face, hit.u, hit.v)
    d = p - closest
    dist = wp.length(d)
    sdf = hit.sign * dist
    if sdf >= r:
        return 0, sdf, wp.vec3(0.0), hit.face, hit.u, hit.v
    n = wp.mesh_eval_face_normal(mesh, hit.face)
    if dist > 1.0e-6 * r:
        n = (hit.sign / dist) * d
    return 1, sdf, n, hit.face, hit.u, hit.v


@wp.func
def box_contact_point(p: wp.vec3, half_extents: wp.vec3, r: float):
    """Contact of a sphere of radius r [m] centred at p (box frame) with the box of half edge lengths half_extents [m]
    centred at the frame's origin: (touch, sdf, n). touch is 1 when the exact signed distance sdf [m] < r, else 0 and
    the rest is not to be used; n is the outward unit normal (inside: the face of least penetration)."""
    q = wp.vec3(wp.abs(p[0]) - half_extents[0], wp.abs(p[1]) - half_extents[1], wp.abs(p[2]) - half_extents[2])
    qmax = wp.max(q[0], wp.max(q[1], q[2]))
    if qmax >= r:
        return 0, qmax, wp.vec3(0.0)
    sdf = float(0.0)
    n_local = wp.vec3(0.0)
    if qmax > 0.0:
        c = wp.vec3(
            wp.clamp(p[0], -half_extents[0], half_extents[0]),
            wp.clamp(p[1], -half_extents[1], half_extents[1]),
            wp.clamp(p[2], -half_extents[2], half_extents[2]),
        )
        d = p - c
        sdf = wp.length(d)
        if sdf >= r:
            return 0, sdf, wp.vec3(0.0)
        n_local = d / sdf
    else:
        sdf = qmax
        if q[0] == qmax:
            n_local = wp.vec3(wp.sign(p[0]), 0.0, 0.0)
        elif q[1] == qmax:
            n_local = wp.vec3(0.0, wp.sign(p[1]), 0.0)
        else:
            n_local = wp.vec3(0.0, 0.0, wp.sign(p[2]))
    return 1, sdf, n_local


@wp.kernel
def collide_sphere(
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    body: wp.array(dtype=RigidMotion),
    sphere_radius: float,
    friction: wp.array(dtype=float),
    mass: wp.array(dtype=float),
    reaction: wp.array(dtype=wp.vec3d),
    phase: int,
):
    """Sphere of radius sphere_radius [m] centred at the pose's translation: sdf = |x - c| - R."""
    i = wp.tid()
    if kind[i] != PARTICLE_FREE:
        return
    motion = body[0]
    pose = motion.pose
    x = rest[i] + displacements[i]
    d = x - wp.transform_get_translation(pose)
    dist = wp.length(d)
    sdf = dist - sphere_radius
    r = radius[i]
    if sdf < r:
        n = wp.vec3(0.0, 0.0, 1.0)
        if dist > 0.0:
            n = d / dist
        push_point(i, x, sdf, n, r, motion, friction[i], displacements, velocities, mass, reaction, phase)


# Warp kernels cannot take a function argument (the signed distance of the shape): collide_box and collide_mesh
# repeat collide_sphere's parameters and point prologue around their own distance test.
@wp.kernel
def collide_box(
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    body: wp.array(dtype=RigidMotion),
    half_extents: wp.vec3,
    friction: wp.array(dtype=float),
    mass: wp.array(dtype=float),
    reaction: wp.array(dtype=wp.vec3d),
    phase: int,
):
    """Oriented box with half edge lengths half_extents [m] in the frame of pose (box_contact_point)."""
    i = wp.tid()
    if kind[i] != PARTICLE_FREE:
        return
    motion = body[0]
    pose = motion.pose
    x = rest[i] + displacements[i]
    r = radius[i]
    p = wp.transform_point(wp.transform_inverse(pose), x)
    touch, sdf, n_local = box_contact_point(p, half_extents, r)
    if touch == 0:
        return
    n = wp.transform_vector(pose, n_local)
    push_point(i, x, sdf, n, r, motion, friction[i], displacements, velocities, mass, reaction, phase)


# Like collide_box, this repeats collide_sphere's parameters and point prologue (a Warp kernel takes no function).
@wp.kernel
def collide_mesh(
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    mesh: wp.uint64,
    body: wp.array(dtype=RigidMotion),
    friction: wp.array(dtype=float),
    mass: wp.array(dtype=float),
    reaction: wp.array(dtype=wp.vec3d),
    phase: int,
):
    """Closed triangle mesh (vertices in the frame of pose). A particle is found when its centre lies within
    radius + band [m] of the surface; the sign (inside/outside) comes from the angle-weighted pseudo-normal, so a
    particle inside the mesh by less than radius + band is pushed out too."""
    i = wp.tid()
    if kind[i] != PARTICLE_FREE:
        return
    motion = body[0]
    pose = motion.pose
    x = rest[i] + displacements[i]
    r = radius[i]
    p = wp.transform_point(wp.transform_inverse(pose), x)
    touch, sdf, n_local, face, u, v = mesh_contact_point(mesh, p, r, r + motion.band)
    if touch == 0:
        return
    n = wp.transform_vector(pose, n_local)
    push_point(i, x, sdf, n, r, motion, friction[i], displacements, velocities, mass, reaction, phase)


@wp.kernel
def ground_plane_force(
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    kind: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    mass: wp.array(dtype=float),
    force_to_newton: wp.array(dtype=float),
    normal: wp.vec3,
    offset: wp.array(dtype=float),
    stiffness_rate: float,
    damping_ratio: wp.array(dtype=float),
    friction: wp.array(dtype=float),
    force: wp.array(dtype=wp.vec3),
):
    """The ground plane n . x = offset[i] (local frame, per point [m]) as a contact pair of the one law
    (penalty_force) for the free points whose pair with the plane has a damping ratio (damping_ratio[i], NaN: none,
    the point is left to the projection): a point (sphere of ``radius`` [m]) overlapping the plane by
    d = r + offset[i] - n . x > 0 gets
    F = penalty_force(n, d, v, k = stiffness_rate m, m, damping_ratio[i], friction[i]) [N] (the plane is immovable:
    the reduced mass is the point's mass m [kg]), added to force[i] as F / force_to_newton[i] (the solver's unit)."""
    i = wp.tid()
    if kind[i] != PARTICLE_FREE or wp.isnan(damping_ratio[i]):
        return
    x = rest[i] + displacements[i]
    depth = radius[i] + offset[i] - wp.dot(normal, x)
    if depth > 0.0:
        m = mass[i]
        f = penalty_force(normal, depth, velocities[i], stiffness_rate * m, m, damping_ratio[i], friction[i])
        force[i] = force[i] + f / force_to_newton[i]


# -- launches (pdsim/colliders.py) ------------------------------------------------------------------------------------
# One thread per point of the solver's arrays: rest positions, displacements, velocities (vec3 [n]), collision radii
# and kinematic kinds (int32 [n]); ``body`` is the collider's one-element RigidMotion array. The kernels' arguments are
# given as keywords named like their parameters (kernels/launch.py).


def push_out_of_plane(*, normal, device, **arguments):
    """Ground plane n . x = ``offset`` [m] (local frame, float [n] per point), ``normal`` 3 numbers, ``friction``
    float [n] per point (collide_ground_plane)."""
    launch(collide_ground_plane, arguments["rest"].shape[0], device=device, normal=wp.vec3(*normal), **arguments)


def ground_forces(*, normal, device, **arguments):
    """The ground plane n . x = ``offset`` [m] (local frame, float [n] per point) as a penalty contact
    (ground_plane_force)."""
    launch(ground_plane_force, arguments["rest"].shape[0], device=device, normal=wp.vec3(*normal), **arguments)


def push_out_of_sphere(*, device, **arguments):
    """Kinematic sphere of ``sphere_radius`` [m] (collide_sphere)."""
    launch(collide_sphere, arguments["rest"].shape[0], device=device, **arguments)


def push_out_of_box(*, half_extents, device, **arguments):
    """Kinematic box of ``half_extents`` [m] (3 numbers) (collide_box)."""
    launch(collide_box, arguments["rest"].shape[0], device=device, half_extents=wp.vec3(*half_extents), **arguments)


def push_out_of_mesh(*, device, **arguments):
    """Closed triangle mesh ``mesh`` (a wp.Mesh id) in the frame of ``body`` (collide_mesh)."""
    launch(collide_mesh, arguments["rest"].shape[0], device=device, **arguments)


def select_step_motion(table, slot: int, band: float, motion, device):
    """motion[0] <- table[slot] with ``band`` [m] added to its band (select_motion)."""
    wp.launch(select_motion, dim=1, inputs=[table, int(slot), float(band), motion], device=device)
