"""Connected components of a graph stored as CSR rows (peridynamic families and their live bonds), on the device.

Every node starts as its own label; then, until nothing changes:

    hook:  for each live edge (k, j) whose endpoints carry different labels a < b: labels[b] <- min(labels[b], a)
    jump:  every node follows its labels to a node that labels itself (a root) and takes that root

Labels only decrease and always name a node of the same component, so the loop ends with every node labelled by the
smallest node index of its component. The loop runs on the device (:func:`label_components`: the loop is
``wp.capture_while``, a conditional node of a CUDA graph when captured; a loop over the recorded operations on the
CPU), and the caller reads only the result.
"""

from typing import Any

import warp as wp


@wp.kernel
def label_init(labels: wp.array(dtype=wp.int32), changed: wp.array(dtype=wp.int32)):
    """labels[i] = i; changed[0] = 1 (the loop runs at least once)."""
    i = wp.tid()
    labels[i] = i
    if i == 0:
        changed[0] = 1


@wp.kernel
def label_clear(changed: wp.array(dtype=wp.int32)):
    """changed[0] = 0 at the start of an iteration."""
    changed[0] = 0


@wp.kernel
def label_hook(
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
    alive: wp.array(dtype=Any),
    labels: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
):
    """For each live edge of node k (``alive`` nonzero): the larger of the two endpoint labels is pointed at the
    smaller one (atomic min); sets changed[0] when the labels differed."""
    k = wp.tid()
    for e in range(offsets[k], offsets[k + 1]):
        if int(alive[e]) != 0:
            j = neighbors[e]
            a = labels[k]
            b = labels[j]
            if a != b:
                wp.atomic_min(labels, wp.max(a, b), wp.min(a, b))
                changed[0] = 1


@wp.kernel
def label_jump(labels: wp.array(dtype=wp.int32), changed: wp.array(dtype=wp.int32)):
    """Node i takes the root its labels lead to (a node labelling itself); sets changed[0] when its label moved."""
    i = wp.tid()
    first = labels[i]
    root = first
    while labels[root] != root:
        root = labels[root]
    if root != first:
        labels[i] = root
        changed[0] = 1


@wp.kernel
def count_live(alive: wp.array(dtype=Any), count: wp.array(dtype=wp.int32)):
    """count[0] += 1 for each nonzero entry of ``alive`` (count zeroed by the caller)."""
    e = wp.tid()
    if int(alive[e]) != 0:
        wp.atomic_add(count, 0, 1)


def label_components(offsets, neighbors, alive, labels, changed, node_count: int, device):
    """Launches the labelling of the ``node_count`` nodes: :func:`label_init`, then iterations of
    :func:`label_clear`, :func:`label_hook` and :func:`label_jump` while changed[0] is set (``wp.capture_while``).
    Afterwards labels[i] is the smallest node index of node i's component.

    Args:
        offsets: CSR row starts, int32 [node_count + 1]; neighbors: neighbour node of each edge, int32.
        alive: per-edge flag (uint8 or int32, nonzero is alive).
        labels: int32 [>= node_count], written; changed: int32 [1], the loop's flag.
        device: Warp device of the launches.
    """

    def iteration():
        wp.launch(label_clear, dim=1, inputs=[changed], device=device)
        wp.launch(label_hook, dim=node_count, inputs=[offsets, neighbors, alive, labels, changed], device=device)
        wp.launch(label_jump, dim=node_count, inputs=[labels, changed], device=device)

    wp.launch(label_init, dim=node_count, inputs=[labels, changed], device=device)
    wp.capture_while(changed, iteration)


def count_live_edges(alive, count, edge_count: int, device):
    """Launches :func:`count_live` over the first ``edge_count`` entries of ``alive``: count[0] += the number of
    nonzero entries (int32 [1], zeroed by the caller)."""
    wp.launch(count_live, dim=edge_count, inputs=[alive, count], device=device)
