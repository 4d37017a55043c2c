"""Dynamic rigid bodies: their kick-drift-kick integration and their contact with the ground, static meshes and each
other (kernels/colliders.py holds their contact with particles and FEM vertices, and the shape queries).

A body's state (``RigidState``, one-element array, float64, the solvers' local frame) is its centre of mass, its
orientation (body frame to world), its velocity and its angular momentum about the centre of mass; the angular
velocity is ``R I_body^-1 R^T L``. A step is

    rigid_drift        v += g dt/2; q <- exp(omega dt) q; x += v dt; the step's RigidMotion for the collision kernels
    (the solvers' colliders add the particles' opposite impulses into ``reaction``: kernels/colliders.py push_point)
    rigid_kick         v += J / M + g dt/2; L += A (J, A: the reaction's impulse and angular impulse)
    rigid_*_contact    the body's surface samples against the ground plane, a static mesh or another body

Contact of a body with the ground, static meshes and other bodies goes through sample spheres on its surface (body
frame points with a radius: a sphere is one sample at its centre with its radius; boxes and meshes are points on
their surface with radius 0) tested against the other's shape query (plane, ``box_contact_point``,
``mesh_contact_point``, sphere). A pair meets in one of two forms, chosen by its damping ratio (NaN: none):

- inelastic (no damping ratio): the colliders' law applied to a body: the deepest penetration is removed by moving
  the body (bodies: shared by their inverse masses) and one impulse at the mean contact point of the penetrating
  samples (along their mean normal) removes the approaching normal velocity of that point and reduces its tangential
  velocity by Coulomb friction (at most ``friction`` times the normal impulse);
- penalty (a damping ratio): the one contact law (kernels/colliders.py penalty_force) at the mean contact point, on
  the mean depth of the penetrating samples, with the pair's effective mass along the normal at that point
  m_eff = 1 / (1/M_a + 1/M_b + n . ((I_a^-1 (r_a x n)) x r_a + (I_b^-1 (r_b x n)) x r_b)) as the reduced mass and
  the stiffness k = stiffness_rate m_eff (stiffness_rate = (CONTACT_OMEGA_DT / dt)^2, pdsim/contact.py): the force
  times dt is one impulse, equal and opposite on the two bodies. A sphere, or a box landing flat (its contact point
  under its centre of mass), then rebounds at the law's restitution of that damping ratio; the body sinks into what it
  hits by up to about v dt / CONTACT_OMEGA_DT at impact speed v, and by g dt^2 / CONTACT_OMEGA_DT^2 at rest.

One force or impulse at the mean point, not one per sample in turn, keeps a face lying on a face from twisting by the
order of the samples.
"""

import warp as wp

from .colliders import RigidMotion, box_contact_point, mesh_contact_point, penalty_force, to_vec3d
from .launch import launch

SHAPE_SPHERE = wp.constant(0)
SHAPE_BOX = wp.constant(1)
SHAPE_MESH = wp.constant(2)


@wp.struct
class RigidState:
    """position: centre of mass [m] (local frame); orientation: body frame to world, unit quaternion (x, y, z, w);
    velocity [m/s]; angular_momentum about the centre of mass [kg m^2/s] (world axes)."""

    position: wp.vec3d
    orientation: wp.quatd
    velocity: wp.vec3d
    angular_momentum: wp.vec3d


@wp.struct
class RigidShape:
    """A body's shape and mass: kind (SHAPE_SPHERE, SHAPE_BOX, SHAPE_MESH), size (sphere: radius in [0]; box: half
    edge lengths [m]), mesh (a wp.Mesh id in the body frame, meshes only), band: detection depth below a mesh
    surface [m]; inv_mass [1/kg], inv_inertia: inverse inertia tensor about the centre of mass in the body frame
    [1/(kg m^2)]."""

    kind: int
    size: wp.vec3
    mesh: wp.uint64
    band: float
    inv_mass: wp.float64
    inv_inertia: wp.mat33d


@wp.func
def world_inverse_inertia(q: wp.quatd, inv_inertia: wp.mat33d):
    """R I_body^-1 R^T [1/(kg m^2)] (world axes) for the orientation q."""
    r = wp.quat_to_matrix(q)
    return r * inv_inertia * wp.transpose(r)


@wp.func
def rotation_quat(w: wp.vec3d):
    """The unit quaternion of the rotation vector w [rad] (axis * angle)."""
    angle = wp.length(w)
    if angle == wp.float64(0.0):
        return wp.quatd(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(1.0))
    s = wp.sin(wp.float64(0.5) * angle) / angle
    return wp.quatd(w[0] * s, w[1] * s, w[2] * s, wp.cos(wp.float64(0.5) * angle))


@wp.func
def to_vec3(v: wp.vec3d):
    """v in float32."""
    return wp.vec3(wp.float32(v[0]), wp.float32(v[1]), wp.float32(v[2]))


@wp.func
def motion_of(s: RigidState, shape: RigidShape):
    """The RigidMotion (float32 pose and velocities) of state s for the collision kernels."""
    q = s.orientation
    w = world_inverse_inertia(q, shape.inv_inertia) * s.angular_momentum
    m = RigidMotion()
    m.pose = wp.transform(
        to_vec3(s.position), wp.quat(wp.float32(q[0]), wp.float32(q[1]), wp.float32(q[2]), wp.float32(q[3]))
    )
    m.linear_velocity = to_vec3(s.velocity)
    m.angular_velocity = to_vec3(w)
    m.band = shape.band
    m.inv_mass = wp.float32(shape.inv_mass)
    inv_i = world_inverse_inertia(q, shape.inv_inertia)
    m.inv_inertia = wp.mat33(
        wp.float32(inv_i[0, 0]),
        wp.float32(inv_i[0, 1]),
        wp.float32(inv_i[0, 2]),
        wp.float32(inv_i[1, 0]),
        wp.float32(inv_i[1, 1]),
        wp.float32(inv_i[1, 2]),
        wp.float32(inv_i[2, 0]),
        wp.float32(inv_i[2, 1]),
        wp.float32(inv_i[2, 2]),
    )
    return m


@wp.kernel
def rigid_drift(
    state: wp.array(dtype=RigidState),
    shape: RigidShape,
    gravity: wp.vec3d,
    dt: wp.float64,
    reaction: wp.array(dtype=wp.vec3d),
    motion: wp.array(dtype=RigidMotion),
):
    """First half kick (gravity [m/s^2]) and drift over ``dt`` [s]: the position by the velocity, the orientation by
    the angular velocity at the start of the drift; then the step's motion and a zeroed reaction (impulse, angular
    impulse, effective mass met: kernels/colliders.py push_point)."""
    s = state[0]
    half = wp.float64(0.5) * dt
    s.velocity = s.velocity + half * gravity
    w = world_inverse_inertia(s.orientation, shape.inv_inertia) * s.angular_momentum
    s.orientation = wp.normalize(rotation_quat(w * dt) * s.orientation)
    s.position = s.position + dt * s.velocity
    state[0] = s
    m = motion_of(s, shape)
    m.step = wp.float32(dt)
    motion[0] = m
    reaction[0] = wp.vec3d(wp.float64(0.0))
    reaction[1] = wp.vec3d(wp.float64(0.0))
    reaction[2] = wp.vec3d(wp.float64(0.0))


@wp.kernel
def rigid_motion(state: wp.array(dtype=RigidState), shape: RigidShape, motion: wp.array(dtype=RigidMotion)):
    """motion[0] <- the RigidMotion of the current state (before the first step, after a restore)."""
    motion[0] = motion_of(state[0], shape)


@wp.kernel
def rigid_kick(
    state: wp.array(dtype=RigidState),
    shape: RigidShape,
    gravity: wp.vec3d,
    dt: wp.float64,
    reaction: wp.array(dtype=wp.vec3d),
):
    """Second half kick: the impulse reaction[0] [N s] and angular impulse reaction[1] [N m s] (about the centre of
    mass) the particles gave the body this step, and gravity over dt/2."""
    s = state[0]
    s.velocity = s.velocity + shape.inv_mass * reaction[0] + wp.float64(0.5) * dt * gravity
    s.angular_momentum = s.angular_momentum + reaction[1]
    state[0] = s


@wp.func
def contact_impulse(
    v_rel: wp.vec3d,
    n: wp.vec3d,
    arm_a: wp.vec3d,
    arm_b: wp.vec3d,
    inv_mass: wp.float64,
    inv_ia: wp.mat33d,
    inv_ib: wp.mat33d,
    friction: wp.float64,
):
    """The impulse [N s] on body a at a contact of normal n (towards a) and relative velocity v_rel [m/s] of a's
    contact point against b's, arms from the centres of mass [m], inv_mass the sum of the inverse masses, inv_ia and
    inv_ib the world inverse inertias (zero for a static b): removes the approaching normal velocity and reduces the
    tangential one by at most ``friction`` times the normal impulse; zero when separating."""
    vn = wp.dot(v_rel, n)
    if vn >= wp.float64(0.0):
        return wp.vec3d(wp.float64(0.0))
    kn = inv_mass + wp.dot(
        n, wp.cross(inv_ia * wp.cross(arm_a, n), arm_a) + wp.cross(inv_ib * wp.cross(arm_b, n), arm_b)
    )
    jn = -vn / kn
    p = jn * n
    vt = v_rel - vn * n
    vt_len = wp.length(vt)
    if vt_len > wp.float64(0.0):
        t = vt / vt_len
        kt = inv_mass + wp.dot(
            t, wp.cross(inv_ia * wp.cross(arm_a, t), arm_a) + wp.cross(inv_ib * wp.cross(arm_b, t), arm_b)
        )
        p = p - wp.min(vt_len / kt, friction * jn) * t
    return p


@wp.func
def body_impulse(s: RigidState, shape: RigidShape, p: wp.vec3d, arm: wp.vec3d):
    """State s with the impulse p [N s] applied at ``arm`` [m] from its centre of mass."""
    out = RigidState()
    out.position = s.position
    out.orientation = s.orientation
    out.velocity = s.velocity + shape.inv_mass * p
    out.angular_momentum = s.angular_momentum + wp.cross(arm, p)
    return out


@wp.kernel
def rigid_plane_contact(
    state: wp.array(dtype=RigidState),
    shape: RigidShape,
    samples: wp.array(dtype=wp.vec3),
    sample_radius: wp.array(dtype=float),
    normal: wp.vec3d,
    offset: wp.float64,
    friction: wp.float64,
    damping_ratio: wp.float64,
    stiffness_rate: wp.float64,
    dt: wp.float64,
):
    """A body against the static plane n . x = offset (local frame). Without a damping ratio (NaN): one impulse
    (contact_impulse, the plane static) at the mean of the penetrating samples' contact points, then the deepest
    sample is moved onto the plane; with one, the penalty form (penalty_pass) over the step dt [s]."""
    s = state[0]
    if not wp.isnan(damping_ratio):
        plane = RigidState()  # at rest, immovable (its shape's inverse mass and inertia are zero)
        plane.orientation = wp.quatd(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(1.0))
        hits, p, la, lb = penalty_pass(s, shape, samples, sample_radius, plane, RigidShape(), 1, normal, offset,
                                       stiffness_rate, damping_ratio, friction, dt)  # fmt: skip
        s.velocity = s.velocity + shape.inv_mass * p
        s.angular_momentum = s.angular_momentum + la
        state[0] = s
        return
    r = wp.quat_to_matrix(s.orientation)
    deepest = wp.float64(0.0)
    arm_sum = wp.vec3d(wp.float64(0.0))
    count = wp.float64(0.0)
    for k in range(samples.shape[0]):
        rk = wp.float64(sample_radius[k])
        arm = r * to_vec3d(samples[k])
        depth = rk + offset - wp.dot(normal, s.position + arm)
        if depth > wp.float64(0.0):
            deepest = wp.max(deepest, depth)
            arm_sum = arm_sum + arm - rk * normal
            count = count + wp.float64(1.0)
    if count == wp.float64(0.0):
        return
    arm = arm_sum / count
    inv_i = world_inverse_inertia(s.orientation, shape.inv_inertia)
    w = inv_i * s.angular_momentum
    p = contact_impulse(s.velocity + wp.cross(w, arm), normal, arm, arm, shape.inv_mass, inv_i, wp.mat33d(), friction)
    s = body_impulse(s, shape, p, arm)
    s.position = s.position + deepest * normal
    state[0] = s


@wp.func
def shape_contact_point(shape: RigidShape, p: wp.vec3, r: float):
    """A sample sphere of radius r [m] centred at p (the shape's body frame) against the shape: (touch, sdf, n) as
    box_contact_point (sphere: exact distance to the centre; mesh: mesh_contact_point within r + band)."""
    if shape.kind == SHAPE_SPHERE:
        dist = wp.length(p)
        sdf = dist - shape.size[0]
        n = wp.vec3(0.0, 0.0, 1.0)
        if dist > 0.0:
            n = p / dist
        touch = int(0)
        if sdf < r:
            touch = 1
        return touch, sdf, n
    if shape.kind == SHAPE_BOX:
        return box_contact_point(p, shape.size, r)
    touch, sdf, n, face, u, v = mesh_contact_point(shape.mesh, p, r, r + shape.band)
    return touch, sdf, n


@wp.func
def sample_touch(
    sa: RigidState,
    pk: wp.vec3,
    rk: float,
    sb: RigidState,
    hb: RigidShape,
    plane: int,
    normal: wp.vec3d,
    offset: wp.float64,
):
    """Sample sphere (pk, rk) of body a (state sa) against the plane n . x = offset (plane 1) or body b's shape
    (state sb): (touch, depth [m], unit normal towards a, the contact point's arm from a's centre of mass [m])."""
    arm0 = wp.quat_to_matrix(sa.orientation) * to_vec3d(pk)
    if plane == 1:
        depth = wp.float64(rk) + offset - wp.dot(normal, sa.position + arm0)
        return wp.where(depth > wp.float64(0.0), 1, 0), depth, normal, arm0 - wp.float64(rk) * normal
    qb = sb.orientation
    rot_b = wp.quat(wp.float32(qb[0]), wp.float32(qb[1]), wp.float32(qb[2]), wp.float32(qb[3]))
    x = to_vec3(sa.position - sb.position + arm0)
    touch, sdf, n_local = shape_contact_point(hb, wp.quat_rotate_inv(rot_b, x), rk)
    n = to_vec3d(wp.quat_rotate(rot_b, n_local))
    return touch, wp.float64(rk - sdf), n, arm0 - wp.float64(rk) * n


@wp.func
def penalty_pass(
    sa: RigidState,
    ha: RigidShape,
    samples: wp.array(dtype=wp.vec3),
    radius: wp.array(dtype=float),
    sb: RigidState,
    hb: RigidShape,
    plane: int,
    normal: wp.vec3d,
    offset: wp.float64,
    stiffness_rate: wp.float64,
    damping_ratio: wp.float64,
    friction: wp.float64,
    dt: wp.float64,
):
    """The penalty form over a step dt [s] for body a's penetrating samples against the plane (plane 1) or body b:
    (count of penetrating samples, impulse on a [N s], angular impulse on a and on b about their centres of mass
    [N m s]). Each penetrating sample i is a pair of the one law (penalty_force on its own depth, normal and relative
    velocity) with 1/count of the stiffness k = stiffness_rate m_eff and of the reduced mass m_eff, the pair's
    effective mass along the mean normal at the mean contact point; the impulses on b are the opposite."""
    count = int(0)
    arm_sum = wp.vec3d(wp.float64(0.0))
    n_sum = wp.vec3d(wp.float64(0.0))
    for k in range(samples.shape[0]):
        touch, depth, n, arm = sample_touch(sa, samples[k], radius[k], sb, hb, plane, normal, offset)
        if touch == 1:
            count += 1
            arm_sum = arm_sum + arm
            n_sum = n_sum + n
    p = wp.vec3d(wp.float64(0.0))
    la = wp.vec3d(wp.float64(0.0))
    lb = wp.vec3d(wp.float64(0.0))
    if count == 0 or wp.length(n_sum) == wp.float64(0.0):
        return int(0), p, la, lb
    inv_ia = world_inverse_inertia(sa.orientation, ha.inv_inertia)
    inv_ib = world_inverse_inertia(sb.orientation, hb.inv_inertia)
    wa = inv_ia * sa.angular_momentum
    wb = inv_ib * sb.angular_momentum
    nm = wp.normalize(n_sum)
    arm_a = arm_sum / wp.float64(count)
    arm_b = sa.position + arm_a - sb.position
    kn = (
        ha.inv_mass
        + hb.inv_mass
        + wp.dot(nm, wp.cross(inv_ia * wp.cross(arm_a, nm), arm_a) + wp.cross(inv_ib * wp.cross(arm_b, nm), arm_b))
    )
    m = wp.float32(wp.float64(1.0) / (kn * wp.float64(count)))  # each sample's share of the effective mass
    k_share = wp.float32(stiffness_rate) * m
    for k in range(samples.shape[0]):
        touch, depth, n, arm = sample_touch(sa, samples[k], radius[k], sb, hb, plane, normal, offset)
        if touch == 1:
            arm_bk = sa.position + arm - sb.position
            v_rel = (sa.velocity + wp.cross(wa, arm)) - (sb.velocity + wp.cross(wb, arm_bk))
            f = penalty_force(to_vec3(n), wp.float32(depth), to_vec3(v_rel), k_share, m, wp.float32(damping_ratio),
                              wp.float32(friction))  # fmt: skip
            dp = dt * to_vec3d(f)
            p = p + dp
            la = la + wp.cross(arm, dp)
            lb = lb - wp.cross(arm_bk, dp)
    return count, p, la, lb


@wp.kernel
def rigid_mesh_contact(
    state: wp.array(dtype=RigidState),
    shape: RigidShape,
    samples: wp.array(dtype=wp.vec3),
    sample_radius: wp.array(dtype=float),
    other: RigidShape,
    other_motion: wp.array(dtype=RigidMotion),
    friction: wp.float64,
    damping_ratio: wp.float64,
    stiffness_rate: wp.float64,
    dt: wp.float64,
):
    """A body against a static shape (a mesh collider) at the pose other_motion[0]. Without a damping ratio (NaN):
    one impulse at the mean contact point of the penetrating samples along their mean normal, then the deepest sample
    is moved out along its normal; with one, the penalty form (penalty_pass) over the step dt [s]."""
    s = state[0]
    pose = other_motion[0].pose
    if not wp.isnan(damping_ratio):
        sb = RigidState()  # the static shape at its pose, immovable (other's inverse mass and inertia are zero)
        sb.position = to_vec3d(wp.transform_get_translation(pose))
        qb = wp.transform_get_rotation(pose)
        sb.orientation = wp.quatd(wp.float64(qb[0]), wp.float64(qb[1]), wp.float64(qb[2]), wp.float64(qb[3]))
        hits, p, la, lb = penalty_pass(s, shape, samples, sample_radius, sb, other, 0, wp.vec3d(), wp.float64(0.0),
                                       stiffness_rate, damping_ratio, friction, dt)  # fmt: skip
        s.velocity = s.velocity + shape.inv_mass * p
        s.angular_momentum = s.angular_momentum + la
        state[0] = s
        return
    inv_pose = wp.transform_inverse(pose)
    r = wp.quat_to_matrix(s.orientation)
    deepest = wp.float64(0.0)
    push = wp.vec3d(wp.float64(0.0))
    arm_sum = wp.vec3d(wp.float64(0.0))
    n_sum = wp.vec3d(wp.float64(0.0))
    count = wp.float64(0.0)
    for k in range(samples.shape[0]):
        rk = sample_radius[k]
        arm0 = r * to_vec3d(samples[k])
        x = to_vec3(s.position + arm0)
        touch, sdf, n_local = shape_contact_point(other, wp.transform_point(inv_pose, x), rk)
        if touch == 1:
            n = to_vec3d(wp.transform_vector(pose, n_local))
            depth = wp.float64(rk - sdf)
            if depth > deepest:
                deepest = depth
                push = depth * n
            arm_sum = arm_sum + arm0 - wp.float64(rk) * n
            n_sum = n_sum + n
            count = count + wp.float64(1.0)
    if count == wp.float64(0.0) or wp.length(n_sum) == wp.float64(0.0):
        return
    inv_i = world_inverse_inertia(s.orientation, shape.inv_inertia)
    n = wp.normalize(n_sum)
    arm = arm_sum / count
    w = inv_i * s.angular_momentum
    p = contact_impulse(s.velocity + wp.cross(w, arm), n, arm, arm, shape.inv_mass, inv_i, wp.mat33d(), friction)
    s = body_impulse(s, shape, p, arm)
    s.position = s.position + push
    state[0] = s


@wp.kernel
def rigid_pair_contact(
    state_a: wp.array(dtype=RigidState),
    shape_a: RigidShape,
    samples_a: wp.array(dtype=wp.vec3),
    radius_a: wp.array(dtype=float),
    state_b: wp.array(dtype=RigidState),
    shape_b: RigidShape,
    samples_b: wp.array(dtype=wp.vec3),
    radius_b: wp.array(dtype=float),
    friction: wp.float64,
    damping_ratio: wp.float64,
    stiffness_rate: wp.float64,
    dt: wp.float64,
):
    """Two bodies: a's samples against b's shape, then b's against a's. Without a damping ratio (NaN) each pass gives
    one impulse, equal and opposite on the two bodies (contact_impulse), at the mean contact point of the
    penetrating samples along their mean normal, and removes the deepest penetration by moving the bodies apart in
    proportion to their inverse masses. With one, both passes of the penalty form (penalty_pass) read the states at
    the start, and each pass that finds a contact gives its impulses divided by the number of passes that found one
    (two spheres: each pass finds the same contact)."""
    if not wp.isnan(damping_ratio):
        sa = state_a[0]
        sb = state_b[0]
        ca, pa, laa, lba = penalty_pass(sa, shape_a, samples_a, radius_a, sb, shape_b, 0, wp.vec3d(),
                                        wp.float64(0.0), stiffness_rate, damping_ratio, friction, dt)  # fmt: skip
        cb, pb, lbb, lab = penalty_pass(sb, shape_b, samples_b, radius_b, sa, shape_a, 0, wp.vec3d(),
                                        wp.float64(0.0), stiffness_rate, damping_ratio, friction, dt)  # fmt: skip
        passes = wp.where(ca > 0, 1, 0) + wp.where(cb > 0, 1, 0)
        if passes == 0:
            return
        share = wp.float64(1.0) / wp.float64(passes)
        p = share * (pa - pb)  # the impulse on a
        sa.velocity = sa.velocity + shape_a.inv_mass * p
        sa.angular_momentum = sa.angular_momentum + share * (laa + lab)
        sb.velocity = sb.velocity - shape_b.inv_mass * p
        sb.angular_momentum = sb.angular_momentum + share * (lba + lbb)
        state_a[0] = sa
        state_b[0] = sb
        return
    for side in range(2):
        sa = state_a[0]
        sb = state_b[0]
        ha = shape_a
        hb = shape_b
        count = samples_a.shape[0]
        if side == 1:
            sa = state_b[0]
            sb = state_a[0]
            ha = shape_b
            hb = shape_a
            count = samples_b.shape[0]
        ra = wp.quat_to_matrix(sa.orientation)
        qb = sb.orientation
        rot_b = wp.quat(wp.float32(qb[0]), wp.float32(qb[1]), wp.float32(qb[2]), wp.float32(qb[3]))
        deepest = wp.float64(0.0)
        push = wp.vec3d(wp.float64(0.0))
        arm_sum = wp.vec3d(wp.float64(0.0))
        n_sum = wp.vec3d(wp.float64(0.0))
        hits = wp.float64(0.0)
        for k in range(count):
            pk = wp.vec3(0.0)
            rk = float(0.0)
            if side == 0:
                pk = samples_a[k]
                rk = radius_a[k]
            else:
                pk = samples_b[k]
                rk = radius_b[k]
            arm0 = ra * to_vec3d(pk)
            # relative to b's centre in float64 first: float32 then only carries the bodies' extent
            x = to_vec3(sa.position - sb.position + arm0)
            touch, sdf, n_local = shape_contact_point(hb, wp.quat_rotate_inv(rot_b, x), rk)
            if touch == 1:
                n = to_vec3d(wp.quat_rotate(rot_b, n_local))
                depth = wp.float64(rk - sdf)
                if depth > deepest:
                    deepest = depth
                    push = depth * n
                arm_sum = arm_sum + arm0 - wp.float64(rk) * n
                n_sum = n_sum + n
                hits = hits + wp.float64(1.0)
        if hits > wp.float64(0.0) and wp.length(n_sum) > wp.float64(0.0):
            n = wp.normalize(n_sum)
            arm_a = arm_sum / hits
            arm_b = sa.position + arm_a - sb.position
            inv_ia = world_inverse_inertia(sa.orientation, ha.inv_inertia)
            inv_ib = world_inverse_inertia(sb.orientation, hb.inv_inertia)
            inv_mass = ha.inv_mass + hb.inv_mass
            v_rel = (sa.velocity + wp.cross(inv_ia * sa.angular_momentum, arm_a)) - (
                sb.velocity + wp.cross(inv_ib * sb.angular_momentum, arm_b)
            )
            p = contact_impulse(v_rel, n, arm_a, arm_b, inv_mass, inv_ia, inv_ib, friction)
            sa = body_impulse(sa, ha, p, arm_a)
            sb = body_impulse(sb, hb, -p, arm_b)
            sa.position = sa.position + (ha.inv_mass / inv_mass) * push
            sb.position = sb.position - (hb.inv_mass / inv_mass) * push
        if side == 0:
            state_a[0] = sa
            state_b[0] = sb
        else:
            state_b[0] = sa
            state_a[0] = sb


# -- launches (pdsim/rigid.py) ----------------------------------------------------------------------------------------
# One thread per body (or pair): a body's arrays are one-element; its samples are looped over in the thread, so the
# impulses at its contact points are applied one after the other.


def drift(*, device, **arguments):
    """First half kick and drift of one body (rigid_drift)."""
    launch(rigid_drift, 1, device=device, **arguments)


def write_motion(*, device, **arguments):
    """The motion of one body's current state (rigid_motion)."""
    launch(rigid_motion, 1, device=device, **arguments)


def kick(*, device, **arguments):
    """Second half kick of one body with the particles' reaction (rigid_kick)."""
    launch(rigid_kick, 1, device=device, **arguments)


def plane_contact(*, device, **arguments):
    """One body against the ground plane (rigid_plane_contact)."""
    launch(rigid_plane_contact, 1, device=device, **arguments)


def mesh_contact(*, device, **arguments):
    """One body against a static mesh (rigid_mesh_contact)."""
    launch(rigid_mesh_contact, 1, device=device, **arguments)


def pair_contact(*, device, **arguments):
    """Two bodies against each other (rigid_pair_contact)."""
    launch(rigid_pair_contact, 1, device=device, **arguments)
