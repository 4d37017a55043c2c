"""Contact between triangle surfaces of mesh methods (FEM): vertices against the faces of another body or piece.

Each surface vertex (a sphere of radius ``skin``) looks for the nearest face of a surface mesh among the faces whose
bounds come within ``band`` of it (``wp.mesh_query_aabb``), skipping the faces of its own piece (same label: faces and
vertices of one connected piece of the current mesh, so a body's own surface and the two sides of a crack that has not
yet cut a piece free never touch). With the signed distance s of the vertex from that face (the side from the face's
outward normal, or, where the nearest point is on an edge or a corner, from the angle-weighted pseudo-normal of that
piece's faces sharing it: one face's normal does not tell the side there; face_side) and the overlap d = skin - s, a
vertex with d > 0 and s > -band is pushed out by the contact law (kernels/colliders.py, penalty_force) and the face's
three vertices take the reaction in proportion to their barycentric weights, so each pair conserves momentum exactly.
Both orders (vertices of A on faces of B and of B on faces of A) are launched: face-to-face contact is then
symmetric. Edges crossing edges with no vertex inside a face are not detected.

A hard floor backs the penalty up (the penalty, tied to the step, gives way by about v dt / CONTACT_OMEGA_DT at an
approach speed v, and a piece pressed by a heavier one or pinched against the ground sinks in until the penalty balances
the press, about 44 a dt^2 deep under an acceleration a): the force pass records each vertex deeper than ``floor``
inside with its face, barycentric weights and normal (vertex_face_contact), and after the step's second half kick, when
the velocities and the accelerations the next drift will use are known, the pair loses the approach that drift would
carry (surface_floor_impulse): the normal relative velocity v_n + a_n dt / 2 of the next step's drift is brought to zero
by an inelastic impulse along the normal, the vertex and the face's free vertices sharing it by their inverse masses (a
face vertex j of barycentric weight w_j changing by w_j / m_j, the face point's inverse mass sum_j w_j^2 / m_j), so a
steady press cannot drive the vertex deeper than about one step's travel past the floor while the penalty pushes it back
out. Pairs that share points (a face-to-face contact is met from both sides) would add up their corrections and throw
the surfaces apart (a single pass of full impulses, each at most reversing its pair's normal velocity, gained 26 % of
the energy of a head-on collision of two FEM cubes): each pass shares a pair's impulse by the largest share of floor
pairs any of its points takes (surface_floor_count: 1 per pair as the vertex, w_j as a face's vertex j), and
pdsim.surface_contact.SURFACE_FLOOR_ITERATIONS passes converge on the correction of all pairs together. The impulses of
a pass are summed (equal and opposite: momentum conserved exactly) and applied by ``apply_floor``. Only velocities
change: moving the vertex back to the floor's depth would strain its elements (a 200 m/s impact on a breakable FEM plate
gained energy that way, tools/stress.py). The impulse removes the approach of the next drift, which can be more than the
approach at the step's end, so that it adds no energy is measured, not given by construction: tests/test_fem_contact.py
(a head-on collision ends with less energy than it began, at the automatic step and a quarter of it) and
tools/stress.py's FEM projectile cases (docs/fem_fracture.md).

A vertex inside one piece that lies nearer to a face of a third piece it is outside of (where three pieces meet) finds
no pair. Trying the nearest face of the next piece there found those vertices (tools/fem_piece_contact.py --classify),
but in a soft block (E = 10 MPa) shattered on the ground at 200 m/s (tools/stress.py map_impact) the pairs it added
collapsed elements (the watchdog stopped the run, which finishes with the nearest face alone), so it is not done.
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


NEAR_REACH = wp.constant(0.25)  # nearest_foreign_face looks within this fraction of its reach first


@wp.func
def foreign_face_within(
    mesh: wp.uint64,
    x: wp.vec3,
    reach: float,
    m_x: wp.array(dtype=wp.vec3),
    m_faces: wp.array(dtype=wp.int32),
    m_label: wp.array(dtype=wp.int32),
    label: int,
):
    """The face of ``mesh`` nearest to x among those whose bounds come within ``reach`` [m] of it (one box query)
    and whose piece label is not ``label``: (face, -1 for none; barycentric weights of its closest point; distance
    [m])."""
    query = wp.mesh_query_aabb(mesh, x - wp.vec3(reach), x + wp.vec3(reach))
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
    return best, best_w, wp.sqrt(best_d2)


@wp.func
def nearest_foreign_face(
    mesh: wp.uint64,
    x: wp.vec3,
    reach: float,
    m_x: wp.array(dtype=wp.vec3),
    m_faces: wp.array(dtype=wp.int32),
    m_label: wp.array(dtype=wp.int32),
    label: int,
):
    """The face of ``mesh`` nearest to x among those whose bounds come within ``reach`` [m] of it and whose piece
    label is not ``label``: (face, -1 for none; barycentric weights of its closest point; distance [m]). It looks
    within NEAR_REACH x reach first, and within the whole reach only where that finds no face as near as that: a face
    whose bounds miss the smaller box lies farther than its half-width, so a face found within it is the nearest of
    all, and the same face (the box's faces are visited in the tree's order either way). Most vertices near another
    piece touch it; the smaller box holds about 1/64 of the faces (a shattered body's surface vertices each met some
    hundreds of faces in the whole reach)."""
    near = NEAR_REACH * reach
    best, best_w, dist = foreign_face_within(mesh, x, near, m_x, m_faces, m_label, label)
    if best < 0 or dist > near:
        best, best_w, dist = foreign_face_within(mesh, x, reach, m_x, m_faces, m_label, label)
    return best, best_w, dist


@wp.func
def corner_angle(p: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3):
    """The interior angle of triangle abc at its corner nearest to p [rad]."""
    da = wp.length(p - a)
    db = wp.length(p - b)
    dc = wp.length(p - c)
    u = b - a
    v = c - a
    if db < da and db <= dc:
        u = a - b
        v = c - b
    elif dc < da and dc < db:
        u = a - c
        v = b - c
    return wp.acos(wp.clamp(wp.dot(wp.normalize(u), wp.normalize(v)), -1.0, 1.0))


@wp.func
def face_side(
    mesh: wp.uint64,
    m_x: wp.array(dtype=wp.vec3),
    m_faces: wp.array(dtype=wp.int32),
    m_label: wp.array(dtype=wp.int32),
    best: int,
    best_w: wp.vec3,
    x: wp.vec3,
    reach: float,
):
    """(unit normal of face ``best``, the side of x: +1 outside its piece, -1 inside), the side from the face's
    normal, or where the closest point (weights best_w) is on an edge or a corner, from the pseudo-normal of the faces
    of that piece sharing it (one face's normal does not tell the side there): on an edge the sum of its faces' unit
    normals, on a corner the sum weighted by each face's angle at the corner. The angle weights make the side exact
    on a closed surface (Baerentzen and Aanaes, IEEE TVCG 11(3), 2005); an unweighted sum at a corner whose faces
    fan unevenly (a crack's staircase of element faces) can point away from the piece and take a vertex outside it
    for one a whole band deep inside. (0, 0) for a degenerate face."""
    a = m_x[m_faces[3 * best + 0]]
    b = m_x[m_faces[3 * best + 1]]
    c = m_x[m_faces[3 * best + 2]]
    face_n = wp.cross(b - a, c - a)
    area2 = wp.length(face_n)
    if area2 == 0.0:
        return wp.vec3(0.0), 0.0
    face_n = face_n / area2
    closest = best_w[0] * a + best_w[1] * b + best_w[2] * c
    side = face_n
    if wp.min(best_w) <= 0.0:
        side = wp.vec3(0.0)
        on_corner = int(best_w[0] > 0.0) + int(best_w[1] > 0.0) + int(best_w[2] > 0.0) == 1
        tol = 1.0e-5 * reach
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
                weight = float(1.0)
                if on_corner:
                    weight = corner_angle(closest, ga, gb, gc)
                side += weight * wp.normalize(wp.cross(gb - ga, gc - ga))
    sign = float(1.0)
    if wp.dot(x - closest, side) < 0.0:
        sign = -1.0
    return face_n, sign


@wp.kernel
def piece_bounds(
    m_x: wp.array(dtype=wp.vec3),
    m_label: wp.array(dtype=wp.int32),
    piece_lo: wp.array(dtype=wp.vec3),
    piece_hi: wp.array(dtype=wp.vec3),
):
    """Bounds of each piece of a surface mesh: the component-wise min and max [m] of its vertices' positions m_x
    (piece m_label[i] of vertex i, 0..count-1) into piece_lo and piece_hi, which start at +-inf (min and max do not
    depend on the order of the additions: the same bounds on the CPU and the GPU)."""
    i = wp.tid()
    p = m_label[i]
    wp.atomic_min(piece_lo, p, m_x[i])
    wp.atomic_max(piece_hi, p, m_x[i])


@wp.func
def near_foreign_piece(
    x: wp.vec3,
    reach: float,
    label: int,
    piece_lo: wp.array(dtype=wp.vec3),
    piece_hi: wp.array(dtype=wp.vec3),
    piece_count: int,
):
    """Whether the box of half-width ``reach`` around x overlaps the bounds of a piece other than ``label`` (always,
    with ``piece_count`` 0: no bounds given). Where it overlaps none, no face of another piece has bounds within
    reach of x, so nearest_foreign_face finds nothing there."""
    if piece_count == 0:
        return True
    for p in range(piece_count):
        if p != label:
            lo = piece_lo[p]
            hi = piece_hi[p]
            if x[0] + reach >= lo[0] and x[0] - reach <= hi[0]:
                if x[1] + reach >= lo[1] and x[1] - reach <= hi[1]:
                    if x[2] + reach >= lo[2] and x[2] - reach <= hi[2]:
                        return True
    return False


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
    pair_face: wp.array(dtype=wp.int32),
    pair_weights: wp.array(dtype=wp.vec3),
    pair_normal: wp.array(dtype=wp.vec3),
    v_step: wp.array(dtype=float),
    m_step: wp.array(dtype=float),
    step_safety: float,
    piece_lo: wp.array(dtype=wp.vec3),
    piece_hi: wp.array(dtype=wp.vec3),
    piece_count: int,
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
    and m_work. Floor (module docstring): a vertex deeper than ``floor`` [m] records its face (pair_face[q], -1 for
    none), the barycentric weights of its closest point and the contact normal for surface_floor_impulse. With
    ``piece_count`` > 0, the bounds of the mesh's pieces (piece_bounds; labels 0..piece_count-1) skip the search of a
    vertex near no other piece (near_foreign_piece: the same result without the mesh query)."""
    q = wp.tid()
    pair_face[q] = -1
    i = v_points[q]
    x = v_rest[i] + v_u[i]
    label = v_label[q]
    reach = wp.max(band, skin)
    if not near_foreign_piece(x, reach, label, piece_lo, piece_hi, piece_count):
        return
    best, best_w, dist = nearest_foreign_face(mesh, x, reach, m_x, m_faces, m_label, label)
    if best < 0:
        return
    face_n, sign = face_side(mesh, m_x, m_faces, m_label, best, best_w, x, reach)
    if sign == 0.0 or sign * dist >= skin or sign * dist <= -band:
        return
    a = m_x[m_faces[3 * best + 0]]
    b = m_x[m_faces[3 * best + 1]]
    c = m_x[m_faces[3 * best + 2]]
    closest = best_w[0] * a + best_w[1] * b + best_w[2] * c
    d = x - closest
    s = sign * dist
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
        pair_face[q] = best
        pair_weights[q] = best_w
        pair_normal[q] = n


@wp.kernel
def surface_floor_count(
    pair_face: wp.array(dtype=wp.int32),
    pair_weights: wp.array(dtype=wp.vec3),
    v_points: wp.array(dtype=wp.int32),
    m_points: wp.array(dtype=wp.int32),
    m_faces: wp.array(dtype=wp.int32),
    v_count: wp.array(dtype=float),
    m_count: wp.array(dtype=float),
):
    """Each point's share of the floor pairs (vertex_face_contact): 1 per pair it is the vertex of, w_j per pair whose
    face's vertex j it is (its barycentric weight); surface_floor_impulse shares a pair's impulse by the largest
    share among the pair's points."""
    q = wp.tid()
    f = pair_face[q]
    if f < 0:
        return
    w = pair_weights[q]
    wp.atomic_add(v_count, v_points[q], 1.0)
    for k in range(3):
        wp.atomic_add(m_count, m_points[m_faces[3 * f + k]], w[k])


@wp.kernel
def surface_floor_impulse(
    pair_face: wp.array(dtype=wp.int32),
    pair_weights: wp.array(dtype=wp.vec3),
    pair_normal: wp.array(dtype=wp.vec3),
    v_points: wp.array(dtype=wp.int32),
    v_v: wp.array(dtype=wp.vec3),
    v_a: wp.array(dtype=wp.vec3),
    v_mass: wp.array(dtype=float),
    v_kind: wp.array(dtype=wp.int32),
    m_points: wp.array(dtype=wp.int32),
    m_faces: wp.array(dtype=wp.int32),
    m_v: wp.array(dtype=wp.vec3),
    m_a: wp.array(dtype=wp.vec3),
    m_mass: wp.array(dtype=float),
    m_kind: wp.array(dtype=wp.int32),
    dt: float,
    v_count: wp.array(dtype=float),
    m_count: wp.array(dtype=float),
    v_kick: wp.array(dtype=wp.vec3),
    m_kick: wp.array(dtype=wp.vec3),
):
    """The floor of surface vertex q recorded by vertex_face_contact (pair_face[q] >= 0), after the step's second
    half kick (velocities v at the step's end [m/s], accelerations a [m/s^2] the next step's first half kick adds
    before its drift): the pair's normal relative velocity at the next drift, v_n + a_n dt / 2 along the contact
    normal (positive: separating), where negative, is brought to zero by an impulse J along the normal (module
    docstring) divided by the largest share of floor pairs among the pair's points (v_count, m_count:
    surface_floor_count; at least 1); J / m goes into v_kick for the vertex and -w_j J / m_j into
    m_kick for face vertex j. Only free points (v_kind, m_kind: PARTICLE_FREE) change."""
    q = wp.tid()
    f = pair_face[q]
    if f < 0:
        return
    i = v_points[q]
    ia = m_points[m_faces[3 * f + 0]]
    ib = m_points[m_faces[3 * f + 1]]
    ic = m_points[m_faces[3 * f + 2]]
    w = pair_weights[q]
    n = pair_normal[q]
    inv_v = wp.where(v_kind[i] == PARTICLE_FREE, 1.0 / v_mass[i], 0.0)
    inv_a = wp.where(m_kind[ia] == PARTICLE_FREE, 1.0 / m_mass[ia], 0.0)
    inv_b = wp.where(m_kind[ib] == PARTICLE_FREE, 1.0 / m_mass[ib], 0.0)
    inv_c = wp.where(m_kind[ic] == PARTICLE_FREE, 1.0 / m_mass[ic], 0.0)
    inv_sum = inv_v + w[0] * w[0] * inv_a + w[1] * w[1] * inv_b + w[2] * w[2] * inv_c
    if inv_sum <= 0.0:
        return
    v_rel = v_v[i] - (w[0] * m_v[ia] + w[1] * m_v[ib] + w[2] * m_v[ic])
    a_rel = v_a[i] - (w[0] * m_a[ia] + w[1] * m_a[ib] + w[2] * m_a[ic])
    vn_drift = wp.dot(v_rel, n) + 0.5 * dt * wp.dot(a_rel, n)
    if vn_drift >= 0.0:
        return
    shared = v_count[i]
    if w[0] > 0.0:
        shared = wp.max(shared, m_count[ia])
    if w[1] > 0.0:
        shared = wp.max(shared, m_count[ib])
    if w[2] > 0.0:
        shared = wp.max(shared, m_count[ic])
    j = -vn_drift / (inv_sum * wp.max(shared, 1.0))  # [kg m/s]
    impulse = j * n  # on the vertex, its opposite on the face
    wp.atomic_add(v_kick, i, inv_v * impulse)
    wp.atomic_sub(m_kick, ia, (w[0] * inv_a) * impulse)
    wp.atomic_sub(m_kick, ib, (w[1] * inv_b) * impulse)
    wp.atomic_sub(m_kick, ic, (w[2] * inv_c) * impulse)


@wp.kernel
def surface_floor_apply(kick: wp.array(dtype=wp.vec3), velocities: wp.array(dtype=wp.vec3)):
    """The floor's velocity changes [m/s] of point i (surface_floor_impulse) added to its velocity, then zeroed."""
    i = wp.tid()
    velocities[i] = velocities[i] + kick[i]
    kick[i] = wp.vec3(0.0)


# -- launches (pdsim/contact.py, MethodContact) -----------------------------------------------------------------------


def vertex_face_forces(*, dt: float, floor: float, device, **arguments):
    """Contact of the surface vertices ``v_points`` with the faces of another piece of a surface mesh
    (vertex_face_contact, step ``dt`` [s], hard floor ``floor`` [m] deep: the pairs deeper go to ``pair_face``,
    ``pair_weights``, ``pair_normal``); the work goes to slot WATCH_COLLIDERS of ``v_work`` and ``m_work``."""
    launch(
        vertex_face_contact,
        arguments["v_points"].shape[0],
        device=device,
        dt=float(dt),
        floor=float(floor),
        work_slot=WATCH_COLLIDERS,
        **arguments,
    )


def bounds_of_pieces(*, device, **arguments):
    """Each piece's bounds into ``piece_lo`` and ``piece_hi`` (reset to +-inf first; piece_bounds)."""
    arguments["piece_lo"].fill_(wp.vec3(float("inf")))
    arguments["piece_hi"].fill_(wp.vec3(float("-inf")))
    launch(piece_bounds, arguments["m_x"].shape[0], device=device, **arguments)


def floor_counts(*, device, **arguments):
    """Each point's number of floor pairs (surface_floor_count), summed into ``v_count`` and ``m_count``."""
    launch(surface_floor_count, arguments["pair_face"].shape[0], device=device, **arguments)


def floor_impulses(*, dt: float, device, **arguments):
    """The floor's velocity changes of the pairs recorded by vertex_face_forces, after the step's second half kick
    (surface_floor_impulse, step ``dt`` [s]), summed into ``v_kick`` and ``m_kick``."""
    launch(surface_floor_impulse, arguments["pair_face"].shape[0], device=device, dt=float(dt), **arguments)


def apply_floor(*, device, **arguments):
    """The floor's accumulated corrections applied to a solver's points and zeroed (surface_floor_apply)."""
    launch(surface_floor_apply, arguments["kick"].shape[0], device=device, **arguments)
