"""Contact kernels: short-range repulsion between particles that share no bond.

**Particle-particle contact** (after LAMMPS ``pair_style peri/*`` short-range forces and the EMU theory manual). Two
particles k, j at current distance r = |y_k - y_j| repel when r < R_kj, the contact distance:

    R_kj = c_f (r_k + r_j)                                  (different bodies; r = collision radius h/2)
    R_kj = min(c_b |X_j - X_k|, c_f (r_k + r_j))            (same body; X = reference positions, c_b = 0.9)

so a pair that was a lattice neighbour (bonded, or a fragment whose bond broke) only repels once compressed below
c_b of its rest distance and a bonded pair at rest feels exactly nothing. The force density on k [N/m^3] is

    f_k = sum_j [ C_kj V_j (R_kj - r) - c^n_kj V_j v_n ]_+ n  +  friction,     n = (y_k - y_j) / r,
    C_kj = 2 C_k C_j / (C_k + C_j)  (contact modulus [N/m^6]),  v_n = (v_k - v_j) . n,

(float32 range: C reaches 4e22 N/m^6 for steel at h = 4 mm and 5e26 for glass at h = 0.5 mm, so C_kj is evaluated
as 2 / (1 / C_k + 1 / C_j) and only products C_kj V_j [N/m^4] are formed: the product C_k C_j would overflow to inf),

with the normal dashpot c^n_kj = 2 zeta sqrt(C_kj m_red / (V_k V_j)) (damping ratio zeta of the pair's relative
oscillation, m_red the reduced mass) clamped so the normal force never pulls (no adhesion), and regularised Coulomb
friction on the tangential relative velocity v_t: |f_t| = min(mu |f_n|, c^t_kj V_j |v_t|) opposing v_t, with the
critically damped c^t_kj (zeta = 1). zeta and mu are the pair's: each particle brings its material's (NaN: none) and
the pair combines them (colliders.py pair_damping_ratio, pair_friction), the scene's values standing in where neither
brings one. The particles' values act between separate surfaces only: particles of different bodies, and, when the
bonds are known (bodies that break), particles of one body across a crack (crack_pair_geometry's ``apart``); intact
neighbours of one body take the scene's values.
The pair energy is 1/2 C_kj V_k V_j (R_kj - r)^2 [J] (times the cap's scale below). Every term is symmetric in
(k, j), so the pair forces V_k f_kj and V_j f_jk are equal and opposite (momentum is conserved; the hard floor
below conserves it only approximately, as each particle averages over its own floor contacts).

**Stiffness cap.** Each particle's contact stiffness row sum sum_j C_kj V_j [N/m^4] (what contact adds to its
Silling-Askari sum, hence to the stable step) is capped at its budget B_k = n_b C_k (2 r_k)^3, the stiffness of n_b
contacts (n_b = 12 by default, so B_k = S_k, one interior bond row sum): every pair term is scaled by
s_kj = min(s_k, s_j), s_k = min(1, B_k / sum_j C_kj V_j), with s_k taken from the previous pass (one step of lag,
double-buffered so no thread reads a value another writes). The scale is symmetric, so momentum stays exact; it is 1
until a particle has more than the budget's worth of contacts, so ordinary contact (a few contacts per particle) is
unchanged, and the contact's stable step sqrt(2 rho_k / B_k) is a bound on the contact springs rather than an
assumption about how many there are.

**Dashpot cap.** An explicit dashpot is stable only while the damping rate it puts on a particle, summed over its
contacts, times the step stays below about 1: sum_j zeta_kj c_crit,kj V_k / m_k <= 1 / T_k, with T_k =
sqrt(2 rho_k / B_k) the contact's stable step (the solver's step is at most T_k). One pair at the default
calibration has T_k zeta c_crit V_k / m_k = 0.58 zeta, so a strong dashpot (zeta = 1.95 for a restitution of 0.05)
passes the bound from two contacts on, and the crack faces of a crushed brittle body, where the materials' values act,
have many. Each pair's dashpot is scaled by d_kj = min(d_k, d_j), d_k = min(1, 1 / (T_k sum_j zeta_kj c_crit,kj
V_k / m_k)) from the previous pass (the stiffness cap's lag and double buffer). d_kj = 1 for the scene's default
(zeta = 0.02) however many contacts, and for one pair with zeta up to 1.7.

A hard floor backs the penalty up: a pair closer than floor_factor R_kj (an impact faster than the penalty can stop
within a step or two) is projected back to that distance and its approaching normal velocity removed (inelastic),
each particle taking its inverse-mass share, averaged over its floor contacts (Jacobi). The projection is computed in
the same pass as the force and applied by a second, per-particle kernel, so every read of the force pass sees the same
positions.

The force kernel is a gather (one thread per particle, no atomics) over a ``wp.HashGrid`` built on current positions
with cells twice the query radius (the largest contact distance): a query then visits at most 8 cells instead of up
to 27 with cells equal to the query radius. Optionally only "exposed" particles (within two lattice shells of a surface
or crack) take part, through a grouped hash grid (see make_particle_contact_kernels).
"""

import warp as wp

from .colliders import (
    contact_step_factor,
    face_point_mass,
    mesh_contact_point,
    pair_damping_ratio,
    pair_friction,
    penalty_force,
)
from .integration import PARTICLE_FREE
from .launch import launch
from .neighbors import same_body_count
from .watchdog import WATCH_COLLIDERS


@wp.func
def contact_pair_distance(
    k: int,
    j: int,
    rest_positions: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    distance_factor: float,
    bonded_factor: float,
):
    """Contact distance R_kj [m] of a pair (see the module docstring)."""
    R = distance_factor * (radius[k] + radius[j])
    if body_id[k] == body_id[j]:
        R = wp.min(R, bonded_factor * wp.length(rest_positions[j] - rest_positions[k]))
    return R


@wp.func
def contact_pair_modulus(ck: float, cj: float):
    """Pair contact modulus C_kj = 2 C_k C_j / (C_k + C_j) [N/m^6], evaluated as 2 / (1 / C_k + 1 / C_j): exactly
    symmetric in k and j, and free of the float32 overflow of the product C_k C_j (C is 4e22 N/m^6 for steel at
    h = 4 mm, 5e26 for glass at h = 0.5 mm: the product would be inf)."""
    return 2.0 / (1.0 / ck + 1.0 / cj)


FACE_NORMAL_MIN = wp.constant(1.0)  # |n_k - n_j| up to one: the two notch faces do not face each other
BOND_NONE = wp.constant(0)  # the pair is not in the family (beyond the horizon)
BOND_LIVE = wp.constant(1)
BOND_DEAD = wp.constant(2)  # broken in the run
BOND_CUT = wp.constant(3)  # cut by a notch (dead from the start)
# A pair of one body with no bond between them (beyond each other's horizon) meets across a crack when either particle
# has lost at least this share of its family's bonds: a particle on a crack face loses about half of its family (the
# bonds across the face), a quarter or more marks a face or a fragment's edge, while the few scattered broken bonds
# of a body that flows or is compacted stay well below it.
CRACK_FACE_DAMAGE = wp.constant(0.25)


@wp.func
def bond_state_and_face_normal(
    k: int,
    j: int,
    rest_positions: wp.array(dtype=wp.vec3),
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_alive: wp.array(dtype=wp.uint8),
    bond_alive_initial: wp.array(dtype=wp.uint8),
):
    """(state of the bond k-j: BOND_NONE, BOND_LIVE, BOND_DEAD or BOND_CUT; the notch-face normal of k, a unit
    vector, zero when no bond of k was cut; k's damage, the share of its family's bonds not alive, in [0, 1]): one
    pass over k's family. The face normal is the direction of k's
    shortest bond a notch cut (``bond_alive_initial`` 0; the mean of the shortest ones when several tie): the bond
    that crosses the notch most squarely, so the normal does not tilt where the notch ends or a free surface cuts the
    family (the sum of all cut bonds tilts there, towards the side with more of them; faces sliding along a tilted
    normal would appear to close). It is fixed for the run: a normal that turned as bonds break would make the
    contact's potential jump."""
    state = BOND_NONE
    normal = wp.vec3(0.0)
    shortest = float(1.0e30)
    xk = rest_positions[k]
    first = family_offsets[k]
    last = family_offsets[k + 1]
    dead = int(0)
    for q in range(first, last):
        m = family_neighbors[q]
        if bond_alive[q] == wp.uint8(0):
            dead += 1
        if m == j:
            state = wp.where(bond_alive[q] == wp.uint8(0), BOND_DEAD, BOND_LIVE)
            if bond_alive_initial[q] == wp.uint8(0):
                state = BOND_CUT
        if bond_alive_initial[q] == wp.uint8(0):
            xi = rest_positions[m] - xk
            length = wp.length(xi)
            if length < shortest * (1.0 - 1.0e-4):
                shortest = length
                normal = xi / length
            elif length <= shortest * (1.0 + 1.0e-4):
                normal += xi / length
    if shortest < 1.0e30:
        normal = wp.normalize(normal)
    damage = float(0.0)
    if last > first:
        damage = float(dead) / float(last - first)
    return state, normal, damage


@wp.func
def crack_pair_geometry(
    k: int,
    j: int,
    d: wp.vec3,
    r2: float,
    rest_positions: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    distance_factor: float,
    bonded_factor: float,
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_alive: wp.array(dtype=wp.uint8),
    bond_alive_initial: wp.array(dtype=wp.uint8),
):
    """Contact geometry of a pair when the bonds are known (bodies that break): (active, R, r, n, apart) with the
    contact distance R [m], the current distance r [m] (active when r < R; overlap R - r), the unit direction n of the
    force on k, for d = y_k - y_j, and apart = 1 when the two particles meet as separate surfaces: of different bodies,
    or of one body across a crack (their bond broke in the run or a notch cut it, or, with no bond between them, either
    particle's damage is at least CRACK_FACE_DAMAGE), 0 otherwise (a live bond: intact neighbours). Particles of
    different bodies, of one body beyond each other's horizon, and pairs with a live bond: the distance rule of
    contact_pair_distance along the pair (overlap R_b - r; a live bond at rest is at its rest distance, beyond R_b, and
    one compressed below it keeps the contact it had, so the contact does not
    jump on when the bond breaks). A pair whose bond a notch cut (BOND_CUT, the particles' fixed normals n_k, n_j of
    bond_state_and_face_normal differing by more than one unit vector): the smaller of that overlap
    and the closing of the gap across the face, measured along nu = normalize(n_k - n_j) (reference frame):
    g = (y_j - y_k) . nu against R_g = bonded_factor (X_j - X_k) . nu, the force along -nu when that is the smaller.
    Faces that slide along each other (g unchanged, R_g - g < 0) feel nothing, however close a diagonal pair comes;
    faces that close repel. The overlap is the min of two continuous functions of the positions, so the force
    switches on from zero; nu is antisymmetric in (k, j), so the pair forces stay equal and opposite. Other pairs
    with a dead bond (cracks grown in the run, whose face normal is not fixed) use the distance rule: a normal that
    turns as bonds break makes the gap, hence the potential, jump (measured: a pre-cracked glass plate pulled apart
    gained 4 times the work put in with the normal taken from the bonds dead at each step)."""
    R = distance_factor * (radius[k] + radius[j])
    if r2 >= R * R or r2 == 0.0:
        return 0, R, float(0.0), wp.vec3(0.0), 0
    r = wp.sqrt(r2)
    n = d / r
    if body_id[k] != body_id[j]:
        return 1, R, r, n, 1
    xi = rest_positions[j] - rest_positions[k]
    Rb = wp.min(R, bonded_factor * wp.length(xi))
    if r >= Rb:  # beyond the distance rule's reach: no contact by either rule (the bond look-up is skipped)
        return 0, Rb, r, n, 0
    state_k, nk, damage_k = bond_state_and_face_normal(
        k, j, rest_positions, family_offsets, family_neighbors, bond_alive, bond_alive_initial
    )
    state_j, nj, damage_j = bond_state_and_face_normal(
        j, k, rest_positions, family_offsets, family_neighbors, bond_alive, bond_alive_initial
    )
    apart = 0
    # BOND_DEAD or BOND_CUT (the two largest states), or no bond and a damaged particle
    if state_k >= BOND_DEAD or (state_k == BOND_NONE and wp.max(damage_k, damage_j) >= CRACK_FACE_DAMAGE):
        apart = 1
    if state_k != BOND_CUT and state_j != BOND_CUT:  # not across a notch: the distance rule
        return wp.where(r < Rb, 1, 0), Rb, r, n, apart
    nu = nk - nj
    g0 = float(0.0)
    if wp.length(nu) > FACE_NORMAL_MIN:
        nu = wp.normalize(nu)
        g0 = wp.dot(xi, nu)
    if g0 <= 0.0:  # no pre-cut face between them: the distance rule
        return wp.where(r < Rb, 1, 0), Rb, r, n, apart
    g = -wp.dot(d, nu)
    Rg = bonded_factor * g0
    if Rg - g < Rb - r:  # the faces' closing is the smaller overlap
        return wp.where(g < Rg, 1, 0), Rg, g, -nu, apart
    return wp.where(r < Rb, 1, 0), Rb, r, n, apart


EXPOSED = wp.constant(1)  # hash-grid group of the particles that take part in contact


@wp.kernel
def count_lattice_neighbors(
    grid: wp.uint64,
    rest_positions: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    shield_factor: float,
    full_count: int,
    exposed: wp.array(dtype=wp.int32),
):
    """exposed[k] = 1 unless particle k has at least full_count particles of its own body within shield_factor
    2 r_k of its reference position (a simple-cubic lattice point with its two full shells: 32 within 2.05 h)."""
    k = wp.tid()
    count = same_body_count(grid, rest_positions, body_id, k, shield_factor * 2.0 * radius[k])
    exposed[k] = wp.where(count >= full_count, 0, EXPOSED)


@wp.kernel
def count_live_lattice_bonds(
    family_offsets: wp.array(dtype=wp.int32),
    family_neighbors: wp.array(dtype=wp.int32),
    bond_alive: wp.array(dtype=wp.uint8),
    rest_positions: wp.array(dtype=wp.vec3),
    radius: wp.array(dtype=float),
    shield_factor: float,
    full_count: int,
    exposed: wp.array(dtype=wp.int32),
):
    """Like count_lattice_neighbors, counting only live bonds: particle k is exposed (for good) once fewer than
    full_count of its bonds shorter than shield_factor 2 r_k are alive (a crack within two shells)."""
    k = wp.tid()
    xk = rest_positions[k]
    cut = shield_factor * 2.0 * radius[k]
    count = int(0)
    for q in range(family_offsets[k], family_offsets[k + 1]):
        if bond_alive[q] != wp.uint8(0):
            if wp.length(rest_positions[family_neighbors[q]] - xk) <= cut:
                count += 1
    if count < full_count:
        exposed[k] = EXPOSED


_contact_kernel_cache = {}


def make_particle_contact_kernels(shielded: bool, cracks: bool = False):
    """(force, energy_and_stiffness) kernels for particle contact, built once per variant. With ``shielded`` only
    exposed particles (group EXPOSED of a grouped hash grid, see count_lattice_neighbors) take part; interior
    particles, which no foreign particle can reach through two exposed layers, are skipped. With ``cracks`` the
    bonds are known (family_offsets, family_neighbors, bond_alive) and a pair of one body follows
    crack_pair_geometry (only faces that close across a dead bond repel); without, contact_pair_distance (the
    family arrays are not read). The energy kernel follows the same rule, so it is the potential of the forces."""
    key = (bool(shielded), bool(cracks))
    if key in _contact_kernel_cache:
        return _contact_kernel_cache[key]
    SHIELDED = key[0]
    CRACKS = key[1]

    @wp.kernel(module="unique")
    def particle_contact_force(
        grid: wp.uint64,
        positions: wp.array(dtype=wp.vec3),
        velocities: wp.array(dtype=wp.vec3),
        rest_positions: wp.array(dtype=wp.vec3),
        body_id: wp.array(dtype=wp.int32),
        radius: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        mass: wp.array(dtype=float),
        modulus: wp.array(dtype=float),
        kind: wp.array(dtype=wp.int32),
        exposed: wp.array(dtype=wp.int32),
        family_offsets: wp.array(dtype=wp.int32),
        family_neighbors: wp.array(dtype=wp.int32),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_alive_initial: wp.array(dtype=wp.uint8),
        query_radius: float,
        distance_factor: float,
        bonded_factor: float,
        damping_ratio: float,
        friction: float,
        point_damping_ratio: wp.array(dtype=float),
        point_friction: wp.array(dtype=float),
        floor_factor: float,
        budget_count: float,
        scale_in: wp.array(dtype=float),
        damp_in: wp.array(dtype=float),
        force_density: wp.array(dtype=wp.vec3),
        position_delta: wp.array(dtype=wp.vec3),
        velocity_delta: wp.array(dtype=wp.vec3),
        scale_out: wp.array(dtype=float),
        damp_out: wp.array(dtype=float),
    ):
        """Adds the contact force density [N/m^3] of every particle j within its contact distance to
        force_density[k], each pair's stiffness and dashpot scaled by min(scale_in[k], scale_in[j]); writes
        scale_out[k] = min(1, B_k / sum_j C_kj V_j) with B_k = budget_count C_k (2 r_k)^3 (the stiffness cap, see the
        module docstring; scale_in and scale_out must be different arrays). The same for the normal dashpots: each
        pair's dashpot is scaled by min(damp_in[k], damp_in[j]) and damp_out[k] = min(1, 1 / (T_k sum_j zeta_kj
        c_crit,kj V_k / m_k)) with T_k = sqrt(2 rho_k / B_k) the contact's stable step (the dashpot cap, see the
        module docstring).

        Hard floor: for pairs closer than floor_factor R_kj the kernel also writes particle k's share of a Jacobi
        (averaged) projection back to that distance into position_delta[k] [m], and of the removal of their
        approaching normal velocity into velocity_delta[k] [m/s], shared by inverse mass (non-free particles do not
        move); apply them with apply_contact_projection."""
        k = wp.tid()
        position_delta[k] = wp.vec3(0.0)
        velocity_delta[k] = wp.vec3(0.0)
        scale_out[k] = 1.0
        damp_out[k] = 1.0
        if wp.static(SHIELDED):
            if exposed[k] != EXPOSED:
                return
        yk = positions[k]
        vk = velocities[k]
        ck = modulus[k]
        sk = scale_in[k]
        dk = damp_in[k]
        row = float(0.0)  # unscaled sum_j C_kj V_j (the cap's measure)
        rate = float(0.0)  # sum_j zeta_kj c_crit,kj V_k / m_k [1/s]: the dashpots' rate on k (the dashpot cap's)
        vol_k = volume[k]
        mk = mass[k]
        free_k = kind[k] == PARTICLE_FREE
        f = wp.vec3(0.0)
        dx = wp.vec3(0.0)
        dv = wp.vec3(0.0)
        floor_count = int(0)
        q2 = query_radius * query_radius
        if wp.static(SHIELDED):
            query = wp.hash_grid_query(grid, yk, query_radius, EXPOSED)
        else:
            query = wp.hash_grid_query(grid, yk, query_radius)
        j = int(0)
        while wp.hash_grid_query_next(query, j):
            d = yk - positions[j]
            r2 = wp.dot(d, d)
            if r2 >= q2 or j == k:
                continue
            if wp.static(CRACKS):
                active, R, r, n, apart = crack_pair_geometry(
                    k, j, d, r2, rest_positions, body_id, radius, distance_factor, bonded_factor,
                    family_offsets, family_neighbors, bond_alive, bond_alive_initial,
                )  # fmt: skip
                if active == 0:
                    continue
            else:
                R = contact_pair_distance(k, j, rest_positions, body_id, radius, distance_factor, bonded_factor)
                if r2 >= R * R or r2 == 0.0:
                    continue
                r = wp.sqrt(r2)
                n = d / r
                apart = wp.where(body_id[k] != body_id[j], 1, 0)
            vol_j = volume[j]
            mj = mass[j]
            # float32 range: C alone reaches 1e27 N/m^6 at sub-mm spacings, so only products with V_j are formed
            cv = contact_pair_modulus(ck, modulus[j]) * vol_j  # C_kj V_j [N/m^4]
            row += cv
            cv *= wp.min(sk, scale_in[j])
            # critical dashpot c_crit V_j = 2 sqrt(C m_red / (V_k V_j)) V_j = 2 sqrt(C V_j m_red / V_k)
            cv_crit = 2.0 * wp.sqrt(cv * (mk * mj / (mk + mj)) / vol_k)
            vrel = vk - velocities[j]
            vn = wp.dot(vrel, n)
            # the materials' values act between separate surfaces: bodies, and the faces of a crack within one body;
            # between intact neighbours of one body the scene's law stands (a material's low restitution, a strong
            # dashpot, between compressed neighbours of a flowing body would tear it)
            zeta = damping_ratio
            mu = friction
            if apart != 0:
                zeta = pair_damping_ratio(point_damping_ratio[k], point_damping_ratio[j], damping_ratio)
                mu = pair_friction(point_friction[k], point_friction[j], friction)
            rate += zeta * cv_crit * vol_k / mk
            fn = wp.max(cv * (R - r) - (zeta * cv_crit * wp.min(dk, damp_in[j])) * vn, 0.0)
            f += fn * n
            if mu > 0.0:
                vt = vrel - vn * n
                vt_len = wp.length(vt)
                if vt_len > 0.0:
                    ft = wp.min(mu * fn, cv_crit * vt_len)
                    f -= (ft / vt_len) * vt
            r_floor = floor_factor * R
            if r < r_floor and free_k:
                floor_count += 1
                w = float(1.0)
                if kind[j] == PARTICLE_FREE:
                    w = mj / (mk + mj)
                dx += (w * (r_floor - r)) * n
                if vn < 0.0:
                    dv -= (w * vn) * n
        force_density[k] = force_density[k] + f
        budget = budget_count * ck * (8.0 * radius[k] * radius[k] * radius[k])
        if row > budget:
            scale_out[k] = budget / row
        step_bound = wp.sqrt(2.0 * mk / (vol_k * budget))  # the contact's stable step for particle k [s]
        if rate * step_bound > 1.0:
            damp_out[k] = 1.0 / (rate * step_bound)
        if floor_count > 0:
            s = 1.0 / float(floor_count)
            position_delta[k] = s * dx
            velocity_delta[k] = s * dv

    # Warp kernels cannot take a function argument, so this kernel repeats the pair loop of particle_contact_force
    # (same candidates, same contact distance): its energy is the potential of exactly those forces.
    @wp.kernel(module="unique")
    def particle_contact_energy_and_stiffness(
        grid: wp.uint64,
        positions: wp.array(dtype=wp.vec3),
        rest_positions: wp.array(dtype=wp.vec3),
        body_id: wp.array(dtype=wp.int32),
        radius: wp.array(dtype=float),
        volume: wp.array(dtype=float),
        modulus: wp.array(dtype=float),
        exposed: wp.array(dtype=wp.int32),
        family_offsets: wp.array(dtype=wp.int32),
        family_neighbors: wp.array(dtype=wp.int32),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_alive_initial: wp.array(dtype=wp.uint8),
        query_radius: float,
        distance_factor: float,
        bonded_factor: float,
        scale: wp.array(dtype=float),
        energy: wp.array(dtype=float),
        row_sum: wp.array(dtype=float),
        contact_count: wp.array(dtype=wp.int32),
    ):
        """Per particle: energy[k] = sum_j 1/4 s_kj C_kj V_k V_j (R_kj - r)^2 [J] (half of each pair's energy), the
        contact stiffness row sum row_sum[k] = sum_j s_kj C_kj V_j [N/m^4] (to add to the Silling-Askari bond sum)
        and the number of active contacts; s_kj = min(scale[k], scale[j]), the cap's scale the force pass uses."""
        k = wp.tid()
        energy[k] = 0.0
        row_sum[k] = 0.0
        contact_count[k] = 0
        if wp.static(SHIELDED):
            if exposed[k] != EXPOSED:
                return
        yk = positions[k]
        ck = modulus[k]
        sk = scale[k]
        vol_k = volume[k]
        e = float(0.0)
        s = float(0.0)
        count = int(0)
        q2 = query_radius * query_radius
        if wp.static(SHIELDED):
            query = wp.hash_grid_query(grid, yk, query_radius, EXPOSED)
        else:
            query = wp.hash_grid_query(grid, yk, query_radius)
        j = int(0)
        while wp.hash_grid_query_next(query, j):
            d = yk - positions[j]
            r2 = wp.dot(d, d)
            if r2 >= q2 or j == k:
                continue
            if wp.static(CRACKS):
                active, R, r, n, apart = crack_pair_geometry(
                    k, j, d, r2, rest_positions, body_id, radius, distance_factor, bonded_factor,
                    family_offsets, family_neighbors, bond_alive, bond_alive_initial,
                )  # fmt: skip
                if active == 0:
                    continue
                gap = R - r
            else:
                R = contact_pair_distance(k, j, rest_positions, body_id, radius, distance_factor, bonded_factor)
                if r2 >= R * R:
                    continue
                gap = R - wp.sqrt(r2)
            cv = contact_pair_modulus(ck, modulus[j]) * volume[j] * wp.min(sk, scale[j])
            e += 0.25 * cv * vol_k * gap * gap
            s += cv
            count += 1
        energy[k] = e
        row_sum[k] = s
        contact_count[k] = count

    kernels = (particle_contact_force, particle_contact_energy_and_stiffness)
    _contact_kernel_cache[key] = kernels
    return kernels


@wp.kernel
def apply_contact_projection(
    displacements: wp.array(dtype=wp.vec3),
    velocities: wp.array(dtype=wp.vec3),
    position_delta: wp.array(dtype=wp.vec3),
    velocity_delta: wp.array(dtype=wp.vec3),
):
    """u += position_delta, v += velocity_delta (the hard-floor projection of particle_contact_force)."""
    i = wp.tid()
    displacements[i] = displacements[i] + position_delta[i]
    velocities[i] = velocities[i] + velocity_delta[i]


@wp.kernel
def particle_mesh_contact(
    p_points: wp.array(dtype=wp.int32),
    p_rest: wp.array(dtype=wp.vec3),
    p_u: wp.array(dtype=wp.vec3),
    p_v: wp.array(dtype=wp.vec3),
    p_mass: wp.array(dtype=float),
    p_to_force: wp.array(dtype=float),
    p_radius: wp.array(dtype=float),
    mesh: wp.uint64,
    m_points: wp.array(dtype=wp.int32),
    m_faces: wp.array(dtype=wp.int32),
    m_v: wp.array(dtype=wp.vec3),
    m_mass: wp.array(dtype=float),
    stiffness_rate: float,
    damping_ratio: float,
    friction: float,
    p_damping_ratio: wp.array(dtype=float),
    p_friction: wp.array(dtype=float),
    m_damping_ratio: wp.array(dtype=float),
    m_friction: wp.array(dtype=float),
    p_force: wp.array(dtype=wp.vec3),
    m_force: wp.array(dtype=wp.vec3),
    dt: float,
    p_work: wp.array(dtype=wp.float64),
    m_work: wp.array(dtype=wp.float64),
    work_slot: int,
    m_step: wp.array(dtype=float),
    step_safety: float,
):
    """Contact between the particles of one method and the closed surface mesh of another (cross-method contact).

    A particle (sphere of radius r at rest + u) closer to the surface than r, or inside it by less than 2 r, is
    pushed out along the outward normal n by the contact law penalty_force (d = r - signed distance, the velocity of
    the particle relative to the surface point, the barycentric velocity of the face); the face's three vertices take
    -F in proportion to their barycentric weights, so the pair's momentum is conserved exactly. The penalty
    k = stiffness_rate m_red uses the pair's reduced mass m_red, with stiffness_rate = (omega dt / dt)^2
    (pdsim/contact.py CONTACT_OMEGA_DT = 0.15): even tens of simultaneous contacts on one point stay inside velocity
    Verlet's stability limit (omega dt < 2). It is sized on the mesh's elements where they take a longer step
    than the run: times (dt / max(dt, T))^2, T = ``step_safety`` times the largest ``m_step`` of the face's vertices
    (each vertex's stable step for the elements around it: SolverFem.contact_steps).
    ``p_to_force`` and the mesh's forces: multiply a force [N] into each solver's force unit (1 / V for a force
    density, 1 for nodal forces); ``m_points`` maps the mesh's vertices to its solver's points. The pair's damping
    ratio and friction combine the particle's side (p_damping_ratio[i], p_friction[i], by solver point; NaN: none)
    with the face's (its first vertex's m_damping_ratio, m_friction), ``damping_ratio`` and ``friction`` standing in
    where neither side brings one (pair_damping_ratio, pair_friction).

    Work: the positive part of the step's work of the contact force on each side, max(F . v_particle dt, 0) and
    max(-F . v_surface dt, 0) [J] at the step's velocities, is added to ``p_work[work_slot]`` and
    ``m_work[work_slot]``, each solver's watchdog's account of the work put in: the energy one body hands the other
    through contact is work put into the receiving body (the positive parts bound it from above; the signed sum of
    both sides, -F v_n dt, is what the penalty spring stores and the dashpot dissipates)."""
    q = wp.tid()
    i = p_points[q]
    x = p_rest[i] + p_u[i]
    r = p_radius[q]
    touch, sdf, n, face, wa, wb = mesh_contact_point(mesh, x, r, 3.0 * r)
    if touch == 0:
        return
    a = m_points[m_faces[3 * face + 0]]
    b = m_points[m_faces[3 * face + 1]]
    c = m_points[m_faces[3 * face + 2]]
    wc = 1.0 - wa - wb
    v_surface = wa * m_v[a] + wb * m_v[b] + wc * m_v[c]
    m_surface = face_point_mass(wa, wb, wc, m_mass[a], m_mass[b], m_mass[c])
    mp = p_mass[i]
    m_red = mp * m_surface / (mp + m_surface)
    zeta = pair_damping_ratio(p_damping_ratio[i], m_damping_ratio[a], damping_ratio)
    mu = pair_friction(p_friction[i], m_friction[a], friction)
    rate = stiffness_rate * contact_step_factor(dt, step_safety * wp.max(m_step[a], wp.max(m_step[b], m_step[c])))
    force = penalty_force(n, r - sdf, p_v[i] - v_surface, rate * m_red, m_red, zeta, mu)
    wp.atomic_add(p_force, i, force * p_to_force[i])
    wp.atomic_sub(m_force, a, force * wa)
    wp.atomic_sub(m_force, b, force * wb)
    wp.atomic_sub(m_force, c, force * wc)
    wp.atomic_add(p_work, work_slot, wp.float64(wp.max(wp.dot(force, p_v[i]) * dt, 0.0)))
    wp.atomic_add(m_work, work_slot, wp.float64(wp.max(-wp.dot(force, v_surface) * dt, 0.0)))


@wp.kernel
def gather_positions(
    points: wp.array(dtype=wp.int32),
    rest: wp.array(dtype=wp.vec3),
    displacements: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=wp.vec3),
):
    """out[q] = rest + u of point points[q] (a surface mesh's current vertices)."""
    q = wp.tid()
    i = points[q]
    out[q] = rest[i] + displacements[i]


# -- launches (pdsim/contact.py) --------------------------------------------------------------------------------------
# Particle contact: one thread per particle of the contact set (``rest_positions`` [n]). Each launch function takes
# the kernel's arguments as keywords named like its parameters (kernels/launch.py).


def mark_exposed_at_rest(*, device, **arguments):
    """Exposure of every particle at rest (count_lattice_neighbors), ``grid`` built on ``rest_positions``."""
    launch(count_lattice_neighbors, arguments["rest_positions"].shape[0], device=device, **arguments)


def mark_exposed_by_cracks(*, device, **arguments):
    """Exposes the particles near broken bonds (count_live_lattice_bonds)."""
    launch(count_live_lattice_bonds, arguments["rest_positions"].shape[0], device=device, **arguments)


def particle_contact_forces(shielded: bool, cracks: bool = False, *, device, **arguments):
    """Contact force density, hard-floor shares and the next stiffness-cap scale (particle_contact_force of
    make_particle_contact_kernels(shielded, cracks))."""
    force_kernel, _ = make_particle_contact_kernels(shielded, cracks)
    launch(force_kernel, arguments["rest_positions"].shape[0], device=device, **arguments)


def particle_contact_energies(shielded: bool, cracks: bool = False, *, device, **arguments):
    """Per-particle contact energy, stiffness row sum and contact count (particle_contact_energy_and_stiffness of
    make_particle_contact_kernels(shielded, cracks))."""
    _, energy_kernel = make_particle_contact_kernels(shielded, cracks)
    launch(energy_kernel, arguments["rest_positions"].shape[0], device=device, **arguments)


def hard_floor(displacements, velocities, position_delta, velocity_delta, device):
    """u += position_delta, v += velocity_delta on every particle of the contact set (apply_contact_projection)."""
    wp.launch(
        apply_contact_projection,
        dim=position_delta.shape[0],
        inputs=[displacements, velocities, position_delta, velocity_delta],
        device=device,
    )


# -- launches (pdsim/contact.py, MethodContact) -----------------------------------------------------------------------


def surface_positions(points, rest, displacements, out):
    """out[q] = rest + u of point points[q], on the points' device (gather_positions)."""
    wp.launch(gather_positions, dim=points.shape[0], inputs=[points, rest, displacements, out], device=points.device)


def particle_mesh_forces(*, dt: float, device, **arguments):
    """Contact of the particles ``p_points`` with a surface mesh (particle_mesh_contact, step ``dt`` [s]); the work
    goes to slot WATCH_COLLIDERS of ``p_work`` and ``m_work``."""
    launch(
        particle_mesh_contact,
        arguments["p_points"].shape[0],
        device=device,
        dt=float(dt),
        work_slot=WATCH_COLLIDERS,
        **arguments,
    )
