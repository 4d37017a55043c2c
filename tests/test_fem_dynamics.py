"""Time integration of the tetrahedral FEM solid: stable step, explicit velocity Verlet and implicit backward Euler
(momentum, energy), the step limit of the explicit integrator. CPU backend (and CUDA when present)."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh

from fem_helpers import critical_step

MAT = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3)
EPS32 = float(np.finfo(np.float32).eps)


def _mesh():
    return box_tet_mesh((0.4, 0.2, 0.2), (6, 3, 3), jitter=0.2, seed=2)


def _excited(solver, mesh, seed=0):
    """A smooth initial deformation (displacements up to 2 cm) and random velocities (0.1 m/s)."""
    X = mesh.vertices
    solver.set_positions(X + 0.02 * np.sin(3.0 * X))
    solver.set_velocities(np.random.default_rng(seed).normal(size=X.shape) * 0.1)


def _critical_step(mesh, material):
    """The critical step [s] of the linear, float64 solver of ``mesh`` (tests/fem_helpers.py)."""
    solver = SolverFem([FemBody(mesh, material, measure="linear")], precision="float64")
    return critical_step(solver, mesh.tets)


@pytest.mark.parametrize("nu", [0.0, 0.3, 0.45])
def test_stable_step_estimate_is_below_the_critical_step(nu):
    """The automatic explicit step 0.5 h_min / c_p (smallest element height, dilatational wave speed) is below the
    true critical step 2 / omega_max of velocity Verlet with lumped masses, on a structured and a jittered mesh, and
    not needlessly small: measured ratios critical / automatic 1.80-1.87 (structured) and 4.96-5.23 (jittered)."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=nu)
    for mesh in (box_tet_mesh((0.4, 0.2, 0.2), (4, 2, 2)), box_tet_mesh((0.4, 0.2, 0.2), (4, 2, 2), jitter=0.25)):
        auto = SolverFem([FemBody(mesh, mat)]).explicit_time_step()
        crit = _critical_step(mesh, mat)
        h = mesh.element_heights.min()
        assert auto == pytest.approx(0.5 * h / mat.p_wave_speed, rel=1e-12)
        assert 1.2 * auto < crit < 10.0 * auto


@pytest.mark.parametrize("measure", ["linear", "corotated", "green"])
def test_explicit_free_vibration_energy_bounded_and_momentum_conserved(measure, device):
    """Free vibration (no gravity, no damping, no constraints) with the explicit integrator at the automatic step:
    the total energy (kinetic + elastic) stays within 3 % of its initial value over 400 steps (velocity Verlet
    oscillates about a shadow energy; measured 2.0-2.1 %), and the linear momentum is conserved (every element's forces
    sum to zero) to float32 round-off: 50 eps32 x sum m |v| (measured 3-20). Angular momentum is conserved by the
    rotation-invariant measures (25 eps32 x sum m |v| x 1 m, measured 1.7-2.5) but not by the linear one (1.4e5)."""
    mesh = _mesh()
    solver = SolverFem([FemBody(mesh, MAT, measure=measure)], device=device)
    _excited(solver, mesh)
    dt = solver.stable_time_step()
    e0 = solver.kinetic_energy() + solver.strain_energy()
    p0 = solver.linear_momentum()
    l0 = solver.angular_momentum()
    scale = float(np.dot(solver.masses(), np.linalg.norm(solver.velocities(), axis=1)))
    energies = []
    for _ in range(400):
        solver.step(dt)
        energies.append(solver.kinetic_energy() + solver.strain_energy())
    energies = np.array(energies)
    assert np.abs(energies - e0).max() <= 0.03 * e0
    assert np.abs(solver.linear_momentum() - p0).max() <= 50.0 * EPS32 * scale
    dl = np.abs(solver.angular_momentum() - l0).max()
    if measure == "linear":
        assert dl > 0.1 * np.abs(l0).max()
    else:
        assert dl <= 50.0 * EPS32 * scale * 0.5


def test_implicit_backward_euler_energy_never_grows_at_10x_step(device):
    """Backward Euler with the corotated stiffness at 10 x the explicit step: the total energy never grows from one
    step to the next (bound: 1e-6 of the initial energy for the CG tolerance and float32 round-off; measured growth
    below 7e-11) and decays (numerical damping) to below 5 % within 100 steps (measured 2e-5). Linear momentum is
    conserved up to the CG residual: float64 with a 1e-12 CG tolerance keeps it to 1e-9 of sum m |v|."""
    mesh = _mesh()
    solver = SolverFem([FemBody(mesh, MAT, integrator="implicit")], device=device)
    _excited(solver, mesh)
    dt = 10.0 * solver.explicit_time_step()
    assert solver.stable_time_step() == pytest.approx(dt)
    e_prev = e0 = solver.kinetic_energy() + solver.strain_energy()
    for _ in range(100):
        solver.step(dt)
        e = solver.kinetic_energy() + solver.strain_energy()
        assert e <= e_prev + 1.0e-6 * e0
        e_prev = e
    assert e_prev < 0.05 * e0

    solver = SolverFem(
        [FemBody(mesh, MAT, integrator="implicit")], device=device, precision="float64", cg_tolerance=1.0e-12
    )
    _excited(solver, mesh)
    p0 = solver.linear_momentum()
    scale = float(np.dot(solver.masses(), np.linalg.norm(solver.velocities(), axis=1)))
    for _ in range(20):
        solver.step(dt)
    assert np.abs(solver.linear_momentum() - p0).max() <= 1.0e-9 * scale


def test_explicit_step_over_the_limit_is_refused_and_simulate_substeps(device):
    """The explicit integrator refuses a step above its stable limit with a ParameterError naming dt and the allowed
    range; simulate() instead splits the step into equal substeps below the limit, so 5 steps of 4.5 x the limit give
    the same state as 25 steps of 0.9 x the limit (float32 round-off: 1e-5 m)."""
    mesh = _mesh()
    a = SolverFem([FemBody(mesh, MAT)], device=device)
    limit = a.explicit_time_step()
    with pytest.raises(pdsim.ParameterError, match=r"dt=.*explicit stable limit"):
        a.step(1.5 * limit)
    b = SolverFem([FemBody(mesh, MAT)], device=device)
    for s in (a, b):
        _excited(s, mesh)
    a.simulate(4.5 * limit, 5)
    b.simulate(0.9 * limit, 25)
    assert a.step_count == b.step_count == 25
    np.testing.assert_allclose(a.positions(), b.positions(), atol=1.0e-5)
    assert np.isfinite(a.positions()).all()


def test_assembled_and_matrix_free_stiffness_give_the_same_implicit_step(device):
    """The implicit step's CG applies K_R either matrix-free (element kernels per iteration) or from the assembled
    3x3-block matrix: the same operator, so the same CG iterates and positions after 5 steps to float32 round-off
    (1e-6 m; measured 1.5e-8 m)."""
    mesh = _mesh()
    solvers = [
        SolverFem([FemBody(mesh, MAT, integrator="implicit")], device=device, stiffness=mode, gravity=(0, 0, -9.81))
        for mode in ("assembled", "matrix_free")
    ]
    for s in solvers:
        _excited(s, mesh)
        s.simulate(10.0 * s.explicit_time_step(), 5)
    np.testing.assert_allclose(solvers[0].positions(), solvers[1].positions(), atol=1.0e-6)
    assert solvers[0].cg_reports[-1].iterations == pytest.approx(solvers[1].cg_reports[-1].iterations, abs=2)


@pytest.mark.parametrize("integrator", ["explicit", "implicit"])
def test_three_phase_step_equals_step(integrator):
    """The scene's three-phase step (begin_step, compute_forces, end_step: the hook for coupling methods) gives the
    same state as step() (bitwise: the explicit step fuses the gather with the kick but adds the same numbers in the
    same order; the implicit step is taken whole in begin_step), with a fixed end, a ramped traction and gravity."""
    mesh = _mesh()
    solvers = []
    for _ in range(2):
        body = FemBody(mesh, MAT, integrator=integrator, damping=1.0)
        body.fix(pdsim.BoxRegion(lo=(-1, -1, -1), hi=(-0.2 + 1e-9, 1, 1)))
        body.add_traction(pdsim.BoxRegion(lo=(0.2 - 1e-9, -1, -1), hi=(1, 1, 1)), (0.0, 0.0, -1.0e3), curve=0.5)
        solvers.append(SolverFem([body], gravity=(0.0, 0.0, -9.81)))
    a, b = solvers
    dt = a.stable_time_step()
    for _ in range(20):
        a.step(dt)
        b.begin_step(dt)
        b.compute_forces()
        b.end_step(dt)
    assert a.time == b.time and a.step_count == b.step_count == 20
    np.testing.assert_array_equal(a.displacements(), b.displacements())
    np.testing.assert_array_equal(a.velocities(), b.velocities())
    np.testing.assert_array_equal(a.force.numpy(), b.force.numpy())
    assert np.abs(a.displacements()).max() > 0.0
