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
flags are cleared by the one thread that owns the pair. Plasticity (its return mapping needs a particle's whole
family) has no pair form: such scenes run the directed kernels.
"""

import warp as wp

from ..launch import range_inputs
from .bonds import deformed_bond

_cache = {}


def make_pair_kernels(fracture: bool, handoff: bool = False):
    """Pair kernels (dilatation, its sum, force, its sum) for the feature set, built once and cached. With
    ``handoff`` thread t of a launch computes particle live_particles[first + t] (as the directed kernels), else
    particle first + t; ``pair_slot`` is indexed like the particles of the launch (list entry or particle)."""
    key = (bool(fracture), bool(handoff))
    if key in _cache:
        return _cache[key]
    FRACTURE = key[0]
    HANDOFF = key[1]

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
    ):
        """For particle k: each live pair's (n, e) (cached in pair_ne), k's share sum w e V beta G^dil into
        theta_sum[k] and j's into j's slot of the range's theta_buffer; with fracture the most compressive stretch
        e / L of k's pairs into stretch_min[k] and, for j, into stretch_buffer (a minimum)."""
        t = first + wp.tid()
        k = t
        if wp.static(HANDOFF):
            k = live_particles[t]
        r = pair_slot[t]
        shift = buffer_base[r] - range_lo[r]
        uk = displacements[k]
        acc = float(0.0)
        smin = float(0.0)
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
        theta_sum[k] = acc
        if wp.static(FRACTURE):
            stretch_min[k] = smin

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
    ):
        """theta_k = d_k (own sum + the ranges' buffers in range order) [-] (theta holds the own sum on entry),
        (b_k, P_k), and with fracture the minimum of the stretches; clears the buffer slots it read."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        s = theta[k]
        smin = float(0.0)
        if wp.static(FRACTURE):
            smin = stretch_min[k]
        for r in range(range_count):
            if k >= range_lo[r] and k <= range_hi[r]:
                i = buffer_base[r] + k - range_lo[r]
                s += theta_buffer[i]
                theta_buffer[i] = 0.0
                if wp.static(FRACTURE):
                    smin = wp.min(smin, stretch_buffer[i])
                    stretch_buffer[i] = 0.0
        th = dil_d[k] * s
        theta[k] = th
        bp[k] = wp.vec2(dev_b[k], dil_coef[k] * th)
        if wp.static(FRACTURE):
            stretch_min[k] = smin

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
    ):
        """For particle k: each live pair's force terms, k's 2 (w^dil (P_k + P_j) + w^dev (b_k + b_j) e) n into
        force_density[k] and j's (with the weights of j -> k, direction -n) into j's slot of the range's
        force_buffer [N/m^3]; then, with fracture, the breaking test of the directed force kernel, clearing both
        directed flags of a broken pair (it takes effect from the next pass)."""
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
        for p in range(pair_offsets[k], pair_offsets[k + 1]):
            q = int(0)
            if wp.static(FRACTURE):
                q = pair_bond[p]
                if bond_alive[q] == wp.uint8(0):
                    continue
            j = pair_neighbors[p]
            c = pair_ne[p]
            bpj = bp[j]
            dev = (bpk[0] + bpj[0]) * c[3]
            dil = bpk[1] + bpj[1]
            w = pair_weights[p]
            n = wp.vec3(c[0], c[1], c[2])
            f += (2.0 * (w[0] * dil + w[2] * dev)) * n
            force_buffer[shift + j] -= (2.0 * (w[1] * dil + w[3] * dev)) * n
            if wp.static(FRACTURE):
                sc0 = bond_critical_stretch[q]
                sc = sc0 - bonus_k * wp.max(wp.min(smin_k, stretch_min[j]), -floor_k * sc0)
                if c[3] > sc * pair_geom[p][3]:
                    bond_alive[q] = wp.uint8(0)
                    bond_alive[pair_reverse[p]] = wp.uint8(0)
        force_density[k] = f

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
    ):
        """force_density[k] += the ranges' buffers in range order [N/m^3]; clears the slots it read."""
        k = first + wp.tid()
        if wp.static(HANDOFF):
            k = live_particles[k]
        f = force_density[k]
        for r in range(range_count):
            if k >= range_lo[r] and k <= range_hi[r]:
                i = buffer_base[r] + k - range_lo[r]
                f += force_buffer[i]
                force_buffer[i] = wp.vec3(0.0)
        force_density[k] = f

    class PairKernels:
        pass

    ks = PairKernels()
    ks.dilatation, ks.dilatation_sum = pair_dilatation, pair_dilatation_sum
    ks.force, ks.force_sum = pair_force, pair_force_sum
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


# ---------------------------------------------------------------------------------------------------- launches
def pair_dilatation(launch, ks, **arguments):
    """The pair dilatation pass of the kernels ``ks`` (make_pair_kernels) through ``launch(kernel, inputs)``: each
    live pair's (n, e), the own sums and the ranges' buffers."""
    launch(ks.dilatation, range_inputs(ks.dilatation, arguments))


def pair_dilatation_sum(launch, ks, **arguments):
    """theta [-], (b_k, P_k) and the most compressive stretch from the own sums and the buffers
    (``ks.dilatation_sum``)."""
    launch(ks.dilatation_sum, range_inputs(ks.dilatation_sum, arguments))


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
