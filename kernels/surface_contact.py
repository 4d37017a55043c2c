"""Contact between triangle surfaces of mesh methods (FEM): vertices against the faces of another body or piece.

Each surface vertex (a sphere of radius ``skin``) looks for the nearest face of a surface mesh among the faces whose
bounds come within ``band`` of it (``wp.mesh_query_aabb``), skipping the faces of its own piece (same label: faces and
vertices of one connected piece of the current mesh, so a body's own surface and the two sides of a crack that has not
yet cut a piece free never touch). With the signed distance s of the vertex from that face (the side from the face's
outward normal, or, where the nearest point is on an edge or a corner, from the sum of the unit normals of that
piece's faces sharing it: one face's normal does not tell the side there) and the overlap d = skin - s, a vertex
with d > 0 and s > -band is pushed out by the contact law (kernels/colliders.py, penalty_force) and the face's three
vertices take the reaction in proportion to their barycentric weights, so each pair conserves momentum exactly.
Both orders (vertices of A on faces of B and of B on faces of A) are launched: face-to-face contact is then
symmetric. Edges crossing edges with no vertex inside a face are not detected.

A hard floor backs the penalty up (the penalty, tied to the step, gives way by about v dt / CONTACT_OMEGA_DT at an
approach speed v, and a piece pinched between others or the ground by more than its contact springs hold sinks in):
a vertex deeper than ``floor`` inside loses the approaching normal velocity of its pair (an inelastic impulse), the
vertex and the face's free vertices sharing it by their inverse masses (a face vertex j of barycentric weight w_j
changing by w_j / m_j, the face point's inverse mass sum_j w_j^2 / m_j), so the vertex sinks no deeper while the
penalty pushes it back out. The impulses are summed (equal and opposite: momentum conserved exactly) and applied by
``apply_floor`` after all pairs. Only velocities change: an impulse that removes approach cannot add energy, where
moving the vertex back to the floor's depth would strain its elements (a 200 m/s impact on a breakable FEM plate
gained energy that way, tools/stress.py).
"""

import warp as wp

from .colliders import contact_step_factor, face_point_mass, pair_damping_ratio, pair_friction, penalty_force
from .integration import PARTICLE_FREE
from .launch import launch
from .watchdog import WATCH_COLLIDERS


@wp.func
def triangle_closest_weights(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """Barycentric weights (w_a, w_b, w_c) of the point of triangle abc closest to p (Ericson, Real-Time Collision
    Detection, 5.1.5: Voronoi regions of the vertices, edges and face)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return wp.vec3(0.0, 1.0, 0.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return wp.vec3(1.0 - t, t, 0.0)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return wp.vec3(0.0, 0.0, 1.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return wp.vec3(1.0 - t, 0.0, t)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return wp.vec3(0.0, 1.0 - t, t)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return wp.vec3(1.0 - v - w, v, w)


@wp.kernel
def vertex_face_contact(
    v_points: wp.array(dtype=wp.int32),
    v_label: wp.array(dtype=wp.int32),
    v_rest: wp.array(dtype=wp.vec3),
    v_u: wp.array(dtype=wp.vec3),
    v_v: wp.array(dtype=wp.vec3),
    v_mass: wp.array(dtype=float),
    v_to_force: wp.array(dtype=float),
    mesh: wp.uint64,
    m_x: wp.array(dtype=wp.vec3),
    m_points: wp.array(dtype=wp.int32),
    m_faces: wp.array(dtype=wp.int32),
    m_label: wp.array(dtype=wp.int32),
    m_v: wp.array(dtype=wp.vec3),
    m_mass: wp.array(dtype=float),
    m_to_force: wp.array(dtype=float),
    skin: float,
    band: float,
    stiffness_rate: float,
    damping_ratio: float,
    friction: float,
    v_damping_ratio: wp.array(dtype=float),
    v_friction: wp.array(dtype=float),
    m_damping_ratio: wp.array(dtype=float),
    m_friction: wp.array(dtype=float),
    v_force: wp.array(dtype=wp.vec3),
    m_force: wp.array(dtype=wp.vec3),
    dt: float,
    v_work: wp.array(dtype=wp.float64),
    m_work: wp.array(dtype=wp.float64),
    work_slot: int,
    floor: float,
    v_kind: wp.array(dtype=wp.int32),
    m_kind: wp.array(dtype=wp.int32),
    v_kick: wp.array(dtype=wp.vec3),
    m_kick: wp.array(dtype=wp.vec3),
    v_step: wp.array(dtype=float),
    m_step: wp.array(dtype=float),
    step_safety: float,
):
    """Contact of surface vertex q (point v_points[q] of its solver, piece v_label[q]) with the nearest face of
    another piece (m_label[f] != v_label[q]) of the surface mesh ``mesh`` (current vertex positions m_x, triangles
    m_faces into them, solver points m_points); see the module docstring. Forces [N] are multiplied by v_to_force /
    m_to_force into each solver's force unit. The penalty k = stiffness_rate m_red (dt / max(dt, T))^2 (m_red the
    reduced mass of the vertex and the face point, colliders.face_point_mass; stiffness_rate = (CONTACT_OMEGA_DT /
    dt)^2; T = step_safety times the largest of v_step[i] and the face's m_step, each point's stable step for the
    elements around it: the pair oscillates at omega T = CONTACT_OMEGA_DT, as stiff as those elements bear); its
    damping ratio and friction combine the vertex's side (v_damping_ratio[i], v_friction[i], by solver point; NaN:
    none) with the face's (its first vertex's), as kernels/contact.py particle_mesh_contact. Work: the positive part
    of each side's work in the step, as kernels/contact.py particle_mesh_contact, into slot ``work_slot`` of v_work
    and m_work. Floor (module docstring): a vertex deeper than ``floor`` [m] adds its share of the velocity change
    [m/s] into v_kick (its face's vertices into m_kick); only free points (v_kind, m_kind: PARTICLE_FREE) change."""
    q = wp.tid()
    i = v_points[q]
    x = v_rest[i] + v_u[i]
    label = v_label[q]
    reach = wp.vec3(wp.max(band, skin))
    query = wp.mesh_query_aabb(mesh, x - reach, x + reach)
    f = int(0)
    best = int(-1)
    best_d2 = float(1.0e30)
    best_w = wp.vec3(0.0)
    while wp.mesh_query_aabb_next(query, f):
        if m_label[f] == label:
            continue
        a = m_x[m_faces[3 * f + 0]]
        b = m_x[m_faces[3 * f + 1]]
        c = m_x[m_faces[3 * f + 2]]
        w = triangle_closest_weights(x, a, b, c)
        d = x - (w[0] * a + w[1] * b + w[2] * c)
        d2 = wp.dot(d, d)
        if d2 < best_d2:
            best_d2 = d2
            best = f
            best_w = w
    if best < 0:
        return
    a = m_x[m_faces[3 * best + 0]]
    b = m_x[m_faces[3 * best + 1]]
    c = m_x[m_faces[3 * best + 2]]
    face_n = wp.cross(b - a, c - a)
    area2 = wp.length(face_n)
    if area2 == 0.0:
        return
    face_n = face_n / area2
    closest = best_w[0] * a + best_w[1] * b + best_w[2] * c
    d = x - closest
    dist = wp.sqrt(best_d2)
    side = face_n
    if wp.min(best_w) <= 0.0:
        # closest on an edge or a corner: the side from the summed unit normals of the faces of that piece sharing
        # the closest point (a pseudo-normal), not from one of them
        side = wp.vec3(0.0)
        tol = 1.0e-5 * wp.max(band, skin)
        again = wp.mesh_query_aabb(mesh, closest - wp.vec3(tol), closest + wp.vec3(tol))
        g = int(0)
        while wp.mesh_query_aabb_next(again, g):
            if m_label[g] != m_label[best]:
                continue
            ga = m_x[m_faces[3 * g + 0]]
            gb = m_x[m_faces[3 * g + 1]]
            gc = m_x[m_faces[3 * g + 2]]
            gw = triangle_closest_weights(closest, ga, gb, gc)
            if wp.length(closest - (gw[0] * ga + gw[1] * gb + gw[2] * gc)) <= tol:
                side += wp.normalize(wp.cross(gb - ga, gc - ga))
    sign = float(1.0)
    if wp.dot(d, side) < 0.0:
        sign = -1.0
    s = sign * dist
    if s >= skin or s <= -band:
        return
    n = face_n
    if dist > 1.0e-6 * wp.max(skin, band):
        n = (sign / dist) * d
    ia = m_points[m_faces[3 * best + 0]]
    ib = m_points[m_faces[3 * best + 1]]
    ic = m_points[m_faces[3 * best + 2]]
    v_surface = best_w[0] * m_v[ia] + best_w[1] * m_v[ib] + best_w[2] * m_v[ic]
    m_surface = face_point_mass(best_w[0], best_w[1], best_w[2], m_mass[ia], m_mass[ib], m_mass[ic])
    mv = v_mass[i]
    m_red = mv * m_surface / (mv + m_surface)
    zeta = pair_damping_ratio(v_damping_ratio[i], m_damping_ratio[ia], damping_ratio)
    mu = pair_friction(v_friction[i], m_friction[ia], friction)
    rate = stiffness_rate * contact_step_factor(
        dt, step_safety * wp.max(wp.max(v_step[i], m_step[ia]), wp.max(m_step[ib], m_step[ic]))
    )
    force = penalty_force(n, skin - s, v_v[i] - v_surface, rate * m_red, m_red, zeta, mu)
    wp.atomic_add(v_force, i, force * v_to_force[i])
    wp.atomic_sub(m_force, ia, force * (best_w[0] * m_to_force[ia]))
    wp.atomic_sub(m_force, ib, force * (best_w[1] * m_to_force[ib]))
    wp.atomic_sub(m_force, ic, force * (best_w[2] * m_to_force[ic]))
    wp.atomic_add(v_work, work_slot, wp.float64(wp.max(wp.dot(force, v_v[i]) * dt, 0.0)))
    wp.atomic_add(m_work, work_slot, wp.float64(wp.max(-wp.dot(force, v_surface) * dt, 0.0)))
    if s < -floor:
        inv_v = wp.where(v_kind[i] == PARTICLE_FREE, 1.0 / mv, 0.0)
        inv_a = wp.where(m_kind[ia] == PARTICLE_FREE, 1.0 / m_mass[ia], 0.0)
        inv_b = wp.where(m_kind[ib] == PARTICLE_FREE, 1.0 / m_mass[ib], 0.0)
        inv_c = wp.where(m_kind[ic] == PARTICLE_FREE, 1.0 / m_mass[ic], 0.0)
        inv_s = best_w[0] * best_w[0] * inv_a + best_w[1] * best_w[1] * inv_b + best_w[2] * best_w[2] * inv_c
        inv_sum = inv_v + inv_s
        vn = wp.dot(v_v[i] - v_surface, n)
        if inv_sum > 0.0 and vn < 0.0:
            impulse = (-vn / inv_sum) * n  # [kg m/s] on the vertex, its opposite on the face
            wp.atomic_add(v_kick, i, inv_v * impulse)
            wp.atomic_sub(m_kick, ia, (best_w[0] * inv_a) * impulse)
            wp.atomic_sub(m_kick, ib, (best_w[1] * inv_b) * impulse)
            wp.atomic_sub(m_kick, ic, (best_w[2] * inv_c) * impulse)


@wp.kernel
def surface_floor_apply(kick: wp.array(dtype=wp.vec3), velocities: wp.array(dtype=wp.vec3)):
    """The floor's velocity changes [m/s] of point i (vertex_face_contact) added to its velocity, then zeroed for the
    next step."""
    i = wp.tid()
    velocities[i] = velocities[i] + kick[i]
    kick[i] = wp.vec3(0.0)


# -- launches (pdsim/contact.py, MethodContact) -----------------------------------------------------------------------


def vertex_face_forces(*, dt: float, floor: float, device, **arguments):
    """Contact of the surface vertices ``v_points`` with the faces of another piece of a surface mesh
    (vertex_face_contact, step ``dt`` [s], hard floor ``floor`` [m] deep); the work goes to slot WATCH_COLLIDERS of
    ``v_work`` and ``m_work``."""
    launch(
        vertex_face_contact,
        arguments["v_points"].shape[0],
        device=device,
        dt=float(dt),
        floor=float(floor),
        work_slot=WATCH_COLLIDERS,
        **arguments,
    )


def apply_floor(*, device, **arguments):
    """The floor's accumulated corrections applied to a solver's points and zeroed (surface_floor_apply)."""
    launch(surface_floor_apply, arguments["kick"].shape[0], device=device, **arguments)
