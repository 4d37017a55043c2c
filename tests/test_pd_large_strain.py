"""Peridynamics at large strain and rotation (CPU backend): the volumetric split of the return mapping must leave an
isochoric plastic stretch of any size without pressure, and the dilatation must not change under a rigid rotation
(the last holds; the others are a known defect).

KNOWN DEFECT, expected to fail (strict xfail: a fix makes these tests pass and the xfail marks must then go). The
dilatation and the return mapping's volumetric measure are linear in the bond extensions, so a large volume-keeping
stretch reads as volume change: a perfectly plastic bar keeps gaining force and loses volume (measured with the
current kernels: F/F_y 1.26 with roller grips and 1.57 with clamped grips at 41.5 % strain, volume -30 % and -38 %;
kappa theta 57 sigma_Y inside an isochoric stretch to 1.3). A fix that fitted each family's deformation gradient and
used J^(1/3) - 1 passed these tests but made a yielding plate under a ball's contact gain energy (scenes/
metal_dent_tear.py stopped by the watchdog at frame 1), so it was not kept (docs/accuracy.md)."""

import math

import numpy as np
import pytest

import pdsim

ORIGIN = np.array([150.0, -40.0, 20.0])  # away from the origin: float32 local frames must not matter


KNOWN_DEFECT = pytest.mark.xfail(
    strict=True, reason="linear dilatation: large isochoric plastic stretch reads as volume change (module docstring)"
)


@KNOWN_DEFECT
def test_isochoric_plastic_stretch_leaves_no_pressure():
    """A perfectly plastic steel block (E = 200 GPa, nu = 0.3, sigma_Y = 250 MPa, centred at ORIGIN) taken through the
    homogeneous isochoric stretch F = diag(l, l^-1/2, l^-1/2) in 30 steps to l = 1.3: the analytic mean stress is 0,
    so kappa theta must stay a fraction of sigma_Y. Tolerance 0.5 sigma_Y on interior particles and 1 sigma_Y on
    every particle: the residual (measured 0.14 sigma_Y at l = 1.1 and 0.36 at 1.3 inside, 0.53 on the surface) is
    what the bond sum of theta reads in the yield-level elastic extensions of a family stretched this far. With the
    family's mean extension as the volumetric split it was 57 sigma_Y inside (121 on the surface) at l = 1.3."""
    sy = 250.0e6
    mat = pdsim.Material(density=7850.0, youngs_modulus=200.0e9, poisson_ratio=0.3, yield_stress=sy)
    h = 0.01
    body = pdsim.PeridynamicBody(pdsim.box((0.16, 0.16, 0.16), center=tuple(ORIGIN)), mat, h)
    solver = pdsim.SolverPeridynamics([body])
    X = body.rest_positions
    interior = np.all(np.abs(X - ORIGIN) < 0.08 - body.horizon - 0.5 * h, axis=1)
    assert interior.sum() >= 100
    for stretch in np.linspace(1.01, 1.3, 30):
        F = np.diag([stretch, stretch**-0.5, stretch**-0.5])
        solver.set_positions(ORIGIN + (X - ORIGIN) @ F.T)
        pressure = mat.bulk_modulus * np.abs(solver.dilatation())
        assert pressure[interior].max() < 0.5 * sy
        assert pressure.max() < 1.0 * sy
    eqps = solver.plastic_strain()[interior]
    assert eqps.min() == pytest.approx(0.3, abs=0.03)  # the plastic flow took the stretch (eps_p ~ l - 1 here)


def _pull(grip_axes: str, *, n=6, h=0.01, length=0.18, strain=0.30, increment=0.01):
    """A perfectly plastic bar n x n particles across (E = 1 MPa, nu = 0.3, sigma_Y = 10 kPa: a 1 % yield strain),
    centred at ORIGIN, pulled quasi-statically by two 3-layer grips (axes "x": roller grips, lateral motion free;
    "xyz": clamped): each increment moves the grips apart by ``increment`` of the bar length over half an axial wave
    transit and holds them for four transits under damping at the fundamental axial frequency. Returns per increment
    (strain of the free length, grip force / (sigma_Y A0), smallest / mean current cross-section of the free length
    over A0). The cross-section of a layer of particles is sqrt(12 var(y) n^2 / (n^2 - 1)) times the same in z (the
    width of n points spread evenly)."""
    sy = 1.0e4
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.3, yield_stress=sy)
    width = n * h
    omega = math.pi * mat.bar_wave_speed / length
    body = pdsim.PeridynamicBody(pdsim.box((length, width, width), center=tuple(ORIGIN)), mat, h, damping=omega)
    grip = 0.5 * length - 3.0 * h
    right = pdsim.HalfSpace((ORIGIN[0] + grip, 0.0, 0.0), (1.0, 0.0, 0.0))
    left = pdsim.HalfSpace((ORIGIN[0] - grip, 0.0, 0.0), (-1.0, 0.0, 0.0))
    probe = pdsim.PeridynamicBody(pdsim.box((length, width, width)), mat, h)
    dt = 0.7 * pdsim.SolverPeridynamics([probe]).stable_time_step()
    transit = length / mat.bar_wave_speed
    move_steps = max(1, int(0.5 * transit / dt))
    relax_steps = int(4.0 * transit / dt)
    v_unit = 0.5 * length / (move_steps * dt)
    count = round(strain / increment)
    times, values, t = [], [], 0.0
    for _ in range(count):
        t1 = t + move_steps * dt
        t = t1 + relax_steps * dt
        times += [t1 - move_steps * dt + 0.1 * dt, t1 - 0.1 * dt, t1 + 0.1 * dt, t - 0.1 * dt]
        values += [increment, increment, 0.0, 0.0]
    curve = pdsim.TimeCurve.table([0.0, *times], [0.0, *values])
    body.set_velocity(right, (v_unit, 0.0, 0.0), axes=grip_axes, curve=curve, name="right_grip")
    body.set_velocity(left, (-v_unit, 0.0, 0.0), axes=grip_axes, curve=curve, name="left_grip")
    solver = pdsim.SolverPeridynamics([body])
    X = body.rest_positions
    layer = np.round((X[:, 0] - X[:, 0].min()) / h).astype(int)
    free = np.unique(layer[np.abs(X[:, 0] - ORIGIN[0]) < grip])
    lo, hi = free.min() - 1, free.max() + 1  # the grips' inner layers
    ref = X[layer == hi, 0].mean() - X[layer == lo, 0].mean()
    path = []
    for _ in range(count):
        solver.simulate(dt, move_steps + relax_steps)
        x = solver.positions()
        force = solver.reaction_forces()[(body.name, "right_grip")][0]
        eng = (x[layer == hi, 0].mean() - x[layer == lo, 0].mean()) / ref - 1.0
        areas = np.array(
            [12.0 * n * n / (n * n - 1.0) * math.sqrt(x[layer == i, 1].var() * x[layer == i, 2].var()) for i in free]
        )
        path.append((eng, force / (sy * width**2), areas.min() / width**2, areas.mean() / width**2))
    return np.array(path)


@KNOWN_DEFECT
@pytest.mark.parametrize("grip_axes", ["x", "xyz"])
def test_perfectly_plastic_bar_to_thirty_percent(grip_axes):
    """A perfectly plastic bar pulled to over 30 % strain of its free length, with roller and with clamped grips.
    Reference: F_y, the grip force at the first increment past 3 % strain (this bar's yield force, measured 0.84
    (roller) and 0.80 (clamped) sigma_Y A0: six particles across is a thin bar for the surface correction), and A_y,
    the smallest cross-section then. Afterwards the force stays between F_y A_min / A_y (sigma_Y times the current
    smallest cross-section) and 1.1 F_y (sigma_Y times the initial area: the yield check caps the bond force state, a
    nominal stress), and the free length keeps its volume within 3 % (A_mean (1 + strain) against A0). Measured at
    41.5 % strain: F / F_y = 0.98 (roller) and 0.89 (clamped) with A_min / A_y = 0.71 and 0.68, volume within +1.9 %
    and -0.5 %. With the family's mean extension as the volumetric split the same pulls reached F / F_y = 1.26 and
    1.57 and the free length lost 30 % and 38 % of its volume (with steel's 0.125 % yield strain the clamped force
    climbed to 7 sigma_Y A0, docs/accuracy.md)."""
    path = _pull(grip_axes)
    strain, force, a_min, a_mean = path.T
    assert strain[-1] > 0.3
    ref = np.argmax(strain > 0.03)
    plastic = strain > 0.03
    assert 0.5 < force[ref] < 1.1
    after = np.arange(len(strain)) > ref
    assert np.all(force[plastic] <= 1.1 * force[ref])
    assert np.all(force[after] >= force[ref] * a_min[after] / a_min[ref])
    volume = a_mean * (1.0 + strain)
    assert np.abs(volume - 1.0).max() < 0.03


@pytest.mark.parametrize("angle", [90.0, 180.0])
def test_dilatation_does_not_change_under_a_rigid_rotation(angle):
    """A steel block (centred at ORIGIN) expanded by 0.1 % and rotated rigidly by ``angle`` degrees about z must read
    the same dilatation as the block expanded without rotation (the dilatation is a scalar of the deformation, not of
    the orientation): within 1e-3 relative on interior particles. With the supplement's directional factor
    Lambda = n . xi / L (n the deformed bond direction, xi the reference bond: the cosine of the bond's rotation, a
    small-rotation form) it read 3.08e-3 unrotated, 2.80e-3 at 30 degrees, 1.03e-3 at 90 and -1.03e-3 at 180, so a
    spinning fragment's bulk stiffness was wrong; the kernels now leave Lambda out (the linear peridynamic solid's
    dilatation, equal to first order in the strain)."""
    from scipy.spatial.transform import Rotation

    mat = pdsim.Material(density=7850.0, youngs_modulus=200.0e9, poisson_ratio=0.3)
    body = pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1), center=tuple(ORIGIN)), mat, 0.01)
    solver = pdsim.SolverPeridynamics([body])
    X = body.rest_positions
    interior = np.all(np.abs(X - ORIGIN) < 0.05 - body.horizon - 0.005, axis=1)
    assert interior.sum() >= 8
    solver.set_positions(ORIGIN + 1.001 * (X - ORIGIN))
    reference = solver.dilatation()[interior]
    assert reference.min() > 2.5e-3  # about 3 x 0.001
    rot = Rotation.from_euler("z", angle, degrees=True).as_matrix()
    solver.set_positions(ORIGIN + 1.001 * (X - ORIGIN) @ rot.T)
    np.testing.assert_allclose(solver.dilatation()[interior], reference, rtol=1e-3)


def test_spinning_vibrating_block_conserves_energy():
    """An undamped block (E = 1 MPa, nu = 0.4, so the dilatation term counts; centred at ORIGIN) released from a 1 %
    expansion while spinning at 60 rad/s about z, integrated over 412 degrees of rotation at 0.3 x the stable step:
    kinetic plus strain energy stays within 0.5 % of its start at every 0.01 s (measured 0.14 %). With the
    supplement's directional factor Lambda the bulk force was no longer the derivative of the energy once bonds had
    turned, and the energy wandered by 2.5 % (0.975 at 103 degrees)."""
    mat = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.4)
    body = pdsim.PeridynamicBody(pdsim.box((0.1, 0.1, 0.1), center=tuple(ORIGIN)), mat, 0.01)
    solver = pdsim.SolverPeridynamics([body])
    r = body.rest_positions - ORIGIN
    solver.set_positions(ORIGIN + 1.01 * r)
    solver.set_velocities(np.cross([0.0, 0.0, 60.0], r))
    dt = 0.3 * solver.stable_time_step()
    e0 = solver.kinetic_energy() + solver.strain_energy()
    worst = 0.0
    for _ in range(12):
        for _ in range(int(0.01 / dt)):
            solver.step(dt)
        worst = max(worst, abs((solver.kinetic_energy() + solver.strain_energy()) / e0 - 1.0))
    print(f"\nlargest energy deviation {worst:.2e}")
    assert worst < 5.0e-3
