"""Crack events of a peridynamic solver: per frame, every bond that broke in it (``Scene.run(crack_events=True)``).

The bonds are found and gathered on the device (kernels/peridynamics/events.py: flags, a prefix sum, a gather), and
only the compact event arrays come back to the host, one EventsView per body: the broken bonds' midpoints [m], their
directions when they broke (the normals of the crack faces they open) and the elastic energy each held then [J].
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..kernels.peridynamics import events as kev
from ..output.views import EventsView


def _entry(array, i: int) -> int:
    """One entry of a Warp int array, read without copying the rest."""
    return int(array[i : i + 1].numpy()[0])


class CrackEvents:
    """Collects the crack events of ``solver`` (a SolverPeridynamics) frame by frame: :meth:`collect` returns the
    bonds broken since the previous call (since the solver's current state for the first one)."""

    def __init__(self, solver):
        self.solver = solver
        m = solver.model
        device = solver.device
        nb = max(m.bond_count, 1)
        self.before = wp.zeros(nb, dtype=wp.uint8, device=device)  # the live flags at the last collect
        self.flags = wp.zeros(nb, dtype=wp.int32, device=device)
        self.rows = wp.zeros(nb, dtype=wp.int32, device=device)
        offsets = m.family_offsets.numpy()
        self._body_bond_start = offsets[np.asarray(m.body_offsets, dtype=np.int64)]  # first bond row of each body
        self.reset()

    def reset(self) -> None:
        """Start counting from the solver's current bonds (at the start of a run, or of a resumed one)."""
        state = self.solver.state
        if self.solver.model.fracture and state.bond_alive.shape[0] == self.before.shape[0]:
            wp.copy(self.before, state.bond_alive)
        else:
            self.before.fill_(1)

    def checkpoint(self) -> np.ndarray:
        """The live flags of the last collect (uint8 per bond), for :meth:`restore`."""
        return self.before.numpy()

    def restore(self, before) -> None:
        """Put a :meth:`checkpoint` back (a run resumed inside a frame counts the whole frame's breaks)."""
        a = np.asarray(before, dtype=np.uint8)
        if a.shape != tuple(self.before.shape):
            raise ValueError(f"crack event state has {a.shape[0]} bonds; the solver has {self.before.shape[0]}")
        self.before.assign(a)

    def collect(self) -> list[EventsView]:
        """One EventsView per body: the bonds that broke since the last call, in particle order."""
        s, m, device = self.solver, self.solver.model, self.solver.device
        n = m.particle_count
        views = []
        if not m.fracture:
            empty = (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
            return [EventsView(b.name, *empty, s.origin) for b in s.bodies]
        kev.broken_bond_flags(
            n, m.family_offsets, m.family_neighbors, s.state.bond_alive, self.before, self.flags, device
        )
        kev.event_rows(self.flags, self.rows)
        nb = m.bond_count
        total = _entry(self.rows, nb - 1) + _entry(self.flags, nb - 1) if nb else 0
        # each body's first row: the row of its first bond (bodies own contiguous bond ranges)
        starts = [total if q >= nb else _entry(self.rows, q) for q in self._body_bond_start.tolist()]
        positions = wp.zeros(max(total, 1), dtype=wp.vec3, device=device)
        normals = wp.zeros(max(total, 1), dtype=wp.vec3, device=device)
        energies = wp.zeros(max(total, 1), dtype=float, device=device)
        if total:
            kev.broken_bond_events(
                n,
                device,
                family_offsets=m.family_offsets,
                family_neighbors=m.family_neighbors,
                flags=self.flags,
                rows=self.rows,
                rest_positions=m.rest_positions,
                displacements=s.kin.u,
                volumes=m.volumes,
                dev_b=m.dev_b,
                bond_wv_dev=m.bond_wv_dev,
                bond_ne=s.bond_cache(),
                plastic_bond_count=m.plastic_bond_count,
                bond_plastic=s.state.bond_plastic,
                event_positions=positions,
                event_normals=normals,
                event_energies=energies,
            )
        wp.copy(self.before, s.state.bond_alive)
        x = positions.numpy()[:total].astype(np.float64) + s.origin
        nrm = normals.numpy()[:total]
        w = energies.numpy()[:total].astype(np.float64)
        for i, b in enumerate(s.bodies):
            lo, hi = int(starts[i]), int(starts[i + 1])
            views.append(EventsView(b.name, x[lo:hi], nrm[lo:hi], w[lo:hi], s.origin))
        return views
