"""The peridynamic bond passes over bond pairs on the CPU (kernels/peridynamics/pairs.py): the pair layout, the fixed
pair ranges and their buffers, and one step's dilatation and force passes.

Each undirected pair is evaluated once, by the thread of its lower particle; the upper particle's share goes to a
buffer of the pair range the lower particle belongs to, and a sum pass adds the buffers in range order. The
PAIR_RANGES ranges are set by the particles' pair counts only (never by the thread count); the threads take
contiguous blocks of whole ranges, so results are bit-identical for any thread count. Used on a CPU device, with
plasticity too (the return mapping in pair passes, kernels/peridynamics/pairs.py), except for yielding bodies with the
rigid hand-off; those scenes and every CUDA scene run the directed kernels of kernels/peridynamics/step.py (the GPU
would need atomics for the scatter)."""

from __future__ import annotations

import numpy as np
import warp as wp

from ..kernels.peridynamics import pairs as kp
from ..kernels.peridynamics import step as pd_step
from .ranges import ParticleRanges, equal_cost_bounds

PAIR_RANGES = 12
"""Fixed pair ranges (and buffers) of the pair passes: the most threads the pair passes use; 12 splits evenly over
1, 2, 3, 4 and 6 threads."""


def pair_layout(
    offsets: np.ndarray, neighbors: np.ndarray, reverse: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For directed bonds in CSR form (``offsets`` [n + 1], ``neighbors`` [bonds]) and the index of each bond's
    reverse j -> k (``reverse``, -1 where a bond has none): the per-particle prefix sums of the pairs (bonds with
    j > k), the pairs' directed bonds k -> j (in family order) and their reverse bonds j -> k, as int64 arrays."""
    n = len(offsets) - 1
    offsets = np.asarray(offsets, dtype=np.int64)
    count = int(offsets[-1])
    owner = np.repeat(np.arange(n, dtype=np.int32), np.diff(offsets))
    forward = np.flatnonzero(np.asarray(neighbors[:count]) > owner)
    back = np.asarray(reverse[:count])[forward].astype(np.int64)
    if (back < 0).any() or 2 * len(forward) != count:
        raise ValueError("peridynamic bonds are not symmetric: a bond k -> j has no reverse j -> k")
    pair_offsets = np.zeros(n + 1, dtype=np.int64)
    pair_offsets[1:] = np.cumsum(np.bincount(owner[forward], minlength=n))
    return pair_offsets, forward, back


class PairPasses:
    """The pair form of one step's bond passes on a CPU device (``ductile``: some yielding body has a failure plastic
    strain, so the ductile breaking test runs): the pair arrays
    (kernels/peridynamics/pairs.py), the fixed ranges over the particles (or over the rigid hand-off's live list,
    :meth:`set_particles`) and the buffers, launched on ``threads`` threads (:meth:`set_threads`)."""

    def __init__(self, model, fracture: bool, handoff: bool, device, ductile: bool = False):
        self.device = device
        self.model = model
        self.plastic = bool(model.plastic)
        self.ductile = bool(ductile) and self.plastic and fracture
        self.kernels = kp.make_pair_kernels(
            fracture, handoff, self.plastic, self.ductile, damped=model.damping_b is not None
        )
        self.fracture = fracture
        n = model.particle_count
        offsets = model.family_offsets.numpy()[: n + 1]
        reverse = wp.zeros(max(model.bond_count, 1), dtype=wp.int32, device=device)
        pd_step.reverse_bonds(n, model.family_offsets, model.family_neighbors, reverse, device)
        neighbors = model.family_neighbors.numpy()
        pair_offsets, forward, reverse = pair_layout(offsets, neighbors, reverse.numpy())
        self.pair_count = len(forward)
        self._pair_offsets_host = pair_offsets
        count = max(self.pair_count, 1)

        def arr(values, dtype):
            if not self.pair_count:
                return wp.zeros(count, dtype=dtype, device=device)
            return wp.array(values, dtype=dtype, device=device)

        # one host temporary at a time (the build's peak memory: pdsim/preflight.py PD_BYTES_PER_BOND)
        self.pair_offsets = wp.array(pair_offsets.astype(np.int32), dtype=wp.int32, device=device)
        self.pair_neighbors = arr(neighbors[forward].astype(np.int32), wp.int32)
        self.pair_bond = arr(forward.astype(np.int32), wp.int32)
        self.pair_reverse = arr(reverse.astype(np.int32), wp.int32)
        self.pair_geom = arr(model.bond_geom.numpy()[forward], wp.vec4)
        weights = np.empty((self.pair_count, 4), dtype=np.float32)
        for column, (source, bonds) in enumerate(
            ((model.bond_wv_dil, forward), (model.bond_wv_dil, reverse), (model.bond_wv_dev, forward),
             (model.bond_wv_dev, reverse))
        ):  # fmt: skip
            weights[:, column] = source.numpy()[bonds]
        self.pair_weights = arr(weights, wp.vec4)
        del weights, forward, reverse
        self.plastic_pair_count = 0
        if self.plastic:  # the yielding particles' pairs (a prefix): w V beta of both directions, (e^p_kj, e^p_jk)
            self.plastic_pair_count = npp = int(pair_offsets[model.plastic_particle_count])
            self.pair_wv = wp.zeros(max(npp, 1), dtype=wp.vec2, device=device)
            kp.pair_values_from_bonds(npp, self.pair_bond, self.pair_reverse, model.bond_wv, self.pair_wv, device)
            self.pair_plastic = wp.zeros(max(npp, 1), dtype=wp.vec2, device=device)
            self.plastic_th3 = wp.zeros(n, dtype=float, device=device)  # theta_p / 3 of the step
            self.plastic_ratio = wp.zeros(n, dtype=float, device=device)  # the return mapping's scale, -1: elastic
            self.plastic_sum = wp.zeros(n, dtype=wp.vec2, device=device)  # own sums of the plastic passes
        self.pair_ne = wp.zeros(count, dtype=wp.vec4, device=device)
        self.cache_stale = False  # the directed bond cache lags the pairs' (bond_cache)
        self.plastic_stale = False  # the directed plastic extensions lag the pairs' (bond_cache)
        self._threads = 1
        self._entries = None  # particle index of each list entry (the hand-off's live list), None: every particle
        self._placeholder = wp.zeros(1, dtype=float, device=device)
        self._placeholder2 = wp.zeros(1, dtype=wp.vec2, device=device)
        self._build()

    # -- ranges ------------------------------------------------------------------------------------------------------
    def set_threads(self, threads: int) -> None:
        """Threads of the pair passes (at most PAIR_RANGES are used); the ranges themselves do not change."""
        self._threads = max(1, int(threads))
        self._build()

    def set_particles(self, entries: np.ndarray | None) -> None:
        """The particles the passes compute, ascending (the rigid hand-off's live list), or None for all. With
        plasticity the list must start with every yielding particle (the plastic passes index particles, not list
        entries: kernels/peridynamics/pairs.py make_pair_kernels); a list without them raises ValueError."""
        entries = None if entries is None else np.asarray(entries, dtype=np.int64)
        npp = self.model.plastic_particle_count if self.plastic else 0
        if entries is not None and npp and not np.array_equal(entries[:npp], np.arange(npp)):
            raise ValueError("the pair passes' live list leaves out yielding particles (a yielding body handed off)")
        self._entries = entries
        self._build()

    def _build(self) -> None:
        """Fixed pair ranges over the entries, their particle spans and buffers, and the threads' spans."""
        n = self.model.particle_count
        entries = np.arange(n, dtype=np.int64) if self._entries is None else self._entries
        d = self.device
        pairs = np.diff(self._pair_offsets_host)[entries]
        cost = np.concatenate([[0], np.cumsum(pairs)]).astype(np.int64)
        bounds = equal_cost_bounds(cost, PAIR_RANGES) if len(entries) else [0, 0]
        count = len(bounds) - 1
        slot = np.repeat(np.arange(count, dtype=np.int32), np.diff(bounds))
        lo = np.zeros(count, dtype=np.int64)
        hi = np.full(count, -1, dtype=np.int64)
        neighbors = self.pair_neighbors.numpy()
        for r in range(count):  # a handful of ranges: each range's particle span and the highest j it writes
            a, b = bounds[r], bounds[r + 1]
            if b > a:
                lo[r] = entries[a]
                first, last = self._pair_offsets_host[entries[a]], self._pair_offsets_host[entries[b - 1] + 1]
                hi[r] = max(int(entries[b - 1]), int(neighbors[first:last].max()) if last > first else -1)
        width = np.maximum(hi - lo + 1, 0)
        base = np.concatenate([[0], np.cumsum(width)[:-1]])
        total = max(int(width.sum()), 1)
        self.range_count = count
        self.pair_slot = wp.array(np.append(slot, 0).astype(np.int32), dtype=wp.int32, device=d)
        self.range_lo = wp.array(lo.astype(np.int32), dtype=wp.int32, device=d)
        self.range_hi = wp.array(hi.astype(np.int32), dtype=wp.int32, device=d)
        self.buffer_base = wp.array(base.astype(np.int32), dtype=wp.int32, device=d)
        self.theta_buffer = wp.zeros(total, dtype=float, device=d)
        self.stretch_buffer = wp.zeros(total, dtype=float, device=d) if self.fracture else self._placeholder
        self.force_buffer = wp.zeros(total, dtype=wp.vec3, device=d)
        self.plastic_buffer = wp.zeros(total, dtype=wp.vec2, device=d) if self.plastic else self._placeholder2
        # the threads' spans: contiguous blocks of whole ranges of about equal cost
        blocks = equal_cost_bounds(cost[bounds], self._threads)
        spans = [bounds[b] for b in blocks]
        self.launcher = ParticleRanges(cost, len(spans) - 1, d, bounds=spans)

    # -- the passes --------------------------------------------------------------------------------------------------
    def dilatation_and_forces(self, s, m, displacements, velocities, alive, live, f1) -> None:
        """One step's dilatation (theta, bp, the most compressive stretch), with plasticity the return mapping (the
        plastic extensions, the equivalent plastic strain), and force density (with the breaking tests and the
        internal damping, which reads ``velocities``) into the state ``s`` of the model ``m`` at ``displacements``;
        ``alive`` the live flags (or a placeholder), ``live`` the hand-off's live list (or a placeholder), ``f1`` a
        float placeholder."""
        launch, ks = self.launcher.launch, self.kernels
        ranges = {"range_lo": self.range_lo, "buffer_base": self.buffer_base}
        sums = {"range_count": self.range_count, "range_hi": self.range_hi, **ranges}
        frac, plastic = self.fracture, self.plastic
        v2 = self._placeholder2
        npp = m.plastic_particle_count if plastic else 0
        common = {
            "plastic_particle_count": npp,
            "plastic_sum": self.plastic_sum if plastic else v2,
        }
        pair_wv = self.pair_wv if plastic else v2
        th3 = self.plastic_th3 if plastic else f1
        ratio = self.plastic_ratio if plastic else f1
        kp.pair_dilatation(
            launch,
            ks,
            live_particles=live,
            pair_slot=self.pair_slot,
            displacements=displacements,
            pair_offsets=self.pair_offsets,
            pair_neighbors=self.pair_neighbors,
            pair_bond=self.pair_bond,
            pair_geom=self.pair_geom,
            pair_weights=self.pair_weights,
            bond_alive=alive,
            pair_ne=self.pair_ne,
            theta_sum=s.theta,
            stretch_min=s.stretch_min if frac else f1,
            theta_buffer=self.theta_buffer,
            stretch_buffer=self.stretch_buffer,
            pair_wv=pair_wv,
            plastic_buffer=self.plastic_buffer,
            **common,
            **ranges,
        )
        kp.pair_dilatation_sum(
            launch,
            ks,
            live_particles=live,
            theta_buffer=self.theta_buffer,
            stretch_buffer=self.stretch_buffer,
            dil_d=m.dil_d,
            dil_coef=m.dil_coef,
            dev_b=m.dev_b,
            theta=s.theta,
            stretch_min=s.stretch_min if frac else f1,
            bp=s.bp,
            plastic_buffer=self.plastic_buffer,
            plastic_th3=th3,
            **common,
            **sums,
        )
        if plastic:
            kp.pair_plastic_norm(
                launch,
                ks,
                pair_slot=self.pair_slot,
                pair_offsets=self.pair_offsets,
                pair_neighbors=self.pair_neighbors,
                pair_bond=self.pair_bond,
                pair_geom=self.pair_geom,
                pair_weights=self.pair_weights,
                pair_wv=pair_wv,
                pair_ne=self.pair_ne,
                pair_plastic=self.pair_plastic,
                bond_alive=alive,
                dev_b=m.dev_b,
                plastic_th3=th3,
                theta_buffer=self.theta_buffer,
                **common,
                **ranges,
            )
            kp.pair_plastic_norm_sum(
                launch,
                ks,
                theta_buffer=self.theta_buffer,
                horizon=m.horizon,
                yield_stress=m.yield_stress,
                hardening=m.hardening,
                psi_scale=m.psi_scale,
                eqps=s.eqps,
                plastic_ratio=ratio,
                **common,
                **sums,
            )
            self.plastic_stale = True
        kp.pair_forces(
            launch,
            ks,
            live_particles=live,
            pair_slot=self.pair_slot,
            pair_offsets=self.pair_offsets,
            pair_neighbors=self.pair_neighbors,
            pair_bond=self.pair_bond,
            pair_reverse=self.pair_reverse,
            pair_geom=self.pair_geom,
            pair_weights=self.pair_weights,
            pair_ne=self.pair_ne,
            bp=s.bp,
            bond_alive=alive,
            bond_critical_stretch=m.bond_critical_stretch if frac else f1,
            compressive_bonus=m.compressive_bonus if frac else f1,
            compressive_stretch_floor=m.compressive_stretch_floor if frac else f1,
            stretch_min=s.stretch_min if frac else f1,
            force_density=s.force_density,
            force_buffer=self.force_buffer,
            pair_wv=pair_wv,
            pair_plastic=self.pair_plastic if plastic else v2,
            plastic_th3=th3,
            plastic_ratio=ratio,
            theta_buffer=self.theta_buffer,
            velocities=velocities,
            damping_b=m.damping_b if m.damping_b is not None else f1,
            **common,
            **ranges,
        )
        kp.pair_force_sum(
            launch,
            ks,
            live_particles=live,
            force_buffer=self.force_buffer,
            force_density=s.force_density,
            theta_buffer=self.theta_buffer,
            plastic_ratio=ratio,
            weighted_volume=m.weighted_volume if plastic else f1,
            eqps=s.eqps if plastic else f1,
            **common,
            **sums,
        )
        if self.ductile:
            kp.pair_ductile_break(
                launch,
                ks,
                plastic_particle_count=npp,
                pair_offsets=self.pair_offsets,
                pair_neighbors=self.pair_neighbors,
                pair_bond=self.pair_bond,
                pair_reverse=self.pair_reverse,
                pair_ne=self.pair_ne,
                eqps=s.eqps,
                failure_eqps=m.failure_eqps,
                bond_alive=alive,
            )
        self.cache_stale = True

    def bond_cache(self, state) -> None:
        """Brings the directed bond cache ``state.bond_ne`` (read by the energy pass, crack events, the watchdog and
        checkpoints) and, with plasticity, the directed plastic extensions ``state.bond_plastic`` up to the pairs'
        last step, if they lag."""
        if self.cache_stale:
            kp.bond_cache_from_pairs(
                self.pair_count, self.pair_bond, self.pair_reverse, self.pair_ne, state.bond_ne, self.device
            )
            self.cache_stale = False
        if self.plastic_stale:
            kp.bond_plastic_from_pairs(
                self.plastic_pair_count, self.pair_bond, self.pair_reverse, self.pair_plastic, state.bond_plastic,
                self.device,
            )  # fmt: skip
            self.plastic_stale = False

    def restore_cache(self, state) -> None:
        """The pairs' cache and plastic extensions from the directed ones (after a checkpoint is restored), so that
        later mirrors of the pairs that no pass visits (broken, or in rigid fragments) write back what the directed
        arrays held."""
        kp.pair_cache_from_bonds(self.pair_count, self.pair_bond, state.bond_ne, self.pair_ne, self.device)
        self.cache_stale = False
        if self.plastic:
            kp.pair_values_from_bonds(
                self.plastic_pair_count, self.pair_bond, self.pair_reverse, state.bond_plastic, self.pair_plastic,
                self.device,
            )  # fmt: skip
        self.plastic_stale = False
