"""Kernels of the position-based particle lattice (dell'Erba 2018).

The state is the displacement u = x - X of every particle (rest position X), double-buffered: a step reads
``u_cur`` (the configuration C_{t-1}, with the leaders already moved to step t: the paper's "intermediate lattice") and
writes ``u_next`` (C_t). A follower therefore only sees what its neighbours did up to the previous step, and a
disturbance travels one neighbour shell per step.

Links are stored per particle as a CSR row (``row_offsets``, ``link_neighbor``) plus a per-link index into the body's
small offset table (``link_offset``): the rest offset dX = X_k - X_j [m], its length and its static weight (the weight
of its shell). Offsets are ordered in +-pairs, so at rest the rule's sums cancel exactly and a lattice at rest stays
exactly at rest in float32.

One lattice step (kernels launched in this order, per body):

1. ``lattice_move_leaders`` (over the leaders): leaders take the displacement of their scripted path at step t
   (piecewise linear in the step number), written to both buffers.
2. the follow kernel from :func:`make_follow_kernel`: every follower j gathers its neighbours' positions relative to
   X_j, p_k = u_k + dX_jk for an intact link and p_k = u_j + s dX_jk (a fictitious point at s times the rest offset)
   for a broken one, forms the weighted centroid c = sum_k w_k p_k / sum_k w_k with w_k = static weight x
   ``weight_fn``(p_k - u_j), and writes u_j <- ``update_fn``(c, u_j, X_j). The sums of w u_k and of w dX are kept
   apart, so the +-paired offsets cancel exactly and a displacement far below the spacing is never rounded away.
3. ``lattice_copy_frame`` (over the frame points, which are numbered last): every frame point takes the mean
   displacement of its assigned source particles (one source for the "single" frame rule).
4. ``lattice_break_links`` (bodies with fracture only): a body link (one end at least a leader or follower) whose
   current length exceeds its shell's threshold is lost for good; links between two frame points are never used and
   never break, so every link-loss count holds body links only.

Kinds: 0 follower, 1 leader, 2 frame. Fictitious points are not particles: they exist per broken link, in the rule.
"""

import warp as wp

from ..launch import launch

wp.set_module_options({"enable_backward": False})  # no gradients needed: halves compile time

LATTICE_FOLLOWER = wp.constant(0)
LATTICE_LEADER = wp.constant(1)
LATTICE_FRAME = wp.constant(2)


@wp.struct
class LatticeRuleParams:
    """Parameters of a follower rule (meaning per rule; see pdsim/lattice/body.py).

    scalars: (relaxation omega, K [1/m] of the mixed-coordinate rule, distance exponent of shell 1, of shell 2).
    axis: unit axis of the mixed-coordinate rule.
    origin: a point of that axis [m].
    """

    scalars: wp.vec4
    axis: wp.vec3
    origin: wp.vec3


# ---------------------------------------------------------------------------------------------------- rule functions
@wp.func
def lattice_weight_uniform(delta: wp.vec3, rest_delta: wp.vec3, shell: int, params: LatticeRuleParams) -> float:
    """Centroid rule: every neighbour counts the same (times its shell weight)."""
    return 1.0


@wp.func
def lattice_weight_distance(delta: wp.vec3, rest_delta: wp.vec3, shell: int, params: LatticeRuleParams) -> float:
    """Distance-weighted centroid: weight dis(k, j)^p with dis the current distance [m] and p = scalars[2] for
    shell 0, scalars[3] for shell 1 (the paper uses p = 1: farther neighbours pull harder, as a spring does)."""
    d = wp.length(delta)
    if d <= 0.0:
        return 0.0
    p = params.scalars[2]
    if shell > 0:
        p = params.scalars[3]
    return wp.pow(d, p)


@wp.func
def lattice_update_centroid(centroid: wp.vec3, u_old: wp.vec3, rest: wp.vec3, params: LatticeRuleParams) -> wp.vec3:
    """u_new = u_old + omega (c - u_old); omega = 1 places the follower on the centroid of its neighbours."""
    return u_old + params.scalars[0] * (centroid - u_old)


@wp.func
def lattice_update_mixed_coordinate(
    centroid: wp.vec3, u_old: wp.vec3, rest: wp.vec3, params: LatticeRuleParams
) -> wp.vec3:
    """Mixed-coordinate (Poisson) rule: the lateral coordinates get -K (u . a) d, with u . a the follower's new
    axial displacement [m] and d its rest offset from the axis, perpendicular to it [m] (the paper's
    y_j = K (x_j(t) - x_j(t0)) da + mean of the neighbours' y, the sign chosen so K > 0 contracts under tension)."""
    a = params.axis
    r = rest - params.origin
    d = r - wp.dot(r, a) * a
    target = centroid - params.scalars[1] * wp.dot(centroid, a) * d
    return u_old + params.scalars[0] * (target - u_old)


# ---------------------------------------------------------------------------------------------------- leaders
@wp.func
def lattice_path_displacement(
    group: int,
    step: int,
    key_offsets: wp.array(dtype=wp.int32),
    key_step: wp.array(dtype=wp.int32),
    key_disp: wp.array(dtype=wp.vec3),
    group_velocity: wp.array(dtype=wp.vec3),
) -> wp.vec3:
    """Displacement [m] of leader path ``group`` at ``step``: piecewise linear between its keyframes (step, u), the
    first keyframe's value before it, and after the last one that value plus group_velocity [m/step] per step."""
    q0 = key_offsets[group]
    q1 = key_offsets[group + 1]
    if step <= key_step[q0]:
        return key_disp[q0]
    for q in range(q0 + 1, q1):
        s1 = key_step[q]
        if step <= s1:
            s0 = key_step[q - 1]
            t = float(step - s0) / float(s1 - s0)
            return key_disp[q - 1] + t * (key_disp[q] - key_disp[q - 1])
    return key_disp[q1 - 1] + float(step - key_step[q1 - 1]) * group_velocity[group]


@wp.kernel
def lattice_step_clock(step_clock: wp.array(dtype=wp.int32)):
    """The step about to be taken: step_clock[0] += 1 (a device counter, so that no launch argument changes from step
    to step and a frame can be replayed as a captured graph)."""
    step_clock[0] = step_clock[0] + 1


@wp.kernel
def lattice_move_leaders(
    step_clock: wp.array(dtype=wp.int32),
    leader_ids: wp.array(dtype=wp.int32),
    group: wp.array(dtype=wp.int32),
    key_offsets: wp.array(dtype=wp.int32),
    key_step: wp.array(dtype=wp.int32),
    key_disp: wp.array(dtype=wp.vec3),
    group_velocity: wp.array(dtype=wp.vec3),
    u_cur: wp.array(dtype=wp.vec3),
    u_next: wp.array(dtype=wp.vec3),
):
    """The leaders ``leader_ids`` take their path's displacement at the step ``step_clock[0]`` (in both buffers: the
    followers of this step see it); a leader without a path (group < 0) holds its displacement."""
    step = step_clock[0]
    i = leader_ids[wp.tid()]
    g = group[i]
    u = u_cur[i]
    if g >= 0:
        u = lattice_path_displacement(g, step, key_offsets, key_step, key_disp, group_velocity)
    u_cur[i] = u
    u_next[i] = u


@wp.kernel
def lattice_set_kind(
    indices: wp.array(dtype=wp.int32),
    new_kind: int,
    new_group: int,
    kind: wp.array(dtype=wp.int32),
    group: wp.array(dtype=wp.int32),
):
    """Category change: particles ``indices`` become ``new_kind`` and follow leader path ``new_group`` (-1: none)."""
    t = wp.tid()
    i = indices[t]
    kind[i] = new_kind
    group[i] = new_group


# ---------------------------------------------------------------------------------------------------- followers
_FOLLOW_KERNELS = {}


def make_follow_kernel(weight_fn, update_fn, fracture: bool, fictitious: bool):
    """The follower kernel for one rule (a weight ``@wp.func`` (delta, rest_delta, shell, params) -> float and an
    update ``@wp.func`` (centroid, u_old, rest, params) -> vec3, as :func:`lattice_weight_uniform` and
    :func:`lattice_update_centroid`). ``fracture`` compiles in the per-link alive
    flags; ``fictitious`` places a fictitious point for each broken link (otherwise a broken link is skipped).
    Kernels are cached per combination."""
    key = (weight_fn, update_fn, bool(fracture), bool(fictitious))
    kernel = _FOLLOW_KERNELS.get(key)
    if kernel is not None:
        return kernel
    use_alive = bool(fracture)
    use_ghost = bool(fracture) and bool(fictitious)

    def follow(
        rest: wp.array(dtype=wp.vec3),
        kind: wp.array(dtype=wp.int32),
        row_offsets: wp.array(dtype=wp.int32),
        link_neighbor: wp.array(dtype=wp.int32),
        link_offset: wp.array(dtype=wp.uint8),
        link_alive: wp.array(dtype=wp.uint8),
        offset_delta: wp.array(dtype=wp.vec3),
        offset_weight: wp.array(dtype=float),
        offset_shell: wp.array(dtype=wp.int32),
        fictitious_scale: float,
        params: LatticeRuleParams,
        u_cur: wp.array(dtype=wp.vec3),
        u_next: wp.array(dtype=wp.vec3),
    ):
        j = wp.tid()
        if kind[j] != LATTICE_FOLLOWER:
            return
        uj = u_cur[j]
        # the neighbours' displacements and rest offsets are summed apart: the offsets cancel in +-pairs, and a tiny
        # displacement is never absorbed into an offset of order the spacing (float32)
        sw = float(0.0)
        su = wp.vec3(0.0)
        sdx = wp.vec3(0.0)
        for q in range(row_offsets[j], row_offsets[j + 1]):
            o = int(link_offset[q])
            dx = offset_delta[o]
            uk = uj
            take = True
            if wp.static(use_alive):
                if link_alive[q] != wp.uint8(0):
                    uk = u_cur[link_neighbor[q]]
                else:
                    if wp.static(use_ghost):
                        dx = fictitious_scale * dx
                    else:
                        take = False
            else:
                uk = u_cur[link_neighbor[q]]
            if take:
                w = offset_weight[o] * wp.static(weight_fn)(uk - uj + dx, dx, offset_shell[o], params)
                sw += w
                su += w * uk
                sdx += w * dx
        c = uj
        if sw > 0.0:
            c = (su + sdx) / sw
        u_next[j] = wp.static(update_fn)(c, uj, rest[j], params)

    kernel = wp.kernel(follow, module="unique", enable_backward=False)
    _FOLLOW_KERNELS[key] = kernel
    return kernel


# ---------------------------------------------------------------------------------------------------- frame
@wp.kernel
def lattice_copy_frame(
    first: int,
    frame_offsets: wp.array(dtype=wp.int32),
    frame_sources: wp.array(dtype=wp.int32),
    u_source: wp.array(dtype=wp.vec3),
    u_next: wp.array(dtype=wp.vec3),
):
    """Frame point first + tid takes the mean displacement of its source particles in ``u_source`` (one source: a
    copy): the new lattice of this step, or the intermediate one (sources' previous displacement, leaders' new one)."""
    i = first + wp.tid()
    q0 = frame_offsets[i]
    q1 = frame_offsets[i + 1]
    if q1 <= q0:
        return
    s = wp.vec3(0.0)
    for q in range(q0, q1):
        s += u_source[frame_sources[q]]
    u_next[i] = s / float(q1 - q0)


# ---------------------------------------------------------------------------------------------------- fracture
@wp.func
def lattice_link_length(u: wp.array(dtype=wp.vec3), uj: wp.vec3, k: int, rest_delta: wp.vec3) -> float:
    """Current length |u_k - u_j + dX| [m] of the link from particle j (displacement uj [m]) to particle k, with dX
    its rest offset [m] (the breaking test and PE1 read it)."""
    return wp.length(u[k] - uj + rest_delta)


@wp.kernel
def lattice_break_links(
    body_count: int,
    row_offsets: wp.array(dtype=wp.int32),
    link_neighbor: wp.array(dtype=wp.int32),
    link_offset: wp.array(dtype=wp.uint8),
    offset_delta: wp.array(dtype=wp.vec3),
    offset_threshold: wp.array(dtype=float),
    u: wp.array(dtype=wp.vec3),
    link_alive: wp.array(dtype=wp.uint8),
    broken_total: wp.array(dtype=wp.int32),
):
    """A body link (at least one end among the first ``body_count`` particles: the frame points are numbered last)
    whose current length |u_k - u_j + dX| [m] exceeds its shell's threshold is lost (irreversibly). Links between two
    frame points never break: no rule reads them (frame points copy). Both directions of a link compute the same
    length bit for bit, so links break in pairs. broken_total[0] counts lost directed links."""
    j = wp.tid()
    uj = u[j]
    n = int(0)
    for q in range(row_offsets[j], row_offsets[j + 1]):
        k = link_neighbor[q]
        if link_alive[q] != wp.uint8(0) and (j < body_count or k < body_count):
            o = int(link_offset[q])
            d = lattice_link_length(u, uj, k, offset_delta[o])
            if d > offset_threshold[o]:
                link_alive[q] = wp.uint8(0)
                n += 1
    if n > 0:
        wp.atomic_add(broken_total, 0, n)


# ---------------------------------------------------------------------------------------------------- diagnostics
@wp.kernel
def lattice_pseudo_energy(
    row_offsets: wp.array(dtype=wp.int32),
    link_neighbor: wp.array(dtype=wp.int32),
    link_offset: wp.array(dtype=wp.uint8),
    link_alive: wp.array(dtype=wp.uint8),
    use_alive: int,
    offset_delta: wp.array(dtype=wp.vec3),
    offset_length: wp.array(dtype=float),
    u: wp.array(dtype=wp.vec3),
    pe1: wp.array(dtype=float),
    pe1_intact: wp.array(dtype=float),
    broken: wp.array(dtype=wp.int32),
):
    """PE1(t, j) = sum over j's Lagrangian neighbours of (dis(t, k, j) - dis(t0, k, j))^2 [m^2] (the paper's
    definition: real points, broken links included); pe1_intact sums intact links only; broken counts lost links
    (body links only: links between two frame points never break)."""
    j = wp.tid()
    uj = u[j]
    e_all = float(0.0)
    e_intact = float(0.0)
    nb = int(0)
    for q in range(row_offsets[j], row_offsets[j + 1]):
        o = int(link_offset[q])
        e = lattice_link_length(u, uj, link_neighbor[q], offset_delta[o]) - offset_length[o]
        e2 = e * e
        e_all += e2
        alive = True
        if use_alive != 0:
            alive = link_alive[q] != wp.uint8(0)
        if alive:
            e_intact += e2
        else:
            nb += 1
    pe1[j] = e_all
    pe1_intact[j] = e_intact
    broken[j] = nb


@wp.kernel
def lattice_record_tracks(
    ids: wp.array(dtype=wp.int32),
    row_offsets: wp.array(dtype=wp.int32),
    link_neighbor: wp.array(dtype=wp.int32),
    link_offset: wp.array(dtype=wp.uint8),
    offset_delta: wp.array(dtype=wp.vec3),
    offset_length: wp.array(dtype=float),
    u: wp.array(dtype=wp.vec3),
    slot: int,
    track_u: wp.array2d(dtype=wp.vec3),
    track_pe1: wp.array2d(dtype=float),
):
    """Stores the displacement [m] and PE1 [m^2] of the tracked particles in row ``slot`` of the history."""
    t = wp.tid()
    j = ids[t]
    uj = u[j]
    e_all = float(0.0)
    for q in range(row_offsets[j], row_offsets[j + 1]):
        o = int(link_offset[q])
        e = lattice_link_length(u, uj, link_neighbor[q], offset_delta[o]) - offset_length[o]
        e_all += e * e
    track_u[slot, t] = uj
    track_pe1[slot, t] = e_all


@wp.kernel
def lattice_check_finite(u: wp.array(dtype=wp.vec3), result: wp.array(dtype=float)):
    """result[0] = max |u| [m]; result[1] = 1 when a displacement is not finite."""
    i = wp.tid()
    s = wp.length(u[i])
    if wp.isnan(s) or wp.isinf(s):
        result[1] = 1.0
    else:
        wp.atomic_max(result, 0, s)


# ---------------------------------------------------------------------------------------------------- launches
def advance_step_clock(step_clock, device):
    """step_clock[0] += 1 on the device (lattice_step_clock)."""
    wp.launch(lattice_step_clock, dim=1, inputs=[step_clock], device=device)


def set_kind(count, indices, new_kind, new_group, kind, group, device):
    """The ``count`` particles ``indices`` become ``new_kind`` with leader path ``new_group`` (lattice_set_kind)."""
    wp.launch(lattice_set_kind, dim=count, inputs=[indices, new_kind, new_group, kind, group], device=device)


def move_leaders(count, *, device, **arguments):
    """The ``count`` leaders ``leader_ids`` take their path's displacement [m] at this step (lattice_move_leaders)."""
    launch(lattice_move_leaders, count, device=device, **arguments)


def follow(kernel, count, *, device, **arguments):
    """The follower rule over ``count`` particles with a kernel from :func:`make_follow_kernel`: u_next [m] of every
    follower from u_cur."""
    launch(kernel, count, device=device, **arguments)


def copy_frame(first, count, frame_offsets, frame_sources, u_source, u_next, device):
    """Frame points first .. first + count - 1 take the mean displacement [m] of their sources (lattice_copy_frame)."""
    wp.launch(
        lattice_copy_frame,
        dim=count,
        inputs=[first, frame_offsets, frame_sources, u_source, u_next],
        device=device,
    )


def break_links(count, *, device, **arguments):
    """Breaks the over-stretched body links of the ``count`` particles and counts them (lattice_break_links)."""
    launch(lattice_break_links, count, device=device, **arguments)


def pseudo_energy(count, *, device, **arguments):
    """PE1 [m^2] (all links and intact links) and lost links of the ``count`` particles (lattice_pseudo_energy)."""
    launch(lattice_pseudo_energy, count, device=device, **arguments)


def record_tracks(count, *, device, **arguments):
    """Displacement [m] and PE1 [m^2] of the ``count`` tracked particles into row ``slot`` (lattice_record_tracks)."""
    launch(lattice_record_tracks, count, device=device, **arguments)


def check_finite(count, u, result, device):
    """result[0] = max |u| [m] over ``count`` particles, result[1] = 1 if one is not finite (lattice_check_finite)."""
    wp.launch(lattice_check_finite, dim=count, inputs=[u, result], device=device)
