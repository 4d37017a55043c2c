"""Kernels that build peridynamic families (CSR neighbour lists) from a ``wp.HashGrid``.

Bonds are directed: particle k's family lists every j != k of the same body with |X_j - X_k| <= radius. Each list is
filled in hash-grid order, which is deterministic for a given grid and particle order.
"""

import warp as wp


@wp.func
def same_body_count(
    grid: wp.uint64,
    rest: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    k: int,
    cut: float,
):
    """Number of particles j != k of particle k's body within ``cut`` [m] of it (positions ``rest``, hashed in
    ``grid``)."""
    xk = rest[k]
    bk = body_id[k]
    n = int(0)
    query = wp.hash_grid_query(grid, xk, cut)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if j != k and body_id[j] == bk:
            if wp.length(rest[j] - xk) <= cut:
                n += 1
    return n


@wp.kernel
def count_family(
    grid: wp.uint64,
    rest: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    counts: wp.array(dtype=wp.int32),
):
    """counts[k] = number of particles j != k of the same body within radius[k] of particle k."""
    k = wp.tid()
    counts[k] = same_body_count(grid, rest, body_id, k, radius[k])


@wp.kernel
def fill_family(
    grid: wp.uint64,
    rest: wp.array(dtype=wp.vec3),
    body_id: wp.array(dtype=wp.int32),
    radius: wp.array(dtype=float),
    offsets: wp.array(dtype=wp.int32),
    neighbors: wp.array(dtype=wp.int32),
):
    """Writes the family of particle k into neighbors[offsets[k] : offsets[k + 1]] (same rule as count_family; the
    loop of same_body_count repeated, since it writes each neighbour where that one counts)."""
    k = wp.tid()
    xk = rest[k]
    r = radius[k]
    bk = body_id[k]
    q = offsets[k]
    query = wp.hash_grid_query(grid, xk, r)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if j != k and body_id[j] == bk:
            if wp.length(rest[j] - xk) <= r:
                neighbors[q] = j
                q += 1


def build_families(rest, body_id, radius, device):
    """CSR families via a hash grid (:func:`count_family`, a scan, :func:`fill_family`): the points within ``radius``
    of each point of ``rest`` in the same body. Returns (offsets, neighbors) Warp arrays and the bond count."""
    n = rest.shape[0]
    cell = float(radius.numpy().max())
    dim = int(max(8, min(128, round(n ** (1.0 / 3.0)))))
    grid = wp.HashGrid(dim, dim, dim, device=device)
    grid.build(rest, cell)
    counts = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(count_family, dim=n, inputs=[grid.id, rest, body_id, radius, counts], device=device)
    offsets = wp.zeros(n + 1, dtype=wp.int32, device=device)
    wp.utils.array_scan(counts, offsets[1:], inclusive=True)
    bond_count = int(offsets.numpy()[-1])
    neighbors = wp.zeros(max(bond_count, 1), dtype=wp.int32, device=device)
    wp.launch(fill_family, dim=n, inputs=[grid.id, rest, body_id, radius, offsets, neighbors], device=device)
    return offsets, neighbors, bond_count
