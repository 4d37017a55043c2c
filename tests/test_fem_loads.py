"""Loads, boundary conditions per axis and reaction forces of the tetrahedral FEM solid on the shared kinematics
(pdsim/loads.py, pdsim/bodies.py, pdsim/kinematics.py): a bar under an end traction, a cantilever under a tip shear
traction, a ramped load following its time curve, the reaction of a clamp to gravity. CPU backend."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh

LENGTH, HEIGHT = 1.0, 0.1
AREA = HEIGHT * HEIGHT
G = 9.81


def _bar(cells_across: int):
    """A bar LENGTH x HEIGHT x HEIGHT along x from x = 0, 10 n x n x n cells of six tetrahedra."""
    n = cells_across
    return box_tet_mesh((LENGTH, HEIGHT, HEIGHT), (10 * n, n, n), center=(0.5 * LENGTH, 0.0, 0.0))


def _end(x: float):
    """Region of the vertices on the cross-section at x [m]."""
    return pdsim.BoxRegion(lo=(x - 1e-9, -1.0, -1.0), hi=(x + 1e-9, 1.0, 1.0))


def _roller_end(body: FemBody) -> None:
    """The x = 0 face held along x only (a roller: free lateral contraction), plus the fewest extra constraints that
    remove the rigid modes: the face's centre vertex fully ("pin"), and the vertex at (0, h/2, 0) along z ("guide",
    it blocks the rotation about x). By symmetry neither extra constraint carries a force under an axial load."""

    def face(p):
        return np.isclose(p[:, 0], 0.0)

    def pin(p):
        return face(p) & np.isclose(p[:, 1], 0.0) & np.isclose(p[:, 2], 0.0)

    def guide(p):
        return face(p) & np.isclose(p[:, 1], 0.5 * HEIGHT) & np.isclose(p[:, 2], 0.0)

    body.fix(pin, axes="xyz", name="pin")
    body.fix(guide, axes="xz", name="guide")
    body.fix(lambda p: face(p) & ~pin(p) & ~guide(p), axes="x", name="roller")


@pytest.mark.parametrize("measure", ["linear", "corotated"])
def test_bar_under_end_traction_elongates_by_PL_over_E(measure):
    """A bar (1 m x 0.1 m x 0.1 m, 40 x 4 x 4 cells, 3,840 elements, nu = 0.3) on a roller at x = 0 with a traction
    P = 1e5 Pa along x on its x = 1 m face (static solve, float64): the stress is uniform, so linear tetrahedra
    reproduce it exactly (patch test) and the end face moves by P L / E = 1e-4 m. Bound 2 % (measured 2e-9 for
    both measures, the round-off of the float32 load table; the corotated strain of a rotation-free uniform stretch
    is the linear one). The
    end's three conditions together react -P A along x (1e-6 relative), and the pin and the guide carry no lateral
    force (1e-6 P A)."""
    E, P = 1.0e9, 1.0e5
    mesh = _bar(4)
    body = FemBody(mesh, pdsim.Material(density=1000.0, youngs_modulus=E, poisson_ratio=0.3), measure=measure)
    _roller_end(body)
    body.add_traction(_end(LENGTH), (P, 0.0, 0.0))
    solver = SolverFem([body], precision="float64")
    assert "loads" in solver.features and "boundary_conditions" in solver.features
    solver.solve_static(tolerance=1.0e-12, cg_tolerance=1.0e-12)
    tip = np.isclose(mesh.vertices[:, 0], LENGTH)
    elongation = float(solver.displacements()[tip, 0].mean())
    expected = P * LENGTH / E
    error = abs(elongation - expected) / expected
    print(f"bar under traction ({measure}): elongation {elongation:.9g} m, P L / E {expected:.9g} m, error {error:.2e}")
    assert error <= 0.02
    reactions = solver.reaction_forces()
    total = sum(reactions[("box", name)] for name in ("pin", "guide", "roller"))
    np.testing.assert_allclose(total, [-P * AREA, 0.0, 0.0], atol=1.0e-6 * P * AREA)
    for name in ("pin", "guide"):
        np.testing.assert_allclose(reactions[("box", name)][1:], 0.0, atol=1.0e-6 * P * AREA)


def test_cantilever_under_tip_shear_matches_beam_theory():
    """A cantilever (1 m x 0.1 m x 0.1 m, clamped at x = 0, nu = 0, E = 1 GPa) under a shear traction F / A on its
    free end (F = 100 N down; static solve, linear measure, float64): the tip deflection (mean over the end face)
    approaches Timoshenko's F L^3 / (3 E I) + F L / (kappa G A) (kappa = 5/6 for a rectangle; the shear term is
    0.6 % of the bending one at L / h = 10, and nu = 0 makes the clamped face consistent with plane sections).
    Linear tetrahedra lock in bending, so the mesh converges from the stiff side at second order: measured errors
    8.75 % with 6 cells across the height (60 x 6 x 6 cells, 12,960 elements) and 3.36 % with 10 (100 x 10 x 10 cells,
    60,000 elements); bound 5 % at 10 cells, and the refinement must shrink the error by at least half (measured
    0.38, second order predicts (6/10)^2 = 0.36). The clamp's reaction balances F (1e-6 relative)."""
    E, F = 1.0e9, 100.0
    mat = pdsim.Material(density=1000.0, youngs_modulus=E, poisson_ratio=0.0)
    inertia = HEIGHT**4 / 12.0
    reference = F * LENGTH**3 / (3.0 * E * inertia) + F * LENGTH / (5.0 / 6.0 * mat.shear_modulus * AREA)
    errors = []
    for n in (6, 10):
        mesh = _bar(n)
        body = FemBody(mesh, mat, measure="linear", name="beam")
        body.fix(_end(0.0), name="clamp")
        body.add_traction(_end(LENGTH), (0.0, 0.0, -F / AREA))
        solver = SolverFem([body], precision="float64")
        solver.solve_static(tolerance=1.0e-10, cg_tolerance=1.0e-10)
        tip = np.isclose(mesh.vertices[:, 0], LENGTH)
        deflection = -float(solver.displacements()[tip, 2].mean())
        errors.append(abs(deflection - reference) / reference)
        np.testing.assert_allclose(solver.reaction_forces()[("beam", "clamp")], [0.0, 0.0, F], atol=1.0e-6 * F)
    print(f"cantilever tip shear: reference {reference:.6g} m, errors {errors[0]:.4f} (n=6), {errors[1]:.4f} (n=10)")
    assert errors[1] <= 0.05
    assert errors[1] <= 0.5 * errors[0]


def test_ramped_traction_follows_its_curve():
    """A bar (1 m x 0.1 m x 0.1 m, E = 1 MPa, clamped at x = 0) under an end traction ramped from 0 to P = 1e3 Pa
    over T = 1 s (TimeCurve.ramp), explicit dynamics with heavy damping (50 /s, about the critical damping of the
    first axial mode, 2 omega_1 = 2 pi c / (2 L) = 99 /s at nu = 0.3 gives 0.5 of it). At t = 0.25, 0.5, 0.75, 1.0
    and 1.5 s the applied load (the sum of all nodal forces: the element forces sum to zero) equals P A curve(t)
    (float32: 1e-4 relative), and the clamp's reaction follows -P A curve(t - tau) with the quasi-static lag of
    mass-proportional damping, tau = c / omega_1^2 = 0.0203 s (1D estimate): within 2 % of P A during the ramp
    (measured 0.44 %: the meshed 3D bar's first mode is a little slower) and 0.5 % after it (measured 1e-6)."""
    E, P, T, damping = 1.0e6, 1.0e3, 1.0, 50.0
    mat = pdsim.Material(density=1000.0, youngs_modulus=E, poisson_ratio=0.3)
    mesh = box_tet_mesh((LENGTH, HEIGHT, HEIGHT), (20, 2, 2), center=(0.5 * LENGTH, 0.0, 0.0))
    body = FemBody(mesh, mat, damping=damping, name="bar")
    body.fix(_end(0.0), name="clamp")
    curve = pdsim.TimeCurve.ramp(T)
    body.add_traction(_end(LENGTH), (P, 0.0, 0.0), curve=curve)
    solver = SolverFem([body])
    dt = solver.stable_time_step()
    # quasi-static lag of a ramp under mass damping: c / omega_1^2 with omega_1 the first axial mode of the clamped
    # bar (pi c_bar / (2 L), c_bar = sqrt(E / rho))
    omega1 = np.pi * np.sqrt(E / mat.density) / (2.0 * LENGTH)
    tau = damping / omega1**2
    for t_sample, bound in ((0.25, 0.02), (0.5, 0.02), (0.75, 0.02), (1.0, 0.02), (1.5, 0.005)):
        steps = round((t_sample - solver.time) / dt)
        solver.simulate((t_sample - solver.time) / steps, steps)
        applied = solver.force.numpy().astype(np.float64).sum(axis=0)
        np.testing.assert_allclose(applied, [P * AREA * curve(t_sample), 0.0, 0.0], atol=1.0e-4 * P * AREA)
        reaction = solver.reaction_forces()[("bar", "clamp")]
        expected = -P * AREA * curve(t_sample - tau)
        print(f"t = {t_sample} s: reaction {reaction[0]:.6g} N, expected {expected:.6g} N")
        assert abs(reaction[0] - expected) <= bound * P * AREA


def test_clamp_reaction_equals_the_weight():
    """A bar clamped at x = 0 sagging under gravity (static solve, corotated, float64; 20 x 2 x 2 cells): the clamp's
    reaction is the bar's weight m g upward (1 % bound; measured 1e-15 relative: equilibrium to the solve's
    tolerance), with no horizontal component (1e-6 m g). The same in float32 after the static solve: 1 %
    (measured 1.2e-7), horizontal below 1e-5 m g (the solve stops at a residual of 1e-6 m g; measured 4e-7)."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.3)
    mesh = box_tet_mesh((LENGTH, HEIGHT, HEIGHT), (20, 2, 2), center=(0.5 * LENGTH, 0.0, 0.0))
    weight = mat.density * mesh.volume * G
    for precision in ("float64", "float32"):
        body = FemBody(mesh, mat, name="bar")
        body.fix(_end(0.0), name="clamp")
        solver = SolverFem([body], gravity=(0.0, 0.0, -G), precision=precision)
        solver.solve_static(tolerance=1.0e-10 if precision == "float64" else 1.0e-6)
        r = solver.reaction_forces()[("bar", "clamp")]
        print(f"{precision}: reaction {r} N, weight {weight:.9g} N")
        assert abs(r[2] - weight) <= 0.01 * weight
        assert np.abs(r[:2]).max() <= (1.0e-6 if precision == "float64" else 1.0e-5) * weight
        assert solver.displacements()[:, 2].min() < 0.0


def test_body_force_and_region_force_are_resolved_on_vertices():
    """A body force a [m/s^2] puts m_i a on every vertex (sum: M a), a region force F [N] is shared by the region's
    vertices in proportion to their mass (sum: F), and a pressure on a closed surface sums to zero (1e-12
    relative, float64 host arithmetic); the forces reach the solver's force array (float32 sum within 1e-5)."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e7, poisson_ratio=0.3)
    mesh = box_tet_mesh((0.4, 0.2, 0.2), (4, 2, 2), jitter=0.1)
    body = FemBody(mesh, mat)
    body.add_body_force((0.0, 2.0, 0.0))
    body.add_force(_end(0.2), (5.0, 0.0, 0.0))
    body.add_pressure(lambda p: np.ones(len(p), dtype=bool), 1.0e3)
    mass = body.point_masses()
    loads = body.resolved_loads(mesh.vertices, mass)
    np.testing.assert_allclose(loads[0][1].sum(axis=0), [0.0, 2.0 * mass.sum(), 0.0], rtol=1e-12)
    np.testing.assert_allclose(loads[1][1].sum(axis=0), [5.0, 0.0, 0.0], rtol=1e-12)
    assert np.abs(loads[2][1].sum(axis=0)).max() <= 1.0e-12 * 1.0e3 * 0.4
    pts, f = body.surface_point_forces(_end(0.2), (0.0, 0.0, 100.0), 0.0)
    assert np.all(np.isclose(mesh.vertices[pts, 0], 0.2))
    np.testing.assert_allclose(f.sum(axis=0), [0.0, 0.0, 100.0 * 0.2 * 0.2], rtol=1e-12)
    solver = SolverFem([body])
    applied = solver.force.numpy().astype(np.float64).sum(axis=0)
    np.testing.assert_allclose(applied, [5.0, 2.0 * mass.sum(), 0.0], atol=1e-5 * 2.0 * mass.sum())
