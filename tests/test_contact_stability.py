"""Particle contact in dynamic fracture stays finite and creates no energy, CPU backend (docs/stability.md, Contact).

The two runs are the cases of tools/contact_stability.py at its ``--quick`` resolution, built with Scene defaults
(contact on automatically for a breakable body, automatic step): a Kalthoff-Winkler-like steel plate hit at 32 m/s and
a pre-cracked glass plate pulled apart at 45 degrees. Before the fix the pair contact modulus 2 C_k C_j / (C_k + C_j)
overflowed float32 (C is 1e22 to 1e27 N/m^6 for these materials and spacings; the product overflows above 1.8e19), so
the first contact gave an infinite force: measured with kernels/contact.py and pdsim/contact.py of revision e153a59,
both runs below go non-finite at their first contact (steel at 24.2 us, glass at 34.1 us), so each test fails there at
``check_state``, and the pair modulus test fails on an infinite modulus (checked: all three fail on that code).

Energy bound: E(t) = kinetic + strain + contact energy must stay below E(0) + W(t), W the work put in (projectile:
v_p . (P(t) - P(0)), exact for a kinematic projectile at constant velocity; grips: the integral of reaction force times
grip velocity plus the grips' own kinetic energy; tools/contact_stability.py), since fracture, the contact dashpot and
the inelastic floor and collider only take energy out. The tolerance is 2 % of W(t) (plus 1e-6 of the run's largest W
for the round-off of the first samples): with fracture off, the glass plate's energy balance closes to 2e-6 of W
(test_grip_work_measure_closes_the_energy_balance_without_fracture).
"""

import math

import contact_stability as cs  # tools/ (on the path through conftest.py)
import numpy as np
import pytest
import warp as wp
from pdsim.kernels import contact as kc

from pdsim.contact import ParticleContact, bond_stiffness_row_sum

ENERGY_TOLERANCE = 0.02


@wp.kernel
def _pair_modulus(ck: wp.array(dtype=float), cj: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = kc.contact_pair_modulus(ck[i], cj[i])


def _contact_modulus(material, h):
    """C = S / (12 h^3) [N/m^6] of ParticleContact's calibration at spacing h (horizon 3.015 h)."""
    return bond_stiffness_row_sum(material.bulk_modulus, material.shear_modulus, 3.015 * h) / (12.0 * h**3)


def test_pair_modulus_of_glass_stiff_particles_is_finite_harmonic_mean():
    """The overflow regression. The pair modulus of two glass particles at h = 0.5 mm (C = 5e26 N/m^6, whose square
    overflows float32), of glass against steel at h = 2 and 4 mm (1.4e24, 4e22), and of two 1e30 moduli is finite and
    equals the harmonic mean 2 C_k C_j / (C_k + C_j) evaluated in float64 to 1e-6. End to end, two glass particles of
    different bodies 0.8 h apart feel the penalty C V (R - r) (R = 1.35 h) to 1e-5, finite, with pair forces V f
    that cancel, also when approaching at 1 m/s (dashpot), and the pair energy 1/2 C V^2 (R - r)^2 to 1e-5."""
    glass, steel = cs.GLASS, cs.STEEL
    c_glass = _contact_modulus(glass, 0.5e-3)
    assert c_glass > 1.0e26 and c_glass**2 > 3.4e38  # the old product overflowed
    pairs = [
        (c_glass, c_glass),
        (c_glass, _contact_modulus(steel, 2.0e-3)),
        (c_glass, _contact_modulus(steel, 4.0e-3)),
        (1.0e30, 1.0e30),
    ]
    ck = wp.array(np.array([p[0] for p in pairs], dtype=np.float32), dtype=float)
    cj = wp.array(np.array([p[1] for p in pairs], dtype=np.float32), dtype=float)
    out = wp.zeros(len(pairs), dtype=float)
    wp.launch(_pair_modulus, dim=len(pairs), inputs=[ck, cj, out])
    got = out.numpy().astype(np.float64)
    a, b = ck.numpy().astype(np.float64), cj.numpy().astype(np.float64)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, 2.0 * a * b / (a + b), rtol=1.0e-6)
    swapped = wp.zeros(len(pairs), dtype=float)
    wp.launch(_pair_modulus, dim=len(pairs), inputs=[cj, ck, swapped])
    assert np.array_equal(swapped.numpy(), out.numpy())  # exactly symmetric

    h = 0.5e-3
    vol = h**3
    contact = ParticleContact(
        np.array([[0.0, 0.0, 0.0], [5.0 * h, 0.0, 0.0]]),
        [0, 1],
        0.5 * h,
        vol,
        glass.density,
        glass.bulk_modulus,
        glass.shear_modulus,
        3.015 * h,
        floor_factor=0.0,
    )
    x = wp.array(np.array([[0.0, 0.0, 0.0], [0.8 * h, 0.0, 0.0]], dtype=np.float32), dtype=wp.vec3)
    fn = c_glass * vol * (1.35 - 0.8) * h
    for v_k in ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]):
        v = wp.array(np.array([v_k, [0.0, 0.0, 0.0]], dtype=np.float32), dtype=wp.vec3)
        f = wp.zeros(2, dtype=wp.vec3)
        contact.apply(x, wp.zeros_like(x), v, f)
        f = f.numpy().astype(np.float64)
        assert np.all(np.isfinite(f))
        np.testing.assert_allclose(f[0] * vol, -f[1] * vol, rtol=1.0e-6, atol=1.0e-6 * np.abs(f).max() * vol)
        if v_k[0] == 0.0:
            np.testing.assert_allclose(f[0], [-fn, 0.0, 0.0], rtol=1.0e-5)
        else:
            assert -f[0][0] > fn  # the dashpot adds to the penalty of an approaching pair
    energy = contact.potential_energy(x)
    assert math.isfinite(energy)
    assert energy == pytest.approx(0.5 * c_glass * vol * vol * ((1.35 - 0.8) * h) ** 2, rel=1.0e-5)


def _assert_energy_bounded(rec):
    """E(t) - E(0) <= (1 + ENERGY_TOLERANCE) W(t) + 1e-6 max W at every sample."""
    gain = rec.total - rec.total[0]
    work = np.asarray(rec.work)
    slack = (1.0 + ENERGY_TOLERANCE) * work + 1.0e-6 * work.max()
    worst = int(np.argmax(gain - slack))
    assert np.all(gain <= slack), (
        f"energy {gain[worst]:.6g} J above E(0) at t = {rec.time[worst]:.3g} s with work {work[worst]:.6g} J put in"
    )


def test_kalthoff_winkler_steel_plate_with_contact_runs_without_creating_energy():
    """The Kalthoff-Winkler-like steel plate (tools/contact_stability.py, kalthoff_winkler; h = 4 mm, 2500
    particles, E 190 GPa, G0 22 kJ/m^2) hit between its two edge notches by a box projectile at 32 m/s runs to 100 us
    (207 steps of 0.48 us; the block between the notches is punched out) with check_state passing every 10 steps.
    Contact must actually occur (the notch faces slide past each other: first contact within 40 us; measured
    24.2 us, up to about 80 particles in contact) and the energy stays within the bound of the module docstring
    (measured: (E - E(0)) / W at most 0.87, about 630 J put in). About 2 s."""
    case = cs.kalthoff_winkler(4.0e-3)
    assert case.solver.contact is not None  # on automatically for the breakable plate
    rec = cs.run(case, 100.0e-6)
    assert rec.diverged_at is None, rec.error
    assert rec.time[-1] >= 100.0e-6 * (1.0 - 1.0e-9)
    assert rec.first_contact() is not None and rec.first_contact() < 40.0e-6
    assert max(rec.in_contact) >= 20
    assert rec.work[-1] > 100.0  # the projectile did push the plate
    _assert_energy_bounded(rec)


def test_precracked_glass_plate_pulled_apart_with_contact_runs_without_creating_energy():
    """The pre-cracked glass plate (tools/contact_stability.py, glass_plate; h = 1 mm, 30 x 30 x 3 particles,
    G0 3.8 J/m^2) pulled apart at 45 degrees by grips at (+-3, +-3) m/s runs to 60 us (about 600 steps of 0.1 us)
    with check_state passing every 10 steps. Contact must occur (fragments touch once the plate has torn: first
    contact within 50 us; measured 34.1 us) and the energy stays within the bound of the module docstring (measured:
    (E - E(0)) / W at most 0.955, at the first sample; 0.89 later). About 6 s."""
    case = cs.glass_plate(1.0e-3)
    assert case.solver.contact is not None
    rec = cs.run(case, 60.0e-6)
    assert rec.diverged_at is None, rec.error
    assert rec.time[-1] >= 60.0e-6 * (1.0 - 1.0e-9)
    assert rec.first_contact() is not None and rec.first_contact() < 50.0e-6
    assert rec.work[-1] > 0.01
    _assert_energy_bounded(rec)


def test_grip_work_measure_closes_the_energy_balance_without_fracture():
    """The energy bound's work measure (tools/contact_stability.py, GripWork: trapezoid integral of reaction force
    times grip velocity plus the grips' own kinetic energy) on the glass plate of the previous test with fracture and
    notch off (elastic, no contact), where nothing takes energy out: E(t) - E(0) = W(t) to 1 % at every sample with W
    above 1 % of its peak (measured 0.7 % at 3 us, the trapezoid rule over the ramp's start) and to 1e-4 at 30 us
    (measured 2e-6). About 2 s."""
    case = cs.glass_plate(1.0e-3, breakable=False)
    assert case.solver.contact is None
    rec = cs.run(case, 30.0e-6)
    assert rec.diverged_at is None, rec.error
    gain, work = rec.total - rec.total[0], np.asarray(rec.work)
    use = work > 0.01 * work.max()
    np.testing.assert_allclose(gain[use], work[use], rtol=0.01)
    assert gain[-1] == pytest.approx(work[-1], rel=1.0e-4)
