"""FEM helpers shared by the tests: the true critical step of the explicit integrator."""

import numpy as np


def critical_step(solver, tets: np.ndarray) -> float:
    """2 / sqrt(largest eigenvalue of M^-1 K) [s] of an FEM ``solver``'s lumped-mass linear system (its element
    stiffness matrices assembled over the element corners ``tets`` [m, 4]; scipy's eigsh): the largest step velocity
    Verlet takes stably on it."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import eigsh

    k = solver.element_stiffness()
    idx = (3 * np.asarray(tets)[:, :, None] + np.arange(3)).reshape(-1, 12)
    rows = np.repeat(idx, 12, axis=1).ravel()
    cols = np.tile(idx, (1, 12)).ravel()
    kg = sp.csr_matrix((k.ravel(), (rows, cols)))
    minv_sqrt = sp.diags(np.repeat(1.0 / np.sqrt(solver.masses()), 3))
    lmax = eigsh(minv_sqrt @ kg @ minv_sqrt, k=1, which="LA", return_eigenvectors=False)[0]
    return 2.0 / np.sqrt(lmax)
