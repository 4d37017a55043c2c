"""Connected components of a graph stored as CSR rows (peridynamic families and their live bonds), on the device.

Every node starts as its own label; then, until nothing changes:

    hook:  for each live edge (k, j) whose endpoints carry different labels a < b: labels[b] <- min(labels[b], a)
    jump:  every node follows its labels to a node that labels itself (a root) and takes that root

Labels only decrease and always name a node of the same component, so the loop ends with every node labelled by the
smallest node index of its component. The loop runs on the device: pdsim/graph.py captures it with
``wp.capture_while`` (a conditional node of a CUDA graph; a loop over the recorded operations on the CPU) and reads
only the result.
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
