"""Peridynamic bond passes over bond pairs (CPU): each undirected pair (k, j), j > k, evaluated once.

The directed passes of kernels/peridynamics/step.py visit every bond twice (k -> j and j -> k) and gather; these
visit each pair once, from its lower particle k, and scatter the share of the upper particle j into a buffer of the
fixed pair range r that k belongs to. A small pass then adds, per particle, its own sum and the buffers in the order
r = 0, 1, ...: the ranges are fixed by the particles' pair counts alone, so every sum has the same order for any
thread count (bit-identical results), and no two threads write the same slot (no atomics). Threads take whole
ranges; a pair kernel reads its particle's range from ``pair_slot``.

Pair layout (built from the directed bonds, pdsim/peridynamics/pairs.py): ``pair_offsets`` (per particle, the pairs
with j > k, in family order), ``pair_neighbors`` (j), ``pair_bond`` and ``pair_reverse`` (the directed bonds k -> j
and j -> k), ``pair_geom`` = (xi / L, L) of k -> j, ``pair_weights`` = (w V beta G^dil of k -> j and of j -> k,
w V beta G^dev of k -> j and of j -> k) [m^3], ``pair_ne`` = (n, e) of k -> j from the last dilatation pass (the
reverse bond's is (-n, e): eta_jk = -eta_kj exactly in float32). Buffers: range r holds the particles
``range_lo[r]`` .. ``range_hi[r]`` at ``buffer_base[r] + (j - range_lo[r])``; the sum passes clear what they read.

The arithmetic per pair is the directed kernels' (the same (n, e) bits, the same force terms); only the order of
each particle's sums differs (float32 round-off). The most compressive stretch is a minimum, so it is the directed
value exactly. A pair breaks once (the test of the directed force kernel, symmetric in k and j) and both directed
flags are cleared by the one thread that owns the pair.

Plasticity (the return mapping of kernels/peridynamics/step.py, per particle over its family) splits into pair passes
and per-particle sums, since each of its family sums is a sum over pairs once theta_p of both ends is known: the
dilatation pass also sums w V beta L e and w V beta L^2 (``pair_wv`` = (w V beta of k -> j, of j -> k)), its sum
pass gives theta_p / 3; a norm pass sums each yielding end's deviatoric_norm_term and its sum pass gives the return
mapping's scale r (yield_ratio, -1 where the particle stays elastic); the force pass returns the plastic extensions
of each live pair's yielding ends (``pair_plastic`` = (e^p_kj, e^p_jk), the state), uses them in the force and the
stretch test, and sums w V beta (e^p)^2 over a yielding end's pairs, live or broken, from which its sum pass gives the
equivalent plastic strain; a last pass, with ductile failure, tests the pairs against this step's equivalent
plastic strain of both ends. Yielding particles come first (pdsim/peridynamics/model.py), so the plastic pairs are a
prefix of the pairs. The plastic variants have no hand-off form.
"""

import warp as wp

from ..launch import range_inputs
from .bonds import deformed_bond, deviatoric_norm_term, returned_plastic_extension, yield_ratio

_cache = {}


def make_pair_kernels(
    fracture: bool, handoff: bool = False, plastic: bool = False, ductile: bool = False, damped: bool = False
):
    """Pair kernels (dilatation, its sum, force, its sum; with ``plastic`` also the return mapping's norm pass and
    its sum, and with ``ductile`` the ductile breaking test) for the feature set, built once and cached. With
    ``handoff`` thread t of a launch computes particle live_particles[first + t] (as the directed kernels), else
    particle first + t; ``pair_slot`` is indexed like the particles of the launch (list entry or particle). The
    plastic passes (norm, its sum, ductile breaking) index particle first + t in both forms: with ``handoff`` and
    ``plastic`` the yielding particles (a prefix) must all be in the live list, so that entry t is particle t there
    (no yielding body is handed off: bonds never cross bodies, so no yielding particle then has a bond, live or
    broken, to a rigid one; pdsim/peridynamics/pairs.py PairPasses.set_particles checks it)."""
    key = (
        bool(fracture), bool(handoff), bool(plastic), bool(ductile) and bool(plastic) and bool(fracture), bool(damped)
    )  # fmt: skip
    if key in _cache:
        return _cache[key]
    FRACTURE = key[0]
    HANDOFF = key[1]
    PLASTIC = key[2]  # key[3], ductile failure: the launches add the ductile_break pass (it has no other variant)
    DAMPED = key[4]  # the internal damping in the force pass (kernels/peridynamics/step.py)

    @wp.kernel(module="unique")
    def pair_dilatation(
        first: int,
        live_particles: wp.array(dtype=wp.int32),
        pair_slot: wp.array(dtype=wp.int32),
        range_lo: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        displacements: wp.array(dtype=wp.vec3),
        pair_offsets: wp.array(dtype=wp.int32),
        pair_neighbors: wp.array(dtype=wp.int32),
        pair_bond: wp.array(dtype=wp.int32),
        pair_geom: wp.array(dtype=wp.vec4),
        pair_weights: wp.array(dtype=wp.vec4),
        bond_alive: wp.array(dtype=wp.uint8),
        pair_ne: wp.array(dtype=wp.vec4),
        theta_sum: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
        theta_buffer: wp.array(dtype=float),
        stretch_buffer: wp.array(dtype=float),
        plastic_particle_count: int,
        pair_wv: wp.array(dtype=wp.vec2),
        plastic_sum: wp.array(dtype=wp.vec2),
        plastic_buffer: wp.array(dtype=wp.vec2),
    ):
        """For particle k: each live pair's (n, e) (cached in pair_ne), k's share sum w e V beta G^dil into
        theta_sum[k] and j's into j's slot of the range's theta_buffer; with fracture the most compressive stretch
        e / L of k's pairs into stretch_min[k] and, for j, into stretch_buffer (a minimum); with plasticity, for a
        yielding particle (k < plastic_particle_count), the plastic volumetric sums (sum w V beta L e, sum w V beta
        L^2) into plastic_sum[k] and j's (with the weight w V beta of j -> k, ``pair_wv``) into plastic_buffer."""
        t = first + wp.tid()
        k = t
        if wp.static(HANDOFF):
            k = live_particles[t]
        r = pair_slot[t]
        shift = buffer_base[r] - range_lo[r]
        uk = displacements[k]
        acc = float(0.0)
        smin = float(0.0)
        yields = int(0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                yields = 1
        num = float(0.0)
        den = float(0.0)
        for p in range(pair_offsets[k], pair_offsets[k + 1]):
            if wp.static(FRACTURE):
                if bond_alive[pair_bond[p]] == wp.uint8(0):
                    continue
            j = pair_neighbors[p]
            g = pair_geom[p]
            L = g[3]
            xi = wp.vec3(g[0], g[1], g[2]) * L
            du = displacements[j] - uk
            n, e = deformed_bond(xi, du, L)
            pair_ne[p] = wp.vec4(n[0], n[1], n[2], e)
            w = pair_weights[p]
            acc += w[0] * e
            theta_buffer[shift + j] += w[1] * e
            if wp.static(FRACTURE):
                s = e / L
                smin = wp.min(smin, s)
                stretch_buffer[shift + j] = wp.min(stretch_buffer[shift + j], s)
            if wp.static(PLASTIC):
                if yields != 0:
                    wv = pair_wv[p]
                    wl = wv[0] * L
                    num += wl * e
                    den += wl * L
                    wl = wv[1] * L
                    plastic_buffer[shift + j] += wp.vec2(wl * e, wl * L)
        theta_sum[k] = acc
        if wp.static(FRACTURE):
            stretch_min[k] = smin
        if wp.static(PLASTIC):
            if yields != 0:
                plastic_sum[k] = wp.vec2(num, den)

    @wp.kernel(module="unique")
    def pair_dilatation_sum(
        first: int,
        live_particles: wp.array(dtype=wp.int32),
        range_count: int,
        range_lo: wp.array(dtype=wp.int32),
        range_hi: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        theta_buffer: wp.array(dtype=float),
        stretch_buffer: wp.array(dtype=float),
        dil_d: wp.array(dtype=float),
        dil_coef: wp.array(dtype=float),
        dev_b: wp.array(dtype=float),
        theta: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
        bp: wp.array(dtype=wp.vec2),
        plastic_particle_count: int,
        plastic_sum: wp.array(dtype=wp.vec2),
        plastic_buffer: wp.array(dtype=wp.vec2),
        plastic_th3: wp.array(dtype=float),
    ):
        """theta_k = d_k (own sum + the ranges' buffers in range order) [-] (theta holds the own sum on entry),
        (b_k, P_k), with fracture the minimum of the stretches, and with plasticity theta_p / 3 = num / den of a
        yielding particle (plastic_th3; 0 where den = 0); clears the buffer slots it read."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        s = theta[k]
        smin = float(0.0)
        if wp.static(FRACTURE):
            smin = stretch_min[k]
        yields = int(0)
        ps = wp.vec2(0.0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                yields = 1
                ps = plastic_sum[k]
        for r in range(range_count):
            if k >= range_lo[r] and k <= range_hi[r]:
                i = buffer_base[r] + k - range_lo[r]
                s += theta_buffer[i]
                theta_buffer[i] = 0.0
                if wp.static(FRACTURE):
                    smin = wp.min(smin, stretch_buffer[i])
                    stretch_buffer[i] = 0.0
                if wp.static(PLASTIC):
                    if yields != 0:
                        ps += plastic_buffer[i]
                        plastic_buffer[i] = wp.vec2(0.0)
        th = dil_d[k] * s
        theta[k] = th
        bp[k] = wp.vec2(dev_b[k], dil_coef[k] * th)
        if wp.static(FRACTURE):
            stretch_min[k] = smin
        if wp.static(PLASTIC):
            if yields != 0:
                th3 = float(0.0)
                if ps[1] > 0.0:
                    th3 = ps[0] / ps[1]
                plastic_th3[k] = th3

    @wp.kernel(module="unique")
    def pair_plastic_norm(
        first: int,
        pair_slot: wp.array(dtype=wp.int32),
        range_lo: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        plastic_particle_count: int,
        pair_offsets: wp.array(dtype=wp.int32),
        pair_neighbors: wp.array(dtype=wp.int32),
        pair_bond: wp.array(dtype=wp.int32),
        pair_geom: wp.array(dtype=wp.vec4),
        pair_weights: wp.array(dtype=wp.vec4),
        pair_wv: wp.array(dtype=wp.vec2),
        pair_ne: wp.array(dtype=wp.vec4),
        pair_plastic: wp.array(dtype=wp.vec2),
        bond_alive: wp.array(dtype=wp.uint8),
        dev_b: wp.array(dtype=float),
        plastic_th3: wp.array(dtype=float),
        plastic_sum: wp.array(dtype=wp.vec2),
        theta_buffer: wp.array(dtype=float),
    ):
        """The return mapping's trial norm for a yielding particle k: over its live pairs, with the deviatoric
        extensions e - (theta_p / 3) L of both ends (kernels/peridynamics/step.py), k's terms deviatoric_norm_term
        into plastic_sum[k][0] and j's (the weights and plastic extension of j -> k) into j's slot of theta_buffer."""
        k = first + wp.tid()
        if k >= plastic_particle_count:
            return
        r = pair_slot[k]
        shift = buffer_base[r] - range_lo[r]
        two_bk = 2.0 * dev_b[k]
        th3k = plastic_th3[k]
        acc = float(0.0)
        for p in range(pair_offsets[k], pair_offsets[k + 1]):
            if wp.static(FRACTURE):
                if bond_alive[pair_bond[p]] == wp.uint8(0):
                    continue
            j = pair_neighbors[p]
            L = pair_geom[p][3]
            e = pair_ne[p][3]
            w = pair_weights[p]
            wv = pair_wv[p]
            ep = pair_plastic[p]
            acc += deviatoric_norm_term(two_bk, w[2], wv[0], L, e - th3k * L, ep[0])
            theta_buffer[shift + j] += deviatoric_norm_term(
                2.0 * dev_b[j], w[3], wv[1], L, e - plastic_th3[j] * L, ep[1]
            )
        plastic_sum[k] = wp.vec2(acc, 0.0)

    @wp.kernel(module="unique")
    def pair_plastic_norm_sum(
        first: int,
        range_count: int,
        range_lo: wp.array(dtype=wp.int32),
        range_hi: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        plastic_particle_count: int,
        theta_buffer: wp.array(dtype=float),
        plastic_sum: wp.array(dtype=wp.vec2),
        horizon: wp.array(dtype=float),
        yield_stress: wp.array(dtype=float),
        hardening: wp.array(dtype=float),
        psi_scale: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
        plastic_ratio: wp.array(dtype=float),
    ):
        """||t||^2 = delta (own terms + the ranges' buffers in range order) of a yielding particle and its return
        mapping scale (yield_ratio: -1 where it does not yield) into plastic_ratio; clears the slots it read."""
        k = first + wp.tid()
        if k >= plastic_particle_count:
            return
        s = plastic_sum[k][0]
        for r in range(range_count):
            if k >= range_lo[r] and k <= range_hi[r]:
                i = buffer_base[r] + k - range_lo[r]
                s += theta_buffer[i]
                theta_buffer[i] = 0.0
        delta = horizon[k]
        plastic_ratio[k] = yield_ratio(s * delta, delta, yield_stress[k] + hardening[k] * eqps[k], psi_scale[k])

    @wp.kernel(module="unique")
    def pair_force(
        first: int,
        live_particles: wp.array(dtype=wp.int32),
        pair_slot: wp.array(dtype=wp.int32),
        range_lo: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        pair_offsets: wp.array(dtype=wp.int32),
        pair_neighbors: wp.array(dtype=wp.int32),
        pair_bond: wp.array(dtype=wp.int32),
        pair_reverse: wp.array(dtype=wp.int32),
        pair_geom: wp.array(dtype=wp.vec4),
        pair_weights: wp.array(dtype=wp.vec4),
        pair_ne: wp.array(dtype=wp.vec4),
        bp: wp.array(dtype=wp.vec2),
        bond_alive: wp.array(dtype=wp.uint8),
        bond_critical_stretch: wp.array(dtype=float),
        compressive_bonus: wp.array(dtype=float),
        compressive_stretch_floor: wp.array(dtype=float),
        stretch_min: wp.array(dtype=float),
        force_density: wp.array(dtype=wp.vec3),
        force_buffer: wp.array(dtype=wp.vec3),
        plastic_particle_count: int,
        pair_wv: wp.array(dtype=wp.vec2),
        pair_plastic: wp.array(dtype=wp.vec2),
        plastic_th3: wp.array(dtype=float),
        plastic_ratio: wp.array(dtype=float),
        plastic_sum: wp.array(dtype=wp.vec2),
        theta_buffer: wp.array(dtype=float),
        velocities: wp.array(dtype=wp.vec3),
        damping_b: wp.array(dtype=float),
    ):
        """For particle k: each live pair's force terms (with ``damped`` the deviatoric term's internal damping (tau_k
        b_k + tau_j b_j) e_dot, ``damping_b`` = tau b per particle, kernels/peridynamics/step.py), k's 2 (w^dil (P_k +
        P_j) + w^dev (b_k + b_j) e) n into force_density[k] and j's (with the weights of j -> k, direction -n) into j's
        slot of the range's force_buffer [N/m^3]; then, with fracture, the breaking test of the directed force kernel,
        clearing both directed flags of a broken pair (it takes effect from the next pass). With plasticity the return
        mapping of both ends comes first (each end whose plastic_ratio r >= 0 yields: e^p <- returned_plastic_extension,
        on live pairs; the pair's (e^p_kj, e^p_jk) in pair_plastic), the deviatoric term is b_k (e - e^p_kj) + b_j (e -
        e^p_jk), the stretch test compares e - (e^p_kj + e^p_jk) / 2, and a yielding end's sum w V beta (e^p)^2 over all
        its pairs, live or broken, goes into plastic_sum[k][0] (k) or theta_buffer (j)."""
        t = first + wp.tid()
        k = t
        if wp.static(HANDOFF):
            k = live_particles[t]
        r = pair_slot[t]
        shift = buffer_base[r] - range_lo[r]
        bpk = bp[k]
        f = wp.vec3(0.0)
        smin_k = float(0.0)
        bonus_k = float(0.0)
        floor_k = float(0.0)
        if wp.static(FRACTURE):
            smin_k = stretch_min[k]
            bonus_k = compressive_bonus[k]
            floor_k = compressive_stretch_floor[k]
        yields = int(0)
        rk = float(-1.0)
        th3k = float(0.0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                yields = 1
                rk = plastic_ratio[k]
                th3k = plastic_th3[k]
        ep2 = float(0.0)
        vk = wp.vec3(0.0)
        tbk = float(0.0)
        if wp.static(DAMPED):
            vk = velocities[k]
            tbk = damping_b[k]
        for p in range(pair_offsets[k], pair_offsets[k + 1]):
            q = int(0)
            live = int(1)
            if wp.static(FRACTURE):
                q = pair_bond[p]
                live = int(bond_alive[q])
            j = pair_neighbors[p]
            if wp.static(PLASTIC):
                if yields != 0 and live == 0:  # a broken pair's frozen plastic extensions still count in ep2
                    rj = plastic_ratio[j]
                    if rk >= 0.0 or rj >= 0.0:
                        wv = pair_wv[p]
                        ep = pair_plastic[p]
                        if rk >= 0.0:
                            ep2 += wv[0] * ep[0] * ep[0]
                        if rj >= 0.0:
                            theta_buffer[shift + j] += wv[1] * ep[1] * ep[1]
            if live == 0:
                continue
            c = pair_ne[p]
            bpj = bp[j]
            dev = (bpk[0] + bpj[0]) * c[3]
            ep_sum = float(0.0)
            if wp.static(PLASTIC):
                if yields != 0:
                    ep = pair_plastic[p]
                    epk = ep[0]
                    epj = ep[1]
                    rj = plastic_ratio[j]
                    if rk >= 0.0 or rj >= 0.0:
                        L = pair_geom[p][3]
                        wv = pair_wv[p]
                        if rk >= 0.0:
                            epk = returned_plastic_extension(c[3] - th3k * L, epk, rk)
                            ep2 += wv[0] * epk * epk
                        if rj >= 0.0:
                            epj = returned_plastic_extension(c[3] - plastic_th3[j] * L, epj, rj)
                            theta_buffer[shift + j] += wv[1] * epj * epj
                        pair_plastic[p] = wp.vec2(epk, epj)
                    dev = dev - bpk[0] * epk - bpj[0] * epj
                    ep_sum = epk + epj
            dil = bpk[1] + bpj[1]
            w = pair_weights[p]
            n = wp.vec3(c[0], c[1], c[2])
            if wp.static(DAMPED):
                dev = dev + (tbk + damping_b[j]) * wp.dot(velocities[j] - vk, n)
            f += (2.0 * (w[0] * dil + w[2] * dev)) * n
            force_buffer[shift + j] -= (2.0 * (w[1] * dil + w[3] * dev)) * n
            if wp.static(FRACTURE):
                sc0 = bond_critical_stretch[q]
                sc = sc0 - bonus_k * wp.max(wp.min(smin_k, stretch_min[j]), -floor_k * sc0)
                if c[3] - 0.5 * ep_sum > sc * pair_geom[p][3]:
                    bond_alive[q] = wp.uint8(0)
                    bond_alive[pair_reverse[p]] = wp.uint8(0)
        force_density[k] = f
        if wp.static(PLASTIC):
            if yields != 0:
                plastic_sum[k] = wp.vec2(ep2, 0.0)

    @wp.kernel(module="unique")
    def pair_force_sum(
        first: int,
        live_particles: wp.array(dtype=wp.int32),
        range_count: int,
        range_lo: wp.array(dtype=wp.int32),
        range_hi: wp.array(dtype=wp.int32),
        buffer_base: wp.array(dtype=wp.int32),
        force_buffer: wp.array(dtype=wp.vec3),
        force_density: wp.array(dtype=wp.vec3),
        plastic_particle_count: int,
        theta_buffer: wp.array(dtype=float),
        plastic_sum: wp.array(dtype=wp.vec2),
        plastic_ratio: wp.array(dtype=float),
        weighted_volume: wp.array(dtype=float),
        eqps: wp.array(dtype=float),
    ):
        """force_density[k] += the ranges' buffers in range order [N/m^3]; with plasticity, for a particle that
        yielded in this step, the equivalent plastic strain sqrt(5 sum w V beta (e^p)^2 / m_k) [-] from its own sum
        and theta_buffer's; clears the slots it read."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        f = force_density[k]
        yields = int(0)
        ep2 = float(0.0)
        if wp.static(PLASTIC):
            if k < plastic_particle_count:
                if plastic_ratio[k] >= 0.0:
                    yields = 1
                    ep2 = plastic_sum[k][0]
        for r in range(range_count):
            if k >= range_lo[r] and k <= range_hi[r]:
                i = buffer_base[r] + k - range_lo[r]
                f += force_buffer[i]
                force_buffer[i] = wp.vec3(0.0)
                if wp.static(PLASTIC):
                    ep2 += theta_buffer[i]
                    theta_buffer[i] = 0.0
        force_density[k] = f
        if wp.static(PLASTIC):
            if yields != 0:
                m = weighted_volume[k]
                if m > 0.0:
                    eqps[k] = wp.sqrt(5.0 * ep2 / m)

    @wp.kernel(module="unique")
    def pair_ductile_break(
        first: int,
        plastic_particle_count: int,
        pair_offsets: wp.array(dtype=wp.int32),
        pair_neighbors: wp.array(dtype=wp.int32),
        pair_bond: wp.array(dtype=wp.int32),
        pair_reverse: wp.array(dtype=wp.int32),
        pair_ne: wp.array(dtype=wp.vec4),
        eqps: wp.array(dtype=float),
        failure_eqps: wp.array(dtype=float),
        bond_alive: wp.array(dtype=wp.uint8),
    ):
        """Ductile failure (the directed force kernel's test): a live stretched pair (e > 0) of a yielding particle
        k breaks, both directed flags, when the larger equivalent plastic strain of its two particles (this step's)
        exceeds k's failure plastic strain."""
        k = first + wp.tid()
        if k >= plastic_particle_count:
            return
        eqps_k = eqps[k]
        fail_k = failure_eqps[k]
        for p in range(pair_offsets[k], pair_offsets[k + 1]):
            q = pair_bond[p]
            if bond_alive[q] != wp.uint8(0):
                if pair_ne[p][3] > 0.0 and wp.max(eqps_k, eqps[pair_neighbors[p]]) > fail_k:
                    bond_alive[q] = wp.uint8(0)
                    bond_alive[pair_reverse[p]] = wp.uint8(0)

    class PairKernels:
        pass

    ks = PairKernels()
    ks.dilatation, ks.dilatation_sum = pair_dilatation, pair_dilatation_sum
    ks.force, ks.force_sum = pair_force, pair_force_sum
    ks.plastic_norm, ks.plastic_norm_sum = pair_plastic_norm, pair_plastic_norm_sum
    ks.ductile_break = pair_ductile_break
    _cache[key] = ks
    return ks


@wp.kernel
def mirror_pair_cache(
    pair_bond: wp.array(dtype=wp.int32),
    pair_reverse: wp.array(dtype=wp.int32),
    pair_ne: wp.array(dtype=wp.vec4),
    bond_ne: wp.array(dtype=wp.vec4),
):
    """The directed bond cache from the pairs': bond_ne[k -> j] = (n, e), bond_ne[j -> k] = (-n, e) (the directed
    dilatation pass's values bit for bit)."""
    p = wp.tid()
    c = pair_ne[p]
    bond_ne[pair_bond[p]] = c
    bond_ne[pair_reverse[p]] = wp.vec4(-c[0], -c[1], -c[2], c[3])


@wp.kernel
def gather_pair_cache(
    pair_bond: wp.array(dtype=wp.int32),
    bond_ne: wp.array(dtype=wp.vec4),
    pair_ne: wp.array(dtype=wp.vec4),
):
    """pair_ne[p] = bond_ne[k -> j] of each pair p (the pairs' cache from the directed one)."""
    p = wp.tid()
    pair_ne[p] = bond_ne[pair_bond[p]]


@wp.kernel
def mirror_pair_plastic(
    pair_bond: wp.array(dtype=wp.int32),
    pair_reverse: wp.array(dtype=wp.int32),
    pair_plastic: wp.array(dtype=wp.vec2),
    bond_plastic: wp.array(dtype=float),
):
    """The directed plastic extensions from the pairs': bond_plastic[k -> j] = e^p_kj, bond_plastic[j -> k] = e^p_jk
    [m]."""
    p = wp.tid()
    ep = pair_plastic[p]
    bond_plastic[pair_bond[p]] = ep[0]
    bond_plastic[pair_reverse[p]] = ep[1]


@wp.kernel
def gather_pair_values(
    pair_bond: wp.array(dtype=wp.int32),
    pair_reverse: wp.array(dtype=wp.int32),
    bond_values: wp.array(dtype=float),
    pair_values: wp.array(dtype=wp.vec2),
):
    """pair_values[p] = (value of k -> j, value of j -> k) of each pair p from a per-bond array (the plastic
    extensions [m], the weights w V beta [m^3])."""
    p = wp.tid()
    pair_values[p] = wp.vec2(bond_values[pair_bond[p]], bond_values[pair_reverse[p]])


# ---------------------------------------------------------------------------------------------------- launches
def pair_dilatation(launch, ks, **arguments):
    """The pair dilatation pass of the kernels ``ks`` (make_pair_kernels) through ``launch(kernel, inputs)``: each
    live pair's (n, e), the own sums and the ranges' buffers."""
    launch(ks.dilatation, range_inputs(ks.dilatation, arguments))


def pair_dilatation_sum(launch, ks, **arguments):
    """theta [-], (b_k, P_k) and the most compressive stretch from the own sums and the buffers
    (``ks.dilatation_sum``)."""
    launch(ks.dilatation_sum, range_inputs(ks.dilatation_sum, arguments))


def pair_plastic_norm(launch, ks, **arguments):
    """The return mapping's trial norm terms of the yielding particles' live pairs, own and buffered
    (``ks.plastic_norm``)."""
    launch(ks.plastic_norm, range_inputs(ks.plastic_norm, arguments))


def pair_plastic_norm_sum(launch, ks, **arguments):
    """Each yielding particle's return mapping scale (-1: it does not yield) from its norm sums
    (``ks.plastic_norm_sum``)."""
    launch(ks.plastic_norm_sum, range_inputs(ks.plastic_norm_sum, arguments))


def pair_ductile_break(launch, ks, **arguments):
    """The ductile breaking test of the yielding particles' live stretched pairs (``ks.ductile_break``)."""
    launch(ks.ductile_break, range_inputs(ks.ductile_break, arguments))


def pair_forces(launch, ks, **arguments):
    """The pair force pass of ``ks``: own force density sums, the buffers, and the breaking test."""
    launch(ks.force, range_inputs(ks.force, arguments))


def pair_force_sum(launch, ks, **arguments):
    """Force density [N/m^3] from the own sums and the buffers (``ks.force_sum``)."""
    launch(ks.force_sum, range_inputs(ks.force_sum, arguments))


def bond_cache_from_pairs(count, pair_bond, pair_reverse, pair_ne, bond_ne, device):
    """Writes both directed bonds' (n, e) of the ``count`` pairs into bond_ne (mirror_pair_cache)."""
    if count > 0:
        wp.launch(mirror_pair_cache, dim=count, inputs=[pair_bond, pair_reverse, pair_ne, bond_ne], device=device)


def pair_cache_from_bonds(count, pair_bond, bond_ne, pair_ne, device):
    """Writes the ``count`` pairs' (n, e) from the directed bond cache (gather_pair_cache)."""
    if count > 0:
        wp.launch(gather_pair_cache, dim=count, inputs=[pair_bond, bond_ne, pair_ne], device=device)


def bond_plastic_from_pairs(count, pair_bond, pair_reverse, pair_plastic, bond_plastic, device):
    """Writes both directed bonds' plastic extensions of the first ``count`` pairs into bond_plastic
    (mirror_pair_plastic)."""
    if count > 0:
        wp.launch(
            mirror_pair_plastic, dim=count, inputs=[pair_bond, pair_reverse, pair_plastic, bond_plastic], device=device
        )


def pair_values_from_bonds(count, pair_bond, pair_reverse, bond_values, pair_values, device):
    """Writes the first ``count`` pairs' (k -> j, j -> k) values from a per-bond array (gather_pair_values)."""
    if count > 0:
        wp.launch(
            gather_pair_values, dim=count, inputs=[pair_bond, pair_reverse, bond_values, pair_values], device=device
        )
