"""Precision of the tetrahedral FEM solid independent of where the scene sits in the world: the state is displacements
from rest positions stored relative to the scene's origin, and element strains come from displacement differences
(kernels/fem/elements.py), so float32 resolves a deformation to about 1e-7 of itself even 1 km from the world origin,
where float32 positions are 6.1e-5 m apart. CPU backend."""

import numpy as np
import pytest

import pdsim
from pdsim.fem import FemBody, SolverFem
from pdsim.fem.mesh import box_tet_mesh
from pdsim.solver import SolverContext

SHIFT = np.array([1000.0, -500.0, 250.0])
ULP_AT_SHIFT = float(np.spacing(np.float32(1000.0)))  # 6.1e-5 m: float32 world positions could not resolve less


def _centre(mesh) -> np.ndarray:
    return 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))


@pytest.mark.parametrize("integrator", ["explicit", "implicit"])
def test_translated_scene_gives_the_same_displacements(integrator):
    """The same small scene (a bar 0.4 m x 0.1 m x 0.1 m clamped at one end, sagging under gravity from rest, E = 1
    MPa, corotated, float32) built at the origin and shifted by (1000, -500, 250) m, each solver's origin at its own
    scene's bounding-box centre: after 300 steps the displacements agree to 1e-6 of the largest displacement and the
    velocities to 1e-6 of the largest speed.

    Why these bounds: the solver's inputs are its local rest positions rounded to float32 (kin.rest) and the element
    geometry Dm^-1 differenced from exactly those in float64, so both solvers get the same bits unless the shift's
    float64 round-off (1e-13 m) straddles a float32 rounding boundary of a local coordinate (odds about 3e-5 per
    coordinate; not the case here, checked first), and then run the same float32 arithmetic: measured bitwise equal.
    The displacement bound leaves room for a perturbation of the geometry at round-off level, which the float32
    dynamics amplify (measured 5e-7 of the displacements, 7e-5 of the speeds, when Dm^-1 was taken from world-frame
    differences that differ by 1e-13 m); the velocity bound relies on the identical inputs checked first. A solver
    integrating float32 world positions would be quantised to their spacing near the shifted scene, 6.1e-5 m: 1.6e-3
    of the largest displacement (about 4 cm explicit, 2 cm implicit), and 6.1e-5 m / dt = 0.2 m/s of velocity noise
    per explicit step, about 70 % of the largest speed."""
    results = []
    for shift in (np.zeros(3), SHIFT):
        mesh = box_tet_mesh((0.4, 0.1, 0.1), (8, 2, 2), center=np.array([0.2, 0.0, 0.0]) + shift)
        body = FemBody(mesh, pdsim.Material(1000.0, 1.0e6, 0.3), integrator=integrator, name="bar")
        body.fix(pdsim.BoxRegion(lo=shift - 1.0, hi=shift + np.array([1e-9, 1.0, 1.0])))
        context = SolverContext(gravity=(0.0, 0.0, -9.81), origin=_centre(mesh))
        solver = SolverFem([body], context)
        inputs = (solver.kin.rest.numpy(), solver._dm_inv.numpy(), solver.inv_mass.numpy(), solver.stable_time_step())
        solver.simulate(solver.stable_time_step(), 300)
        results.append((solver.displacements(), solver.velocities(), solver.positions() - shift, inputs))
    (u0, v0, x0, in0), (u1, v1, x1, in1) = results
    for a, b in zip(in0[:3], in1[:3], strict=True):
        np.testing.assert_array_equal(a, b)  # the same float32 inputs (see the docstring)
    assert in0[3] == pytest.approx(in1[3], rel=1e-12)
    scale = np.abs(u0).max()
    speed = np.abs(v0).max()
    print(
        f"{integrator}: max |u| {scale:.3g} m, max |du| {np.abs(u1 - u0).max() / scale:.2e} of it; "
        f"max |v| {speed:.3g} m/s, max |dv| {np.abs(v1 - v0).max() / speed:.2e} of it"
    )
    assert scale > 1.0e-3  # and float32 world positions there are 6.1e-5 m apart: 1.6e-3 of it
    assert 1.0e-3 * scale < ULP_AT_SHIFT
    assert np.abs(u1 - u0).max() <= 1.0e-6 * scale
    assert np.abs(v1 - v0).max() <= 1.0e-6 * speed
    # world positions are formed in float64 on the host: the shifted scene's are the origin scene's plus the shift
    assert np.abs(x1 - x0).max() <= 1.0e-6 * scale + 1.0e-12 * np.abs(SHIFT).max()


def test_tiny_strain_far_from_the_origin_in_float32():
    """A bar (1 m x 0.1 m x 0.1 m, 20 x 2 x 2 cells, nu = 0) 1 km from the world origin, clamped at one end and pulled
    by a traction P = 1 kPa (E = 1 GPa: strain 1e-6, elongation P L / E = 1e-6 m, 1/60 of the float32 spacing of
    world coordinates there): the float32 static solve gives the elongation within 1e-3 of the float64 solve of the
    same scene and of P L / E (measured 1.6e-5 and 6e-9). The strain is formed as sym(G) from displacement
    differences; forming F = I + G in float32 first would round G to 6e-8, 6 % of this strain."""
    E, P = 1.0e9, 1.0e3
    elongations = {}
    for precision in ("float32", "float64"):
        mesh = box_tet_mesh((1.0, 0.1, 0.1), (20, 2, 2), center=SHIFT + np.array([0.5, 0.0, 0.0]))
        body = FemBody(mesh, pdsim.Material(1000.0, E, 0.0), measure="linear", name="bar")
        body.fix(lambda p, s=SHIFT: np.isclose(p[:, 0] - s[0], 0.0))
        body.add_traction(lambda p, s=SHIFT: np.isclose(p[:, 0] - s[0], 1.0), (P, 0.0, 0.0))
        solver = SolverFem([body], SolverContext(origin=_centre(mesh)), precision=precision)
        solver.solve_static(tolerance=1.0e-8, cg_tolerance=1.0e-7 if precision == "float32" else 1.0e-12)
        tip = np.isclose(mesh.vertices[:, 0] - SHIFT[0], 1.0)
        elongations[precision] = float(solver.displacements()[tip, 0].mean())
    expected = P * 1.0 / E
    assert expected < ULP_AT_SHIFT
    e32, e64 = elongations["float32"], elongations["float64"]
    print(f"elongation float32 {e32:.9g} m, float64 {e64:.9g} m, P L / E {expected:.9g} m")
    assert abs(e32 - e64) <= 1.0e-3 * expected
    assert abs(e64 - expected) <= 1.0e-3 * expected
