"""The internal (Kelvin-Voigt) damping of peridynamic bodies, Material.retardation_time
(a term of the force pass, kernels/peridynamics/step.py and pairs.py).

Covered: a free bar's first longitudinal mode decays with the damping ratio omega tau / 2 (Poisson's ratio 1/4,
where the damping is stiffness-proportional), near the origin and 1 km away, and as the viscosities predict at 0.2
and 0.3; linear and angular momentum are kept while the energy only falls; a rigid spin is not damped; the stable
step shrinks by sqrt(1 + z^2) - z and the undamped step is unstable with a strong damping; and the setting's range.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest

import pdsim
from pdsim.errors import InstabilityError, ParameterError

LENGTH = 0.6


def _bar(tau, centre=(0.0, 0.0, 0.0), poisson_ratio=0.25):
    material = pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=poisson_ratio, retardation_time=tau)
    body = pdsim.PeridynamicBody(pdsim.box((LENGTH, 0.15, 0.15), center=centre), material, 0.025)
    return body, pdsim.SolverPeridynamics([body])


def _mode_decay(tau, centre=(0.0, 0.0, 0.0), poisson_ratio=0.25):
    """(angular frequency [rad/s], damping ratio) of the free bar's first longitudinal mode, from 0.1 % strain: the
    frequency from the zero crossings of the mode's amplitude, the ratio from the log decrement of its peaks (a line
    through log |peak| against time, over about 14 periods)."""
    body, s = _bar(tau, centre, poisson_ratio)
    x = body.rest_positions[:, 0] - float(centre[0])
    shape = np.sin(math.pi * x / LENGTH)
    y = body.rest_positions.copy()
    y[:, 0] += 1.0e-3 * LENGTH * shape
    s.set_positions(y)
    m = s.masses()
    dt = 0.7 * s.stable_time_step()
    t, q = [], []
    for _ in range(400):
        s.simulate(dt, 5)
        t.append(s.time)
        q.append((m * shape) @ s.displacements()[:, 0] / ((m * shape) @ shape))
    t, q = np.array(t), np.array(q)
    zc = np.flatnonzero(np.sign(q[1:]) != np.sign(q[:-1]))
    crossings = t[zc] - q[zc] * (t[zc + 1] - t[zc]) / (q[zc + 1] - q[zc])
    omega = math.pi / np.mean(np.diff(crossings))
    peaks = [a + int(np.argmax(np.abs(q[a : b + 1]))) for a, b in itertools.pairwise(zc)]
    assert len(peaks) >= 20
    slope = np.polyfit(t[peaks], np.log(np.abs(q[peaks])), 1)[0]
    return omega, -slope / omega


@pytest.mark.parametrize("centre", [(0.0, 0.0, 0.0), (1000.0, -700.0, 300.0)], ids=["origin", "1km"])
def test_bar_mode_decays_with_damping_ratio_omega_tau_over_two(centre):
    """At Poisson's ratio 1/4 the damping is tau times the stiffness (module docstring of the kernels): the bar's
    first mode (about 27 Hz) decays with zeta = omega tau / 2 = 0.017 within 2 % (measured 0.04 %), and the
    undamped bar's zeta is below 1e-4 (measured 4e-6: the log decrement's floor)."""
    tau = 2.0e-4
    omega, zeta = _mode_decay(tau, centre)
    assert abs(zeta / (0.5 * omega * tau) - 1.0) < 0.02
    assert abs(omega / (2.0 * math.pi) - 27.1) < 0.5  # the mode measured is the first one
    if centre == (0.0, 0.0, 0.0):
        assert abs(_mode_decay(0.0)[1]) < 1.0e-4


@pytest.mark.parametrize("poisson_ratio", [0.2, 0.3])
def test_bar_mode_damping_at_other_poisson_ratios(poisson_ratio):
    """Away from Poisson's ratio 1/4 the damping's shear viscosity is tau mu and its bulk viscosity 5 tau mu / 3 (not
    tau kappa), so a bar's longitudinal mode sees the viscous modulus E_v = 9 kappa_v mu_v / (3 kappa_v + mu_v) =
    2.5 tau mu and the damping ratio (omega tau / 2) 1.25 / (1 + nu): 1.042 and 0.962 times omega tau / 2 at 0.2 and
    0.3, within 3 % (measured 1.060 and 0.967: the bar is not thin)."""
    tau = 2.0e-4
    omega, zeta = _mode_decay(tau, poisson_ratio=poisson_ratio)
    assert zeta / (0.5 * omega * tau) == pytest.approx(1.25 / (1.0 + poisson_ratio), rel=0.03)


def test_damping_keeps_momentum_and_only_takes_energy():
    """Random velocities in a free block with a strong damping (z = tau / dt0 = 0.3): linear momentum within 1e-6 and
    angular momentum within 1e-5 of their scales over 300 steps (the forces are central, equal and opposite), the
    total energy never rises (within 1e-6 of the start) and ends well below the undamped run's."""
    body, s = _bar(0.0)
    dt0 = s.stable_time_step()
    body, s = _bar(0.3 * dt0)
    _, undamped = _bar(0.0)
    rng = np.random.default_rng(1)
    v = rng.uniform(-0.1, 0.1, (body.particle_count, 3))
    m = s.masses()
    c = body.rest_positions.mean(axis=0)
    p_scale = m @ np.linalg.norm(v, axis=1)
    l_scale = m @ (np.linalg.norm(body.rest_positions - c, axis=1) * np.linalg.norm(v, axis=1))
    energies = {}
    for name, solver in (("damped", s), ("undamped", undamped)):
        solver.set_velocities(v)
        p0, l0 = solver.linear_momentum(), solver.angular_momentum(c)
        dt = 0.7 * solver.stable_time_step()
        e = [solver.kinetic_energy() + solver.strain_energy()]
        for _ in range(30):
            solver.simulate(dt, 10)
            e.append(solver.kinetic_energy() + solver.strain_energy())
        assert np.linalg.norm(solver.linear_momentum() - p0) < 1.0e-6 * p_scale
        assert np.linalg.norm(solver.angular_momentum(c) - l0) < 1.0e-5 * l_scale
        energies[name] = np.array(e)
    e = energies["damped"]
    assert np.all(np.diff(e) < 1.0e-6 * e[0])
    assert e[-1] < 0.5 * energies["undamped"][-1]


def test_a_rigid_spin_is_not_damped():
    """A block spinning and drifting as a rigid body keeps its kinetic energy with a strong damping (z = 0.3) as it
    does without, within 1e-3 over 400 steps: the damping reads only the bonds' extension rates, which a rigid motion
    leaves at 0 (a damping of the whole relative velocity would stop the spin within these steps). The spin's edge
    speed, 0.3 m/s against a wave speed of 32 m/s, stretches the block by about 1e-4 (its centrifugal vibration)."""
    body, s = _bar(0.0)
    dt0 = s.stable_time_step()
    ke = {}
    for tau in (0.0, 0.3 * dt0):
        body, s = _bar(tau)
        r = body.rest_positions - body.rest_positions.mean(axis=0)
        omega = np.array([0.3, 0.8, 0.5])
        omega *= 0.3 / (np.linalg.norm(omega) * np.linalg.norm(r, axis=1).max())
        s.set_velocities(np.cross(omega, r) + np.array([0.2, -0.1, 0.05]))
        k0 = s.kinetic_energy()
        s.simulate(0.7 * dt0 * (math.sqrt(1.0 + 0.09) - 0.3), 400)
        ke[tau] = s.kinetic_energy() / k0
    damped = ke[0.3 * dt0]
    assert abs(damped - ke[0.0]) < 1.0e-3
    assert damped > 0.995


def test_stable_step_shrinks_with_the_damping_ratio_of_the_highest_mode():
    """With tau = 2 dt0 (dt0: the undamped stable step) the stable step is dt0 (sqrt(1 + 4) - 2) = 0.236 dt0: a run at
    0.9 of it stays within its energy for 1000 steps, and a run at 0.9 dt0 with the damping blows up."""
    _, s = _bar(0.0)
    dt0 = s.stable_time_step()
    _, s = _bar(2.0 * dt0)
    assert s.stable_time_step() == pytest.approx(dt0 * (math.sqrt(5.0) - 2.0), rel=1.0e-5)
    rng = np.random.default_rng(2)
    v = rng.uniform(-0.01, 0.01, (s.masses().size, 3))
    s.set_velocities(v)
    k0 = s.kinetic_energy()
    s.simulate(0.9 * s.stable_time_step(), 1000)
    assert s.kinetic_energy() + s.strain_energy() <= k0
    _, s = _bar(2.0 * dt0)
    s.set_velocities(v)
    with pytest.raises((InstabilityError, FloatingPointError, AssertionError)):
        for _ in range(20):
            s.simulate(0.9 * dt0, 50)
            s.check_state(100.0)
            assert s.kinetic_energy() + s.strain_energy() < 100.0 * k0


def test_retardation_time_must_not_be_negative():
    """A negative retardation time is refused naming the field (the FEM's refusal of the setting is in
    tests/test_fem_scene.py)."""
    with pytest.raises(ParameterError, match="retardation_time"):
        pdsim.Material(density=1000.0, youngs_modulus=1.0e6, poisson_ratio=0.25, retardation_time=-1.0e-6)


@pytest.mark.parametrize("pairs", [True, False], ids=["pairs", "directed"])
def test_damping_force_is_tau_times_the_elastic_force_of_the_velocities(pairs):
    """At Poisson's ratio 1/4 the elastic model has no c0 term, so the damping force density of a velocity field v is
    tau times the elastic force density of the displacement field s v, over s, to first order in s: within 1e-3 of
    its largest value for a smooth random field (s = 1e-4 s), with either form of the bond passes."""
    tau = 1.0e-4
    body, _ = _bar(tau)
    x = body.rest_positions - body.rest_positions.mean(axis=0)
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((3, 3)), rng.standard_normal((3, 3))
    field = np.sin(x @ a * 4.0) + np.cos(x @ b * 3.0)  # smooth on the 2.5 cm spacing
    damped = pdsim.SolverPeridynamics([body], pairs=pairs)
    damped.set_velocities(field)
    f_damping = damped.force_density()
    body0, _ = _bar(0.0)
    elastic = pdsim.SolverPeridynamics([body0], pairs=pairs)
    scale = 1.0e-4
    elastic.set_displacements(scale * field)
    f_elastic = tau * elastic.force_density() / scale
    assert np.abs(f_damping).max() > 0.0
    np.testing.assert_allclose(f_damping, f_elastic, rtol=0, atol=1.0e-3 * np.abs(f_elastic).max())
    assert "internal_damping" in damped.features and "internal_damping" not in elastic.features  # --explain lists it


def test_rigid_fragments_are_not_damped():
    """Once both halves of a notched block are rigid fragments the damping visits none of their bonds: an expansion
    rate gives them no force density, where it gives one above 1e3 N/m^3 before the hand-off."""
    material = pdsim.Material(
        density=2500.0, youngs_modulus=5.0e9, poisson_ratio=0.25, critical_stretch=2.0e-3, retardation_time=1.0e-7
    )
    body = pdsim.PeridynamicBody(
        pdsim.box((0.08, 0.04, 0.04)), material, 0.01, rigid_handoff=pdsim.RigidHandoff(strain=1.0, frames=1)
    )
    body.add_notch(pdsim.BoxRegion(lo=(-0.001, -1.0, -1.0), hi=(0.001, 1.0, 1.0)))
    s = pdsim.SolverPeridynamics([body], threads=1)
    x = s.positions()
    s.set_velocities(0.1 * (x - x.mean(axis=0)))
    before = np.abs(s.force_density()).max()
    assert s.handoff.update() == 2 and s.handoff.rigid_particles().all()
    s.set_velocities(0.1 * (x - x.mean(axis=0)))
    assert before > 1.0e3
    assert np.abs(s.force_density()).max() == 0.0


def test_a_ringing_fragment_calms_down_and_is_handed_off():
    """The stretched half of tests/test_rigid_handoff.py, let go, rings above the hand-off's threshold for 10 frames
    without damping (that test); with a retardation time of 1e-6 s (damping ratio 0.06 at its 19 kHz first mode, z =
    0.18) its vibration falls below the threshold and it is handed off by frame 8."""
    from test_rigid_handoff import _stretched_half

    s, half = _stretched_half(tau=1.0e-6)
    dt = 0.5 * s.stable_time_step()
    handed = None
    for frame in range(1, 11):
        s.simulate(dt, 47)
        s.handoff.update()
        if handed is None and s.handoff.rigid_particles()[half].all():
            handed = frame
    assert handed is not None and handed <= 8


def _damped_pieces(frames=16):
    """tests/test_rigid_handoff.py's notched block thrown at the ground, its material with a retardation time of
    2e-6 s (z = tau / dt0 of about 0.05)."""
    from test_rigid_handoff import _pieces

    scene = _pieces(frames)
    for body in scene.bodies:
        body.material = dataclasses.replace(body.material, retardation_time=2.0e-6)
    return scene


def test_resume_with_internal_damping_is_bit_identical(tmp_path):
    """Stopped after frame 1 (the halves still deformable and damped; they go rigid at frame 2), then resumed: the
    cache equals the uninterrupted run's bit for bit (the force pass reads the velocities the checkpoint restores)."""
    from test_resume_cache import _assert_resume_is_bit_identical

    _assert_resume_is_bit_identical(_damped_pieces, tmp_path, 1, 16)
