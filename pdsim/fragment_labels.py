"""Fragments of a peridynamic body: connected components of its live bonds.

A fragment is a set of particles joined by paths of live (unbroken) bonds. Bonds only ever break, so fragments only
ever split; :class:`FragmentTracker` recomputes the labels only on frames where the number of live bonds dropped, and
reports whether the partition actually changed (bonds can break inside a fragment without splitting it).

Labels are numbered **per body**: within each body (a range ``body_offsets[b] : body_offsets[b + 1]`` of the
concatenated particles) the fragments are numbered in the order of their smallest particle index, so the fragment
holding the body's first particle is 0. With ``compact=False`` the label of a fragment is instead the body-local index
of its smallest particle; that number never changes over an animation (the piece keeping a fragment's smallest
particle keeps its label when the fragment splits), which keeps per-fragment colours stable in a render.

Two labellers give the same labels: scipy's on the host (numpy input), and :class:`DeviceLabeller` on the Warp device
(kernels/fragment_labels.py: label propagation with pointer jumping, its loop captured with ``wp.capture_while`` so that
it runs on the device without a launch and a read per iteration); :class:`FragmentTracker` uses the device one when it
is
given Warp arrays, and then reads only the live-bond count and, when bonds broke, one label per particle.
"""

from __future__ import annotations

import warnings

import numpy as np
import warp as wp
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components as scipy_components

from .kernels import fragment_labels as kg

__all__ = ["DeviceLabeller", "FragmentTracker", "connected_components", "fragment_labels"]


def _as_numpy(array) -> np.ndarray:
    """A numpy view of a numpy array, a Warp array (``.numpy()``) or a sequence."""
    return np.asarray(array.numpy() if hasattr(array, "numpy") else array)


def connected_components(node_count: int, first, second) -> np.ndarray:
    """Component label of each of ``node_count`` nodes joined by the edges (first[e], second[e]) (undirected), as
    int64 [node_count]; components are numbered 0, 1, ... in the order of their smallest node. The one labeller of
    pdsim: peridynamic fragments, FEM pieces and lattice fragments all come from it."""
    a = np.asarray(first, dtype=np.int64).ravel()
    b = np.asarray(second, dtype=np.int64).ravel()
    graph = coo_matrix((np.ones(a.shape[0], dtype=np.int8), (a, b)), shape=(node_count, node_count)).tocsr()
    _, labels = scipy_components(graph, directed=True, connection="weak")
    return renumber_by_first(labels)


def renumber_by_first(labels) -> np.ndarray:
    """Labels renumbered 0, 1, ... in the order of each label's first occurrence, int64."""
    labels = np.asarray(labels).ravel()
    if labels.size == 0:
        return labels.astype(np.int64)
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(first.shape[0], dtype=np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(first.shape[0])
    return rank[inverse.ravel()]


def fragment_labels(family_offsets, family_neighbors, bond_alive, body_offsets=None, *, compact: bool = True):
    """Fragment id of every particle: connected components of the graph of live bonds, numbered per body.

    Args:
        family_offsets: CSR row starts, int shape [particle_count + 1]; the bonds of particle k are
            ``family_offsets[k]:family_offsets[k + 1]``.
        family_neighbors: neighbour particle of each bond, int shape [>= bond_count] (entries past
            ``family_offsets[-1]`` are ignored).
        bond_alive: per-bond flag, bool or int shape [>= bond_count]; nonzero means alive. A pair of particles is
            joined when a bond between them is alive in either direction.
        body_offsets: first particle of each body, int shape [body_count + 1] (``[0, particle_count]`` when None).
        compact: True numbers each body's fragments 0, 1, ... in the order of their smallest particle index; False
            labels each fragment by the body-local index of its smallest particle (stable over an animation).

    Returns:
        Fragment id per particle, int32 shape [particle_count].

    Raises:
        ValueError: inconsistent array shapes, or a live bond joining two bodies.
    """
    offsets = _as_numpy(family_offsets).astype(np.int64, copy=False).ravel()
    n = offsets.shape[0] - 1
    if n < 0:
        raise ValueError("family_offsets must have particle_count + 1 entries")
    bond_count = int(offsets[-1]) if n > 0 else 0
    neighbors = _as_numpy(family_neighbors).astype(np.int64, copy=False).ravel()
    alive = _as_numpy(bond_alive).ravel()
    if neighbors.shape[0] < bond_count or alive.shape[0] < bond_count:
        raise ValueError(
            f"family_neighbors ({neighbors.shape[0]}) and bond_alive ({alive.shape[0]}) need at least "
            f"family_offsets[-1] = {bond_count} entries"
        )
    if body_offsets is None:
        body_offsets = np.array([0, n], dtype=np.int64)
    body_offsets = _as_numpy(body_offsets).astype(np.int64, copy=False).ravel()
    if body_offsets.shape[0] < 2 or body_offsets[0] != 0 or body_offsets[-1] != n or np.any(np.diff(body_offsets) < 0):
        raise ValueError(f"body_offsets must rise from 0 to particle_count = {n}, got {body_offsets.tolist()}")
    if n == 0:
        return np.zeros(0, dtype=np.int32)

    # The families are already a CSR adjacency matrix: keep the live bonds (a prefix count gives the new row starts).
    live = alive[:bond_count] != 0
    live_before = np.zeros(bond_count + 1, dtype=np.int64)
    np.cumsum(live, out=live_before[1:])
    graph = csr_matrix(
        (np.ones(int(live_before[-1]), dtype=np.int8), neighbors[:bond_count][live], live_before[offsets]),
        shape=(n, n),
    )
    _, component = scipy_components(graph, directed=True, connection="weak")
    # Smallest particle index of each component (np.unique's first occurrence).
    _, first = np.unique(component, return_index=True)
    return labels_from_roots(first[component], body_offsets, compact=compact)


def labels_from_roots(root, body_offsets, *, compact: bool = True) -> np.ndarray:
    """Fragment labels (see :func:`fragment_labels`) from ``root``, the smallest particle index of each particle's
    component (int [particle_count]); ``body_offsets`` int [body_count + 1] as there.

    Raises:
        ValueError: a component holding particles of two bodies (a live bond joining two bodies).
    """
    root = np.asarray(root, dtype=np.int64).ravel()
    body_offsets = np.asarray(body_offsets, dtype=np.int64).ravel()
    n = root.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int32)
    first = np.flatnonzero(root == np.arange(n))  # the roots, ascending: one per component
    body_of = np.searchsorted(body_offsets, np.arange(n), side="right") - 1
    if np.any(body_of[root] != body_of):
        raise ValueError("a live bond joins particles of two different bodies")
    if not compact:
        return (root - body_offsets[body_of]).astype(np.int32)
    # Global rank of each component by its root; a body's components hold consecutive ranks starting at the rank
    # of the component of its first particle, so subtracting that rank numbers fragments per body.
    rank = np.searchsorted(first, root)
    nonempty = np.diff(body_offsets) > 0
    base = np.zeros(body_offsets.shape[0] - 1, dtype=np.int64)
    base[nonempty] = rank[body_offsets[:-1][nonempty]]
    return (rank - base[body_of]).astype(np.int32)


class DeviceLabeller:
    """Connected components of the live edges of a CSR graph on the Warp device (kernels/fragment_labels.py).

    The labelling (an initialisation, then hook and jump passes until a pass changes nothing) is captured once as a
    graph whose loop is ``wp.capture_while`` on a device flag: on CUDA a conditional node, so one graph launch runs
    it to convergence on the device; on the CPU Warp's recorded replay. :meth:`roots` launches it and returns the
    device labels: the smallest node index of each node's component.

    Args:
        offsets: CSR row starts, int32 Warp array [node_count + 1] (or numpy, copied to ``device``).
        neighbors: neighbour node of each edge, int32 Warp array [>= edge_count] (or numpy).
        alive: per-edge flag (Warp array of uint8 or int32, nonzero is alive), read at each launch.
        device: Warp device (default: ``alive``'s).
    """

    _warned = False  # the host-loop warning was given (class-wide: once per process)

    def __init__(self, offsets, neighbors, alive, device=None):
        self.device = wp.get_device(device if device is not None else alive.device)

        def on_device(a):
            if isinstance(a, wp.array) and a.dtype == wp.int32 and a.device == self.device:
                return a
            return wp.array(_as_numpy(a).astype(np.int32).ravel(), dtype=wp.int32, device=self.device)

        self.offsets = on_device(offsets)
        self.neighbors = on_device(neighbors)
        self.alive = alive
        self.node_count = int(self.offsets.shape[0]) - 1
        self.labels = wp.zeros(max(self.node_count, 1), dtype=wp.int32, device=self.device)
        self.changed = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._graph = None

    def _launch_all(self):
        kg.label_components(
            self.offsets, self.neighbors, self.alive, self.labels, self.changed, self.node_count, self.device
        )

    def roots(self):
        """Labels the components now (``alive`` as it is); returns the int32 Warp array [node_count] of each node's
        smallest component member."""
        if self.node_count <= 0:
            return self.labels[:0]
        if self.device.is_cuda and not wp.is_conditional_graph_supported():
            # the loop's conditional node needs a CUDA 12.4+ driver: said once, then the loop runs from the host
            # (wp.capture_while outside a capture: a launch of the iteration and a read of the flag per iteration)
            if not DeviceLabeller._warned:
                DeviceLabeller._warned = True
                warnings.warn(
                    "fragment labelling loops from the host: this CUDA driver has no conditional graph nodes "
                    "(CUDA 12.4+ needed)",
                    stacklevel=2,
                )
            self._launch_all()
            return self.labels[: self.node_count]
        if self._graph is None:
            # warm-up outside the capture: loads the kernels, then the capture records the labelling
            self._launch_all()
            with wp.ScopedCapture(device=self.device) as capture:
                self._launch_all()
            self._graph = capture.graph
        wp.capture_launch(self._graph)
        return self.labels[: self.node_count]


class FragmentTracker:
    """Keeps the fragment labels of all peridynamic bodies of a solver up to date, cheaply.

    :meth:`update` counts the live bonds (one vectorised pass); only when that number dropped since the previous
    call does it recompute the connected components. It returns True when the labels changed.

    Args:
        family_offsets: CSR row starts, int shape [particle_count + 1] (numpy or Warp array).
        family_neighbors: neighbour of each bond, int shape [>= bond_count].
        body_offsets: first particle of each body, int shape [body_count + 1] (None: one body).
        compact: numbering of the labels (see :func:`fragment_labels`).

    Attributes:
        labels: fragment id per particle, int32 shape [particle_count]; all zeros before the first update
            (one fragment per body: the intact state).
        version: number of times the labels changed (0 for the intact state).
    """

    def __init__(self, family_offsets, family_neighbors, body_offsets=None, *, compact: bool = True):
        self.family_offsets = _as_numpy(family_offsets).astype(np.int64).ravel()
        n = self.family_offsets.shape[0] - 1
        self.bond_count = int(self.family_offsets[-1]) if n > 0 else 0
        self.family_neighbors = _as_numpy(family_neighbors).astype(np.int64).ravel()[: self.bond_count]
        self.body_offsets = (
            np.array([0, n], dtype=np.int64)
            if body_offsets is None
            else _as_numpy(body_offsets).astype(np.int64).ravel()
        )
        self.compact = bool(compact)
        self._device_inputs = (family_offsets, family_neighbors)
        self._labeller = None  # DeviceLabeller, made on the first update given a Warp array
        self._count = None
        self.live_bond_count: int | None = None
        # Intact: one fragment per body, label 0 in both numberings (each body's first particle has local index 0).
        self.labels = np.zeros(n, dtype=np.int32)
        self.version = 0

    @property
    def body_count(self) -> int:
        return self.body_offsets.shape[0] - 1

    def body_labels(self, body: int) -> np.ndarray:
        """Labels of the particles of ``body``, int32 shape [body particle_count] (a view)."""
        return self.labels[self.body_offsets[body] : self.body_offsets[body + 1]]

    def fragment_count(self, body: int) -> int:
        """Number of fragments of ``body`` (1 while it is intact)."""
        return int(np.unique(self.body_labels(body)).shape[0])

    def update(self, bond_alive, *, live_bond_count: int | None = None) -> bool:
        """Recomputes the labels if bonds broke since the previous call.

        Args:
            bond_alive: per-bond flag, bool or int shape [>= bond_count] (numpy or Warp array); nonzero is alive.
            live_bond_count: number of live bonds if the caller already knows it (e.g. reduced on the device);
                counted here otherwise.

        Returns:
            True when the labels differ from those returned by the previous call.
        """
        if isinstance(bond_alive, wp.array):
            return self._update_on_device(bond_alive, live_bond_count)
        alive = _as_numpy(bond_alive).ravel()[: self.bond_count]
        count = int(np.count_nonzero(alive)) if live_bond_count is None else int(live_bond_count)
        if count == self.live_bond_count:
            return False
        self.live_bond_count = count
        labels = fragment_labels(
            self.family_offsets, self.family_neighbors, alive, self.body_offsets, compact=self.compact
        )
        if np.array_equal(labels, self.labels):
            return False
        self.labels = labels
        self.version += 1
        return True

    def _update_on_device(self, bond_alive, live_bond_count) -> bool:
        """:meth:`update` for a Warp array: the live bonds are counted on the device (one number read) and, when
        their number dropped, labelled there (:class:`DeviceLabeller`; one label per particle read)."""
        n = self.labels.shape[0]
        if self.bond_count == 0 or n == 0:
            return False
        if live_bond_count is None:
            if self._count is None:
                self._count = wp.zeros(1, dtype=wp.int32, device=bond_alive.device)
            self._count.zero_()
            kg.count_live_edges(bond_alive, self._count, self.bond_count, bond_alive.device)
            live_bond_count = int(self._count.numpy()[0])
        count = int(live_bond_count)
        if count == self.live_bond_count:
            return False
        self.live_bond_count = count
        if self._labeller is None or self._labeller.alive is not bond_alive:
            offsets, neighbors = self._device_inputs
            self._labeller = DeviceLabeller(offsets, neighbors, bond_alive)
        root = self._labeller.roots().numpy()
        labels = labels_from_roots(root, self.body_offsets, compact=self.compact)
        if np.array_equal(labels, self.labels):
            return False
        self.labels = labels
        self.version += 1
        return True
