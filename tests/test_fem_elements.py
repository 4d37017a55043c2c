"""Element kernels of the tetrahedral FEM solid (kernels/fem/elements.py): patch test, rigid motions, element stiffness.
CPU backend (and CUDA when present)."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
EPS32 = float(np.finfo(np.float32).eps)
EPS64 = float(np.finfo(np.float64).eps)

# a uniform (affine) displacement field u = A X + c with a general (non-symmetric) gradient
GRAD = np.array([[1.0e-3, 2.0e-3, -1.0e-3], [0.5e-3, -2.0e-3, 1.0e-3], [3.0e-3, 1.0e-3, 2.0e-3]])
SHIFT = np.array([1.0e-3, -2.0e-3, 0.5e-3])


def _irregular_mesh():
    """A unit cube of 5^3 cells cut into tetrahedra, interior vertices moved randomly by up to 0.25 cell."""
    return box_tet_mesh((1.0, 1.0, 1.0), (5, 5, 5), jitter=0.25, seed=1)


def _boundary_mask(mesh):
    mask = np.zeros(mesh.vertex_count, dtype=bool)
    mask[mesh.boundary_faces().ravel()] = True
    return mask


def test_patch_test_float64_reproduces_uniform_strain_to_round_off(device):
    """Patch test (linear measure, float64): the affine displacement imposed on the boundary of an irregular mesh is
    reproduced at every interior vertex by the static solve. Bound: 1e-12 of the largest displacement (the CG runs to
    a relative residual of 1e-14; the measured error is about 1e-14)."""
    mesh = _irregular_mesh()
    bnd = _boundary_mask(mesh)
    X = mesh.vertices
    U = X @ GRAD.T + SHIFT
    solver = SolverFem([FemBody(mesh, MAT, measure="linear")], device=device, precision="float64")
    x0 = X.copy()
    x0[bnd] += U[bnd]  # interior starts at rest
    solver.set_positions(x0)
    report = solver.solve_static(constrained=bnd, tolerance=1.0e-14, cg_tolerance=1.0e-14)
    err = np.abs(solver.positions() - (X + U))[~bnd].max()
    assert report.newton_iterations == 1
    assert err <= 1.0e-12 * np.abs(U).max()


def test_patch_test_float32_interior_forces_vanish_to_round_off(device):
    """Patch test in float32: under a uniform strain every interior vertex is in equilibrium, so its force is zero up
    to the round-off of the positions. Bound: 50 x the force of a strain equal to that round-off,
    50 eps32 |x|_max / h_min x E h_min^2 (the boundary vertices, which carry the traction, are about 1e3 x larger).
    The float32 static solve reproduces the affine field to a few float32 ulps of the positions."""
    mesh = _irregular_mesh()
    bnd = _boundary_mask(mesh)
    X = mesh.vertices
    Y = X + X @ GRAD.T + SHIFT
    solver = SolverFem([FemBody(mesh, MAT, measure="linear")], device=device)
    f = solver.nodal_forces(Y)
    h = mesh.element_heights.min()
    bound = 50.0 * EPS32 * np.abs(Y).max() / h * MAT.youngs_modulus * h**2
    assert np.abs(f[~bnd]).max() <= bound
    assert np.abs(f[bnd]).max() > 100.0 * bound

    x0 = X.copy()
    x0[bnd] = Y[bnd]
    solver.set_positions(x0)
    solver.solve_static(constrained=bnd, cg_tolerance=1.0e-7)
    assert np.abs(solver.positions() - Y)[~bnd].max() <= 8.0 * EPS32 * np.abs(Y).max()


@pytest.mark.parametrize("measure", ["corotated", "green"])
def test_rigid_rotation_by_90_degrees_gives_zero_force(measure, device):
    """The corotated and Green-Saint-Venant measures are rotation invariant: a rigid rotation by 90 degrees (plus a
    translation) gives zero strain and zero force up to float32 round-off. Bound: the force of a strain of
    100 eps32 on a cell face, 100 eps32 E h^2 = 0.48 N (measured 0.037 N corotated, 0.030 N Green; the linear measure
    gives 7.7e4 N)."""
    mesh = _irregular_mesh()
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Y = mesh.vertices @ rot.T + np.array([0.3, -0.2, 0.1])
    solver = SolverFem([FemBody(mesh, MAT, measure=measure)], device=device)
    f = solver.nodal_forces(Y)
    h = 0.2  # cell size
    bound = 100.0 * EPS32 * MAT.youngs_modulus * h**2
    assert np.abs(f).max() <= bound
    solver.set_positions(Y)
    assert solver.strain_energy() <= 1.0e-9 * MAT.youngs_modulus * mesh.volume


def test_linear_measure_is_not_rotation_invariant(device):
    """Documented limitation of the linear measure: under a rigid rotation by 90 degrees eps = sym(R) - I is not zero
    (here diag(-1, -1, 0)), so large spurious forces and energy appear: the energy is that of a strain of -1 along two
    axes, V (mu 2 + lambda/2 4) = V (2 mu + 2 lambda) (1e-9 relative)."""
    mesh = _irregular_mesh()
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    solver = SolverFem([FemBody(mesh, MAT, measure="linear")], device=device, precision="float64")
    solver.set_positions(mesh.vertices @ rot.T)
    expected = mesh.volume * (2.0 * MAT.shear_modulus + 2.0 * MAT.lame_lambda)
    assert abs(solver.strain_energy() - expected) <= 1.0e-9 * expected
    f = solver.nodal_forces()
    assert np.abs(f).max() > 0.1 * MAT.youngs_modulus * 0.2**2


def test_measures_agree_at_small_strain(device):
    """For a small displacement gradient (entries up to 3e-4) all three measures give the same forces up to terms of
    the order of the gradient: relative difference below 5e-3 (measured 7.2e-4 corotated, 9.7e-4 Green)."""
    mesh = _irregular_mesh()
    Y = mesh.vertices + 0.1 * (mesh.vertices @ GRAD.T)
    forces = [
        SolverFem([FemBody(mesh, MAT, measure=m)], device=device).nodal_forces(Y)
        for m in ("linear", "corotated", "green")
    ]
    scale = np.abs(forces[0]).max()
    for f in forces[1:]:
        assert np.abs(f - forces[0]).max() <= 5.0e-3 * scale


def test_element_stiffness_matches_forces_and_has_six_rigid_modes(device):
    """The element stiffness K_e = V B^T E B (12 x 12) is symmetric, has exactly six zero eigenvalues (three
    translations, three infinitesimal rotations) and six positive ones, and K_e u equals minus the linear-measure
    force of the displacement u (float64, 1e-9 relative)."""
    mesh = box_tet_mesh((0.3, 0.2, 0.1), (1, 1, 1), jitter=0.0)
    solver = SolverFem([FemBody(mesh, MAT, measure="linear")], device=device, precision="float64")
    k = solver.element_stiffness()
    assert k.shape == (mesh.element_count, 12, 12)
    scale = np.abs(k).max()
    assert np.abs(k - k.transpose(0, 2, 1)).max() <= 1.0e-12 * scale
    ev = np.linalg.eigvalsh(k)
    assert np.all(np.abs(ev[:, :6]) <= 1.0e-10 * scale)
    assert np.all(ev[:, 6:] > 1.0e-3 * scale)
    rng = np.random.default_rng(3)
    u = rng.normal(size=mesh.vertices.shape) * 1.0e-3
    f = solver.nodal_forces(mesh.vertices + u)
    ku = np.zeros_like(u)
    ue = u[mesh.tets].reshape(-1, 12)
    np.add.at(ku, mesh.tets.ravel(), np.einsum("eij,ej->ei", k, ue).reshape(-1, 3))
    assert np.abs(f + ku).max() <= 1.0e-9 * np.abs(f).max()


def test_element_pass_scatter_equals_the_vertex_gather_bit_for_bit():
    """The explicit step on the CPU adds the corner forces onto the vertices in the element pass (scatter); the other
    paths write corners and gather them per vertex over the incidence list, whose slots run in element order. Both
    sums start from the loads and add the same corner vectors in the same order, so they agree bit for bit (an
    irregular mesh, a general displacement field, corotated elements turned by up to 0.3 rad)."""
    mesh = _irregular_mesh()
    body = FemBody(mesh, MAT, measure="corotated", integrator="explicit")
    body.add_body_force((0.0, 0.0, -50.0))
    solver = SolverFem([body], device="cpu")
    rng = np.random.default_rng(4)
    x = mesh.vertices - mesh.vertices.mean(axis=0)
    turn = np.array([[np.cos(0.3), -np.sin(0.3), 0.0], [np.sin(0.3), np.cos(0.3), 0.0], [0.0, 0.0, 1.0]])
    solver.set_displacements(x @ turn.T - x + 1.0e-3 * rng.normal(size=x.shape))
    solver.loads_into_force(0.0)
    solver.element_forces(0.0)
    solver.add_element_forces()
    gathered = solver.force.numpy().copy()
    solver.loads_into_force(0.0)
    solver.element_forces(0.0, scatter=True)
    scattered = solver.force.numpy()
    assert np.abs(gathered).max() > 1.0
    assert np.array_equal(gathered, scattered)
