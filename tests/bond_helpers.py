"""Bond helpers shared by the tests: the two particles of every bond of a model, and bonds broken by hand."""

import numpy as np


def bond_ends(model) -> tuple[np.ndarray, np.ndarray]:
    """(k, j): the first and the second particle of every bond of a peridynamic ``model``, in its families' order
    (int64 arrays of its bond count)."""
    offsets = model.family_offsets.numpy().astype(np.int64)
    k = np.repeat(np.arange(len(offsets) - 1), np.diff(offsets))
    j = model.family_neighbors.numpy()[: offsets[-1]].astype(np.int64)
    return k, j


def break_bonds_across_planes(solver, x: np.ndarray, axes=(0, 1)) -> None:
    """Breaks by hand every bond of a peridynamic ``solver`` whose two particles lie on either side of a plane
    x[axis] = 0 for one of ``axes`` (``x``: the particles' rest positions relative to a point of the planes [m],
    [n, 3], in the model's order); nothing is run."""
    k, j = bond_ends(solver.model)
    across = np.zeros(len(k), dtype=bool)
    for axis in axes:
        across |= (x[k, axis] > 0.0) != (x[j, axis] > 0.0)
    alive = solver.state.bond_alive.numpy()
    alive[: len(across)] &= ~across
    solver.state.bond_alive.assign(alive)
